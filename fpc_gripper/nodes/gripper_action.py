"""The gripper controller's control_msgs/GripperCommand action server, for MoveIt and friends."""

import functools
import math

from rclpy.action import ActionServer
from rclpy.action import CancelResponse
from rclpy.action import GoalResponse

from fpc_gripper.control.gripper_command import check_goal
from fpc_gripper.control.gripper_command import CommandGoal
from fpc_gripper.control.gripper_command import Outcome
from fpc_gripper.services.periods import period_passed

__all__ = ['FEEDBACK_PERIOD_S', 'GripperCommandServer']

#: Feedback at 20 Hz at most (the control steps may come faster) [s].
FEEDBACK_PERIOD_S = 0.05


class GripperCommandServer:
    """
    Serve ``control_msgs/action/GripperCommand`` at ``<node name>/gripper_cmd``.

    A goal runs as a `CommandGoal` on the controller's law, stepped by the controller's
    loop (`step`). A new goal, or a command on the simple Float64 topics (`preempt`),
    ends the running goal ABORTED. A cancel holds the present pressures at once; the
    goal ends CANCELED at the next step.

    Parameters
    ----------
    node : rclpy.node.Node
        The controller.
    law : GripperControlLaw
    now : callable
        The controller's time [s].
    log : NodeLog

    Raises
    ------
    ImportError
        When control_msgs is not importable.

    """

    def __init__(self, node, law, now, log):
        from control_msgs.action import GripperCommand
        self._action = GripperCommand
        self._law = law
        self._now = now
        self._log = log
        self._active = None     # (goal handle, CommandGoal) of the running goal
        self._concluding = 0    # ended goals whose execution has not run yet
        self._last_out = None
        self._last_feedback = None
        self.name = f'{node.get_name()}/gripper_cmd'
        self._server = ActionServer(
            node, GripperCommand, self.name, self._unplanned,
            goal_callback=self._on_goal, handle_accepted_callback=self._on_accepted,
            cancel_callback=self._on_cancel)

    def stopping(self):
        """Abort a running goal; return a check that its execution ran, or None if none."""
        if not self.preempt('the controller is stopping'):
            return None
        return lambda: not self._concluding

    def destroy(self):
        """Abort a running goal and destroy the server."""
        self.preempt('the controller is shutting down')
        self._server.destroy()

    # -- the controller's side --------------------------------------------------------------

    def step(self, out):
        """Take a control step's output: end, cancel or give feedback on the running goal."""
        self._last_out = out
        if self._active is None:
            return
        handle, goal = self._active
        now = self._now()
        if handle.is_cancel_requested:
            self._finish(goal.cancel(out, now))
            return
        result = goal.update(out, now)
        if result is not None:
            self._finish(result)
        elif period_passed(self._last_feedback, now, FEEDBACK_PERIOD_S):
            self._last_feedback = now
            handle.publish_feedback(self._message(self._action.Feedback, goal.feedback(out)))

    def preempt(self, why):
        """End the running goal ABORTED because something else drives the law; True if any."""
        if self._active is None:
            return False
        self._finish(self._active[1].abort(self._last_out, why))
        return True

    # -- the action's side ------------------------------------------------------------------

    def _on_goal(self, request):
        command = request.command
        reason = check_goal(self._law, command.position, command.max_effort)
        if reason:
            self._log.warning(f'{self.name}: goal rejected: {reason}')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _on_accepted(self, handle):
        # A deferred goal (rclpy's term): it runs on the law, stepped by the control loop,
        # and is executed only once its result is known. An execute callback that waited
        # instead would be a pending task, which rclpy's executors poll on every spin.
        command = handle.request.command
        self.preempt('preempted by a new goal')
        self._active = (handle, CommandGoal(self._law, command.position, command.max_effort,
                                            self._now()))
        self._last_feedback = None
        self._log.info(f'{self.name}: goal {command.position * 1e3:.1f} mm, max_effort '
                       f'{command.max_effort:g} N')

    def _on_cancel(self, handle):
        if self._active is not None and self._active[0] is handle:
            # The pressures stop changing now; the goal ends at the next step.
            self._law.hold(self._now())
            return CancelResponse.ACCEPT
        return CancelResponse.REJECT

    def _finish(self, result):
        handle, _ = self._active
        self._active = None
        self._concluding += 1
        handle.execute(functools.partial(self._conclude, result))

    def _unplanned(self, handle):
        """Abort a goal executed other than through `_finish` (nothing here does that)."""
        handle.abort()
        return self._action.Result()

    def _conclude(self, result, handle):
        """Execute callback of an ended goal: set its terminal state, return its result."""
        self._concluding -= 1
        if result.outcome is Outcome.SUCCEEDED:
            handle.succeed()
        elif result.outcome is Outcome.CANCELED and handle.is_cancel_requested:
            handle.canceled()
        else:
            handle.abort()
        self._log.info(f'{self.name}: {result.outcome.value}: {result.message}')
        return self._message(self._action.Result, result)

    @staticmethod
    def _message(cls, result):
        position = result.position if math.isfinite(result.position) else 0.0
        return cls(position=position, effort=float(result.effort),
                   stalled=bool(result.stalled), reached_goal=bool(result.reached_goal))
