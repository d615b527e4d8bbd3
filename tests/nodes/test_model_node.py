"""Tests of the model node with real rclpy nodes in the private network namespace."""

import math
import threading
import time

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
from rclpy.qos import qos_profile_sensor_data
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import FluidPressure
from std_msgs.msg import Float64
from visualization_msgs.msg import Marker
from visualization_msgs.msg import MarkerArray

from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.io.messages import serialized_shape
from fpc_gripper.io.messages import shape_message
from fpc_gripper.io.messages import time_to_ns
from fpc_gripper.model import AdaptiveSolver, CCMSolver, choose_model, Scene
from fpc_gripper.model.pipeline import DEFAULT_TOLERANCE
from fpc_gripper.nodes.model_node import ModelNode

ATM = 101325.0
FINGERS = ('finger_0', 'finger_1', 'finger_2')
DESIGN = load_gripper_config().fingers[0].design
TIMEOUT = 10.0


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


class Ros:
    """One context and one executor thread for all the nodes of this module."""

    def __init__(self):
        self.context = Context()
        rclpy.init(context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes = []
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def add(self, node):
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def close(self):
        self.executor.shutdown(timeout_sec=5.0)
        self.thread.join(timeout=5.0)
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
def test_initial_state_at_rest(model):
    node, probe = model
    rest = direct(0.0)
    for finger in FINGERS:
        assert probe.wait(lambda f=finger: probe.shapes[f]), f'no {finger} shape'
        assert_shape_is(probe.shapes[finger][0], rest, finger)
        probe.curvature_becomes(finger, rest.curvature)
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
    ('pressure_model', 'polytropic', "`pressure_model` must be one of ['adiabatic', 'isobaric']"),
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
    stamp = probe.send_pressure('finger_0', ATM + 120e3)
    probe.shape_stamped('finger_0', stamp)
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
    stamp = probe.send_pressure('finger_2', ATM + 55.2e3)
    probe.shape_stamped('finger_2', stamp)
    got = {'rigidity': [], 'markers': []}
    cond = threading.Condition()

    def record(key):
        def store(msg):
            with cond:
                got[key].append(msg)
                cond.notify_all()
        return store

    subs = [probe.node.create_subscription(Vector3Stamped, '/m/finger_2/rigidity',
                                           record('rigidity'), 10),
            probe.node.create_subscription(MarkerArray, '/m/markers', record('markers'), 10)]
    try:
        with cond:
            assert cond.wait_for(lambda: got['rigidity'] and got['markers'], TIMEOUT)
        rigidity = got['rigidity'][0]
        assert rigidity.header.frame_id == 'finger_2'
        solver = CCMSolver(DESIGN)
        assert_allclose(rigidity.vector.x, solver.rigidity(55.2e3, axis='x').value, rtol=1e-6)
        assert_allclose(rigidity.vector.z, solver.rigidity(55.2e3, axis='z').value, rtol=1e-6)
        assert rigidity.vector.x == pytest.approx(1.396e-3, rel=1e-3)  # SPEC reference
        markers = {m.id: m for m in got['markers'][0].markers}
        assert sorted(markers) == [0, 1, 2]
        strip = markers[2]
        assert strip.type == Marker.LINE_STRIP and strip.header.frame_id == 'finger_2'
        points = np.array([[p.x, p.y, p.z] for p in strip.points])
        assert_allclose(points[:, [0, 2]], direct(55.2e3).points, atol=1e-9)
        # While subscribed, both follow the input (throttled, the last one always sent).
        stamps = [probe.send_pressure('finger_2', ATM + kpa * 1e3) for kpa in (10, 0)]
        with cond:
            assert cond.wait_for(lambda: any(
                time_to_ns(m.header.stamp) == stamps[-1] for m in got['rigidity']), TIMEOUT)
            assert cond.wait_for(lambda: any(
                time_to_ns(m.header.stamp) == stamps[-1] for a in got['markers']
                for m in a.markers), TIMEOUT)
        last = next(m for m in got['rigidity'] if time_to_ns(m.header.stamp) == stamps[-1])
        assert last.vector.x == pytest.approx(1.636e-3, rel=1e-3)  # SPEC reference, 0 kPa
    finally:
        for sub in subs:
            probe.node.destroy_subscription(sub)


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
    assert probe.wait(lambda: probe.shapes['finger_2'])
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
