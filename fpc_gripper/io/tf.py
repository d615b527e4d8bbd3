"""The gripper's tf frames: palm -> finger mounts, finger -> tip transforms, their QoS and CDR."""

import struct

from geometry_msgs.msg import TransformStamped
import numpy as np

from .messages import _cdr_header, _CDR_LE, _points_and_half_angles, ns_to_time
from .qos import TF_QOS, TF_STATIC_QOS

__all__ = ['TF_QOS', 'TF_STATIC_QOS', 'TIP_SUFFIX', 'palm_transform', 'serialized_tip_tf',
           'tip_frame', 'tip_transform']

#: A finger's tip frame is its base frame with this suffix: ``finger_<i>_tip``.
TIP_SUFFIX = '_tip'


def tip_frame(finger_frame):
    """Return the tip frame id of a finger (base) frame id, ``<finger_frame>_tip``."""
    return finger_frame + TIP_SUFFIX


def palm_transform(placement, palm_frame, finger_frame, stamp_ns=0):
    """
    Build the static transform palm -> finger of a finger placement, as tf2 broadcasts it.

    Parameters
    ----------
    placement : FingerPlacement
        The finger's clamp.
    palm_frame, finger_frame : str
        Parent and child frame ids.
    stamp_ns : int
        Header stamp [ns].

    Returns
    -------
    geometry_msgs.msg.TransformStamped
        Maps finger-frame coordinates to palm-frame ones.

    """
    msg = TransformStamped()
    msg.header.stamp = ns_to_time(stamp_ns)
    msg.header.frame_id = palm_frame
    msg.child_frame_id = finger_frame
    t = msg.transform.translation
    t.x, t.y, t.z = (float(v) for v in placement.translation)
    r = msg.transform.rotation
    r.x, r.y, r.z, r.w = (float(v) for v in placement.quaternion)
    return msg


def _tip_pose(result):
    """Return the tip's (X, Z) [m] and quaternion (y, w) halves: the shape's last pose."""
    points, half = _points_and_half_angles(result)
    return float(points[-1, 0]), float(points[-1, 1]), np.sin(half[-1]), np.cos(half[-1])


def tip_transform(result, finger_frame, stamp_ns):
    """
    Build the transform finger -> tip of a result: the last pose of its shape message.

    Parameters
    ----------
    result : Result
        Uses ``points`` (M, 2) [m] and, if present, ``tangent`` (M,) [rad].
    finger_frame : str
        The finger's base frame (``finger_<i>``, the clamp); the child is `tip_frame` of it.
    stamp_ns : int
        Header stamp: that of the answered input [ns].

    Returns
    -------
    geometry_msgs.msg.TransformStamped
        Translation (X, 0, Z) [m]; rotation about +Y turning +X onto the tip's tangent.

    """
    x, z, y_rot, w_rot = _tip_pose(result)
    msg = TransformStamped()
    msg.header.stamp = ns_to_time(stamp_ns)
    msg.header.frame_id = finger_frame
    msg.child_frame_id = tip_frame(finger_frame)
    msg.transform.translation.x = x
    msg.transform.translation.z = z
    msg.transform.rotation.y = float(y_rot)
    msg.transform.rotation.w = float(w_rot)
    return msg


def serialized_tip_tf(result, finger_frame, stamp_ns):
    """
    Serialize a ``tf2_msgs/TFMessage`` holding the `tip_transform` alone, to CDR bytes.

    It decodes to exactly ``TFMessage(transforms=[tip_transform(...)])`` (tested); built
    without message objects for the per-command path. ``Publisher.publish`` accepts it.

    Parameters
    ----------
    result, finger_frame, stamp_ns
        As for `tip_transform`.

    Returns
    -------
    bytes
        Little-endian CDR: the encapsulation, the sequence length 1, the header, the child
        frame id, then translation and rotation as doubles aligned to 8 bytes.

    """
    x, z, y_rot, w_rot = _tip_pose(result)
    out = bytearray(struct.pack('<I', 1))
    out += _cdr_header(stamp_ns, finger_frame)
    out += bytes(-len(out) % 4)
    child = tip_frame(finger_frame).encode('utf-8') + b'\x00'
    out += struct.pack('<I', len(child)) + child
    out += bytes(-len(out) % 8)
    out += struct.pack('<7d', x, 0.0, z, 0.0, y_rot, 0.0, w_rot)
    return _CDR_LE + bytes(out)
