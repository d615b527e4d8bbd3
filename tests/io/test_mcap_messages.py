"""Message builders shared by replay-model and the model node."""

import math
import struct

from mcap_ros2._dynamic import generate_dynamic
from mcap_test_utils import FakeResult
from nav_msgs.msg import Path
import numpy as np
from numpy.testing import assert_allclose
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64
from visualization_msgs.msg import Marker, MarkerArray

from fpc_gripper.io.mcap_writer import message_definition
from fpc_gripper.io.messages import (curvature_message, FingerPlacement, gripper_shape_markers,
                                     GRIPPER_SHAPE_NAMESPACES, gripper_topics,
                                     MAX_CIRCLE_RADIUS, ns_to_time, rigidity_message,
                                     serialized_curvature, serialized_gripper_shape,
                                     serialized_shape,
                                     serialized_shape_markers, shape_marker, shape_message,
                                     tangent_angles, time_to_ns)


def _rotate_x_axis(q):
    """Image of +X under the unit quaternion q = (x, y, z, w)."""
    x, y, z, w = q
    return np.array([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)])


@pytest.mark.parametrize('kappa', [0.0, 12.5, -30.0])
def test_shape_poses_follow_the_midplane_and_its_tangent(kappa):
    result = FakeResult(kappa)
    path = shape_message(result, 'finger_1', 1_234_567_890_123)
    assert path.header.frame_id == 'finger_1'
    assert time_to_ns(path.header.stamp) == 1_234_567_890_123
    assert len(path.poses) == len(result.points)
    for pose, (x, z), phi in zip(path.poses, result.points, result.tangent):
        p, q = pose.pose.position, pose.pose.orientation
        # Exact: the points are copied into the poses unchanged; y, q.x, q.z are never set.
        assert (p.x, p.y, p.z) == (x, 0.0, z)
        assert pose.header == path.header
        # The pose's +X axis is the tangent (cos phi, 0, sin phi): a rotation about Y only.
        assert_allclose(_rotate_x_axis((q.x, q.y, q.z, q.w)),
                        [math.cos(phi), 0.0, math.sin(phi)], atol=1e-15)
        assert q.x == q.z == 0.0


def test_finite_difference_tangents_without_exact_ones():
    result = FakeResult(20.0, n=201)
    assert_allclose(tangent_angles(result.points), result.tangent, atol=1e-4)


@pytest.mark.parametrize('frame_id', ['', 'f', 'finger_0', 'finger_10', 'a' * 13])
@pytest.mark.parametrize('n', [2, 3, 129])
def test_serialized_shape_decodes_to_the_path(frame_id, n):
    result = FakeResult(7.0, n=n)
    data = serialized_shape(result, frame_id, 98_765_432_123_456_789)
    reference = shape_message(result, frame_id, 98_765_432_123_456_789)
    # Exact: both encode the same doubles (one numpy sin/cos of the same half angles), and
    # CDR stores float64 verbatim.
    assert deserialize_message(data, Path) == reference
    assert len(data) == len(serialize_message(reference))
    decode = generate_dynamic('nav_msgs/msg/Path', message_definition('nav_msgs/msg/Path'))
    decoded = decode['nav_msgs/msg/Path'](data)
    assert [p.pose.position.z for p in decoded.poses] == list(result.points[:, 1])


@pytest.mark.parametrize('kappa', [0.0, -0.0, 12.5, -30.0, 1e-300, math.inf])
def test_serialized_curvature_decodes_to_the_message(kappa):
    result = FakeResult(kappa)
    data = serialized_curvature(result)
    reference = curvature_message(result)
    assert data == serialize_message(reference)
    decoded = deserialize_message(data, Float64)
    # Exact: a double stored verbatim; compared as bits (signed zero included).
    assert struct.pack('<d', decoded.data) == struct.pack('<d', reference.data)


def test_rigidity_and_marker():
    msg = rigidity_message(1.5e-3, None, 'finger_2', 5)
    # Exact here and below: values passed through unchanged or set to 0.0 explicitly.
    assert (msg.vector.x, msg.vector.y) == (1.5e-3, 0.0) and math.isnan(msg.vector.z)
    assert msg.header.stamp == ns_to_time(5)
    marker = shape_marker(FakeResult(10.0), 'finger_2', 5, 2, color=(1.0, 0.5, 0.0, 1.0))
    assert marker.header.frame_id == 'finger_2' and marker.id == 2
    assert len(marker.points) == 17 and marker.points[3].y == 0.0
    assert (marker.color.r, marker.color.g, marker.color.a) == (1.0, 0.5, 1.0)


def _fingers(kappas):
    """`gripper_shape_markers` input: one FakeResult finger per curvature, around the palm."""
    colors = [(0.1, 0.7, 0.2, 1.0), (1.0, 0.55, 0.0, 1.0)]
    return [(i, FakeResult(kappa, n=9 + 40 * i), 1_700_000_000_123_456_789 + i,
             FingerPlacement(0.031, 2.0 * math.pi * i / len(kappas)), colors[i % 2])
            for i, kappa in enumerate(kappas)]


def _through_rclpy(markers):
    # Object fields hold Python floats until serialized (colors are float32 in CDR): compare
    # what a subscriber receives.
    return deserialize_message(serialize_message(MarkerArray(markers=markers)), MarkerArray)


@pytest.mark.parametrize('palm', ['', 'p', 'palm', 'pälm_frame', 'a' * 13])
@pytest.mark.parametrize('kappas', [[12.5], [12.5, 0.0, -30.0], [1.0, 5.0, 20.0, 1e-9]])
def test_serialized_markers_decode_to_the_marker_objects(palm, kappas):
    fingers = _fingers(kappas)
    shape = serialized_gripper_shape(fingers, palm)
    assert deserialize_message(shape, MarkerArray) == _through_rclpy(
        gripper_shape_markers(fingers, palm))
    markers = serialized_shape_markers(fingers, palm)
    assert deserialize_message(markers, MarkerArray) == _through_rclpy(
        [shape_marker(r, palm, t, i, color=c, placement=p) for i, r, t, p, c in fingers])
    # A second, independent CDR reader: mcap's own.
    decode = generate_dynamic('visualization_msgs/msg/MarkerArray',
                              message_definition('visualization_msgs/msg/MarkerArray'))
    decoded = decode['visualization_msgs/msg/MarkerArray'](shape)
    assert len(decoded.markers) == 3 * len(kappas)
    flat = [i for i, kappa in enumerate(kappas) if abs(kappa) < 1.0 / MAX_CIRCLE_RADIUS]
    for marker in decoded.markers:
        assert marker.header.frame_id == palm and marker.frame_locked
        assert marker.text == '' and marker.mesh_file.filename == ''
        assert len(marker.colors) == len(marker.mesh_file.data) == 0
        if marker.ns == GRIPPER_SHAPE_NAMESPACES['circle']:
            assert (marker.action == Marker.DELETE) == (marker.id in flat)


def test_gripper_shape_circle_and_tip_are_the_arc_s():
    kappa, placement = 12.5, FingerPlacement(0.031, 0.7)
    fingers = [(0, FakeResult(kappa, n=33), 5, placement, (0.1, 0.7, 0.2, 1.0))]
    markers = deserialize_message(serialized_gripper_shape(fingers, 'palm'), MarkerArray).markers
    midplane, tip, circle = markers
    # The arc's centre is (0, -1/kappa) in the finger's (X, Z); every drawn point of the
    # circle is 1/kappa from it in the palm frame, in the finger's plane.
    centre = placement.to_palm([[0.0, -1.0 / kappa]])[0]
    ring = np.array([[p.x, p.y, p.z] for p in circle.points])
    assert_allclose(np.linalg.norm(ring - centre, axis=1), 1.0 / kappa, rtol=1e-9)
    normal = placement.rotation[:, 1]
    assert_allclose((ring - centre) @ normal, 0.0, atol=1e-12)
    end = placement.to_palm(FakeResult(kappa, n=33).points[-1:])[0]
    p = tip.pose.position
    assert_allclose([p.x, p.y, p.z], end, rtol=0, atol=1e-15)
    assert [(q.x, q.y, q.z) for q in midplane.points][-1] == pytest.approx(tuple(end),
                                                                           abs=1e-15)


def test_default_topic_list():
    topics = gripper_topics(['finger_0', 'finger_1'])
    assert topics[:6] == ['finger_0/pressure_command', 'finger_0/pressure',
                          'finger_0/tip_force', 'finger_0/shape', 'finger_0/curvature',
                          'finger_0/rigidity']
    assert len(topics) == 12 + 9 and '/diagnostics' in topics and 'markers' in topics
    assert 'gripper_shape' in topics and '/tf_static' in topics and '/tf' in topics
