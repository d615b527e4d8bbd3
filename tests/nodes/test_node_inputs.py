"""Issue 12's node-input findings, each reproduced on real nodes whose callbacks the test calls."""

from builtin_interfaces.msg import Time
from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Path
import pytest
import rclpy
from rclpy.context import Context
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from rclpy.serialization import serialize_message
from sensor_msgs.msg import FluidPressure
from std_msgs.msg import Float64

from fpc_gripper.control.inputs import ControllerInputs
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.io.messages import time_to_ns
from fpc_gripper.model import CCMSolver
from fpc_gripper.nodes.gripper_controller import GripperController
from fpc_gripper.nodes.model_node import ModelNode
from fpc_gripper.nodes.regulator_bridge import RegulatorBridge
from fpc_gripper.regulators.safety import SupervisorMode

pytestmark = pytest.mark.ros

ATM = 101325.0
DESIGN = load_gripper_config().fingers[0].design
S = 1_000_000_000


def direct(gauge, force=(0.0, 0.0)):
    """The one-segment CCM answer, solved here from the flat state."""
    return CCMSolver(DESIGN, n_segments=1).solve(gauge, force)


def pressure(absolute=None, stamp=None, frame='finger_0'):
    msg = FluidPressure()
    if absolute is not None:
        msg.fluid_pressure = float(absolute)
    if stamp is not None:
        msg.header.stamp = Time(sec=stamp[0], nanosec=stamp[1])
    msg.header.frame_id = frame
    return msg


def wrench(fx, fz, frame, stamp=None):
    msg = WrenchStamped()
    msg.header.frame_id = frame
    if stamp is not None:
        msg.header.stamp = Time(sec=stamp[0], nanosec=stamp[1])
    msg.wrench.force.x, msg.wrench.force.z = float(fx), float(fz)
    return msg


class Tee:
    """A logger that records each line and passes it on: one call site per severity."""

    def __init__(self, logger):
        self.logger, self.lines = logger, []

    def debug(self, line):
        self.lines.append(('debug', line))
        self.logger.debug(line)

    def info(self, line):
        self.lines.append(('info', line))
        self.logger.info(line)

    def warning(self, line):
        self.lines.append(('warn', line))
        self.logger.warning(line)

    def error(self, line):
        self.lines.append(('error', line))
        self.logger.error(line)


def record(publisher):
    """Keep what a publisher sends (and send it)."""
    sent, send = [], publisher.publish

    def publish(msg):
        sent.append(msg)
        send(msg)
    publisher.publish = publish
    return sent


@pytest.fixture(scope='module')
def context():
    ctx = Context()
    rclpy.init(context=ctx)
    yield ctx
    ctx.try_shutdown()


class ModelRig:
    """A one-segment model node whose callbacks the test calls, with what it sends."""

    def __init__(self, context):
        self.node = ModelNode(context=context, namespace='/inputs', parameter_overrides=[
            Parameter('tolerance', value=0.0), Parameter('n_segments', value=1),
            # Every input solved at once: no rate budget between direct calls.
            Parameter('max_rate_hz', value=10000.0)])
        self.log = Tee(self.node.get_logger())
        self.node._log._logger = self.log
        self.shapes = [record(p) for p in self.node._outputs.shape_publishers]
        self.diagnostics = record(self.node._outputs.diagnostics_publisher)

    def now(self):
        ns = self.node.get_clock().now().nanoseconds
        return ns // S, ns % S

    def status(self, index):
        status = self.diagnostics[-1].status[index]
        return status, {kv.key: kv.value for kv in status.values}

    def shape(self, index):
        return deserialize_message(self.shapes[index][-1], Path)


@pytest.fixture(scope='module')
def model(context):
    rig = ModelRig(context)
    yield rig
    rig.node.destroy_node()


def test_finding_1_a_rejection_and_a_failed_solve_at_one_finger(model):
    """NaN pressure, then a failed solve, and the other way round: the node logs both."""
    node = model.node
    node._on_pressure(2, pressure(ATM, frame='finger_2'))
    count = len(model.shapes[2])
    for first, second in (('rejected', 'failed'), ('failed', 'rejected')):
        for kind in (first, second):
            if kind == 'rejected':
                node._on_pressure(2, pressure(float('nan'), frame='finger_2'))
            else:
                # One segment cannot carry (-2.5, 4.3) N, inside the 5 N envelope.
                node._on_tip_force(2, wrench(-2.5, 4.3, 'finger_2'))
        node._on_tip_force(2, wrench(0.0, 0.0, 'finger_2'))
    levels = [level for level, line in model.log.lines if 'finger_2' in line]
    assert levels.count('warn') >= 1 and levels.count('error') >= 1
    assert node._log.dropped == 0
    # The good inputs were answered, the bad ones not.
    assert len(model.shapes[2]) == count + 2
    assert model.shape(2).poses[-1].pose.position.x == pytest.approx(
        direct(0.0).points[-1, 0], abs=1e-9)


def test_finding_2_stamps_that_are_no_time_or_far_ahead(model):
    node = model.node
    node._on_pressure(0, pressure(ATM + 10e3))
    count = len(model.shapes[0])
    node._on_pressure(0, pressure(ATM + 20e3, stamp=(2147483647, 4000000000)))
    status, values = model.status(0)
    assert 'invalid stamp' in status.message and 'nanosec = 4000000000' in status.message
    sec, nanosec = model.now()
    node._on_pressure(0, pressure(ATM + 20e3, stamp=(sec + 3600, nanosec)))
    status, values = model.status(0)
    assert 'ahead of the node clock, more than future_limit_s = 1 s' in status.message
    assert len(model.shapes[0]) == count and values['pressure_pa'] == '10000.0'
    # Half a second ahead is within the limit: accepted, and its stamp is the output's.
    node._on_pressure(0, pressure(ATM + 30e3, stamp=(sec, nanosec + 1)))
    assert time_to_ns(model.shape(0).header.stamp) == sec * S + nanosec + 1
    # Unstamped: the arrival time on the node clock.
    before = node.get_clock().now().nanoseconds
    node._on_pressure(0, pressure(ATM + 40e3))
    assert before <= time_to_ns(model.shape(0).header.stamp) <= \
        node.get_clock().now().nanoseconds
    # With the lead check off, the latest time a header can carry is a valid stamp.
    assert node.set_parameters([Parameter('future_limit_s', value=0.0)])[0].successful
    try:
        node._on_pressure(0, pressure(ATM + 50e3, stamp=(2147483647, 999999999)))
        assert time_to_ns(model.shape(0).header.stamp) == 2147483647 * S + 999999999
    finally:
        node.set_parameters([Parameter('future_limit_s', value=1.0)])


def test_finding_4_default_pressure_huge_force_and_megabyte_frame(model):
    node = model.node
    node._on_pressure(1, pressure(frame='finger_1'))     # a default-constructed message
    status, values = model.status(1)
    assert status.level == b'\x01' and 'below min_absolute_pressure' in status.message
    assert not node.core.fingers[1].has_pressure and not model.shapes[1]
    node._on_pressure(1, pressure(ATM + 50e3, frame='finger_1'))
    state = node.core.fingers[1]
    kept, solves, failures = state.result, state.solves, state.failures
    node._on_tip_force(1, wrench(1e30, 0.0, 'finger_1'))
    status, values = model.status(1)
    assert 'magnitude 1e+30 N, over max_tip_force = 5 N' in status.message
    assert (state.result, state.solves, state.failures) == (kept, solves, failures)
    count = len(model.log.lines)
    node._on_tip_force(1, wrench(0.1, 0.0, 'x' * 1_000_000))
    status, values = model.status(1)
    assert 'frame_id of 1000000 characters' in status.message
    line = model.log.lines[count][1]
    assert 'frame_id of 1000000 characters' in line and len(line) < 1000
    assert max(len(kv.value) for kv in status.values) < 1000 and len(status.message) < 1000
    assert state.result is kept and len(model.shapes[1]) == 1


def test_finding_4_bounds_are_parameters(model):
    node = model.node
    node._on_pressure(1, pressure(ATM + 60e3, frame='finger_1'))
    (result,) = node.set_parameters([Parameter('max_frame_id_length', value=7)])
    assert not result.successful and 'longest finger frame' in result.reason
    assert node.set_parameters([Parameter('max_tip_force', value=1.0)])[0].successful
    try:
        node._on_tip_force(1, wrench(0.0, 1.2, 'finger_1'))
        assert 'over max_tip_force = 1 N' in model.status(1)[0].message
        node._on_tip_force(1, wrench(0.0, 0.9, 'finger_1'))
        assert model.shape(1).poses[-1].pose.position.z == pytest.approx(
            direct(60e3, (0.0, 0.9)).points[-1, 1], abs=1e-9)
    finally:
        node.set_parameters([Parameter('max_tip_force', value=5.0)])


def test_finding_3_payloads_the_guard_refuses_and_lost_messages(model):
    node = model.node
    take = node._pressure_subs[0].callback         # what the executor calls with the bytes
    count, rejected = len(model.shapes[0]), node.core.fingers[0].rejected
    take(b'')
    status, values = model.status(0)
    assert 'malformed payload' in status.message and 'no FluidPressure' in status.message
    take(bytes(range(256)) * 20)
    assert 'larger than max_payload_bytes = 4096; not decoded' in model.status(0)[0].message
    node._on_lost(0, 'pressure_command', 3)
    status, values = model.status(0)
    assert 'messages lost' in status.message and values['lost_messages'] == '3'
    assert len(model.shapes[0]) == count
    take(serialize_message(pressure(ATM + 70e3)))
    status, values = model.status(0)
    assert 'rejected' not in status.message and len(model.shapes[0]) == count + 1
    assert (values['rejected'], values['lost_messages']) == (str(rejected + 2), '3')


def test_controller_rejects_and_reports_then_recovers(context):
    node = GripperController(context=context, namespace='/controller_inputs')
    try:
        node._log._logger = log = Tee(node.get_logger())
        states = record(node._state_pub)
        node._on_timer()
        assert states[-1].level == b'\x00'
        node._on_pressure(0, pressure())                 # default: 0 Pa absolute
        node._on_tip_force(1, wrench(0.0, 6.0, 'finger_1'))
        node._on_grasp(Float64(data=1e30))
        node._on_aperture(Float64(data=float('inf')))
        assert node._inputs.measurements() == ControllerInputs(
            node.law, node._inputs.frames).measurements()
        assert node.law.mode.value == 'idle'
        node._on_timer()
        state = states[-1]
        assert state.level == b'\x01'
        for text in ('finger_0/pressure (below vacuum): fluid_pressure 0.0 Pa absolute',
                     'finger_1/tip_force (over the force limit): force',
                     'grasp_force_command (out of range): grasp force 1e+30 N',
                     'aperture_command (not finite): inf is not a finite number'):
            assert text in state.message
        assert [kv.value for kv in state.values if kv.key == 'rejected_inputs'] == ['4']
        # One line per rejection, and one for the controller's change to WARN.
        assert [line.split(' rejected (')[0] for level, line in log.lines
                if level == 'warn' and ' rejected (' in line] == [
            'finger_0/pressure', 'finger_1/tip_force', 'grasp_force_command',
            'aperture_command']
        assert sum(level == 'warn' for level, _ in log.lines) == 5
        node._on_pressure(0, pressure(ATM + 1e3))
        node._on_tip_force(1, wrench(0.0, 0.5, 'finger_1'))
        node._on_grasp(Float64(data=0.3))
        node._on_aperture(Float64(data=0.08))
        node._on_timer()
        assert states[-1].level == b'\x00' and 'rejected' not in states[-1].message
        assert node._inputs.pressure[0] == pytest.approx(1e3, abs=1e-9)
    finally:
        node.destroy_node()


def test_bridge_refuses_a_default_command(context):
    bridge = RegulatorBridge.create_active(context=context, namespace='/bridge_inputs')
    try:
        bridge._on_command(0, pressure())
        assert bridge.supervisors[0].mode is SupervisorMode.IDLE
        report = bridge.core.step(bridge._latch()).reports[0]
        assert report.level == 1 and 'command rejected (below vacuum)' in report.message
        bridge._on_command(0, pressure(ATM + 50e3))
        assert bridge.supervisors[0].mode is SupervisorMode.TRACKING
        report = bridge.core.step(bridge._latch()).reports[0]
        assert report.level == 0 and report.values['rejected_commands'] == '1'
    finally:
        bridge.destroy_node()


def test_controller_reports_lost_messages_apart_from_rejections(context):
    node = GripperController(context=context, namespace='/controller_lost')
    try:
        node._log._logger = log = Tee(node.get_logger())
        states = record(node._state_pub)
        node._on_pressure(0, pressure(ATM + 1e3))
        node._on_lost('finger_0/pressure', 3)
        node._on_lost('finger_0/pressure', 2)
        node._on_timer()
        state = states[-1]
        values = {kv.key: kv.value for kv in state.values}
        assert state.level == b'\x01'
        assert ('finger_0/pressure (messages lost): 2 message(s) lost (5 in all)'
                in state.message)
        # A loss is no rejection, and says so.
        assert 'rejected' not in state.message and values['rejected_inputs'] == '0'
        assert values['lost_messages'] == '5'
        assert node._inputs.pressure[0] == pytest.approx(1e3, abs=1e-9)
        # One line for the losses (throttled per key), not worded as a rejection.
        assert [line for level, line in log.lines if line.startswith('finger_0/pressure')] == [
            'finger_0/pressure (messages lost), keeping the last good value: 3 message(s) '
            'lost (3 in all): the middleware could not deliver them']
        node._on_pressure(0, pressure(ATM + 2e3))
        node._on_timer()
        values = {kv.key: kv.value for kv in states[-1].values}
        assert states[-1].level == b'\x00' and 'lost' not in states[-1].message
        assert values['lost_messages'] == '5'
    finally:
        node.destroy_node()


def test_bridge_reports_lost_commands_until_a_good_one(context):
    bridge = RegulatorBridge.create_active(context=context, namespace='/bridge_lost')
    try:
        bridge._on_command(0, pressure(ATM + 50e3))
        bridge._on_lost(0, 4)
        report = bridge.core.step(bridge._latch()).reports[0]
        assert report.level == 1
        assert 'messages lost: 4 command(s) lost (4 in all)' in report.message
        assert (report.values['lost_commands'], report.values['rejected_commands']) == ('4', '0')
        assert report.values['last_rejection'].startswith('messages lost: 4 command(s)')
        # The last good command stands: a loss changes no setpoint.
        assert bridge.supervisors[0].mode is SupervisorMode.TRACKING
        assert bridge.core.step(bridge._latch()).reports[1].level == 0
        bridge._on_command(0, pressure(ATM + 60e3))
        report = bridge.core.step(bridge._latch()).reports[0]
        assert report.level == 0 and report.values['lost_commands'] == '4'
    finally:
        bridge.destroy_node()
