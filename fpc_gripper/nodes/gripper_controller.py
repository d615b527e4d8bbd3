"""
Node that closes the loop: aperture and grasp-force goals to finger pressure commands.

Inputs (relative to the namespace): ``aperture_command`` (std_msgs/Float64, [m]),
``grasp_force_command`` (std_msgs/Float64, the total normal force of the fingers on the
object [N]), per finger ``finger_<i>/pressure`` (sensor_msgs/FluidPressure, measured,
absolute [Pa], sensor-data QoS) and ``finger_<i>/tip_force`` (geometry_msgs/WrenchStamped,
frame ``finger_<i>``: the contact force on the finger, force.x and force.z the resultant
(F_X, F_Z) [N]; torque is not used). The object to grasp is a parameter (``object``,
``object_diameter``, ``object_height``; ``unknown``: a cylinder on the palm axis through
the point where contact is felt). Outputs: ``finger_<i>/pressure_command``
(FluidPressure, ABSOLUTE [Pa] = gauge + atmospheric_pressure), ``aperture``
(std_msgs/Float64, the model estimate [m]), ``contacts`` (visualization_msgs/MarkerArray:
each finger's points in contact on the object's contact model, in its frame, at 10 Hz at
most while any finger is in contact), ``controller_state`` and ``/diagnostics``. The
``<node name>/gripper_cmd`` action (control_msgs/GripperCommand) is served by
:mod:`fpc_gripper.nodes.gripper_action`.

``controller_state`` is a diagnostic_msgs/DiagnosticStatus, published every control
step: a standard, typed message (level OK/WARN/ERROR, a message, key/value pairs) that
every ROS 2 distribution ships, that records to MCAP and decodes without a custom
schema, and whose level means the same as on ``/diagnostics``. Keys: mode, goal_status,
aperture_m, aperture_target_m, force_target_n, normal_force_n (the estimated total) and per
finger ``finger_<i>/{command_pa,feedforward_pa,rho_m,phase,contact_force_n,saturated}``
(contact_force_n: the finger's estimated normal force)
(pressures gauge). ``/diagnostics`` carries the same status at 1 Hz and at every change
of mode, goal status or level (goal reached, stalled, feedback lost).

The control law is :class:`fpc_gripper.control.controller.GripperControlLaw`; every input
reaches it through :class:`fpc_gripper.control.inputs.ControllerInputs`, which checks it
first (a rejected input keeps the last good value and makes the status WARN).
"""

import functools
import math
import sys

from diagnostic_msgs.msg import DiagnosticArray
from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_msgs.msg import KeyValue
from geometry_msgs.msg import WrenchStamped
from rcl_interfaces.msg import ParameterDescriptor
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import HistoryPolicy
from rclpy.qos import qos_profile_sensor_data
from rclpy.qos import QoSProfile
from rclpy.qos import ReliabilityPolicy
from sensor_msgs.msg import FluidPressure
from std_msgs.msg import Float64
from visualization_msgs.msg import MarkerArray

from fpc_gripper.control.controller import ControllerConfig
from fpc_gripper.control.controller import GoalStatus
from fpc_gripper.control.controller import GripperControlLaw
from fpc_gripper.control.controller import SAFE_STATES
from fpc_gripper.control.geometry import PalmGeometry
from fpc_gripper.control.inputs import ControllerInputs
from fpc_gripper.control.inverse import InverseModel
from fpc_gripper.grasp.finger import FingerGrasp
from fpc_gripper.grasp.objects import make_object
from fpc_gripper.grasp.objects import OBJECTS
from fpc_gripper.io.config import default_gripper_config_path
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.io.contact_markers import contact_marker
from fpc_gripper.io.messages import STATE_QOS
from fpc_gripper.model import PRESSURE_MODEL_NAMES
from fpc_gripper.model.pipeline import MAX_SEGMENTS
from fpc_gripper.model.pipeline import ModelSettings
from fpc_gripper.nodes.gripper_action import GripperCommandServer
from fpc_gripper.nodes.guard import InputGuard
from fpc_gripper.nodes.parameters import BOUND_NAMES
from fpc_gripper.nodes.parameters import declare_table
from fpc_gripper.nodes.parameters import float_range
from fpc_gripper.nodes.parameters import input_bound_table
from fpc_gripper.nodes.parameters import input_bounds
from fpc_gripper.nodes.parameters import int_range
from fpc_gripper.nodes.runner import run_node
from fpc_gripper.services.input_limits import checked_bounds
from fpc_gripper.services.logs import bounded
from fpc_gripper.services.logs import NodeLog

__all__ = ['GripperController', 'main']

_RELIABLE = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                       reliability=ReliabilityPolicy.RELIABLE)
_DIAGNOSTICS_PERIOD_S = 1.0
#: Contact markers at 10 Hz at most, for people [s].
_CONTACTS_PERIOD_S = 0.1
#: Parameters copied into ControllerConfig (same names).
_LAW_PARAMETERS = ('max_pressure', 'slew_rate_pa_s', 'approach_rate_pa_s', 'kp', 'ki',
                   'kp_force', 'ki_force', 'goal_tolerance_m',
                   'force_tolerance', 'settle_time_s', 'stall_timeout_s', 'feedback_timeout_s',
                   'safe_state', 'contact_threshold_n')


def _parameter_table(config_max_pressure):
    """Return ``(name, default, description, extra descriptor fields)`` of every parameter."""
    defaults = ControllerConfig()
    model = ModelSettings()
    return (
        ('gripper_config', str(default_gripper_config_path()),
         'Gripper YAML: fingers, palm radius, pressure limit.', {'read_only': True}),
        ('tolerance', model.tolerance,
         "Finger model's tip-position tolerance against the rod [m], as model_node's "
         '(0: the paper CCM with n_segments); set both nodes alike.',
         {'read_only': True, 'floating_point_range': float_range(0.0, 0.05)}),
        ('n_segments', model.n_segments, 'CCM segments of the finger model when tolerance '
         'is 0.', {'read_only': True, 'integer_range': int_range(1, MAX_SEGMENTS)}),
        ('pressure_model', model.pressure_model,
         f"Pressure work model, one of {list(PRESSURE_MODEL_NAMES)} ('design': each finger "
         "design's pressure_work_factor).",
         {'read_only': True, 'additional_constraints': f'one of {list(PRESSURE_MODEL_NAMES)}'}),
        ('max_pressure', config_max_pressure,
         'Largest command [Pa gauge]; at most the gripper config max_pressure.',
         {'floating_point_range': float_range(0.0, config_max_pressure)}),
        ('slew_rate_pa_s', defaults.slew_rate_pa_s, 'Command slew limit [Pa/s].',
         {'floating_point_range': float_range(1.0e3, 1.0e8)}),
        ('approach_rate_pa_s', defaults.approach_rate_pa_s,
         'Slew limit while closing on an object and pressing it [Pa/s].',
         {'floating_point_range': float_range(1.0e3, 1.0e8)}),
        ('kp', defaults.kp, 'Proportional gain on the aperture error in Pa [-].',
         {'floating_point_range': float_range(0.0, 100.0)}),
        ('ki', defaults.ki, 'Integral gain on the aperture error in Pa [1/s].',
         {'floating_point_range': float_range(0.0, 100.0)}),
        ('kp_force', defaults.kp_force, 'Proportional gain on the force error in Pa [-].',
         {'floating_point_range': float_range(0.0, 100.0)}),
        ('ki_force', defaults.ki_force, 'Integral gain on the force error in Pa [1/s].',
         {'floating_point_range': float_range(0.0, 100.0)}),
        ('control_rate_hz', 50.0, 'Control loop rate [Hz].',
         {'floating_point_range': float_range(1.0, 1000.0)}),
        ('goal_tolerance_m', defaults.goal_tolerance_m, 'Aperture goal tolerance [m].',
         {'floating_point_range': float_range(1.0e-5, 0.05)}),
        ('force_tolerance', defaults.force_tolerance,
         'Relative contact-force goal tolerance [-].',
         {'floating_point_range': float_range(0.0, 1.0)}),
        ('settle_time_s', defaults.settle_time_s,
         'Time within tolerance before a goal is reached [s].',
         {'floating_point_range': float_range(0.0, 60.0)}),
        ('stall_timeout_s', defaults.stall_timeout_s,
         'A goal not reached after this long is reported stalled [s].',
         {'floating_point_range': float_range(0.1, 3600.0)}),
        ('feedback_timeout_s', defaults.feedback_timeout_s,
         'Pressure feedback older than this is lost: safe state and ERROR [s].',
         {'floating_point_range': float_range(0.01, 60.0)}),
        ('safe_state', defaults.safe_state,
         "On lost feedback: 'vent' commands 0 Pa gauge, 'hold' keeps the last command.",
         {'additional_constraints': f'one of {list(SAFE_STATES)}'}),
        ('contact_threshold_n', defaults.contact_threshold_n,
         'Normal contact force above which a finger is in contact [N].',
         {'floating_point_range': float_range(1.0e-4, 10.0)}),
        ('object', 'unknown',
         f'Object to grasp: unknown, or one of {list(OBJECTS)} (resting on the palm).',
         {'read_only': True, 'additional_constraints': f"one of {['unknown', *OBJECTS]}"}),
        ('object_diameter', 0.040, 'Size D of the object to grasp [m].',
         {'read_only': True, 'floating_point_range': float_range(1.0e-3, 0.5)}),
        ('object_height', 0.0, "Height of the object's lowest point above the palm [m].",
         {'read_only': True, 'floating_point_range': float_range(0.0, 0.5)}),
        ('atmospheric_pressure', 101325.0,
         'Atmospheric pressure [Pa]: absolute = gauge + atmospheric_pressure.',
         {'floating_point_range': float_range(3.0e4, 1.2e5)}),
        ('frame_prefix', '', 'Prefix of the finger frames (<prefix>finger_<i>) of the '
         "commands and of the tip forces accepted, as model_node's.", {'read_only': True}),
        *input_bound_table(),
    )


class GripperController(Node):
    """
    Aperture and grasp-force controller of a gripper of FPC fingers.

    Parameters
    ----------
    node_name : str
        Node name.
    **kwargs
        Passed to :class:`rclpy.node.Node` (namespace, parameter_overrides, context, ...).

    Raises
    ------
    ValueError
        On an unreadable gripper config or invalid starting parameters.

    """

    def __init__(self, node_name='gripper_controller', **kwargs):
        super().__init__(node_name, **kwargs)
        self.declare_parameter('gripper_config', str(default_gripper_config_path()),
                               ParameterDescriptor(description='Gripper YAML.', read_only=True))
        config = load_gripper_config(self.get_parameter('gripper_config').value)
        self._gripper = config
        declare_table(self, _parameter_table(config.max_pressure)[1:])
        # Overrides bypass the on-set callback: check the starting values the same way.
        result = self._validate_parameters([self.get_parameter(n) for n in _LAW_PARAMETERS])
        if not result.successful:
            raise ValueError(result.reason)
        self._names = config.names
        self._frames = tuple(self.get_parameter('frame_prefix').value + name
                             for name in self._names)
        settings = ModelSettings(tolerance=self.get_parameter('tolerance').value,
                                 n_segments=self.get_parameter('n_segments').value,
                                 pressure_model=self.get_parameter('pressure_model').value)
        models = {}
        for finger in config.fingers:
            if finger.design not in models:
                models[finger.design] = InverseModel(
                    finger.design, config.palm_radius, config.max_pressure, settings)
        self._law = GripperControlLaw([models[f.design] for f in config.fingers],
                                      PalmGeometry.from_config(config), self._law_config(),
                                      self._grasps(config, settings))
        n = len(self._names)
        self._log = NodeLog(self.get_logger())
        self._inputs = ControllerInputs(self._law, self._frames,
                                        self.get_parameter('atmospheric_pressure').value,
                                        input_bounds(self))
        self._guard = InputGuard(self.get_parameter('max_payload_bytes').value)
        self._last_output = None
        self._max_command = -math.inf
        self._last_key = None
        self._last_diagnostics = None
        self._command_pubs = tuple(
            self.create_publisher(FluidPressure, f'{name}/pressure_command', _RELIABLE)
            for name in self._names)
        self._aperture_pub = self.create_publisher(Float64, 'aperture', _RELIABLE)
        self._state_pub = self.create_publisher(DiagnosticStatus, 'controller_state', _RELIABLE)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', _RELIABLE)
        self._contacts_pub = self.create_publisher(MarkerArray, 'contacts', STATE_QOS)
        self._contacts_shown = [False] * len(self._names)
        self._last_contacts = None
        for i, (name, frame) in enumerate(zip(self._names, self._frames)):
            self._subscribe(FluidPressure, f'{name}/pressure', f'{frame}/pressure',
                            qos_profile_sensor_data, functools.partial(self._on_pressure, i))
            self._subscribe(WrenchStamped, f'{name}/tip_force', f'{frame}/tip_force', _RELIABLE,
                            functools.partial(self._on_tip_force, i))
        self._subscribe(Float64, 'aperture_command', 'aperture_command', _RELIABLE,
                        self._on_aperture)
        self._subscribe(Float64, 'grasp_force_command', 'grasp_force_command', _RELIABLE,
                        self._on_grasp)
        try:
            self._gripper_cmd = GripperCommandServer(self, self._law, self._now, self._log)
            action = f'action {self._gripper_cmd.name}'
        except ImportError:
            self._gripper_cmd = None
            action = 'control_msgs not importable: no GripperCommand action'
        self._timer = None
        self._start_timer()
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        low, high = self._law.aperture_range()
        self.get_logger().info(
            f'ready: {n} fingers, palm radius {config.palm_radius * 1e3:.1f} mm, aperture '
            f'{low * 1e3:.1f}..{high * 1e3:.1f} mm, max_pressure '
            f'{self._law.max_pressure:.0f} Pa gauge, {self._rate():g} Hz, {action}')

    def _grasps(self, config, settings):
        """Every finger's FingerGrasp of the declared object (None for 'unknown')."""
        kind = self.get_parameter('object').value
        if kind == 'unknown':
            return None
        if kind not in OBJECTS:
            raise ValueError(f"`object` must be 'unknown' or one of {list(OBJECTS)}, got "
                             f'{kind!r}')
        obj = make_object(kind, self.get_parameter('object_diameter').value,
                          self.get_parameter('object_height').value)
        return [FingerGrasp(f.design, obj.section(f.mount_angle, config.palm_radius),
                            config.max_pressure, settings) for f in config.fingers]

    # -- public helpers ---------------------------------------------------------------------

    @property
    def law(self):
        """The ROS-free control law."""
        return self._law

    @property
    def last_output(self):
        """The ControlOutput of the last step (None before the first)."""
        return self._last_output

    @property
    def max_command_seen(self):
        """Largest gauge pressure commanded so far [Pa] (-inf before the first command)."""
        return self._max_command

    @property
    def finger_names(self):
        """Finger names in index order."""
        return self._names

    def stopping(self):
        """Abort a running GripperCommand goal; return a check that its end ran, or None."""
        if self._gripper_cmd is None:
            return None
        return self._gripper_cmd.stopping()

    def destroy_node(self):
        """Abort a running GripperCommand goal, then destroy the node."""
        if getattr(self, '_gripper_cmd', None) is not None:
            self._gripper_cmd.destroy()
            self._gripper_cmd = None
        return super().destroy_node()

    # -- parameters -------------------------------------------------------------------------

    def _rate(self):
        return self.get_parameter('control_rate_hz').value

    def _subscribe(self, msg_type, topic, source, qos, callback):
        """Subscribe an input through the guard; `source` names it in the diagnostics."""
        self._guard.subscribe(self, msg_type, topic, qos, callback,
                              functools.partial(self._on_refused, source))

    def _law_config(self, overrides=None):
        values = {name: self.get_parameter(name).value for name in _LAW_PARAMETERS}
        values.update(overrides or {})
        values['max_pressure'] = min(values['max_pressure'], self._gripper.max_pressure)
        return ControllerConfig(**values)

    def _validate_parameters(self, parameters):
        try:
            checked_bounds(input_bounds(self, {p.name: p.value for p in parameters}),
                           getattr(self, '_frames', ()))
        except (TypeError, ValueError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        overrides = {}
        for param in parameters:
            if param.name == 'max_pressure' and param.value > self._gripper.max_pressure:
                return SetParametersResult(
                    successful=False,
                    reason=f'`max_pressure` must be <= the gripper config limit '
                           f'{self._gripper.max_pressure:.0f} [Pa], got {param.value}')
            if param.name in _LAW_PARAMETERS:
                overrides[param.name] = param.value
        try:
            self._law_config(overrides)
        except (TypeError, ValueError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters):
        names = {p.name for p in parameters}
        changed = sorted(names & set(_LAW_PARAMETERS))
        if changed:
            self._law.configure(self._law_config())
            self.get_logger().info('control parameters now ' + ', '.join(
                f'{n} {self.get_parameter(n).value}' for n in changed))
        if 'control_rate_hz' in names:
            self._start_timer()
        if names & set(BOUND_NAMES):
            self._inputs.bounds = input_bounds(self)
            self._guard.max_payload_bytes = self._inputs.bounds.max_payload_bytes
        if 'atmospheric_pressure' in names:
            self._inputs.atmospheric_pressure = self.get_parameter('atmospheric_pressure').value

    def _start_timer(self):
        if self._timer is not None:
            self.destroy_timer(self._timer)
        self._timer = self.create_timer(1.0 / self._rate(), self._on_timer)

    # -- inputs -----------------------------------------------------------------------------

    def _now(self):
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_pressure(self, index, msg):
        self._after_input(self._inputs.offer_pressure(
            index, msg.fluid_pressure, self._now(), msg.header.frame_id), 'pressure', index)

    def _on_tip_force(self, index, msg):
        force = msg.wrench.force
        self._after_input(self._inputs.offer_tip_force(
            index, force.x, force.z, msg.header.frame_id), 'tip_force', index)

    def _on_aperture(self, msg):
        check = self._after_input(self._inputs.offer_aperture(msg.data, self._now()),
                                  'aperture_command')
        if check.accepted:
            self._preempt_action('aperture_command')
            self._log.info(f'aperture goal {msg.data * 1e3:.1f} mm '
                           f'(using {check.value * 1e3:.1f} mm)')

    def _on_grasp(self, msg):
        check = self._after_input(self._inputs.offer_grasp_force(msg.data, self._now()),
                                  'grasp_force_command')
        if check.accepted:
            self._preempt_action('grasp_force_command')
            self._log.info(f'grasp goal {msg.data:.3f} N total normal force')

    def _preempt_action(self, topic):
        if self._gripper_cmd is not None:
            self._gripper_cmd.preempt(f'preempted by {topic}')

    def _on_refused(self, source, check):
        self._after_input(self._inputs.reject(source, check.rejection, check.detail), source)

    def _after_input(self, check, topic, index=None):
        if not check.accepted:
            where = topic if index is None else f'{self._names[index]}/{topic}'
            self._log.warning(f'{where} rejected ({check.rejection.value}), keeping the last '
                              f'good value: {check.detail}', key=(where, check.rejection))
        return check

    # -- the loop ---------------------------------------------------------------------------

    def _on_timer(self):
        now = self._now()
        out = self._law.step(now, self._inputs.measurements())
        self._last_output = out
        stamp = self.get_clock().now().to_msg()
        atmospheric = self.get_parameter('atmospheric_pressure').value
        if out.commands is not None:
            ceiling = self._law.max_pressure
            for i, command in enumerate(out.commands):
                msg = FluidPressure()
                msg.header.stamp = stamp
                msg.header.frame_id = self._frames[i]
                gauge = min(max(command, 0.0), ceiling)
                self._max_command = max(self._max_command, gauge)
                msg.fluid_pressure = gauge + atmospheric
                self._command_pubs[i].publish(msg)
        if math.isfinite(out.aperture):
            self._aperture_pub.publish(Float64(data=out.aperture))
        status = self._status(out)
        self._state_pub.publish(status)
        self._report(out, status, now)
        if self._gripper_cmd is not None:
            self._gripper_cmd.step(out)
        self._publish_contacts(now)

    def _contact(self, index, pressure):
        try:
            return self._law.contact(index, pressure)
        except (RuntimeError, ValueError, ArithmeticError):
            return None         # no contact state here: the finger shows none

    def _publish_contacts(self, now):
        """Send the contact points of the fingers in contact, and delete those that left."""
        if self._last_contacts is not None and now - self._last_contacts < _CONTACTS_PERIOD_S:
            return
        states = [self._contact(i, m.pressure)
                  for i, m in enumerate(self._inputs.measurements())]
        if all(state is None for state in states) and not any(self._contacts_shown):
            return
        self._last_contacts = now
        stamp = self.get_clock().now().nanoseconds
        markers = [contact_marker(state, frame, stamp, i)
                   for i, (state, frame) in enumerate(zip(states, self._frames))]
        self._contacts_shown = [state is not None for state in states]
        self._contacts_pub.publish(MarkerArray(markers=markers))

    def _status(self, out):
        # A rejected input is a WARN until its topic delivers a good one.
        problems = self._inputs.problems
        level = max(int(out.level), 1 if problems else 0)
        values = {
            'mode': out.mode.value,
            'goal_status': out.status.name.lower(),
            'aperture_m': f'{out.aperture:.6f}',
            'aperture_target_m': f'{out.aperture_target:.6f}',
            'force_target_n': f'{out.force_target:.4f}',
            'normal_force_n': f'{out.normal_force:.4f}',
        }
        for name, finger in zip(self._names, out.fingers):
            values[f'{name}/command_pa'] = f'{finger.command:.1f}'
            values[f'{name}/feedforward_pa'] = f'{finger.feedforward:.1f}'
            values[f'{name}/rho_m'] = f'{finger.rho:.6f}'
            values[f'{name}/phase'] = finger.phase.value
            values[f'{name}/contact_force_n'] = f'{finger.contact_force:.4f}'
            values[f'{name}/saturated'] = str(finger.saturated)
        values['rejected_inputs'] = str(self._inputs.rejected)
        values['last_rejection'] = self._inputs.last_rejection
        return DiagnosticStatus(
            level=bytes([level]), name=self.get_fully_qualified_name(),
            message=bounded(f'{out.message}; {problems}' if problems else out.message),
            hardware_id='gripper', values=[KeyValue(key=k, value=v) for k, v in values.items()])

    def _report(self, out, status, now):
        level = ord(status.level)
        key = (out.mode, out.status, level)
        changed = key != self._last_key
        if changed:
            if level == 2:
                self._log.error(status.message)
            elif level == 1:
                self._log.warning(status.message)
            elif out.status is not GoalStatus.ACTIVE:
                self._log.info(status.message)
            self._last_key = key
        due = self._last_diagnostics is None or now - self._last_diagnostics \
            >= _DIAGNOSTICS_PERIOD_S
        if changed or due:
            self._last_diagnostics = now
            array = DiagnosticArray()
            array.header.stamp = self.get_clock().now().to_msg()
            array.status = [status]
            self._diagnostics_pub.publish(array)


def main(args=None):
    """Run the controller until SIGINT or SIGTERM: 0 then, 1 when it cannot start."""
    return run_node(GripperController, 'gripper_controller', args)


if __name__ == '__main__':
    sys.exit(main())
