"""Pure conversions between CCM results and the gripper's ROS messages, and topic names."""

import math
import struct

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, PoseStamped, Vector3Stamped
from nav_msgs.msg import Path
import numpy as np
from std_msgs.msg import ColorRGBA, Float64
from visualization_msgs.msg import Marker

__all__ = [
    'DEFAULT_ATMOSPHERIC_PRESSURE', 'FINGER_TOPICS', 'GRIPPER_TOPICS', 'MODEL_OUTPUT_TYPES',
    'curvature_message', 'finger_topic', 'gripper_topics', 'model_messages', 'ns_to_time',
    'rigidity_message', 'shape_message', 'tangent_angles', 'time_to_ns',
]

#: Standard atmosphere, the default for absolute-to-gauge conversion [Pa].
DEFAULT_ATMOSPHERIC_PRESSURE = 101325.0
#: Per-finger topics, relative to the node namespace, under ``finger_<i>/``.
FINGER_TOPICS = ('pressure_command', 'pressure', 'tip_force', 'shape', 'curvature',
                 'rigidity')
#: Gripper-level topics (relative, except the absolute ``/diagnostics``).
GRIPPER_TOPICS = ('markers', 'aperture_command', 'grasp_force_command', 'aperture',
                  'controller_state', '/diagnostics')
#: Message types of the model outputs, by per-finger topic.
MODEL_OUTPUT_TYPES = {
    'shape': 'nav_msgs/msg/Path',
    'curvature': 'std_msgs/msg/Float64',
    'rigidity': 'geometry_msgs/msg/Vector3Stamped',
}


def finger_topic(finger, name, namespace=''):
    """
    Build a per-finger topic name.

    Parameters
    ----------
    finger : str
        Finger name, ``finger_<i>``.
    name : str
        One of `FINGER_TOPICS`.
    namespace : str
        Prefix such as ``/gripper`` ('' for a relative name).

    Returns
    -------
    str
        ``<namespace>/<finger>/<name>``, or ``<finger>/<name>`` without a namespace.

    """
    if not namespace:
        return f'{finger}/{name}'
    return f'{namespace.rstrip("/")}/{finger}/{name}'


def gripper_topics(finger_names):
    """
    List every input and output topic of the gripper, relative to its namespace.

    Parameters
    ----------
    finger_names : iterable of str
        Finger names, for instance ``('finger_0', 'finger_1', 'finger_2')``.

    Returns
    -------
    list of str
        Per-finger topics for each finger, then `GRIPPER_TOPICS`.

    """
    topics = [finger_topic(f, name) for f in finger_names for name in FINGER_TOPICS]
    return topics + list(GRIPPER_TOPICS)


def ns_to_time(nanoseconds):
    """
    Convert a time in nanoseconds to ``builtin_interfaces/Time``.

    Parameters
    ----------
    nanoseconds : int
        Time [ns].

    Returns
    -------
    builtin_interfaces.msg.Time

    """
    nanoseconds = int(nanoseconds)
    return Time(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)


def time_to_ns(stamp):
    """
    Convert a ``builtin_interfaces/Time`` (or any object with sec and nanosec) to ns.

    Parameters
    ----------
    stamp : object
        Has integer ``sec`` and ``nanosec``.

    Returns
    -------
    int
        Time [ns].

    """
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _points_and_half_angles(result):
    """Return a result's (M, 2) points [m] and half the negated tangent angles [rad]."""
    points = np.asarray(result.points, dtype=float)
    angles = getattr(result, 'tangent', None)
    angles = tangent_angles(points) if angles is None else np.asarray(angles, dtype=float)
    if angles.shape != (points.shape[0],):
        raise ValueError(f'`result.tangent` must have shape ({points.shape[0]},) [rad], '
                         f'got {angles.shape}')
    # A tangent angle t from +X towards +Z is a rotation of -t about +Y.
    return points, -0.5 * angles


def tangent_angles(points):
    """
    Estimate tangent angles of a sampled planar curve by second-order differences.

    Used only for results that do not carry exact tangents (``result.tangent``).

    Parameters
    ----------
    points : array_like, shape (M, 2)
        (X, Z) samples [m], M >= 2.

    Returns
    -------
    ndarray, shape (M,)
        Angle of the tangent from +X towards +Z [rad].

    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2:
        raise ValueError(f'`points` must have shape (M >= 2, 2) [m], got {pts.shape}')
    if pts.shape[0] == 2:
        d = np.repeat(np.diff(pts, axis=0), 2, axis=0)
    else:
        d = np.gradient(pts, axis=0, edge_order=2)
    return np.unwrap(np.arctan2(d[:, 1], d[:, 0]))


def _shape_arrays(result):
    """Return the (M, 2) points and the quaternion (y, w) halves of a result's shape."""
    points, half = _points_and_half_angles(result)
    return points, np.sin(half), np.cos(half)


def shape_message(result, frame_id, stamp_ns):
    """
    Build the ``finger_<i>/shape`` Path of a CCM result.

    Each pose is a midplane sample at (X, 0, Z) in the finger frame; its orientation
    turns +X onto the tangent, a rotation about +Y by minus the tangent angle (an angle
    from +X towards +Z is a negative rotation about +Y in a right-handed frame).

    Parameters
    ----------
    result : CCMResult
        Uses ``points`` (M, 2) [m] and, if present, the exact ``tangent`` (M,) [rad].
    frame_id : str
        Finger frame, ``finger_<i>``.
    stamp_ns : int
        Header stamp of the path and every pose [ns].

    Returns
    -------
    nav_msgs.msg.Path

    """
    points, qy, qw = _shape_arrays(result)
    stamp = ns_to_time(stamp_ns)
    path = Path()
    path.header.stamp = stamp
    path.header.frame_id = frame_id
    poses = []
    for (x, z), y_rot, w_rot in zip(points.tolist(), qy.tolist(), qw.tolist()):
        pose = PoseStamped()
        pose.header.stamp = stamp
        pose.header.frame_id = frame_id
        pose.pose.position.x = x
        pose.pose.position.z = z
        pose.pose.orientation.y = y_rot
        pose.pose.orientation.w = w_rot
        poses.append(pose)
    path.poses = poses
    return path


def curvature_message(result):
    """
    Build the ``finger_<i>/curvature`` message: signed circle-fit curvature [1/m].

    Parameters
    ----------
    result : CCMResult
        Equilibrium; uses ``curvature`` [1/m].

    Returns
    -------
    std_msgs.msg.Float64

    """
    return Float64(data=float(result.curvature))


def _rigidity_value(value):
    if value is None:
        return math.nan
    value = getattr(value, 'value', value)
    return float(value)


def rigidity_message(k_x, k_z, frame_id, stamp_ns):
    """
    Build the ``finger_<i>/rigidity`` message: x = K_x, z = K_z, y = 0 [N·m²].

    Parameters
    ----------
    k_x, k_z : float, RigidityResult or None
        Flexural rigidities along X and Z [N·m²]; None (not computed) gives NaN.
    frame_id : str
        Finger frame.
    stamp_ns : int
        Header stamp [ns].

    Returns
    -------
    geometry_msgs.msg.Vector3Stamped

    """
    msg = Vector3Stamped()
    msg.header.stamp = ns_to_time(stamp_ns)
    msg.header.frame_id = frame_id
    msg.vector.x = _rigidity_value(k_x)
    msg.vector.z = _rigidity_value(k_z)
    return msg


def model_messages(result, frame_id, stamp_ns, rigidity=(None, None)):
    """
    Build every model output of one finger.

    Parameters
    ----------
    result : CCMResult
        Equilibrium to publish.
    frame_id : str
        Finger frame, ``finger_<i>``.
    stamp_ns : int
        Header stamp [ns].
    rigidity : (k_x, k_z)
        See `rigidity_message`.

    Returns
    -------
    dict
        ``{'shape': Path, 'curvature': Float64, 'rigidity': Vector3Stamped}``.

    """
    return {
        'shape': shape_message(result, frame_id, stamp_ns),
        'curvature': curvature_message(result),
        'rigidity': rigidity_message(rigidity[0], rigidity[1], frame_id, stamp_ns),
    }


# -- Additions for the model node: a fast serialized shape, and RViz/Foxglove markers. --------

__all__ += ['SHAPE_MARKER_NAMESPACE', 'serialized_shape', 'shape_marker']

#: ``ns`` of the per-finger LINE_STRIP markers on ``markers``; the marker id is the finger index.
SHAPE_MARKER_NAMESPACE = 'fpc_gripper/shape'
#: CDR little-endian encapsulation, as every ROS 2 middleware writes it.
_CDR_LE = b'\x00\x01\x00\x00'


def _cdr_header(stamp_ns, frame_id):
    """CDR bytes of a ``std_msgs/Header`` (stamp, then the NUL-terminated frame id)."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    frame = frame_id.encode('utf-8') + b'\x00'
    return struct.pack('<iII', sec, nanosec, len(frame)) + frame


def serialized_shape(result, frame_id, stamp_ns):
    """
    Serialize the `shape_message` of a result straight to CDR bytes, without message objects.

    The bytes decode to exactly `shape_message` (the tests and the model node check it;
    only the alignment padding, which the middleware leaves uninitialised, may differ from
    ``rclpy.serialization.serialize_message``). A Path of 129 poses costs some 4 ms through
    Python message objects (build and serialize) and some 0.02 ms here.
    ``Publisher.publish`` accepts the bytes.

    Parameters
    ----------
    result : CCMResult
        As for `shape_message`.
    frame_id : str
        Finger frame, ``finger_<i>``.
    stamp_ns : int
        Header stamp of the path and every pose [ns].

    Returns
    -------
    bytes
        Little-endian CDR (XCDR1) of a ``nav_msgs/Path``; doubles are aligned to 8 bytes
        from the start of the payload, after the 4-byte encapsulation header.

    """
    points, half = _points_and_half_angles(result)
    count = points.shape[0]
    # Pose: position (x, y, z), orientation (x, y, z, w), as in shape_message.
    values = np.zeros((count, 7))
    values[:, 0] = points[:, 0]
    values[:, 2] = points[:, 1]
    values[:, 4] = np.sin(half)
    values[:, 6] = np.cos(half)
    header = _cdr_header(stamp_ns, frame_id)
    out = bytearray(header)
    out += bytes(-len(out) % 4)
    out += struct.pack('<I', count)
    if count:
        # The first pose may start at 4 mod 8; every later one starts 8-aligned.
        out += header
        out += bytes(-len(out) % 8)
        out += values[0].tobytes()
    if count > 1:
        width = len(header) + (-len(header) % 8)
        records = np.zeros((count - 1, width + 56), dtype=np.uint8)
        records[:, :len(header)] = np.frombuffer(header, dtype=np.uint8)
        records[:, width:] = np.ascontiguousarray(values[1:], dtype='<f8').view(
            np.uint8).reshape(count - 1, 56)
        out += records.tobytes()
    return _CDR_LE + bytes(out)


def shape_marker(result, frame_id, stamp_ns, marker_id, color=(0.1, 0.7, 0.2, 1.0),
                 width=0.002):
    """
    Build a LINE_STRIP marker of a finger's midplane for RViz or Foxglove.

    Parameters
    ----------
    result : CCMResult
        Uses ``points`` (M, 2) [m], drawn at (X, 0, Z) in the finger frame.
    frame_id : str
        Finger frame, ``finger_<i>``.
    stamp_ns : int
        Header stamp [ns].
    marker_id : int
        Marker id within `SHAPE_MARKER_NAMESPACE`, the finger index.
    color : (float, float, float, float)
        RGBA in [0, 1].
    width : float
        Line width [m].

    Returns
    -------
    visualization_msgs.msg.Marker
        Frame-locked, no lifetime, identity pose.

    """
    marker = Marker()
    marker.header.stamp = ns_to_time(stamp_ns)
    marker.header.frame_id = frame_id
    marker.ns = SHAPE_MARKER_NAMESPACE
    marker.id = int(marker_id)
    marker.type = Marker.LINE_STRIP
    marker.action = Marker.ADD
    marker.pose.orientation.w = 1.0
    marker.scale.x = float(width)
    marker.color = ColorRGBA(r=float(color[0]), g=float(color[1]), b=float(color[2]),
                             a=float(color[3]))
    marker.frame_locked = True
    marker.points = [Point(x=x, z=z)
                     for x, z in np.asarray(result.points, dtype=float).tolist()]
    return marker
