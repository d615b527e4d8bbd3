"""Tests of the model node with real rclpy nodes in the private network namespace."""

import functools
import math
import sys
import threading
import time
import types

from diagnostic_msgs.msg import DiagnosticArray
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import Vector3Stamped
from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Path
import numpy as np
from numpy.testing import assert_allclose
import pytest
import rclpy
from rclpy.context import Context
from rclpy.exceptions import InvalidParameterValueException
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy
from rclpy.qos import qos_profile_sensor_data
from rclpy.qos import QoSProfile
from rclpy.qos import ReliabilityPolicy
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import FluidPressure
from std_msgs.msg import Float64
from visualization_msgs.msg import Marker
from visualization_msgs.msg import MarkerArray

from fpc_gripper.control.geometry import aperture_from_points
from fpc_gripper.control.geometry import PalmGeometry
from fpc_gripper.control.geometry import tips_in_palm_frame
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.io.messages import serialized_shape
from fpc_gripper.io.messages import shape_message
from fpc_gripper.io.messages import time_to_ns
from fpc_gripper.io.tf import TF_QOS
from fpc_gripper.io.tf import TF_STATIC_QOS
from fpc_gripper.model import AdaptiveSolver, CCMSolver, choose_model, Scene
from fpc_gripper.model.pipeline import DEFAULT_TOLERANCE
from fpc_gripper.nodes.model_node import ModelNode

ATM = 101325.0
FINGERS = ('finger_0', 'finger_1', 'finger_2')
CONFIG = load_gripper_config()
DESIGN = CONFIG.fingers[0].design
PALM = PalmGeometry.from_config(CONFIG)
TIMEOUT = 10.0
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
STATE_TOPICS = [(f'{f}/{kind}', cls) for f in FINGERS for kind, cls in (
    ('shape', Path), ('curvature', Float64), ('rigidity', Vector3Stamped))] + [
    ('markers', MarkerArray), ('gripper_shape', MarkerArray)]


def palm_points(index, xz):
    """Finger-frame (X, Z) points in the palm frame, by the controller's palm geometry."""
    xz = np.asarray(xz, dtype=float)
    return tips_in_palm_frame(xz, PALM.palm_radius, [PALM.mount_angles[index]] * len(xz))


def direct(gauge, force=(0.0, 0.0), n_segments=8, pressure_model='adiabatic'):
    """Solve the finger directly with the core, from the flat state."""
    return CCMSolver(DESIGN, n_segments=n_segments, pressure_model=pressure_model).solve(
        gauge, force)


def assert_shape_is(path, result, frame):
    """Compare a received Path with a core result to 1e-9."""
    assert path.header.frame_id == frame
    xyz = np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z]
                    for p in path.poses])
    quat = np.array([[p.pose.orientation.x, p.pose.orientation.y, p.pose.orientation.z,
                      p.pose.orientation.w] for p in path.poses])
    assert xyz.shape == (result.points.shape[0], 3)
    assert_allclose(xyz[:, [0, 2]], result.points, rtol=0, atol=1e-9)
    assert np.all(xyz[:, 1] == 0.0)          # exact: y is never set, it stays 0.0
    # +X of each pose along the tangent: a rotation of -tangent about +Y.
    half = -0.5 * result.tangent
    expected = np.column_stack([0 * half, np.sin(half), 0 * half, np.cos(half)])
    assert_allclose(quat, expected, rtol=0, atol=1e-9)
    assert all(p.header.frame_id == frame and p.header.stamp == path.header.stamp
               for p in path.poses)


class Probe:
    """A test node: publishes inputs and records the outputs of one model node."""

    def __init__(self, context, namespace, measured=False):
        self.ns = namespace
        self.node = rclpy.create_node(f'probe{namespace.replace("/", "_")}', context=context)
        self.cond = threading.Condition()
        self.shapes = {f: [] for f in FINGERS}
        self.curvatures = {f: [] for f in FINGERS}
        self.diagnostics = []
        node = self.node
        for f in FINGERS:
            node.create_subscription(Path, f'{namespace}/{f}/shape',
                                     self._recorder(self.shapes[f]), 10)
            node.create_subscription(Float64, f'{namespace}/{f}/curvature',
                                     self._recorder(self.curvatures[f]), 10)
        node.create_subscription(DiagnosticArray, '/diagnostics',
                                 self._recorder(self.diagnostics), 50)
        topic, qos = ('pressure', qos_profile_sensor_data) if measured else \
            ('pressure_command', 10)
        self.pressure_pubs = {f: node.create_publisher(FluidPressure, f'{namespace}/{f}/{topic}',
                                                       qos) for f in FINGERS}
        self.force_pubs = {f: node.create_publisher(WrenchStamped, f'{namespace}/{f}/tip_force',
                                                    10) for f in FINGERS}

    def _recorder(self, store):
        def record(msg):
            with self.cond:
                store.append(msg)
                self.cond.notify_all()
        return record

    def wait(self, predicate, timeout=TIMEOUT):
        with self.cond:
            return self.cond.wait_for(predicate, timeout)

    def wait_connected(self, timeout=TIMEOUT):
        """Wait until the node subscribes to every input (else a first message is lost)."""
        pubs = [*self.pressure_pubs.values(), *self.force_pubs.values()]
        deadline = time.monotonic() + timeout
        while not all(p.get_subscription_count() for p in pubs):
            assert time.monotonic() < deadline, 'the model node never subscribed'
            time.sleep(0.01)

    def now(self):
        return self.node.get_clock().now()

    def send_pressure(self, finger, absolute, stamp=None):
        msg = FluidPressure()
        msg.header.stamp = (stamp or self.now()).to_msg()
        msg.header.frame_id = finger
        msg.fluid_pressure = float(absolute)
        self.pressure_pubs[finger].publish(msg)
        return time_to_ns(msg.header.stamp)

    def send_force(self, finger, f0, p0, frame=None, stamp=None):
        msg = WrenchStamped()
        msg.header.stamp = (stamp or self.now()).to_msg()
        msg.header.frame_id = finger if frame is None else frame
        msg.wrench.force.x = float(f0)
        msg.wrench.force.z = float(p0)
        self.force_pubs[finger].publish(msg)
        return time_to_ns(msg.header.stamp)

    def shape_stamped(self, finger, stamp_ns):
        """Wait for the shape answering the input stamped `stamp_ns`."""
        def found():
            return any(time_to_ns(p.header.stamp) == stamp_ns for p in self.shapes[finger])
        assert self.wait(found), f'no {finger} shape stamped {stamp_ns}'
        return next(p for p in self.shapes[finger] if time_to_ns(p.header.stamp) == stamp_ns)

    def curvature_becomes(self, finger, value):
        def close():
            c = self.curvatures[finger]
            return bool(c) and abs(c[-1].data - value) <= 1e-9
        ok = self.wait(close)
        last = self.curvatures[finger][-1].data if self.curvatures[finger] else None
        assert ok, f'{finger} curvature {last} never became {value}'

    def status_where(self, finger, predicate, since=0):
        """Wait for a diagnostic status of `finger` satisfying `predicate`; return it."""
        name = f'{self.ns}/model_node: {finger}'
        found = []

        def match():
            for array in self.diagnostics[since:]:
                for status in array.status:
                    if status.name == name and predicate(status):
                        found.append(status)
                        return True
            return False
        assert self.wait(match), f'no diagnostics of {name} matched'
        return found[0]


def values(status):
    return {kv.key: kv.value for kv in status.values}


class Latecomer:
    """
    A node that joins late: one subscription per model state topic, with a given QoS.

    It lives as long as the module's executor: destroying a node while another thread
    spins the executor races with its wait set.
    """

    def __init__(self, ros, namespace, qos=LATCHED, name='latecomer'):
        self.ros = ros
        self.node = ros.add(rclpy.create_node(f'{name}{namespace.replace("/", "_")}',
                                              context=ros.context))
        self.cond = threading.Condition()
        self.got = {topic: [] for topic, _ in STATE_TOPICS}
        for topic, cls in STATE_TOPICS:
            self.node.create_subscription(cls, f'{namespace}/{topic}',
                                          functools.partial(self._store, topic), qos)

    def _store(self, topic, msg):
        with self.cond:
            self.got[topic].append(msg)
            self.cond.notify_all()

    def count(self):
        with self.cond:
            return sum(len(v) for v in self.got.values())

    def wait(self, predicate, timeout=TIMEOUT):
        with self.cond:
            return self.cond.wait_for(predicate, timeout)


class Ros:
    """One context and one executor thread for all the nodes of this module."""

    def __init__(self):
        self.context = Context()
        rclpy.init(context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self):
        while not self.stop.is_set():
            self.executor.spin_once(timeout_sec=0.05)

    def add(self, node):
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def close(self):
        # The spin thread ends first: shutting the executor down under it races with the
        # guard condition it triggers.
        self.stop.set()
        self.thread.join(timeout=5.0)
        self.executor.shutdown(timeout_sec=5.0)
        for node in self.nodes:
            node.destroy_node()
        self.context.try_shutdown()


@pytest.fixture(scope='module')
def ros():
    env = Ros()
    yield env
    env.close()


@pytest.fixture(scope='module')
def model(ros):
    """A paper-CCM8 model node in /m (tolerance 0: fixed n_segments), with its probe."""
    node = ros.add(ModelNode(context=ros.context, namespace='/m', parameter_overrides=[
        Parameter('tolerance', value=0.0)]))
    probe = Probe(ros.context, '/m')
    ros.add(probe.node)
    return node, probe


@pytest.fixture(scope='module')
def single(ros):
    """A single-segment model node in /f reading measured pressure, with its probe."""
    node = ros.add(ModelNode(context=ros.context, namespace='/f', parameter_overrides=[
        Parameter('tolerance', value=0.0), Parameter('n_segments', value=1),
        Parameter('pressure_input', value='measured')]))
    probe = Probe(ros.context, '/f', measured=True)
    ros.add(probe.node)
    return node, probe


def test_serialized_shape_decodes_to_shape_message():
    for n_segments in (1, 3, 8):
        result = direct(1.5e5, n_segments=n_segments)
        for frame in ('finger_0', 'f', 'abc', ''):
            for stamp in (0, 1_795_000_000_123_456_789):
                data = serialized_shape(result, frame, stamp)
                # Exact: both encode the same doubles, and CDR stores float64 verbatim.
                assert deserialize_message(data, Path) == shape_message(result, frame, stamp)


@pytest.mark.ros
def test_nothing_before_the_first_pressure_then_the_rest_state(ros, model):
    node, probe = model
    for finger in FINGERS:
        status = probe.status_where(finger, lambda s: s.level == DiagnosticStatus.WARN)
        assert status.message == 'waiting for pressure input'
    # Nothing was published: a transient-local subscriber joining now gets no history.
    late = Latecomer(ros, '/m', name='early')
    time.sleep(0.5)
    assert late.count() == 0 and all(not probe.shapes[f] for f in FINGERS)
    # A tip force alone is no pressure: still nothing.
    probe.send_force('finger_0', 0.0, 0.0)
    time.sleep(0.3)
    assert late.count() == 0 and not probe.shapes['finger_0']
    since = len(probe.diagnostics)
    rest = direct(0.0)
    stamps = [probe.send_pressure(f, ATM) for f in FINGERS]
    for finger, stamp in zip(FINGERS, stamps):
        assert_shape_is(probe.shape_stamped(finger, stamp), rest, finger)
        probe.curvature_becomes(finger, rest.curvature)
        probe.status_where(finger, lambda s: s.level == DiagnosticStatus.OK, since)
    assert sum(s.solves for s in node.core.fingers) == 1


@pytest.mark.ros
@pytest.mark.parametrize('finger, gauge', [('finger_0', 150e3), ('finger_2', 320e3)])
def test_pressure_command_gives_the_core_solution(model, finger, gauge):
    _, probe = model
    stamp = probe.send_pressure(finger, ATM + gauge)
    path = probe.shape_stamped(finger, stamp)
    expected = direct(gauge)
    assert_shape_is(path, expected, finger)
    probe.curvature_becomes(finger, expected.curvature)


@pytest.fixture(scope='module')
def adaptive(ros):
    """A model node with the default tolerance (0.5 mm) in /a, with its probe."""
    node = ros.add(ModelNode(context=ros.context, namespace='/a'))
    probe = Probe(ros.context, '/a')
    ros.add(probe.node)
    return node, probe


@pytest.mark.ros
def test_default_tolerance_uses_the_model_the_scene_needs(adaptive):
    node, probe = adaptive
    assert node.get_parameter('tolerance').value == DEFAULT_TOLERANCE   # verbatim
    reference = AdaptiveSolver(DESIGN, tolerance=DEFAULT_TOLERANCE)
    stamp = probe.send_pressure('finger_0', ATM + 150e3)
    expected = reference.solve(150e3)
    assert_shape_is(probe.shape_stamped('finger_0', stamp), expected, 'finger_0')
    # The choice is an independent decision of choose_model for this scene.
    choice = choose_model(Scene(DESIGN, 150e3), DEFAULT_TOLERANCE)
    assert (expected.model_choice.rung, expected.model_choice.n_segments) == (
        choice.rung, choice.n_segments)
    # Loaded, the node still makes choose_model's choice for the loaded scene.
    stamp = probe.send_force('finger_0', 0.0, 0.5)
    loaded = reference.solve(150e3, (0.0, 0.5))
    assert_shape_is(probe.shape_stamped('finger_0', stamp), loaded, 'finger_0')
    choice = choose_model(Scene(DESIGN, 150e3, (0.0, 0.5)), DEFAULT_TOLERANCE)
    assert (loaded.model_choice.rung, loaded.model_choice.n_segments) == (
        choice.rung, choice.n_segments)
    assert loaded.model_choice.predicted_error > expected.model_choice.predicted_error


@pytest.mark.ros
def test_tip_force_changes_the_shape(model):
    _, probe = model
    stamp = probe.send_pressure('finger_1', ATM + 100e3)
    probe.shape_stamped('finger_1', stamp)
    stamp = probe.send_force('finger_1', 0.05, -0.2)
    path = probe.shape_stamped('finger_1', stamp)
    expected = direct(100e3, (0.05, -0.2))
    assert_shape_is(path, expected, 'finger_1')
    probe.curvature_becomes('finger_1', expected.curvature)
    assert np.abs(expected.points - direct(100e3).points).max() > 1e-3
    stamp = probe.send_force('finger_1', 0.0, 0.0)
    assert_shape_is(probe.shape_stamped('finger_1', stamp), direct(100e3), 'finger_1')


@pytest.mark.ros
def test_identical_commands_share_one_solve(model):
    node, probe = model
    before = [(s.solves, s.shared) for s in node.core.fingers]
    stamps = [probe.send_pressure(f, ATM + 222e3) for f in FINGERS]
    paths = [probe.shape_stamped(f, s) for f, s in zip(FINGERS, stamps)]
    after = [(s.solves, s.shared) for s in node.core.fingers]
    assert sum(a[0] - b[0] for a, b in zip(after, before)) == 1
    assert sum(a[1] - b[1] for a, b in zip(after, before)) == 2
    expected = direct(222e3)
    for finger, path in zip(FINGERS, paths):
        assert_shape_is(path, expected, finger)


BAD_INPUTS = [
    ('pressure', math.nan, 'fluid_pressure nan Pa is not finite'),
    ('pressure', -1.0, 'fluid_pressure -1.0 Pa absolute is below vacuum'),
    ('pressure', ATM + 450e3, '450000.0 Pa gauge, over the limit 400000.0 Pa gauge'),
    ('stale', ATM + 50e3, 's old, more than stale_after_s = 1 s'),
    ('force', math.inf, 'is not finite'),
    ('frame', 'finger_0', "frame_id 'finger_0' is not 'finger_1'"),
    ('frame', '', "frame_id '' is not 'finger_1'"),
]


@pytest.mark.ros
@pytest.mark.parametrize('kind, value, text', BAD_INPUTS)
def test_bad_input_is_rejected_and_the_state_kept(model, kind, value, text):
    node, probe = model
    finger = 'finger_1'
    good_stamp = probe.send_pressure(finger, ATM + 80e3)
    probe.shape_stamped(finger, good_stamp)
    state = node.core.fingers[1]
    kept = state.result
    count = len(probe.shapes[finger])
    since = len(probe.diagnostics)
    if kind == 'pressure':
        probe.send_pressure(finger, value)
    elif kind == 'stale':
        probe.send_pressure(finger, value, stamp=probe.now() - rclpy.duration.Duration(seconds=5))
    elif kind == 'force':
        probe.send_force(finger, value, 0.0)
    else:
        probe.send_force(finger, 0.1, 0.0, frame=value)
    status = probe.status_where(
        finger, lambda s: s.level == DiagnosticStatus.WARN and text in values(s)['last_rejection'],
        since)
    assert text in status.message
    assert values(status)['pressure_pa'] == '80000.0'    # formatted to 0.1 Pa
    time.sleep(0.2)
    assert len(probe.shapes[finger]) == count
    assert state.result is kept and not state.pending
    # The next good input clears the warning.
    since = len(probe.diagnostics)
    stamp = probe.send_pressure(finger, ATM + 90e3)
    assert_shape_is(probe.shape_stamped(finger, stamp), direct(90e3), finger)
    probe.status_where(finger, lambda s: s.level == DiagnosticStatus.OK, since)


@pytest.mark.ros
@pytest.mark.parametrize('name, value, reason', [
    ('n_segments', 0, 'out of range'),
    ('n_segments', 65, 'out of range'),
    ('pressure_model', 'polytropic',
     "`pressure_model` must be one of ['design', 'adiabatic', 'isobaric']"),
    ('max_rate_hz', 0.5, 'out of range'),
    ('max_rate_hz', math.nan, 'max_rate_hz'),
    ('atmospheric_pressure', 2.0e6, 'out of range'),
    ('stale_after_s', -1.0, 'out of range'),
    ('gripper_config', '/tmp/other.yaml', 'read-only'),
    ('pressure_input', 'measured', 'read-only'),
    ('n_segments', 4.0, 'type'),
])
def test_bad_parameters_are_refused_with_a_reason(model, name, value, reason):
    node, _ = model
    before = node.get_parameter(name).value
    (result,) = node.set_parameters([Parameter(name, value=value)])
    assert not result.successful
    assert reason in result.reason
    assert node.get_parameter(name).value == before    # unchanged, not recomputed: exact


@pytest.mark.ros
def test_parameter_changes_rebuild_the_solvers(model):
    node, probe = model
    for finger, kpa in zip(FINGERS, (120, 60, 30)):
        probe.shape_stamped(finger, probe.send_pressure(finger, ATM + kpa * 1e3))
    try:
        # Every finger is re-solved after a rebuild: wait for all of them, so that a late
        # shape of one change cannot pass for the next one.
        counts = {f: len(probe.shapes[f]) for f in FINGERS}
        (result,) = node.set_parameters([Parameter('n_segments', value=4)])
        assert result.successful
        assert probe.wait(lambda: all(len(probe.shapes[f]) > counts[f] for f in FINGERS))
        assert_shape_is(probe.shapes['finger_0'][-1], direct(120e3, n_segments=4), 'finger_0')
        counts = {f: len(probe.shapes[f]) for f in FINGERS}
        (result,) = node.set_parameters([Parameter('pressure_model', value='isobaric')])
        assert result.successful
        assert probe.wait(lambda: all(len(probe.shapes[f]) > counts[f] for f in FINGERS))
        gauge = node.core.fingers[2].gauge
        assert_shape_is(probe.shapes['finger_2'][-1],
                        direct(gauge, n_segments=4, pressure_model='isobaric'), 'finger_2')
    finally:
        assert all(r.successful for r in node.set_parameters([
            Parameter('n_segments', value=8), Parameter('pressure_model', value='adiabatic')]))
    (result,) = node.set_parameters([Parameter('max_rate_hz', value=500.0)])
    assert result.successful and node.core.max_rate_hz == 500.0    # passed through: exact
    (result,) = node.set_parameters([Parameter('atmospheric_pressure', value=100e3)])
    try:
        stamp = probe.send_pressure('finger_0', 100e3 + 60e3)
        assert_shape_is(probe.shape_stamped('finger_0', stamp), direct(60e3), 'finger_0')
    finally:
        node.set_parameters([Parameter('atmospheric_pressure', value=ATM),
                             Parameter('max_rate_hz', value=200.0)])


@pytest.mark.ros
def test_rigidity_and_markers_for_new_subscribers(ros, model):
    node, probe = model
    for finger in FINGERS:
        probe.shape_stamped(finger, probe.send_pressure(finger, ATM + 10e3))
    stamp = probe.send_pressure('finger_2', ATM + 55.2e3)
    probe.shape_stamped('finger_2', stamp)
    late = Latecomer(ros, '/m', name='slow_outputs')

    def rigidity_stamped(stamp):
        return next((m for m in late.got['finger_2/rigidity']
                     if time_to_ns(m.header.stamp) == stamp), None)

    def markers_stamped(stamp):
        return next((a for a in late.got['markers'] for m in a.markers
                     if m.id == 2 and time_to_ns(m.header.stamp) == stamp), None)

    # The newest state, from the publishers' transient-local history.
    assert late.wait(lambda: rigidity_stamped(stamp) and markers_stamped(stamp))
    rigidity = rigidity_stamped(stamp)
    assert rigidity.header.frame_id == 'finger_2'
    solver = CCMSolver(DESIGN)
    assert_allclose(rigidity.vector.x, solver.rigidity(55.2e3, axis='x').value, rtol=1e-6)
    assert_allclose(rigidity.vector.z, solver.rigidity(55.2e3, axis='z').value, rtol=1e-6)
    assert rigidity.vector.x == pytest.approx(1.396e-3, rel=1e-3)  # SPEC reference
    markers = {m.id: m for m in markers_stamped(stamp).markers}
    assert sorted(markers) == [0, 1, 2]
    strip = markers[2]
    assert strip.type == Marker.LINE_STRIP and strip.header.frame_id == 'palm'
    points = np.array([[p.x, p.y, p.z] for p in strip.points])
    # Placed by the controller's palm geometry (an independent formula of the placement).
    assert_allclose(points, palm_points(2, direct(55.2e3).points), rtol=0, atol=1e-12)
    # Both follow the input (throttled, the last one always sent).
    stamps = [probe.send_pressure('finger_2', ATM + kpa * 1e3) for kpa in (10, 0)]
    assert late.wait(lambda: rigidity_stamped(stamps[-1]) and markers_stamped(stamps[-1]))
    assert rigidity_stamped(stamps[-1]).vector.x == pytest.approx(1.636e-3, rel=1e-3)  # 0 kPa


@pytest.mark.ros
def test_measured_pressure_input(single):
    _, probe = single
    stamp = probe.send_pressure('finger_0', ATM + 30e3)
    assert_shape_is(probe.shape_stamped('finger_0', stamp), direct(30e3, n_segments=1),
                    'finger_0')


@pytest.mark.ros
def test_solver_failure_keeps_the_last_good_state(single):
    # One segment cannot carry (-2.5, 4.3) N, back and up, inside the model's 5 N
    # envelope: the solve fails.
    node, probe = single
    probe.shape_stamped('finger_2', probe.send_pressure('finger_2', ATM))
    state = node.core.fingers[2]
    kept = state.result
    count = len(probe.shapes['finger_2'])
    since = len(probe.diagnostics)
    probe.send_force('finger_2', -2.5, 4.3)
    status = probe.status_where('finger_2', lambda s: s.level == DiagnosticStatus.ERROR, since)
    kv = values(status)
    assert 'continuation' in kv['solver_message'] and 'solver failed' in status.message
    assert kv['tip_force'] == 'f0=0 N, p0=0 N'
    assert kv['input_tip_force'] == 'f0=-2.5 N, p0=4.3 N'
    time.sleep(0.2)
    assert len(probe.shapes['finger_2']) == count
    assert state.result is kept
    since = len(probe.diagnostics)
    stamp = probe.send_force('finger_2', 0.0, 0.0)
    assert_shape_is(probe.shape_stamped('finger_2', stamp), direct(0.0, n_segments=1),
                    'finger_2')
    # The single-segment rest state breaks the small-rotation rule: a warning, not an error.
    status = probe.status_where('finger_2', lambda s: s.level == DiagnosticStatus.WARN, since)
    assert 'valid=False' in status.message


@pytest.mark.ros
def test_invalid_parameter_overrides_refuse_to_start(ros):
    with pytest.raises(ValueError, match='`pressure_model` must be one of'):
        ModelNode(context=ros.context, namespace='/bad',
                  parameter_overrides=[Parameter('pressure_model', value='polytropic')])
    with pytest.raises(InvalidParameterValueException):
        ModelNode(context=ros.context, namespace='/bad',
                  parameter_overrides=[Parameter('n_segments', value=0)])


@pytest.mark.ros
def test_late_subscribers_get_the_newest_state_and_volatile_ones_connect(ros, model):
    node, probe = model
    for finger, kpa in zip(FINGERS, (70, 90, 110)):
        probe.shape_stamped(finger, probe.send_pressure(finger, ATM + kpa * 1e3))
    stamp = probe.send_pressure('finger_1', ATM + 130e3)
    probe.shape_stamped('finger_1', stamp)
    expected = direct(130e3)
    # Wait until every slow output went out: rigidity at <= 10 Hz, markers at 1 Hz while
    # nobody watches them (30 Hz while someone does).
    time.sleep(1.3)
    late = Latecomer(ros, '/m')
    volatile = Latecomer(ros, '/m', qos=QoSProfile(depth=10), name='volatile')
    best_effort = Latecomer(ros, '/m', qos=qos_profile_sensor_data, name='best_effort')
    assert late.wait(lambda: all(late.got.values()))
    time.sleep(0.3)
    # Exactly the newest state of each topic, once: history, not a republish.
    assert {t: len(v) for t, v in late.got.items()} == {t: 1 for t, _ in STATE_TOPICS}
    assert time_to_ns(late.got['finger_1/shape'][0].header.stamp) == stamp
    assert_shape_is(late.got['finger_1/shape'][0], expected, 'finger_1')
    # The circle fit stops at its own tolerance (~1e-10 relative).
    assert_allclose(late.got['finger_1/curvature'][0].data, expected.curvature, rtol=1e-9)
    assert time_to_ns(late.got['finger_1/rigidity'][0].header.stamp) == stamp
    tips = {m.id: m for m in late.got['gripper_shape'][0].markers
            if m.ns == 'fpc_gripper/tip'}
    assert time_to_ns(tips[1].header.stamp) == stamp
    # Volatile and best-effort subscribers are matched, and get no history ...
    for other in (volatile, best_effort):
        for topic, _ in STATE_TOPICS:
            publishers = other.node.get_publishers_info_by_topic(f'/m/{topic}')
            assert [i.node_name for i in publishers] == ['model_node'], topic
        assert other.count() == 0
    assert all(p.get_subscription_count() >= 3 for p in node._outputs.shape_publishers)
    # ... but every answer to a new input.
    stamp = probe.send_pressure('finger_1', ATM + 140e3)
    for other in (volatile, best_effort):
        assert other.wait(lambda o=other: any(
            time_to_ns(m.header.stamp) == stamp for m in o.got['finger_1/shape'])
            and o.got['finger_1/curvature'] and o.got['finger_1/rigidity']
            and o.got['gripper_shape'])


@pytest.mark.ros
def test_gripper_shape_places_every_finger_on_the_palm(ros, model):
    """Tip positions in the palm frame give the controller's aperture; circles fit."""
    node, probe = model
    gauges = (40e3, 180e3, 260e3)
    stamps = [probe.send_pressure(f, ATM + g) for f, g in zip(FINGERS, gauges)]
    for finger, stamp in zip(FINGERS, stamps):
        probe.shape_stamped(finger, stamp)
    late = Latecomer(ros, '/m', name='palm')
    assert late.wait(lambda: any(
        {time_to_ns(m.header.stamp) for m in a.markers} == set(stamps)
        for a in late.got['gripper_shape']))
    shape = next(a for a in late.got['gripper_shape']
                 if {time_to_ns(m.header.stamp) for m in a.markers} == set(stamps))
    parts = {(m.ns, m.id): m for m in shape.markers}
    assert all(m.header.frame_id == 'palm' for m in shape.markers)
    results = [direct(g) for g in gauges]
    tips = np.array([r.points[-1] for r in results])
    got_tips = np.array([[parts['fpc_gripper/tip', i].pose.position.x,
                          parts['fpc_gripper/tip', i].pose.position.y,
                          parts['fpc_gripper/tip', i].pose.position.z] for i in range(3)])
    assert_allclose(got_tips, PALM.tip_points(tips), rtol=0, atol=1e-12)
    assert_allclose(aperture_from_points(got_tips), PALM.aperture(tips), rtol=1e-12)
    assert PALM.aperture(tips) > 0.02      # a real triangle, not a degenerate check
    for i, result in enumerate(results):
        strip = parts['fpc_gripper/midplane', i]
        points = np.array([[p.x, p.y, p.z] for p in strip.points])
        assert_allclose(points, palm_points(i, result.points), rtol=0, atol=1e-12)
        assert_allclose(points[-1], got_tips[i], rtol=0, atol=0)
        circle = parts['fpc_gripper/circle', i]
        ring = np.array([[p.x, p.y, p.z] for p in circle.points])
        # In the finger's plane (spanned by the palm normal and its radial direction) ...
        phi = PALM.mount_angles[i]
        assert_allclose(ring @ [-math.sin(phi), math.cos(phi), 0.0], 0.0, atol=1e-12)
        # ... a circle of the fitted curvature's radius.
        # Evenly spaced round the whole circle (the last point closes it): their mean is
        # its centre.
        centre = ring[:-1].mean(axis=0)
        radius = np.linalg.norm(ring - centre, axis=1)
        assert_allclose(radius, 1.0 / abs(result.curvature), rtol=1e-9)


class _FakeBroadcaster:
    sent = []

    def __init__(self, node):
        self.node = node

    def sendTransform(self, transforms):  # noqa: N802 - tf2_ros's name
        _FakeBroadcaster.sent.extend(transforms)


@pytest.mark.ros
def test_frame_prefix_and_the_static_palm_transforms(ros, monkeypatch):
    """With tf2_ros importable the node broadcasts palm -> finger_<i>, all prefixed."""
    module = types.ModuleType('tf2_ros.static_transform_broadcaster')
    module.StaticTransformBroadcaster = _FakeBroadcaster
    monkeypatch.setitem(sys.modules, 'tf2_ros', types.ModuleType('tf2_ros'))
    monkeypatch.setitem(sys.modules, 'tf2_ros.static_transform_broadcaster', module)
    _FakeBroadcaster.sent.clear()
    node = ros.add(ModelNode(context=ros.context, namespace='/left', parameter_overrides=[
        Parameter('tolerance', value=0.0), Parameter('frame_prefix', value='left/')]))
    probe = Probe(ros.context, '/left')
    ros.add(probe.node)
    probe.wait_connected()
    sent = _FakeBroadcaster.sent
    assert [(t.header.frame_id, t.child_frame_id) for t in sent] == [
        ('left/palm', f'left/{f}') for f in FINGERS]
    assert node.palm_frame == 'left/palm'
    stamp = probe.send_pressure('finger_1', ATM + 200e3)
    result = direct(200e3)
    assert_shape_is(probe.shape_stamped('finger_1', stamp), result, 'left/finger_1')
    # The transform maps the finger-frame midplane onto the palm-frame one.
    transform = sent[1].transform
    q = [transform.rotation.x, transform.rotation.y, transform.rotation.z,
         transform.rotation.w]
    xyz = np.column_stack([result.points[:, 0], 0 * result.points[:, 0], result.points[:, 1]])
    rotated = np.array([quaternion_rotate(q, p) for p in xyz])
    offset = [transform.translation.x, transform.translation.y, transform.translation.z]
    assert_allclose(rotated + offset, palm_points(1, result.points), rtol=0, atol=1e-12)
    # Tip forces must come in the prefixed finger frame.
    since = len(probe.diagnostics)
    probe.send_force('finger_1', 0.0, 0.1)
    probe.status_where('finger_1', lambda s: "is not 'left/finger_1'" in s.message, since)
    stamp = probe.send_force('finger_1', 0.0, 0.1, frame='left/finger_1')
    assert_shape_is(probe.shape_stamped('finger_1', stamp), direct(200e3, (0.0, 0.1)),
                    'left/finger_1')


def quaternion_rotate(q, v):
    """Rotate v by the unit quaternion q = (x, y, z, w): q v q*."""
    x, y, z, w = q
    u = np.array([x, y, z])
    v = np.asarray(v, dtype=float)
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


@pytest.mark.ros
def test_tf_builds_palm_to_finger_to_tip_and_the_tip_is_the_shapes_last_pose(ros, model):
    """A tf subscriber joins the mount (/tf_static) and the tip (/tf) of an answered input."""
    from tf2_msgs.msg import TFMessage
    _, probe = model
    seen = {'/tf_static': [], '/tf': []}
    for topic, qos in (('/tf_static', TF_STATIC_QOS), ('/tf', TF_QOS)):
        probe.node.create_subscription(TFMessage, topic, probe._recorder(seen[topic]), qos)
    probe.wait_connected()
    stamp = probe.send_pressure('finger_1', ATM + 120e3)
    last = probe.shape_stamped('finger_1', stamp).poses[-1]

    def transform(topic, child, stamp_ns=None):
        for msg in seen[topic]:
            for t in msg.transforms:
                if t.child_frame_id == child and (
                        stamp_ns is None or time_to_ns(t.header.stamp) == stamp_ns):
                    return t
        return None
    assert probe.wait(lambda: transform('/tf', 'finger_1_tip', stamp) is not None)
    assert probe.wait(lambda: transform('/tf_static', 'finger_1') is not None)
    tip = transform('/tf', 'finger_1_tip', stamp)
    mount = transform('/tf_static', 'finger_1')
    assert (mount.header.frame_id, tip.header.frame_id) == ('palm', 'finger_1')
    t, p = tip.transform.translation, last.pose.position
    assert_allclose([t.x, t.y, t.z], [p.x, p.y, p.z], rtol=0, atol=1e-9)
    q, o = tip.transform.rotation, last.pose.orientation
    assert_allclose([q.x, q.y, q.z, q.w], [o.x, o.y, o.z, o.w], rtol=0, atol=1e-9)
    # The tree palm -> finger_1 -> finger_1_tip puts the tip where the controller's palm
    # geometry (its own formula, not tf's) puts the solved tip.
    r = mount.transform.rotation
    offset = mount.transform.translation
    in_palm = quaternion_rotate([r.x, r.y, r.z, r.w], [t.x, t.y, t.z]) + [
        offset.x, offset.y, offset.z]
    assert_allclose(in_palm, palm_points(1, [direct(120e3).points[-1]])[0], rtol=0, atol=1e-9)


@pytest.mark.ros
def test_publish_tf_false_sends_no_tf(ros):
    node = ros.add(ModelNode(context=ros.context, namespace='/notf', parameter_overrides=[
        Parameter('publish_tf', value=False)]))
    assert not [p for p in node.publishers if p.topic_name in ('/tf', '/tf_static')]
