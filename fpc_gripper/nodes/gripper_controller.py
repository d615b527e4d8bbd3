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
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import FluidPressure
from std_msgs.msg import Float64
from visualization_msgs.msg import MarkerArray

from fpc_gripper.control.controller_parameters import law_config
from fpc_gripper.control.controller_parameters import LAW_PARAMETERS
from fpc_gripper.control.controller_parameters import make_law
from fpc_gripper.control.controller_parameters import parameter_table
from fpc_gripper.control.controller_status import contact_states
from fpc_gripper.control.controller_status import ContactDisplay
from fpc_gripper.control.controller_status import controller_status
from fpc_gripper.control.controller_status import StatusSchedule
from fpc_gripper.control.inputs import ControllerInputs
from fpc_gripper.io.config import default_gripper_config_path
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.io.contact_markers import contact_marker
from fpc_gripper.io.qos import RELIABLE_QOS
from fpc_gripper.io.qos import STATE_QOS
from fpc_gripper.io.qos import writer_qos
from fpc_gripper.nodes.gripper_action import GripperCommandServer
from fpc_gripper.nodes.guard import InputGuard
from fpc_gripper.nodes.parameters import check_change
from fpc_gripper.nodes.parameters import declare_table
from fpc_gripper.nodes.parameters import input_bounds
from fpc_gripper.nodes.runner import run_node
from fpc_gripper.services.input_limits import BOUND_NAMES
from fpc_gripper.services.input_limits import input_bound_table
from fpc_gripper.services.logs import NodeLog

__all__ = ['GripperController', 'main']


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
        table = parameter_table(config.max_pressure)
        declare_table(self, (*table, *input_bound_table()))
        # Overrides bypass the on-set callback: check the starting values the same way.
        result = self._validate_parameters([self.get_parameter(n) for n in LAW_PARAMETERS])
        if not result.successful:
            raise ValueError(result.reason)
        self._names = config.names
        self._frames = tuple(self.get_parameter('frame_prefix').value + name
                             for name in self._names)
        self._law = make_law(config, self._values(row[0] for row in table))
        n = len(self._names)
        self._log = NodeLog(self.get_logger())
        self._inputs = ControllerInputs(self._law, self._frames,
                                        self.get_parameter('atmospheric_pressure').value,
                                        input_bounds(self))
        self._guard = InputGuard(self.get_parameter('max_payload_bytes').value)
        self._last_output = None
        self._max_command = -math.inf
        self._schedule = StatusSchedule()
        # Once a control period; the history for a recorder that stalls is sized at the start rate.
        stream = writer_qos(RELIABLE_QOS, self._rate())
        self._command_pubs = tuple(
            self.create_publisher(FluidPressure, f'{name}/pressure_command', stream)
            for name in self._names)
        self._aperture_pub = self.create_publisher(Float64, 'aperture', stream)
        self._state_pub = self.create_publisher(DiagnosticStatus, 'controller_state', stream)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics',
                                                      RELIABLE_QOS)
        self._contacts_pub = self.create_publisher(MarkerArray, 'contacts', STATE_QOS)
        self._contacts = ContactDisplay(n)
        for i, (name, frame) in enumerate(zip(self._names, self._frames)):
            self._subscribe(FluidPressure, f'{name}/pressure', f'{frame}/pressure',
                            qos_profile_sensor_data, functools.partial(self._on_pressure, i))
            self._subscribe(WrenchStamped, f'{name}/tip_force', f'{frame}/tip_force', RELIABLE_QOS,
                            functools.partial(self._on_tip_force, i))
        self._subscribe(Float64, 'aperture_command', 'aperture_command', RELIABLE_QOS,
                        self._on_aperture)
        self._subscribe(Float64, 'grasp_force_command', 'grasp_force_command', RELIABLE_QOS,
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
        """Abort a running GripperCommand goal, close the lost-message handles, then destroy."""
        if getattr(self, '_gripper_cmd', None) is not None:
            self._gripper_cmd.destroy()
            self._gripper_cmd = None
        if getattr(self, '_guard', None) is not None:
            self._guard.close()
        return super().destroy_node()

    # -- parameters -------------------------------------------------------------------------

    def _rate(self):
        return self.get_parameter('control_rate_hz').value

    def _subscribe(self, msg_type, topic, source, qos, callback):
        """Subscribe an input through the guard; `source` names it in the diagnostics."""
        self._guard.subscribe(self, msg_type, topic, qos, callback,
                              functools.partial(self._on_refused, source),
                              functools.partial(self._on_lost, source))

    def _values(self, names):
        return {name: self.get_parameter(name).value for name in names}

    def _law_config(self, changes=None):
        values = {**self._values(LAW_PARAMETERS), **(changes or {})}
        return law_config(values, self._gripper.max_pressure)

    def _validate_parameters(self, parameters):
        return check_change(self, parameters, self._law_refusal, getattr(self, '_frames', ()))

    def _law_refusal(self, changes):
        # the law's config raises a ValueError that names what it cannot take
        self._law_config(changes)

    def _apply_parameters(self, parameters):
        names = {p.name for p in parameters}
        changed = sorted(names & set(LAW_PARAMETERS))
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

    def _on_lost(self, source, count):
        """Report messages the middleware lost on an input (see README: empty payloads)."""
        self._after_input(self._inputs.lost(source, count), source)

    def _after_input(self, check, topic, index=None):
        if not check.accepted:
            where = topic if index is None else f'{self._names[index]}/{topic}'
            self._log.warning(f'{check.headline(where)}, keeping the last good value: '
                              f'{check.detail}', key=(where, check.rejection))
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
        status = controller_status(out, self._names, self._inputs)
        diagnostic = DiagnosticStatus(
            level=bytes([status.level]), name=self.get_fully_qualified_name(),
            message=status.message, hardware_id='gripper',
            values=[KeyValue(key=k, value=v) for k, v in status.values.items()])
        self._state_pub.publish(diagnostic)
        severity, send = self._schedule.update(out, status, now)
        if severity is not None:
            self._log.log(severity, status.message)
        if send:
            array = DiagnosticArray()
            array.header.stamp = self.get_clock().now().to_msg()
            array.status = [diagnostic]
            self._diagnostics_pub.publish(array)
        if self._gripper_cmd is not None:
            self._gripper_cmd.step(out)
        self._publish_contacts(now)

    def _publish_contacts(self, now):
        """Send the contact points of the fingers in contact, and delete those that left."""
        if not self._contacts.due(now):
            return
        states = contact_states(self._law, self._inputs.measurements())
        if not self._contacts.show(now, states):
            return
        stamp = self.get_clock().now().nanoseconds
        markers = [contact_marker(state, frame, stamp, i)
                   for i, (state, frame) in enumerate(zip(states, self._frames))]
        self._contacts_pub.publish(MarkerArray(markers=markers))


def main(args=None):
    """Run the controller until SIGINT or SIGTERM: 0 then, 1 when it cannot start."""
    return run_node(GripperController, 'gripper_controller', args)


if __name__ == '__main__':
    sys.exit(main())
