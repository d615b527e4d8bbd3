"""Node that turns finger pressures and tip forces into CCM shapes, curvatures and rigidities."""

import functools
import math
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_msgs.msg import KeyValue
from geometry_msgs.msg import Vector3Stamped
from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Path
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock
from rclpy.clock import ClockType
from rclpy.node import Node
from rclpy.qos import HistoryPolicy
from rclpy.qos import qos_profile_sensor_data
from rclpy.qos import QoSProfile
from rclpy.qos import ReliabilityPolicy
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import FluidPressure
from std_msgs.msg import Float64
from visualization_msgs.msg import MarkerArray

from fpc_gripper.io.config import default_gripper_config_path
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.io.messages import curvature_message
from fpc_gripper.io.messages import FingerPlacement
from fpc_gripper.io.messages import ns_to_time
from fpc_gripper.io.messages import rigidity_message
from fpc_gripper.io.messages import serialized_gripper_shape
from fpc_gripper.io.messages import serialized_shape
from fpc_gripper.io.messages import serialized_shape_markers
from fpc_gripper.io.messages import shape_message
from fpc_gripper.io.messages import STATE_QOS
from fpc_gripper.io.tf import palm_transform
from fpc_gripper.io.tf import serialized_tip_tf
from fpc_gripper.io.tf import TF_QOS
from fpc_gripper.io.tf import TF_STATIC_QOS
from fpc_gripper.model import PRESSURE_MODEL_NAMES
from fpc_gripper.model.pipeline import finger_model
from fpc_gripper.model.pipeline import MAX_SEGMENTS
from fpc_gripper.model.pipeline import ModelSettings
from fpc_gripper.nodes.guard import InputGuard
from fpc_gripper.nodes.parameters import BOUND_NAMES
from fpc_gripper.nodes.parameters import declare_table
from fpc_gripper.nodes.parameters import float_range
from fpc_gripper.nodes.parameters import input_bound_table
from fpc_gripper.nodes.parameters import input_bounds
from fpc_gripper.nodes.parameters import int_range
from fpc_gripper.nodes.runner import run_node
from fpc_gripper.services.input_limits import checked_bounds
from fpc_gripper.services.logs import NodeLog
from fpc_gripper.services.model_core import DEFAULT_STALE_AFTER_S
from fpc_gripper.services.model_core import Level
from fpc_gripper.services.model_core import ModelCore

PRESSURE_INPUTS = ('command', 'measured')
# The model settings every consumer of the finger pipeline defaults to.
_DEFAULTS = ModelSettings()
_CHOICES = {'pressure_model': PRESSURE_MODEL_NAMES, 'pressure_input': PRESSURE_INPUTS}
# Parameters whose change rebuilds the solvers.
_SOLVER_PARAMETERS = ('n_segments', 'pressure_model', 'tolerance')

_COMMAND_QOS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                          reliability=ReliabilityPolicy.RELIABLE)
_DIAGNOSTICS_QOS = _COMMAND_QOS
_DIAGNOSTICS_PERIOD_S = 1.0
# Slow outputs, at most once per period and the last update always sent: markers are for
# people, and rigidity (two displacement-controlled solves) must not hold up the shapes [s].
_MARKER_PERIOD_S = 1.0 / 30.0
# Markers cost some 0.4 ms a send (serialized, three circle fits): with nobody watching,
# the newest state still reaches the transient-local history, but at 1 Hz.
_UNWATCHED_MARKER_PERIOD_S = 1.0
_PALM_FRAME = 'palm'
_LEVELS = {Level.OK: DiagnosticStatus.OK, Level.WARN: DiagnosticStatus.WARN,
           Level.ERROR: DiagnosticStatus.ERROR}
_VALID_COLOR = (0.1, 0.7, 0.2, 1.0)
_INVALID_COLOR = (1.0, 0.55, 0.0, 1.0)


class _SlowOutput:
    """
    Fingers whose slow output is out of date, sent at most once per `period_s` [s].

    An update is sent at once when a period has passed since the last send; else a timer of
    its own (steady time, running only while something is out of date) sends it later, so
    the last update is always sent and nothing polls in between.
    """

    def __init__(self, node, period_s, publish, clock, lock):
        self.period_s = period_s
        self.publish = publish
        self.dirty = set()
        self.last_ns = None
        self._lock = lock
        self.timer = node.create_timer(self._timer_period(), self._on_timer, clock=clock)
        self.timer.cancel()

    def _timer_period(self):
        return self.period_s if math.isfinite(self.period_s) else 1.0

    def set_period(self, period_s):
        """Change the period [s] (inf: never sent)."""
        if period_s != self.period_s:
            self.period_s = period_s
            self.timer.timer_period_ns = int(round(self._timer_period() * 1e9))
            if not math.isfinite(period_s):
                self.dirty.clear()

    def due(self, now_ns):
        """Whether a period has passed since the last send [ns]."""
        return self.last_ns is None or (now_ns - self.last_ns) * 1e-9 >= self.period_s

    def take(self, now_ns):
        """Mark a send at `now_ns` [ns] and return the out-of-date finger indices."""
        self.last_ns = now_ns
        indices = sorted(self.dirty)
        self.dirty.clear()
        return indices

    def update(self, indices, now_ns):
        """Mark fingers out of date and send them if due, else let the timer send them."""
        if not math.isfinite(self.period_s):
            return
        self.dirty.update(indices)
        if not self.dirty:
            return
        if self.due(now_ns):
            self.publish(self.take(now_ns))
        elif self.timer.is_canceled():
            self.timer.reset()

    def _on_timer(self):
        with self._lock:
            if self.dirty:
                self.publish(self.take(time.monotonic_ns()))
            else:
                self.timer.cancel()


def _parameter_table():
    """Return ``(name, default, description, extra descriptor fields)`` of every parameter."""
    return (
        ('gripper_config', str(default_gripper_config_path()),
         'Gripper YAML: one set of topics per finger, named and framed finger_<i>.',
         {'read_only': True}),
        ('tolerance', _DEFAULTS.tolerance,
         'Tip-position tolerance against the geometrically exact rod [m]: per scene the node '
         'uses the cheapest model that meets it (fpc_gripper.model.AdaptiveSolver), refining '
         'when a segment passes 45 degrees. 0 uses the paper CCM with a fixed n_segments.',
         {'floating_point_range': float_range(0.0, 0.05)}),
        ('n_segments', _DEFAULTS.n_segments, 'Number N of CCM segments per finger when '
         'tolerance is 0; a change rebuilds the solvers.',
         {'integer_range': int_range(1, MAX_SEGMENTS)}),
        ('pressure_model', _DEFAULTS.pressure_model,
         "Pressure work: 'design' (each finger design's pressure_work_factor k_p), "
         "'adiabatic' (k_p = 1/(gamma - 1) = 2.5, paper eq. 20) or 'isobaric' (k_p = 1); a "
         'change rebuilds the solvers.',
         {'additional_constraints': f'one of {list(PRESSURE_MODEL_NAMES)}'}),
        ('max_rate_hz', 200.0,
         'Solve-rate cap per finger [Hz]; newer input replaces pending input (latest wins).',
         {'floating_point_range': float_range(1.0, 10000.0)}),
        ('pressure_input', 'command',
         "'command': finger_<i>/pressure_command (reliable); 'measured': finger_<i>/pressure "
         '(sensor data QoS). Both absolute [Pa].',
         {'read_only': True, 'additional_constraints': f'one of {list(PRESSURE_INPUTS)}'}),
        ('atmospheric_pressure', 101325.0,
         'Atmospheric pressure [Pa]: gauge = absolute - atmospheric_pressure.',
         {'floating_point_range': float_range(3.0e4, 1.2e5)}),
        ('stale_after_s', DEFAULT_STALE_AFTER_S,
         'Inputs whose header stamp is older than this against the node clock are rejected '
         '[s]; 0 disables. Unstamped (zero) headers are never stale.',
         {'floating_point_range': float_range(0.0, 3600.0)}),
        ('future_limit_s', 1.0,
         'Inputs whose header stamp is more than this ahead of the node clock are rejected '
         '[s]; 0 disables. Stamps that are no time (sec < 0, nanosec >= 1e9) always are.',
         {'floating_point_range': float_range(0.0, 3600.0)}),
        ('rigidity_rate_hz', 10.0,
         "Largest rate of each finger's rigidity output [Hz]: K_x and K_z take two "
         "displacement-controlled solves at the state's pressure; 0 publishes none.",
         {'floating_point_range': float_range(0.0, 100.0)}),
        ('frame_prefix', '',
         'Prefix of every frame id published or expected (<prefix>palm, <prefix>finger_<i>), '
         'so that two grippers can share a tf tree, e.g. "left/".',
         {'read_only': True}),
        ('publish_tf', True,
         'Send tf: the mounts palm -> finger_<i> on /tf_static, and finger_<i> -> '
         'finger_<i>_tip on /tf with every shape.',
         {'read_only': True}),
        *input_bound_table(),
    )


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
    transient local with depth 1: a late subscriber gets the newest state from the
    publisher's history, and every message answers an input. Bad inputs are rejected and
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
        declare_table(self, _parameter_table())
        # Overrides bypass the on-set callback: check the starting values the same way.
        result = self._validate_parameters([self.get_parameter(n)
                                            for n, *_ in _parameter_table()])
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
        self._markers = _SlowOutput(self, _UNWATCHED_MARKER_PERIOD_S, self._publish_markers,
                                    self._steady, self._lock)
        self._rigidities = _SlowOutput(self, self._rigidity_period(), self._publish_rigidities,
                                       self._steady, self._lock)
        self._last_kinds = None
        self._serialize_shapes = None
        self._create_topics(names)
        self._tf_pub, tf_state = self._create_tf()
        self._rate_timer = self.create_timer(1.0 / param('max_rate_hz').value, self._on_timer,
                                             clock=self._steady)
        self._rate_timer.cancel()
        self._diagnostics_timer = self.create_timer(
            _DIAGNOSTICS_PERIOD_S, functools.partial(self._publish_diagnostics, True),
            clock=self._steady)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.get_logger().info(
            f'ready: {len(names)} fingers ({", ".join(names)}), tolerance '
            f'{param("tolerance").value} m, n_segments {param("n_segments").value}, '
            f'{param("pressure_model").value} pressure model, '
            f'input {self._pressure_topic}, max_rate_hz {param("max_rate_hz").value:g}, '
            f'frames {self._palm_frame} -> {", ".join(self._frames)} '
            f'({tf_state}); '
            'waiting for pressure input')
        self._publish_diagnostics(force=True)

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

    def _create_topics(self, names):
        self._shape_pubs = tuple(self.create_publisher(Path, f'{name}/shape', STATE_QOS)
                                 for name in names)
        self._curvature_pubs = tuple(
            self.create_publisher(Float64, f'{name}/curvature', STATE_QOS) for name in names)
        self._rigidity_pubs = tuple(
            self.create_publisher(Vector3Stamped, f'{name}/rigidity', STATE_QOS)
            for name in names)
        self._markers_pub = self.create_publisher(MarkerArray, 'markers', STATE_QOS)
        self._gripper_shape_pub = self.create_publisher(MarkerArray, 'gripper_shape',
                                                        STATE_QOS)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics',
                                                      _DIAGNOSTICS_QOS)
        if self.get_parameter('pressure_input').value == 'measured':
            self._pressure_topic, qos = 'pressure', qos_profile_sensor_data
        else:
            self._pressure_topic, qos = 'pressure_command', _COMMAND_QOS
        self._pressure_subs = tuple(
            self._subscribe(i, FluidPressure, self._pressure_topic, qos, self._on_pressure)
            for i in range(len(names)))
        self._force_subs = tuple(
            self._subscribe(i, WrenchStamped, 'tip_force', _COMMAND_QOS, self._on_tip_force)
            for i in range(len(names)))

    def _subscribe(self, index, msg_type, topic, qos, callback):
        """Subscribe one input of a finger through the guard (raw, size- and decode-checked)."""
        name = self._core.names[index]
        return self._guard.subscribe(
            self, msg_type, f'{name}/{topic}', qos, functools.partial(callback, index),
            functools.partial(self._on_refused, index, topic),
            functools.partial(self._on_lost, index, topic))

    def _create_tf(self):
        """
        Send palm -> finger_<i> on /tf_static; return the /tf publisher and what was done.

        tf2_ros's static broadcaster sends them where it imports. Otherwise the node
        publishes tf2_msgs/TFMessage itself, with tf2_ros's QoS (a PyPI install gets
        tf2_msgs from scripts/build_interfaces.sh). Without tf2_msgs there is no tf.
        """
        if not self.get_parameter('publish_tf').value:
            return None, 'publish_tf false: no tf'
        try:
            from tf2_msgs.msg import TFMessage
        except ImportError:
            return None, 'tf2_msgs not importable: no tf'
        stamp = self._now_ns()
        mounts = [palm_transform(placement, self._palm_frame, frame, stamp)
                  for placement, frame in zip(self._placements, self._frames)]
        try:
            from tf2_ros.static_transform_broadcaster import StaticTransformBroadcaster
        except ImportError:
            self._static_tf_pub = self.create_publisher(TFMessage, '/tf_static', TF_STATIC_QOS)
            self._static_tf_pub.publish(TFMessage(transforms=mounts))
            how = 'tf2_msgs'
        else:
            self._static_tf_pub = StaticTransformBroadcaster(self)
            self._static_tf_pub.sendTransform(mounts)
            how = 'tf2_ros'
        return (self.create_publisher(TFMessage, '/tf', TF_QOS),
                f'tf through {how}: mounts on /tf_static, finger -> tip on /tf')

    def _rigidity_period(self):
        rate = self.get_parameter('rigidity_rate_hz').value
        return 1.0 / rate if rate > 0.0 else math.inf

    # -- parameters -------------------------------------------------------------------------

    def _validate_parameters(self, parameters):
        for param in parameters:
            value = param.value
            if param.name in _CHOICES and value not in _CHOICES[param.name]:
                return SetParametersResult(
                    successful=False,
                    reason=f'`{param.name}` must be one of {list(_CHOICES[param.name])}, '
                           f'got {value!r}')
            if isinstance(value, float) and not math.isfinite(value):
                return SetParametersResult(
                    successful=False, reason=f'`{param.name}` must be finite, got {value}')
        bounds = {p.name: p.value for p in parameters if p.name in BOUND_NAMES}
        if bounds:
            try:
                checked_bounds(input_bounds(self, bounds), getattr(self, '_frames', ()))
            except (TypeError, ValueError) as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

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
                self._rigidities.set_period(self._rigidity_period())
            if values.keys() & set(_SOLVER_PARAMETERS):
                self._core.rebuild(self._create_solver)
                self.get_logger().info(
                    f'solvers rebuilt: tolerance {self.get_parameter("tolerance").value} m, '
                    f'n_segments {self.get_parameter("n_segments").value}, '
                    f'{self.get_parameter("pressure_model").value} pressure model')
                self._run(range(len(self._core.fingers)))

    # -- inputs -----------------------------------------------------------------------------

    def _now_ns(self):
        return self.get_clock().now().nanoseconds

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
                f'{name}/{topic} rejected ({check.rejection.value}), keeping the last good '
                f'state: {check.detail}', key=(index, check.rejection))
            self._publish_diagnostics()
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
        good = [u for u in updates if u.result is not None]
        for update in good:
            self._publish_shape(update)
        for update in good:
            self._curvature_pubs[update.index].publish(curvature_message(update.result))
        for update in updates:
            if update.result is None:
                state = self._core.fingers[update.index]
                self._log.error(
                    f'{state.name}: solve at {state.gauge:.1f} Pa gauge, tip force '
                    f'({state.tip_force[0]:g}, {state.tip_force[1]:g}) N failed, keeping the '
                    f'last good state: {update.failure}', key=(update.index, 'solver'))
        self._publish_diagnostics()
        indices = [u.index for u in good]
        now = time.monotonic_ns()
        watched = (self._markers_pub.get_subscription_count()
                   or self._gripper_shape_pub.get_subscription_count())
        self._markers.set_period(_MARKER_PERIOD_S if watched else _UNWATCHED_MARKER_PERIOD_S)
        self._markers.update(indices, now)
        self._rigidities.update(indices, now)

    def _shape_payload(self, result, frame_id, stamp_ns):
        if self._serialize_shapes is None:
            # The fast serializer must decode to the reference message; else fall back.
            reference = shape_message(result, frame_id, stamp_ns)
            decoded = deserialize_message(serialized_shape(result, frame_id, stamp_ns), Path)
            self._serialize_shapes = decoded == reference
            if not self._serialize_shapes:
                self.get_logger().warning('serialized_shape does not decode to shape_message; '
                                          'publishing Path objects (slower)')
        if self._serialize_shapes:
            return serialized_shape(result, frame_id, stamp_ns)
        return shape_message(result, frame_id, stamp_ns)

    def _publish_shape(self, update):
        frame = self._frames[update.index]
        self._shape_pubs[update.index].publish(
            self._shape_payload(update.result, frame, update.stamp_ns))
        if self._tf_pub is not None:
            self._tf_pub.publish(serialized_tip_tf(update.result, frame, update.stamp_ns))

    def _publish_rigidities(self, indices):
        for index in indices:
            state = self._core.fingers[index]
            if state.result is None:
                continue
            k_x = self._core.rigidity(index, 'x')
            k_z = self._core.rigidity(index, 'z')
            self._rigidity_pubs[index].publish(
                rigidity_message(k_x, k_z, self._frames[index], state.result_stamp_ns))

    def _publish_markers(self, indices):
        """Send ``markers`` and ``gripper_shape`` with every finger that has a state."""
        fingers = [
            (i, state.result, state.result_stamp_ns, self._placements[i],
             _VALID_COLOR if state.result.valid else _INVALID_COLOR)
            for i, state in enumerate(self._core.fingers) if state.result is not None]
        if not fingers:
            return
        self._markers_pub.publish(serialized_shape_markers(fingers, self._palm_frame))
        self._gripper_shape_pub.publish(serialized_gripper_shape(fingers, self._palm_frame))

    def _publish_diagnostics(self, force=False):
        with self._lock:
            kinds = tuple(self._core.health(i) for i in range(len(self._core.fingers)))
            if not force and kinds == self._last_kinds:
                return
            self._last_kinds = kinds
            statuses = [self._core.status(i) for i in range(len(kinds))]
            array = DiagnosticArray()
            array.header.stamp = ns_to_time(self._now_ns())
            array.status = [
                DiagnosticStatus(
                    level=_LEVELS[s.level], name=f'{self.get_fully_qualified_name()}: {name}',
                    message=s.message, hardware_id=name,
                    values=[KeyValue(key=k, value=v) for k, v in s.values.items()])
                for name, s in zip(self._core.names, statuses)]
            self._diagnostics_pub.publish(array)


def main(args=None):
    """Run the model node until SIGINT or SIGTERM: 0 then, 2 on a bad config, else 1."""
    return run_node(ModelNode, 'model_node', args)


if __name__ == '__main__':
    sys.exit(main())
