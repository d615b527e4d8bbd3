"""The tip transform and its CDR bytes against the shape message; the contact markers."""

import math

from nav_msgs.msg import Path
import numpy as np
from numpy.testing import assert_allclose
from rclpy.serialization import deserialize_message
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import Marker

from fpc_gripper.io.contact_markers import contact_marker, CONTACT_NAMESPACE
from fpc_gripper.io.messages import serialized_shape
from fpc_gripper.io.tf import serialized_tip_tf
from fpc_gripper.io.tf import tip_frame
from fpc_gripper.io.tf import tip_transform
from fpc_gripper.model import CCMSolver, Result
from fpc_gripper.model.design import ActuatorDesign

STAMPS = (0, 1_795_000_000_123_456_789)


def test_serialized_tip_tf_decodes_to_the_tip_transform():
    result = CCMSolver(ActuatorDesign.paper(), n_segments=4).solve(1.2e5, (0.1, -0.05))
    for frame in ('finger_0', 'left/finger_12', 'f', ''):
        for stamp in STAMPS:
            decoded = deserialize_message(serialized_tip_tf(result, frame, stamp), TFMessage)
            # Exact: both carry the same doubles, and CDR stores float64 verbatim.
            assert decoded == TFMessage(transforms=[tip_transform(result, frame, stamp)])


def test_the_tip_transform_is_the_last_pose_of_the_shape():
    result = CCMSolver(ActuatorDesign.paper(), n_segments=8).solve(2.0e5)
    for stamp in STAMPS:
        last = deserialize_message(serialized_shape(result, 'finger_2', stamp), Path).poses[-1]
        tf = tip_transform(result, 'finger_2', stamp)
        assert (tf.header.frame_id, tf.child_frame_id) == ('finger_2', 'finger_2_tip')
        assert tf.header.stamp == last.header.stamp
        t, q = tf.transform.translation, tf.transform.rotation
        p, o = last.pose.position, last.pose.orientation
        assert_allclose([t.x, t.y, t.z], [p.x, p.y, p.z], rtol=0, atol=1e-15)
        assert_allclose([q.x, q.y, q.z, q.w], [o.x, o.y, o.z, o.w], rtol=0, atol=1e-15)


def test_the_tip_frame_turns_x_onto_the_tip_tangent():
    """A quarter circle by hand: the tip at (R, R) heads along +Z, so its frame's x is +Z."""
    radius = 0.05
    angle = np.linspace(0.0, 0.5 * math.pi, 9)
    points = np.column_stack([radius * np.sin(angle), radius * (1.0 - np.cos(angle))])
    tf = tip_transform(Result.of({'points': points, 'tangent': angle}), 'finger_0', 0)
    q = tf.transform.rotation
    # x axis of the rotation (x, y, z, w): the first column of its matrix.
    x_axis = [1 - 2 * (q.y ** 2 + q.z ** 2), 2 * (q.x * q.y + q.z * q.w),
              2 * (q.x * q.z - q.y * q.w)]
    assert_allclose(x_axis, [0.0, 0.0, 1.0], atol=1e-12)
    assert_allclose([tf.transform.translation.x, tf.transform.translation.z],
                    [radius, radius], atol=1e-15)
    assert tip_frame('left/finger_1') == 'left/finger_1_tip'


def test_contact_markers_show_the_points_in_contact_and_delete_without():
    positions = np.array([[0.01, -0.002], [0.02, -0.003], [0.03, -0.004]])
    state = Result.of({'position': positions, 'in_contact': np.array([False, True, True])})
    marker = contact_marker(state, 'finger_1', 5, 1)
    assert (marker.type, marker.action) == (Marker.SPHERE_LIST, Marker.ADD)
    assert (marker.ns, marker.id, marker.header.frame_id) == (CONTACT_NAMESPACE, 1, 'finger_1')
    assert [(p.x, p.y, p.z) for p in marker.points] == [(0.02, 0.0, -0.003),
                                                        (0.03, 0.0, -0.004)]
    for gone in (None, Result.of({'position': positions, 'in_contact': np.zeros(3, bool)})):
        deleted = contact_marker(gone, 'finger_1', 5, 1)
        assert deleted.action == Marker.DELETE and (deleted.ns, deleted.id) == (
            CONTACT_NAMESPACE, 1)
