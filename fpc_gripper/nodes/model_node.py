"""Node that turns finger pressures and tip forces into CCM shapes, curvatures and rigidities."""

import functools
import math
import sys
import threading
import time

from geometry_msgs.msg import WrenchStamped
from rclpy.clock import Clock
from rclpy.clock import ClockType
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import FluidPressure

from fpc_gripper.io.config import default_gripper_config_path
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.io.messages import FingerPlacement
from fpc_gripper.io.qos import RELIABLE_QOS
from fpc_gripper.model.pipeline import finger_model
from fpc_gripper.model.pipeline import ModelSettings
from fpc_gripper.nodes.guard import InputGuard
from fpc_gripper.nodes.model_outputs import ModelOutputs
from fpc_gripper.nodes.parameters import check_change
from fpc_gripper.nodes.parameters import declare_table
from fpc_gripper.nodes.parameters import input_bounds
from fpc_gripper.nodes.runner import run_node
from fpc_gripper.services.input_limits import BOUND_NAMES
from fpc_gripper.services.logs import NodeLog
from fpc_gripper.services.model_core import ModelCore
from fpc_gripper.services.model_parameters import parameter_table
from fpc_gripper.services.model_parameters import refusal
from fpc_gripper.services.model_parameters import SOLVER_PARAMETERS

_DIAGNOSTICS_PERIOD_S = 1.0
_PALM_FRAME = 'palm'


class ModelNode(Node):
    """
    Publish the CCM equilibrium of every finger of a gripper in answer to its inputs.

    Per finger ``finger_<i>`` of the gripper config it subscribes ``pressure_command`` (or
    ``pressure`` with ``pressure_input:=measured``; absolute [Pa]) and ``tip_force``
    (frame ``<frame_prefix>finger_<i>``, force.x = f0, force.z = p0 [N]) and publishes
    ``shape`` (nav_msgs/Path) and ``curvature`` (std_msgs/Float64, [1/m]) for every
    solved input, ``rigidity`` (x = K_x, z = K_z [N·m²], at most ``rigidity_rate_hz``),
    and ``markers`` and ``gripper_shape`` (MarkerArray in the palm frame; at most 30 Hz
    while subscribed, 1 Hz otherwise, the newest state always sent), plus
    ``/diagnostics`` (1 Hz and on every change of a finger's level or kind of problem).
    With tf2_msgs importable it also sends tf: palm -> finger_<i> (the mounts) on
    /tf_static, and finger_<i> -> finger_<i>_tip (the shape's last pose, stamped with the
    answered input) on /tf with every shape.

    Nothing is published for a finger before its first valid pressure (its diagnostics
    say "waiting for pressure input" at WARN). Shape, curvature, rigidity and markers are
    transient local, depth 1 for readers: a late subscriber gets the newest state from the
    publisher's history, and every message answers an input. With
    ``FPC_GRIPPER_WRITER_HISTORY_S`` set, their writers keep that many seconds at their
    rate, so a recorder that stalls that long loses none (`io.qos.writer_qos`; the depth is
    set at the start value of ``max_rate_hz``). Bad inputs are rejected and
    a failed solve publishes nothing: each finger keeps its last good state (see
    :class:`~fpc_gripper.services.model_core.ModelCore`). Every input is checked before any
    solve or serialisation against bounds that are parameters: payload size (checked
    before decoding: inputs are raw subscriptions), header stamp (a valid time, not
    older than ``stale_after_s`` nor more than ``future_limit_s`` ahead of the node
    clock), frame_id length, absolute pressure (``min_absolute_pressure`` up to
    atmospheric plus the gripper's limit) and tip force magnitude (``max_tip_force``,
    within the model's envelope); a refused payload and a message the middleware lost
    are reported too. Outputs carry the header stamp of the input they answer (its
    arrival time when unstamped): a stamp that passed these checks, so always a valid
    time.

    Parameters
    ----------
    node_name : str
        Node name.
    solver_factory : callable, optional
        ``solver_factory(design, settings)`` with a
        :class:`~fpc_gripper.model.pipeline.ModelSettings`; default
        :func:`~fpc_gripper.model.pipeline.finger_model`, the one finger pipeline.
    **kwargs
        Passed to :class:`rclpy.node.Node` (namespace, parameter_overrides, context, ...).

    Raises
    ------
    ValueError
        On an unreadable gripper config or an invalid parameter value.
    rclpy.exceptions.ParameterException
        On a parameter override of the wrong type or out of its range.

    """

    def __init__(self, node_name='model_node', *, solver_factory=None, **kwargs):
        super().__init__(node_name, **kwargs)
        try:
            self._set_up(solver_factory)
        except Exception:
            self.destroy_node()
            raise

    def _set_up(self, solver_factory):
        table = parameter_table(str(default_gripper_config_path()))
        declare_table(self, table)
        # Overrides bypass the on-set callback: check the starting values the same way.
        result = self._validate_parameters([self.get_parameter(n) for n, *_ in table])
        if not result.successful:
            raise ValueError(result.reason)
        self._solver_factory = solver_factory or finger_model
        self._lock = threading.RLock()
        # Rate budget and timers run on steady time (time.monotonic_ns), so that they keep
        # going while a simulated clock stands still; staleness uses the node clock.
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        param = self.get_parameter
        config = load_gripper_config(param('gripper_config').value)
        if abs(param('atmospheric_pressure').value - config.atmospheric_pressure) > 1.0:
            self.get_logger().info(
                f'atmospheric_pressure parameter {param("atmospheric_pressure").value:.0f} Pa '
                f'differs from the gripper config {config.atmospheric_pressure:.0f} Pa; '
                'the parameter is used')
        prefix = param('frame_prefix').value
        self._core = ModelCore(
            [(f.name, f.design) for f in config.fingers], self._create_solver,
            max_pressure=config.max_pressure,
            atmospheric_pressure=param('atmospheric_pressure').value,
            stale_after_s=param('stale_after_s').value,
            max_rate_hz=param('max_rate_hz').value, frame_prefix=prefix,
            future_limit_s=param('future_limit_s').value, bounds=input_bounds(self))
        self._log = NodeLog(self.get_logger())
        self._guard = InputGuard(param('max_payload_bytes').value)
        self._core.warm_up(rigidity=param('rigidity_rate_hz').value > 0.0)
        names = self._core.names
        self._frames = tuple(prefix + name for name in names)
        self._palm_frame = prefix + _PALM_FRAME
        self._placements = tuple(FingerPlacement(config.palm_radius, f.mount_angle)
                                 for f in config.fingers)
        self._outputs = ModelOutputs(self, self._core, self._frames, self._palm_frame,
                                     self._placements, self._lock, self._steady,
                                     self._now_ns, self._rigidity_period(),
                                     param('publish_tf').value, param('max_rate_hz').value)
        self._subscribe_inputs(names)
        self._rate_timer = self.create_timer(1.0 / param('max_rate_hz').value, self._on_timer,
                                             clock=self._steady)
        self._rate_timer.cancel()
        self._diagnostics_timer = self.create_timer(
            _DIAGNOSTICS_PERIOD_S, functools.partial(self._outputs.publish_diagnostics, True),
            clock=self._steady)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.get_logger().info(
            f'ready: {len(names)} fingers ({", ".join(names)}), tolerance '
            f'{param("tolerance").value} m, n_segments {param("n_segments").value}, '
            f'{param("pressure_model").value} pressure model, '
            f'input {self._pressure_topic}, max_rate_hz {param("max_rate_hz").value:g}, '
            f'frames {self._palm_frame} -> {", ".join(self._frames)} '
            f'({self._outputs.tf_state}); '
            'waiting for pressure input')
        self._outputs.publish_diagnostics(force=True)

    # -- public helpers ---------------------------------------------------------------------

    @property
    def core(self):
        """The ROS-free model state (:class:`~fpc_gripper.services.model_core.ModelCore`)."""
        return self._core

    @property
    def finger_names(self):
        """Finger names of the gripper config, in index order."""
        return self._core.names

    @property
    def palm_frame(self):
        """Frame id of the palm, ``<frame_prefix>palm``."""
        return self._palm_frame

    @property
    def finger_frames(self):
        """Frame id of every finger, ``<frame_prefix><finger name>``, in index order."""
        return self._frames

    @property
    def placements(self):
        """Clamp of every finger on the palm (FingerPlacement), in index order."""
        return self._placements

    def settings(self):
        """Return the :class:`~fpc_gripper.model.pipeline.ModelSettings` of the parameters."""
        param = self.get_parameter
        return ModelSettings(tolerance=param('tolerance').value,
                             n_segments=param('n_segments').value,
                             pressure_model=param('pressure_model').value)

    def destroy_node(self):
        """Close the input guard's lost-message handles, then destroy the node."""
        guard = getattr(self, '_guard', None)   # None when the set-up failed before it
        if guard is not None:
            guard.close()
        return super().destroy_node()

    def _create_solver(self, design):
        """Build the solver of one design through the finger pipeline (or the injected one)."""
        return self._solver_factory(design, self.settings())

    # -- set-up -----------------------------------------------------------------------------

    def _subscribe_inputs(self, names):
        if self.get_parameter('pressure_input').value == 'measured':
            self._pressure_topic, qos = 'pressure', qos_profile_sensor_data
        else:
            self._pressure_topic, qos = 'pressure_command', RELIABLE_QOS
        self._pressure_subs = tuple(
            self._subscribe(i, FluidPressure, self._pressure_topic, qos, self._on_pressure)
            for i in range(len(names)))
        self._force_subs = tuple(
            self._subscribe(i, WrenchStamped, 'tip_force', RELIABLE_QOS, self._on_tip_force)
            for i in range(len(names)))

    def _subscribe(self, index, msg_type, topic, qos, callback):
        """Subscribe one input of a finger through the guard (raw, size- and decode-checked)."""
        name = self._core.names[index]
        return self._guard.subscribe(
            self, msg_type, f'{name}/{topic}', qos, functools.partial(callback, index),
            functools.partial(self._on_refused, index, topic),
            functools.partial(self._on_lost, index, topic))

    def _rigidity_period(self):
        rate = self.get_parameter('rigidity_rate_hz').value
        return 1.0 / rate if rate > 0.0 else math.inf

    # -- parameters -------------------------------------------------------------------------

    def _validate_parameters(self, parameters):
        return check_change(self, parameters, refusal, getattr(self, '_frames', ()))

    def _apply_parameters(self, parameters):
        values = {p.name: p.value for p in parameters}
        with self._lock:
            if 'atmospheric_pressure' in values:
                self._core.atmospheric_pressure = values['atmospheric_pressure']
            if 'stale_after_s' in values:
                self._core.stale_after_s = values['stale_after_s']
            if 'future_limit_s' in values:
                self._core.future_limit_s = values['future_limit_s']
            if values.keys() & set(BOUND_NAMES):
                self._core.bounds = input_bounds(self)
                self._guard.max_payload_bytes = self._core.bounds.max_payload_bytes
            if 'max_rate_hz' in values:
                self._core.max_rate_hz = values['max_rate_hz']
                self._rate_timer.timer_period_ns = int(round(1e9 / values['max_rate_hz']))
            if 'rigidity_rate_hz' in values:
                self._outputs.set_rigidity_period(self._rigidity_period())
            if values.keys() & set(SOLVER_PARAMETERS):
                self._core.rebuild(self._create_solver)
                self.get_logger().info(
                    f'solvers rebuilt: tolerance {self.get_parameter("tolerance").value} m, '
                    f'n_segments {self.get_parameter("n_segments").value}, '
                    f'{self.get_parameter("pressure_model").value} pressure model')
                self._run(range(len(self._core.fingers)))

    # -- inputs -----------------------------------------------------------------------------

    def _now_ns(self):
        # The rcl clock's reading (ROS time, simulated or not) without rclpy's Time object.
        clock = self.get_clock().handle
        with clock:
            return clock.get_now().nanoseconds

    def _on_pressure(self, index, msg):
        header = msg.header
        with self._lock:
            check = self._core.offer_pressure(
                index, msg.fluid_pressure, (header.stamp.sec, header.stamp.nanosec),
                self._now_ns(), source=self._pressure_topic, frame_id=header.frame_id)
            self._after_input(index, check, self._pressure_topic)

    def _on_tip_force(self, index, msg):
        header, force = msg.header, msg.wrench.force
        with self._lock:
            check = self._core.offer_tip_force(
                index, force.x, force.z, header.frame_id,
                (header.stamp.sec, header.stamp.nanosec), self._now_ns())
            self._after_input(index, check, 'tip_force')

    def _on_refused(self, index, topic, check):
        """Report a payload the guard refused (too large, or no message of the type)."""
        with self._lock:
            self._after_input(index, self._core.reject(index, check.rejection, check.detail,
                                                       topic), topic)

    def _on_lost(self, index, topic, count):
        """Report messages the middleware lost on an input (see README: empty payloads)."""
        with self._lock:
            self._after_input(index, self._core.lost(index, count, topic), topic)

    def _after_input(self, index, check, topic):
        if not check.accepted:
            name = self._core.names[index]
            self._log.warning(
                f'{check.headline(f"{name}/{topic}")}, keeping the last good state: '
                f'{check.detail}', key=(index, check.rejection))
            self._outputs.publish_diagnostics()
            return
        self._run(self._core.ready(time.monotonic_ns()))
        if self._core.pending:
            self._wake()

    def _on_timer(self):
        with self._lock:
            self._run(self._core.ready(time.monotonic_ns()))
            if not self._core.pending:
                self._rate_timer.cancel()

    def _wake(self):
        if self._rate_timer.is_canceled():
            self._rate_timer.reset()

    # -- outputs ----------------------------------------------------------------------------

    def _run(self, indices):
        """Process the given fingers' pending input and publish what changed."""
        updates = self._core.process(indices, time.monotonic_ns())
        if not updates:
            return
        self._outputs.publish(updates)
        for update in updates:
            if update.result is None:
                state = self._core.fingers[update.index]
                self._log.error(
                    f'{state.name}: solve at {state.gauge:.1f} Pa gauge, tip force '
                    f'({state.tip_force[0]:g}, {state.tip_force[1]:g}) N failed, keeping the '
                    f'last good state: {update.failure}', key=(update.index, 'solver'))


def main(args=None):
    """Run the model node until SIGINT or SIGTERM: 0 then, 2 on a bad config, else 1."""
    return run_node(ModelNode, 'model_node', args)


if __name__ == '__main__':
    sys.exit(main())
