"""Lost input messages: counted by polling, never by an executor-armed event (a deadlock)."""

import subprocess
import sys
import time

import pytest
import rclpy
from rclpy.context import Context
from rclpy.event_handler import EventHandler
from rclpy.event_handler import QoSSubscriptionEventType
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import FluidPressure

from fpc_gripper.nodes.guard import InputGuard
from fpc_gripper.nodes.lost_messages import LOST_POLL_PERIOD_S
from fpc_gripper.nodes.model_node import ModelNode
from fpc_gripper.nodes.runner import make_executor

TOPIC = '/guard_lost/flood'
SENT = 20_000
# A second process floods a best-effort, depth-1 topic with 2 kB messages faster than the
# subscriber's DDS thread takes them: the middleware reports the gaps as lost samples.
FLOODER = """
import sys, time
import rclpy
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import FluidPressure
rclpy.init()
node = rclpy.create_node('flooder')
pub = node.create_publisher(FluidPressure, sys.argv[1], QoSProfile(
    depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT))
deadline = time.monotonic() + 60.0
while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
    time.sleep(0.05)
time.sleep(0.5)
msg = FluidPressure()
msg.header.frame_id = 'x' * 2000
for i in range(int(sys.argv[2])):
    msg.fluid_pressure = float(i)
    pub.publish(msg)
time.sleep(1.0)
node.destroy_node()
rclpy.shutdown()
"""


@pytest.fixture
def context():
    ctx = Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.shutdown(context=ctx)


def _armed_handlers(node):
    """Lost-message handlers an executor would arm: among the node's waitables."""
    lost = QoSSubscriptionEventType.RCL_SUBSCRIPTION_MESSAGE_LOST
    # Publisher event types are another enum whose values overlap: compare the type too.
    return [w for w in node.waitables if isinstance(w, EventHandler)
            and type(w.event_type) is type(lost) and w.event_type == lost]


def test_model_node_arms_no_lost_message_event(context):
    # The armed MESSAGE_LOST event is what deadlocked the composed gripper in a soak:
    # rmw_fastrtps locks its event mutex and the DataReader's in opposite orders.
    node = ModelNode(context=context, namespace='/guard_arms')
    try:
        assert len(node._pressure_subs) == len(node._force_subs) == 3
        assert _armed_handlers(node) == []
    finally:
        node.destroy_node()


def test_lost_messages_are_counted_while_the_executor_keeps_running(context):
    node = rclpy.create_node('guard_lost', context=context)
    guard = InputGuard(max_payload_bytes=10_000)
    received, lost = [], []
    guard.subscribe(node, FluidPressure, TOPIC, QoSProfile(
        depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT),
        received.append, pytest.fail, lost.append)
    ticks = []
    node.create_timer(0.01, lambda: ticks.append(time.monotonic()))
    executor, _ = make_executor([node])
    flooder = subprocess.Popen([sys.executable, '-c', FLOODER, TOPIC, str(SENT)])
    try:
        deadline = time.monotonic() + 120.0
        while flooder.poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert flooder.wait(timeout=10.0) == 0
        # One more poll period, so the last losses are read.
        end = time.monotonic() + 2 * LOST_POLL_PERIOD_S + 0.2
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        assert _armed_handlers(node) == []
        assert received and all(m.header.frame_id == 'x' * 2000 for m in received[:5])
        assert sum(lost) == guard.lost > 0 and all(count > 0 for count in lost)
        # What was lost was not received: a loss count is never a double count.
        assert len(received) + guard.lost <= SENT
        # The timer kept ticking through the flood: the executor was never stuck.
        assert len(ticks) > 50
    finally:
        if flooder.poll() is None:
            flooder.kill()
        guard.close()
        executor.shutdown()
        node.destroy_node()


def test_the_recorder_arms_no_lost_message_event(context, tmp_path):
    # The recorder counts losses too (its stop line), through the same poll.
    from rclpy.parameter import Parameter

    from fpc_gripper.nodes.mcap_recorder import McapRecorder
    publisher_node = rclpy.create_node('guard_arms_publisher', context=context)
    publisher_node.create_publisher(FluidPressure, TOPIC, 1)
    recorder = McapRecorder(context=context, parameter_overrides=[
        Parameter('output_path', value=str(tmp_path / 'r.mcap')),
        Parameter('topics', value=[TOPIC])])
    try:
        deadline = time.monotonic() + 10.0
        while not recorder.recorded_topics and time.monotonic() < deadline:
            recorder._discover()
            time.sleep(0.05)
        assert recorder.recorded_topics == [TOPIC]
        assert _armed_handlers(recorder) == []
    finally:
        recorder.destroy_node()
        publisher_node.destroy_node()


# A writer in another process sends one empty payload, then enough good messages (12, over
# its depth of 10) for Fast DDS to drop the empty one from its history and send a GAP: the
# reader's middleware then counts one lost message (README: empty payloads).
STALLER = """
import sys, time
import rclpy
from rclpy.serialization import serialize_message
from sensor_msgs.msg import FluidPressure
from std_msgs.msg import Float64
rclpy.init()
node = rclpy.create_node('staller')
pubs = [node.create_publisher(FluidPressure, sys.argv[1], 10),
        node.create_publisher(Float64, sys.argv[2], 10)]
deadline = time.monotonic() + 60.0
while any(p.get_subscription_count() == 0 for p in pubs) and time.monotonic() < deadline:
    time.sleep(0.05)
time.sleep(0.5)
good = [serialize_message(FluidPressure(fluid_pressure=150e3)),
        serialize_message(Float64(data=0.08))]
for pub, payload in zip(pubs, good):
    pub.publish(b'')
    for _ in range(12):
        pub.publish(payload)
        time.sleep(0.01)
time.sleep(float(sys.argv[3]))
node.destroy_node()
rclpy.shutdown()
"""


def test_the_bridge_and_the_controller_report_a_message_lost_in_another_process(context):
    from fpc_gripper.nodes.gripper_controller import GripperController
    from fpc_gripper.nodes.regulator_bridge import RegulatorBridge
    # Apart, so that the controller's commands never reach this bridge.
    bridge = RegulatorBridge.create_active(context=context, namespace='/lost_bridge')
    controller = GripperController(context=context, namespace='/lost_controller')
    executor, _ = make_executor([bridge, controller])
    staller = subprocess.Popen([sys.executable, '-c', STALLER,
                                '/lost_bridge/finger_0/pressure_command',
                                '/lost_controller/aperture_command', '30'])
    guards = (bridge._guard, controller._guard)
    try:
        assert _armed_handlers(bridge) == [] and _armed_handlers(controller) == []
        deadline = time.monotonic() + 60.0
        # A reader keeps the last 10 (its depth) of what the GAP releases at once.
        while (any(g.lost == 0 or g.decoded < 10 for g in guards)
               and staller.poll() is None and time.monotonic() < deadline):
            executor.spin_once(timeout_sec=0.05)
        # The empty payload is lost, counted once; the good messages after it came.
        assert [(g.lost, g.refused) for g in guards] == [(1, 0)] * 2
        assert all(10 <= g.decoded <= 12 for g in guards)
        assert bridge.core._channels[0].lost == controller._inputs.lost_messages == 1
        report = bridge.core.step(bridge._latch()).reports[0]
        assert (report.values['lost_commands'], report.values['rejected_commands']) == ('1', '0')
        assert controller.law.mode.value == 'aperture'
    finally:
        staller.kill()
        staller.wait()
        executor.shutdown()
        controller.destroy_node()
        bridge.destroy_node()


def test_the_bridge_forgets_its_watches_with_its_subscriptions(context):
    from fpc_gripper.nodes.regulator_bridge import RegulatorBridge
    bridge = RegulatorBridge.create_active(context=context, namespace='/lost_cycle')
    try:
        watched = bridge._guard._lost._events
        assert set(watched) == set(bridge._command_subs) and len(watched) == 3
        for trigger in (bridge.trigger_deactivate, bridge.trigger_cleanup):
            trigger()
        assert bridge._command_subs == () and watched == {}
        assert bridge.configure_and_activate(raise_on_failure=True)
        assert set(watched) == set(bridge._command_subs) and len(watched) == 3
        bridge._guard.poll_lost()              # every handle is live: no InvalidHandle
    finally:
        bridge.destroy_node()
    assert watched == {}
