"""Scripted gripper session in one process: open, grasp a virtual object, hold, release."""

import argparse
import math
import pathlib
import signal
import sys
import time

from diagnostic_msgs.msg import DiagnosticStatus
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from std_msgs.msg import Float64

from fpc_gripper.grasp.objects import OBJECTS
from fpc_gripper.io.config import default_gripper_config_path
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.io.messages import gripper_topics
from fpc_gripper.io.qos import RELIABLE_QOS
from fpc_gripper.io.session_chart import make_chart
from fpc_gripper.io.session_chart import message_count
from fpc_gripper.nodes.gripper import bridge_exit_code
from fpc_gripper.nodes.gripper import compose
from fpc_gripper.nodes.middleware import apply_middleware_settings
from fpc_gripper.nodes.runner import make_executor
from fpc_gripper.nodes.runner import own_arguments
from fpc_gripper.nodes.runner import SPIN_TIMEOUT_S
from fpc_gripper.nodes.runner import StopRequest
from fpc_gripper.services.session import default_phases
from fpc_gripper.services.session import format_summary
from fpc_gripper.services.session import Phase
from fpc_gripper.services.session import Session

__all__ = ['Phase', 'SessionScript', 'main', 'run_session']


class SessionScript(Node):
    """
    Drive the controller through a list of phases, from timers, and judge each one.

    The judging is :class:`fpc_gripper.services.session.Session`'s; this node publishes
    each phase's goal on ``aperture_command`` or ``grasp_force_command`` and gives it what
    ``controller_state`` says. `done` completes (every phase reached its goal, or not)
    after the last phase or the first failure.
    """

    def __init__(self, phases, grasp_force, dwell_s=0.5, force_band=0.10, arcs=None,
                 **kwargs):
        super().__init__('session_script', **kwargs)
        self.done = Future()
        self._aperture_pub = self.create_publisher(Float64, 'aperture_command', RELIABLE_QOS)
        self._force_pub = self.create_publisher(Float64, 'grasp_force_command', RELIABLE_QOS)
        self.create_subscription(DiagnosticStatus, 'controller_state', self._on_state,
                                 RELIABLE_QOS)
        self._session = Session(phases, grasp_force, self._now(), dwell_s, force_band, arcs)
        self._timer = self.create_timer(0.02, self._on_timer)

    @property
    def phases(self):
        """The phases, as judged so far."""
        return self._session.phases

    @property
    def state(self):
        """The newest controller_state values (with ``level`` and ``message``)."""
        return self._session.state

    def _now(self):
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_state(self, msg):
        state = {kv.key: kv.value for kv in msg.values}
        state['level'] = int.from_bytes(msg.level, 'little') if isinstance(
            msg.level, bytes) else int(msg.level)
        state['message'] = msg.message
        self._session.state = state

    def _on_timer(self):
        ready = (self._aperture_pub.get_subscription_count() > 0
                 and self._force_pub.get_subscription_count() > 0)
        phase = self._session.step(self._now(), ready)
        if phase is not None:
            if phase.kind == 'aperture':
                self._aperture_pub.publish(Float64(data=phase.value))
            elif phase.kind == 'grasp':
                self._force_pub.publish(Float64(data=phase.value))
            self.get_logger().info(f'phase {phase.name}: {phase.kind} {phase.value:g}')
        if self._session.finished:
            self._timer.cancel()
            if not self.done.done():
                self.done.set_result(self._session.passed)


def run_session(output_dir, object_diameter=0.040, grasp_force=1.5, open_aperture=0.120,
                hold_s=3.0, context=None, gripper_config=None, obj='cylinder', mu=0.5,
                stop_requested=None):
    """
    Run the composed gripper (`fpc_gripper.nodes.gripper.compose`) and the session script.

    The nodes are the ones the ``gripper`` executable runs with ``--record
    --virtual-object``, on the same executor, with the demo's parameters on top of
    their defaults.

    Parameters
    ----------
    obj : {'cylinder', 'sphere', 'box'}
        The virtual object (resting on the palm), of size `object_diameter` [m].
    grasp_force : float
        Total normal force on the object to grasp with [N].
    mu : float
        Friction coefficient of the holding force reported for the hold phase [-].
    stop_requested : callable, optional
        True when the session is to end early (a stop signal); checked every 0.1 s.

    Returns
    -------
    phases : list of Phase
    info : dict
        mcap path, message count, contact residual [m], wall time [s], max command [Pa].

    """
    output_dir = pathlib.Path(output_dir)
    output_dir.mkdir(parents=True, exist_ok=True)
    mcap_path = output_dir / 'session.mcap'
    config_path = str(gripper_config or default_gripper_config_path())
    config = load_gripper_config(config_path)
    common = {'context': context} if context is not None else {}
    cfg = Parameter('gripper_config', value=config_path)
    described = [Parameter('object', value=obj),
                 Parameter('object_diameter', value=float(object_diameter))]
    topics = [t for t in gripper_topics(config.names) if not t.endswith('/rigidity')]
    overrides = {
        'regulator_bridge': [cfg, Parameter('backend', value='sim'),
                             Parameter('publish_rate_hz', value=50.0)],
        # Default model settings throughout: the model node, the controller's inverse and
        # the virtual object all compute the finger through the same pipeline. No
        # rigidity: K_x and K_z take two more solves per new pressure, and the session
        # does not use them.
        'model_node': [cfg, Parameter('pressure_input', value='measured'),
                       Parameter('max_rate_hz', value=10.0),
                       Parameter('rigidity_rate_hz', value=0.0)],
        # The controller is told the object, as a robot is by its perception.
        'gripper_controller': [cfg, *described],
        'virtual_object': [cfg, *described],
        'mcap_recorder': [Parameter('output_path', value=str(mcap_path)),
                          Parameter('overwrite', value=True), Parameter('topics', value=topics),
                          Parameter('discovery_period_s', value=0.2), cfg]}
    wall = time.monotonic()
    nodes = compose(record=True, virtual_object=True, overrides=overrides, **common)
    by_name = {node.get_name(): node for node in nodes}
    recorder, virtual = by_name['mcap_recorder'], by_name['virtual_object']
    controller = by_name['gripper_controller']
    executor = None
    try:
        if bridge_exit_code(nodes) is not None:
            raise RuntimeError('the regulator bridge did not activate (its log says why)')
        script = SessionScript(default_phases(open_aperture, grasp_force, hold_s),
                               grasp_force, arcs=virtual.arcs, **common)
        nodes.append(script)
        executor, _ = make_executor(nodes)
        deadline = time.monotonic() + 30.0 + sum(p.timeout for p in script.phases)
        stop_requested = stop_requested or (lambda: False)
        while not (script.done.done() or stop_requested()) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)
        max_command = getattr(controller, 'max_command_seen', math.nan)
        recorder.close()
        for phase in script.phases:
            if phase.kind == 'hold' and phase.reached:
                pressures = [float(v) for k, v in phase.final.items()
                             if k.endswith('command_pa')]
                phase.holding = virtual.virtual.holding_force(
                    sum(pressures) / len(pressures), mu).holding_force
        info = {'mcap': mcap_path, 'messages': message_count(mcap_path),
                'contact_residual': max((virtual.residual(p.start, p.end)
                                         for p in script.phases if p.kind == 'hold'),
                                        default=math.nan),
                'wall_s': time.monotonic() - wall, 'max_command': max_command,
                'max_pressure': config.max_pressure}
        return script.phases, info
    finally:
        if executor is not None:
            executor.shutdown()
        for node in reversed(nodes):
            node.destroy_node()


def main(args=None):
    """Run the scripted session; exit 0 only if every phase reached its goal."""
    # Ctrl-C or SIGTERM: the session ends, its nodes are destroyed (the recording closed),
    # exit 130. rclpy's own handlers would shut the context down under running callbacks.
    stop = StopRequest()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, stop)
    argv = own_arguments(args, 'gripper_demo')
    if argv is None:
        return 1
    parser = argparse.ArgumentParser(prog='gripper_demo', description=__doc__)
    parser.add_argument('--output-dir', default='.', help='writes session.mcap and session.png')
    parser.add_argument('--object', default='cylinder', choices=OBJECTS,
                        help='virtual object, resting on the palm')
    parser.add_argument('--object-diameter', type=float, default=0.040, help='[m]')
    parser.add_argument('--grasp-force', type=float, default=1.5,
                        help='total normal force on the object [N]')
    parser.add_argument('--mu', type=float, default=0.5,
                        help='friction coefficient of the reported holding force [-]')
    parser.add_argument('--open-aperture', type=float, default=0.120, help='[m]')
    parser.add_argument('--hold', type=float, default=3.0, help='hold duration [s]')
    parser.add_argument('--gripper-config', default=None, help='gripper YAML')
    options = parser.parse_args(argv[1:])
    apply_middleware_settings()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    phases, info = [], None
    try:
        phases, info = run_session(options.output_dir, options.object_diameter,
                                   options.grasp_force, options.open_aperture, options.hold,
                                   gripper_config=options.gripper_config,
                                   obj=options.object, mu=options.mu,
                                   stop_requested=lambda: stop.requested)
    except ExternalShutdownException:
        return 130
    finally:
        stop.stopping = True
        rclpy.try_shutdown()
    if stop.requested:
        print(f'session stopped by signal {stop.signum}; recording: {info["mcap"]}')
        return 130
    png = pathlib.Path(options.output_dir) / 'session.png'
    try:
        make_chart(info['mcap'], png, phases, options.grasp_force)
        chart = f'chart: {png}'
    except Exception as exc:  # noqa: BLE001 - the session result still stands; say why
        chart = f'chart failed: {exc}'
        phases.append(Phase('chart', 'hold', 0.0, detail=str(exc)))
    print(format_summary(phases, info))
    print(chart)
    ok = bool(phases) and all(p.reached for p in phases)
    print('session ' + ('PASSED: every phase reached its goal' if ok else 'FAILED'))
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
