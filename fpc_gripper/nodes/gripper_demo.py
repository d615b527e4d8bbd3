"""Scripted gripper session in one process: open, grasp a virtual object, hold, release."""

import argparse
import collections
from dataclasses import dataclass, field
import functools
import math
import pathlib
import struct
import sys
import time

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Path
from rcl_interfaces.msg import ParameterDescriptor
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy
from rclpy.qos import qos_profile_sensor_data
from rclpy.qos import QoSProfile
from rclpy.qos import ReliabilityPolicy
from rclpy.task import Future
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import FluidPressure
from std_msgs.msg import Float64

from fpc_gripper.control.virtual_object import VirtualObject
from fpc_gripper.grasp.objects import make_object
from fpc_gripper.grasp.objects import OBJECTS
from fpc_gripper.io.config import default_gripper_config_path
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.io.messages import gripper_topics
from fpc_gripper.nodes.parameters import float_range

__all__ = ['Phase', 'SessionScript', 'VirtualObjectNode', 'main', 'make_chart', 'run_session']

_RELIABLE = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                       reliability=ReliabilityPolicy.RELIABLE)


class VirtualObjectNode(Node):
    """
    A virtual object in the palm: publishes ``finger_<i>/tip_force`` for every finger.

    On each measured pressure ``finger_<i>/pressure`` it solves that finger's contact with
    the object (:class:`fpc_gripper.control.virtual_object.VirtualObject`: frictionless,
    along the whole finger, on the contact model) and publishes its resultant as a
    WrenchStamped in frame ``finger_<i>``: force.x, force.z the contact force on the
    finger [N], torque.y its moment about the fingertip [N m] (the wrench at the tip
    equivalent to the contact loads). It also reads the tip of the model node's
    ``finger_<i>/shape`` and records, while in contact, its distance from the contact
    model's tip (`residuals`): how far the model node's tip-force finger is from the
    finger in contact. Shapes are taken raw and only the tip is decoded (a 129-pose Path
    costs milliseconds as Python objects).

    Parameters
    ----------
    node_name : str
    **kwargs
        Passed to :class:`rclpy.node.Node`.

    """

    def __init__(self, node_name='virtual_object', **kwargs):
        super().__init__(node_name, **kwargs)
        positive = float_range(1e-3, 0.5)
        self.declare_parameter('gripper_config', str(default_gripper_config_path()),
                               ParameterDescriptor(description='Gripper YAML.', read_only=True))
        self.declare_parameter('object', 'cylinder', ParameterDescriptor(
            description='cylinder (coaxial with the palm axis), sphere (centred on it) or box '
                        '(D x D section, across the palm).', read_only=True,
            additional_constraints=f'one of {list(OBJECTS)}'))
        self.declare_parameter('object_diameter', 0.040, ParameterDescriptor(
            description='Object size D [m].', read_only=True, floating_point_range=positive))
        self.declare_parameter('object_height', 0.0, ParameterDescriptor(
            description="Height of the object's lowest point above the palm [m].",
            read_only=True, floating_point_range=float_range(0.0, 0.5)))
        self.declare_parameter('method', 'exact', ParameterDescriptor(
            description="'exact' (rigid) or 'penalty' (compliant, stiffness_n_m).",
            read_only=True, additional_constraints="one of ['exact', 'penalty']"))
        self.declare_parameter('stiffness_n_m', 200.0, ParameterDescriptor(
            description='Surface stiffness of the penalty method [N/m].', read_only=True,
            floating_point_range=float_range(1.0, 1e6)))
        self.declare_parameter('atmospheric_pressure', 101325.0, ParameterDescriptor(
            description='[Pa]: gauge = absolute - atmospheric_pressure.',
            floating_point_range=float_range(3e4, 1.2e5)))
        param = self.get_parameter
        config = load_gripper_config(param('gripper_config').value)
        method = param('method').value
        if method not in ('exact', 'penalty'):
            raise ValueError(f"`method` must be 'exact' or 'penalty', got {method!r}")
        self._names = config.names
        self._palm_radius = config.palm_radius
        self.object = make_object(param('object').value, param('object_diameter').value,
                                  param('object_height').value)
        self.exact = method == 'exact'
        self.virtual = VirtualObject(self.object, config, penalty=0.0 if self.exact
                                     else param('stiffness_n_m').value)
        self.contacts = [None] * len(self._names)
        self.residuals = collections.deque(maxlen=100000)
        self._pubs = tuple(self.create_publisher(WrenchStamped, f'{n}/tip_force', _RELIABLE)
                           for n in self._names)
        for i, name in enumerate(self._names):
            self.create_subscription(FluidPressure, f'{name}/pressure',
                                     functools.partial(self._on_pressure, i),
                                     qos_profile_sensor_data)
            self.create_subscription(Path, f'{name}/shape', functools.partial(self._on_shape, i),
                                     _RELIABLE, raw=True)
        self.get_logger().info(
            f'{param("object").value} D = {param("object_diameter").value * 1e3:.1f} mm '
            f'({method}); the free fingers touch it below '
            f'{self.virtual.touch_pressure:.0f} Pa gauge')

    @property
    def forces(self):
        """Latest normal force on every finger [N] (0 before any contact)."""
        return [0.0 if c is None else c.normal_force for c in self.contacts]

    def arcs(self):
        """Latest contact arc (start, end) [m] of every finger, or None."""
        return [None if c is None else c.arc for c in self.contacts]

    def _on_pressure(self, index, msg):
        gauge = msg.fluid_pressure - self.get_parameter('atmospheric_pressure').value
        if not math.isfinite(gauge):
            return
        try:
            contact = self.virtual.contact(index, max(gauge, 0.0))
        except (RuntimeError, ValueError, ArithmeticError) as exc:
            # No contact force can be given for this pressure: publish none, so the model
            # node keeps the last one it had.
            self.get_logger().error(f'{self._names[index]}: no contact at {gauge:.0f} Pa '
                                    f'gauge: {exc}', throttle_duration_sec=2.0)
            return
        self.contacts[index] = contact
        out = WrenchStamped()
        out.header.stamp = self.get_clock().now().to_msg()
        out.header.frame_id = self._names[index]
        out.wrench.force.x, out.wrench.force.z = contact.force
        out.wrench.torque.y = contact.torque
        self._pubs[index].publish(out)

    def _on_shape(self, index, data):
        contact = self.contacts[index]
        if contact is None or not contact.in_contact or not self.exact:
            return
        z = _path_tip_z(data)
        if z is None:
            return
        self.residuals.append((self.get_clock().now().nanoseconds * 1e-9,
                               abs(z - contact.tip[1])))

    def residual(self, start, end):
        """Largest |Z_tip(model node) - Z_tip(contact)| of the shapes in [start, end] [m]."""
        return max((r for t, r in self.residuals if start <= t <= end), default=math.nan)


def _path_tip_z(data):
    """
    Z of the last pose of a serialized nav_msgs/Path, or None.

    The CDR payload ends with the last pose: position (x, y, z) then orientation
    (x, y, z, w), eight little- or big-endian doubles aligned to 8 bytes, so z is the
    fifth double from the end.
    """
    if len(data) < 20 or data[0] != 0 or data[1] not in (0, 1):
        return None
    order = '<' if data[1] == 1 else '>'
    # Payload (after the 4-byte encapsulation): stamp (8), frame_id (uint32 length + bytes),
    # then the uint32 pose count aligned to 4 from the payload start.
    offset = 16 + struct.unpack_from(order + 'I', data, 12)[0]
    offset += -(offset - 4) % 4
    if offset + 4 > len(data) or struct.unpack_from(order + 'I', data, offset)[0] == 0:
        return None
    return struct.unpack(order + 'd', data[-40:-32])[0]


@dataclass
class Phase:
    """
    One step of the scripted session.

    Attributes
    ----------
    name : str
    kind : {'aperture', 'grasp', 'hold'}
    value : float
        Aperture [m], grasp force [N], or the duration of a hold [s].
    timeout : float
        Longest time allowed to reach the goal [s].
    reached : bool
    time_to_goal : float
        [s] (nan if never reached).
    start, end : float
        Node-clock times [s].
    final : dict
        Last controller_state values of the phase.
    arcs : list
        Contact arc (start, end) [m] of every finger at the end of the phase, or None.
    holding : float
        Holding force of the grasp at the end of the phase [N] (hold phase only).

    """

    name: str
    kind: str
    value: float
    timeout: float = 10.0
    reached: bool = False
    time_to_goal: float = math.nan
    start: float = math.nan
    end: float = math.nan
    detail: str = ''
    final: dict = field(default_factory=dict)
    arcs: list = field(default_factory=list)
    holding: float = math.nan


class SessionScript(Node):
    """
    Drive the controller through a list of phases, from timers, and judge each one.

    An aperture or grasp phase publishes its goal and waits for ``controller_state`` to
    report that goal (same target) as reached, then dwells `dwell_s`. A hold phase checks
    for its duration that the goal stays reached and that every finger's normal force
    stays within `force_band` of its share of the grasp force. `done` completes after the
    last phase or the first failure; `arcs` (optional) gives every finger's contact arc,
    stored with each phase as it ends.
    """

    def __init__(self, phases, grasp_force, dwell_s=0.5, force_band=0.10, arcs=None,
                 **kwargs):
        super().__init__('session_script', **kwargs)
        self.phases = list(phases)
        self.grasp_force = float(grasp_force)
        self.dwell_s = float(dwell_s)
        self.force_band = float(force_band)
        self._arcs = arcs
        self.done = Future()
        self.state = {}
        self._index = -1
        self._goal_seen_active = False
        self._reached_at = None
        self._aperture_pub = self.create_publisher(Float64, 'aperture_command', _RELIABLE)
        self._force_pub = self.create_publisher(Float64, 'grasp_force_command', _RELIABLE)
        self.create_subscription(DiagnosticStatus, 'controller_state', self._on_state,
                                 _RELIABLE)
        self.started = self._now()
        self._timer = self.create_timer(0.02, self._on_timer)

    def _now(self):
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_state(self, msg):
        self.state = {kv.key: kv.value for kv in msg.values}
        self.state['level'] = int.from_bytes(msg.level, 'little') if isinstance(
            msg.level, bytes) else int(msg.level)
        self.state['message'] = msg.message

    def _ready(self):
        return (self._aperture_pub.get_subscription_count() > 0
                and self._force_pub.get_subscription_count() > 0 and self.state)

    def _start(self, index, now):
        self._index = index
        phase = self.phases[index]
        phase.start = now
        self._goal_seen_active = False
        self._reached_at = None
        if phase.kind == 'aperture':
            self._aperture_pub.publish(Float64(data=phase.value))
        elif phase.kind == 'grasp':
            self._force_pub.publish(Float64(data=phase.value))
        self.get_logger().info(f'phase {phase.name}: {phase.kind} {phase.value:g}')

    def _finish(self, now, reached, detail=''):
        phase = self.phases[self._index]
        phase.end = now
        phase.reached = reached
        phase.detail = detail or phase.detail
        phase.final = dict(self.state)
        if self._arcs is not None:
            phase.arcs = list(self._arcs())
        if not reached or self._index + 1 >= len(self.phases):
            for rest in self.phases[self._index + 1:]:
                rest.detail = 'not run'
            self._timer.cancel()
            if not self.done.done():
                self.done.set_result(all(p.reached for p in self.phases))
            return
        self._start(self._index + 1, now)

    def _matches(self, phase):
        try:
            if phase.kind == 'aperture':
                return abs(float(self.state['aperture_target_m']) - phase.value) < 1e-6 \
                    or 'clamped' in self.state.get('message', '')
            return abs(float(self.state['force_target_n']) - phase.value) < 1e-3
        except (KeyError, ValueError):
            return False

    def _on_timer(self):
        now = self._now()
        if self._index < 0:
            if self._ready() and now - self.started > 1.0:
                self._start(0, now)
            elif now - self.started > 20.0:
                self.phases[0].detail = 'the controller did not come up'
                self._index = 0
                self._finish(now, False)
            return
        phase = self.phases[self._index]
        elapsed = now - phase.start
        status = self.state.get('goal_status', '')
        if phase.kind == 'hold':
            forces = [float(v) for k, v in self.state.items() if k.endswith('contact_force_n')]
            share = self.grasp_force / max(len(forces), 1)
            worst = max((abs(f - share) for f in forces), default=math.inf)
            phase.final = dict(self.state)
            if status != 'reached' or worst > self.force_band * share:
                self._finish(now, False, f'left the goal: status {status}, worst force error '
                                         f'{worst:.3f} N')
            elif elapsed >= phase.value:
                phase.time_to_goal = 0.0
                self._finish(now, True)
            return
        if self._matches(phase) and status == 'active':
            self._goal_seen_active = True
        if self._reached_at is None and self._goal_seen_active and status == 'reached':
            self._reached_at = now
            phase.time_to_goal = now - phase.start
        if self._reached_at is not None and now - self._reached_at >= self.dwell_s:
            self._finish(now, True)
        elif elapsed > phase.timeout:
            self._finish(now, False, f'not reached in {phase.timeout:.1f} s (status {status})')


def default_phases(open_aperture=0.120, grasp_force=1.5, hold_s=3.0):
    """Open, close on the object and grasp, hold, release (open)."""
    return [Phase('open', 'aperture', open_aperture, timeout=8.0),
            Phase('grasp', 'grasp', grasp_force, timeout=10.0),
            Phase('hold', 'hold', hold_s, timeout=hold_s + 1.0),
            Phase('release', 'aperture', open_aperture, timeout=8.0)]


def run_session(output_dir, object_diameter=0.040, grasp_force=1.5, open_aperture=0.120,
                hold_s=3.0, context=None, gripper_config=None, obj='cylinder', mu=0.5):
    """
    Build every node on one executor, run the session and close the recording.

    Parameters
    ----------
    obj : {'cylinder', 'sphere', 'box'}
        The virtual object (resting on the palm), of size `object_diameter` [m].
    grasp_force : float
        Total normal force on the object to grasp with [N].
    mu : float
        Friction coefficient of the holding force reported for the hold phase [-].

    Returns
    -------
    phases : list of Phase
    info : dict
        mcap path, message count, contact residual [m], wall time [s], max command [Pa].

    """
    from fpc_gripper.nodes.gripper_controller import GripperController
    from fpc_gripper.nodes.mcap_recorder import McapRecorder
    from fpc_gripper.nodes.model_node import ModelNode
    from fpc_gripper.nodes.regulator_bridge import RegulatorBridge

    output_dir = pathlib.Path(output_dir)
    output_dir.mkdir(parents=True, exist_ok=True)
    mcap_path = output_dir / 'session.mcap'
    config_path = str(gripper_config or default_gripper_config_path())
    config = load_gripper_config(config_path)
    common = {'context': context} if context is not None else {}
    cfg = Parameter('gripper_config', value=config_path)
    wall = time.monotonic()
    nodes = []
    executor = SingleThreadedExecutor(**common)
    try:
        nodes.append(RegulatorBridge.create_active(parameter_overrides=[
            cfg, Parameter('backend', value='sim'), Parameter('publish_rate_hz', value=50.0)],
            **common))
        # Default model settings throughout: the model node, the controller's inverse and
        # the virtual object all compute the finger through the same pipeline.
        # No rigidity: K_x and K_z take two more solves per new pressure, and the session
        # does not use them.
        nodes.append(ModelNode(parameter_overrides=[
            cfg, Parameter('pressure_input', value='measured'),
            Parameter('max_rate_hz', value=10.0), Parameter('rigidity_rate_hz', value=0.0)],
            **common))
        described = [Parameter('object', value=obj),
                     Parameter('object_diameter', value=float(object_diameter))]
        # The controller is told the object, as a robot is by its perception.
        nodes.append(GripperController(parameter_overrides=[cfg, *described], **common))
        virtual = VirtualObjectNode(parameter_overrides=[cfg, *described], **common)
        nodes.append(virtual)
        topics = [t for t in gripper_topics(config.names) if not t.endswith('/rigidity')]
        recorder = McapRecorder(parameter_overrides=[
            Parameter('output_path', value=str(mcap_path)), Parameter('overwrite', value=True),
            Parameter('topics', value=topics), Parameter('discovery_period_s', value=0.2),
            Parameter('gripper_config', value=config_path)], **common)
        nodes.append(recorder)
        script = SessionScript(default_phases(open_aperture, grasp_force, hold_s),
                               grasp_force, arcs=virtual.arcs, **common)
        nodes.append(script)
        controller = nodes[2]
        for node in nodes:
            executor.add_node(node)
        budget = 30.0 + sum(p.timeout for p in script.phases)
        executor.spin_until_future_complete(script.done, timeout_sec=budget)
        max_command = controller.max_command_seen if hasattr(
            controller, 'max_command_seen') else math.nan
        recorder.close()
        for phase in script.phases:
            if phase.kind == 'hold' and phase.reached:
                pressures = [float(v) for k, v in phase.final.items()
                             if k.endswith('command_pa')]
                phase.holding = virtual.virtual.holding_force(
                    sum(pressures) / len(pressures), mu).holding_force
        info = {'mcap': mcap_path, 'messages': recorder_count(mcap_path),
                'contact_residual': max((virtual.residual(p.start, p.end)
                                         for p in script.phases if p.kind == 'hold'),
                                        default=math.nan),
                'wall_s': time.monotonic() - wall, 'max_command': max_command,
                'max_pressure': config.max_pressure}
        return script.phases, info
    finally:
        for node in reversed(nodes):
            executor.remove_node(node)
            node.destroy_node()
        executor.shutdown()


def recorder_count(path):
    """Message count of a closed MCAP file (0 if it cannot be read)."""
    from fpc_gripper.io.mcap_reader import McapFile
    try:
        with McapFile(path) as mcap:
            return mcap.message_count
    except Exception:  # noqa: BLE001 - reported as 0 messages in the summary
        return 0


def _series(mcap_path, atmospheric):
    """Read the charted topics from the recording: dict of name -> (t [s], values)."""
    from fpc_gripper.io.mcap_reader import McapFile
    data = {}
    start = None
    with McapFile(mcap_path) as mcap:
        wanted = [t for t in mcap.topics if t.endswith(
            ('/pressure', '/pressure_command', '/curvature', '/tip_force', '/aperture'))]
        for rec in mcap.messages(topics=wanted):
            start = rec.log_time if start is None else start
            msg = rec.ros_msg
            if rec.topic.endswith('/tip_force'):
                value = math.hypot(msg.wrench.force.x, msg.wrench.force.z)
            elif rec.topic.endswith(('/pressure', '/pressure_command')):
                value = (msg.fluid_pressure - atmospheric) * 1e-3
            else:
                value = msg.data
            t, v = data.setdefault(rec.topic, ([], []))
            t.append(rec.log_time * 1e-9)
            v.append(value)
    return data


def make_chart(mcap_path, png_path, phases, grasp_force, atmospheric=101325.0):
    """
    Chart aperture, pressures, curvatures and contact forces against time from the MCAP.

    Parameters
    ----------
    mcap_path : path-like
        The session recording.
    png_path : path-like
        The chart to write.
    phases : list of Phase
        Drawn as shaded spans.
    grasp_force : float
        Total normal force goal [N]; its share per finger is drawn as a reference line.
    atmospheric : float
        Subtracted from the absolute pressures [Pa].

    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    data = _series(mcap_path, atmospheric)
    t0 = min((t[0] for t, _ in data.values() if t), default=0.0)
    fig, axes = plt.subplots(4, 1, figsize=(11, 11), sharex=True)
    rows = [('/aperture', 'aperture [mm]', 1e3), ('pressure', 'pressure [kPa gauge]', 1.0),
            ('/curvature', 'curvature [1/m]', 1.0), ('/tip_force', 'contact force |F| [N]', 1.0)]
    for ax, (suffix, label, scale) in zip(axes, rows):
        for topic in sorted(data):
            t, v = data[topic]
            if suffix == 'pressure':
                if not topic.endswith(('/pressure', '/pressure_command')):
                    continue
                style = '--' if topic.endswith('command') else '-'
                name = topic.strip('/').replace('/pressure_command', ' command').replace(
                    '/pressure', ' measured')
                ax.plot([x - t0 for x in t], v, style, lw=1.0, label=name)
            elif topic.endswith(suffix):
                ax.plot([x - t0 for x in t], [x * scale for x in v], lw=1.2,
                        label=topic.strip('/').split('/')[0] if suffix != '/aperture'
                        else 'model estimate')
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    share = grasp_force / max(1, sum(t.endswith('/tip_force') for t in data))
    axes[3].axhline(share, color='k', ls=':', lw=1, label=f'goal per finger {share:.3g} N')
    for phase in phases:
        if math.isfinite(phase.start):
            end = phase.end if math.isfinite(phase.end) else phase.start
            for ax in axes:
                ax.axvspan(phase.start - t0, end - t0, alpha=0.06,
                           color='tab:green' if phase.reached else 'tab:red')
            axes[0].text(phase.start - t0, axes[0].get_ylim()[1], f' {phase.name}',
                         va='top', fontsize=9)
            if phase.kind == 'aperture':
                axes[0].hlines(phase.value * 1e3, phase.start - t0, end - t0, colors='k',
                               linestyles=':', lw=1)
    for ax in axes:
        ax.legend(fontsize=7, ncol=3, loc='upper right')
    axes[-1].set_xlabel('time [s]')
    fig.suptitle('fpc_gripper scripted session (simulated regulator, virtual object)')
    fig.tight_layout()
    fig.savefig(png_path, dpi=90)
    plt.close(fig)


def _arc_text(arc):
    """'s0-s1' in mm of a contact arc, a single value for a point, '-' for none."""
    if arc is None:
        return '-'
    start, end = arc[0] * 1e3, arc[1] * 1e3
    return f'{start:.1f}' if end - start < 0.05 else f'{start:.1f}-{end:.1f}'


def format_summary(phases, info):
    """Return the summary table printed at the end of the session."""
    lines = [f'{"phase":<9} {"goal":>12} {"result":>8} {"t_goal[s]":>9} {"aperture[mm]":>12} '
             f'{"normal force[N]":>22} {"contact arc s[mm]":>32} {"holding[N]":>10}  detail']
    for p in phases:
        goal = {'aperture': f'{p.value * 1e3:.1f} mm', 'grasp': f'{p.value:.3f} N',
                'hold': f'{p.value:.1f} s'}[p.kind]
        aperture = p.final.get('aperture_m')
        aperture = f'{float(aperture) * 1e3:.2f}' if aperture else '-'
        forces = [v for k, v in sorted(p.final.items()) if k.endswith('contact_force_n')]
        forces = ' '.join(f'{float(f):.3f}' for f in forces) or '-'
        arcs = ' '.join(_arc_text(a) for a in p.arcs) or '-'
        holding = f'{p.holding:.3f}' if math.isfinite(p.holding) else '-'
        result = 'REACHED' if p.reached else 'FAILED'
        lines.append(f'{p.name:<9} {goal:>12} {result:>8} {p.time_to_goal:>9.2f} '
                     f'{aperture:>12} {forces:>22} {arcs:>32} {holding:>10}  {p.detail}')
    lines.append(f'recording: {info["mcap"]} ({info["messages"]} messages); largest command '
                 f'{info["max_command"] * 1e-3:.1f} kPa (limit {info["max_pressure"] * 1e-3:.0f});'
                 f' model-node tip (tip-force model) to the contact model tip during hold '
                 f'{info["contact_residual"] * 1e3:.3f} mm; wall time {info["wall_s"]:.1f} s')
    return '\n'.join(lines)


def main(args=None):
    """Run the scripted session; exit 0 only if every phase reached its goal."""
    argv = remove_ros_args(sys.argv if args is None else args)
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
    rclpy.init(args=args)
    phases, info = [], None
    try:
        phases, info = run_session(options.output_dir, options.object_diameter,
                                   options.grasp_force, options.open_aperture, options.hold,
                                   gripper_config=options.gripper_config,
                                   obj=options.object, mu=options.mu)
    except (KeyboardInterrupt, ExternalShutdownException):
        return 130
    finally:
        rclpy.try_shutdown()
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
