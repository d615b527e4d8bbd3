"""GripperCommand goals (control_msgs' meaning) on the control law, free of ROS."""

import dataclasses
import enum
import math

from .controller import FingerPhase, GoalStatus, Mode

__all__ = ['CommandGoal', 'CommandResult', 'Outcome', 'check_goal']


class Outcome(str, enum.Enum):
    """How a goal ends: the action's terminal states."""

    SUCCEEDED = 'succeeded'
    ABORTED = 'aborted'
    CANCELED = 'canceled'


@dataclasses.dataclass(frozen=True)
class CommandResult:
    """
    A goal's feedback or result, with the fields of ``control_msgs/action/GripperCommand``.

    Attributes
    ----------
    position : float
        The aperture estimate [m] (nan when unknown).
    effort : float
        The estimated total normal force of the fingers on the object [N].
    stalled : bool
        An object stopped the fingers before the goal, and they hold it.
    reached_goal : bool
        The aperture settled within the controller's ``goal_tolerance_m`` of the goal.
    outcome : Outcome or None
        None while the goal runs (feedback).
    message : str
        Why it ended, for the log.

    """

    position: float
    effort: float
    stalled: bool
    reached_goal: bool
    outcome: Outcome = None
    message: str = ''


def check_goal(law, position, max_effort):
    """
    Return why a goal cannot be taken ('' when it can).

    Parameters
    ----------
    law : GripperControlLaw
    position : float
        Aperture goal [m]: within `GripperControlLaw.aperture_range`.
    max_effort : float
        Limit on the total normal force [N], >= 0 (0: no limit).

    """
    low, high = law.aperture_range()
    if not math.isfinite(position) or not low <= position <= high:
        return (f'position must be within the aperture range {low * 1e3:.1f}..'
                f'{high * 1e3:.1f} mm, got {position * 1e3:g} mm')
    if not math.isfinite(max_effort) or max_effort < 0.0:
        return f'max_effort must be >= 0 [N] (0: no limit), got {max_effort:g} N'
    return ''


def _in_contact(law, out):
    threshold = law.config.contact_threshold_n
    return any(f.phase is FingerPhase.CONTACT or f.contact_force >= threshold
               for f in out.fingers)


class CommandGoal:
    """
    One GripperCommand goal on a `GripperControlLaw`: started, then stepped until it ends.

    The goal starts as an aperture goal. While closing, an object the fingers touch
    stops them: with a force limit (``max_effort`` > 0) the law then holds that total
    normal force on it (its grasp mode), and the goal ends STALLED once the force has
    settled, with the force as ``effort``. Without a limit the fingers press as the
    aperture goal drives them, and the goal ends stalled at the law's stall timeout. An
    aperture that settles within tolerance ends it with ``reached_goal``. Lost pressure
    feedback (the law's safe state) aborts it; a cancel holds the present pressures.

    Parameters
    ----------
    law : GripperControlLaw
    position, max_effort : float
        As `check_goal` accepts them.
    now : float
        [s].

    Raises
    ------
    ValueError
        With `check_goal`'s reason.

    """

    def __init__(self, law, position, max_effort, now):
        reason = check_goal(law, position, max_effort)
        if reason:
            raise ValueError(reason)
        self.law = law
        self.position = float(position)
        self.max_effort = float(max_effort)
        self.grasping = False
        law.set_aperture(self.position, now)

    @staticmethod
    def _report(out, **fields):
        """Return the CommandResult of a step's output (None before the first step: unknown)."""
        position = math.nan if out is None else out.aperture
        effort = 0.0 if out is None or not math.isfinite(out.normal_force) \
            else out.normal_force
        values = dict(position=position, effort=effort, stalled=False, reached_goal=False)
        values.update(fields)
        return CommandResult(**values)

    def update(self, out, now):
        """
        Take the law's output of a step; return the result when the goal ends, else None.

        Parameters
        ----------
        out : ControlOutput
            Of the step just taken.
        now : float
            [s].

        """
        if out.status is GoalStatus.FAULT:
            return self._report(out, outcome=Outcome.ABORTED, message=out.message)
        contact = _in_contact(self.law, out)
        if not self.grasping:
            closing = math.isfinite(out.aperture) and self.position < out.aperture
            if self.max_effort > 0.0 and contact and closing:
                self.law.set_grasp_force(self.max_effort, now)
                self.grasping = True
                return None
            if out.status is GoalStatus.REACHED:
                return self._report(out, reached_goal=True, outcome=Outcome.SUCCEEDED,
                                    message=out.message)
            if out.status is GoalStatus.STALLED:
                # Held by an object: what the action calls stalled. Nothing in the way:
                # the aperture was not reached, a failure.
                outcome = Outcome.SUCCEEDED if contact else Outcome.ABORTED
                return self._report(out, stalled=contact, outcome=outcome,
                                    message=out.message)
            return None
        if out.status in (GoalStatus.REACHED, GoalStatus.STALLED):
            return self._report(out, stalled=True, outcome=Outcome.SUCCEEDED,
                                message=f'stalled on an object, holding {out.message}')
        if not contact and math.isfinite(out.aperture) and out.aperture <= self.position:
            # The object went away: back to the aperture goal.
            self.law.set_aperture(self.position, now)
            self.grasping = False
        return None

    def feedback(self, out):
        """Return the feedback of a running goal for a step's output."""
        return self._report(out, stalled=self.grasping and out.mode is Mode.GRASP)

    def cancel(self, out, now):
        """Hold the present pressures and return the CANCELED result (`out` may be None)."""
        self.law.hold(now)
        return self._report(out, outcome=Outcome.CANCELED,
                            message='canceled: holding the present pressures')

    def abort(self, out, why):
        """Return the ABORTED result of a goal something else ended (`out` may be None)."""
        return self._report(out, outcome=Outcome.ABORTED, message=why)
