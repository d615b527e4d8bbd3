"""Pure conversions between CCM results and the gripper's ROS messages, and topic names."""

import dataclasses
import math
import struct
from typing import NamedTuple

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, PoseStamped, Vector3Stamped
from nav_msgs.msg import Path
import numpy as np
from std_msgs.msg import ColorRGBA, Float64
from visualization_msgs.msg import Marker

from fpc_gripper.model.validation import STANDARD_ATMOSPHERE

from .qos import STATE_QOS

__all__ = [
    'DEFAULT_ATMOSPHERIC_PRESSURE', 'FINGER_TOPICS', 'GRIPPER_TOPICS', 'MODEL_OUTPUT_TYPES',
    'STATE_QOS',
    'curvature_message', 'finger_topic', 'gripper_topics', 'model_messages', 'ns_to_time',
    'rigidity_message', 'shape_message', 'tangent_angles', 'time_to_ns',
]

#: Standard atmosphere, the default for absolute-to-gauge conversion [Pa].
DEFAULT_ATMOSPHERIC_PRESSURE = STANDARD_ATMOSPHERE
#: Per-finger topics, relative to the node namespace, under ``finger_<i>/``.
FINGER_TOPICS = ('pressure_command', 'pressure', 'tip_force', 'shape', 'curvature',
                 'rigidity')
#: Gripper-level topics (relative, except the absolute ``/diagnostics``, ``/tf_static``
#: and ``/tf``).
GRIPPER_TOPICS = ('markers', 'gripper_shape', 'aperture_command', 'grasp_force_command',
                  'aperture', 'controller_state', '/diagnostics', '/tf_static', '/tf')
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
    result : Result
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
    result : Result
        Equilibrium; uses ``curvature`` [1/m].

    Returns
    -------
    std_msgs.msg.Float64

    """
    return Float64(data=float(result.curvature))


def serialized_curvature(result):
    """Serialize the `curvature_message` of a result to CDR bytes (the per-command path)."""
    return _CDR_LE + struct.pack('<d', float(result.curvature))


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
    k_x, k_z : float, rigidity Result or None
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
    result : Result
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

__all__ += ['GRIPPER_SHAPE_NAMESPACES', 'SHAPE_MARKER_NAMESPACE', 'FingerPlacement',
            'gripper_shape_markers', 'serialized_gripper_shape',
            'serialized_curvature', 'serialized_shape', 'serialized_shape_markers',
            'shape_marker']

#: ``ns`` of the per-finger LINE_STRIP markers on ``markers``; the marker id is the finger index.
SHAPE_MARKER_NAMESPACE = 'fpc_gripper/shape'
#: ``ns`` of the markers on ``gripper_shape``, by part; the marker id is the finger index.
GRIPPER_SHAPE_NAMESPACES = {'midplane': 'fpc_gripper/midplane', 'tip': 'fpc_gripper/tip',
                            'circle': 'fpc_gripper/circle'}
#: Fitted circles larger than this are not drawn (a nearly flat finger) [m].
MAX_CIRCLE_RADIUS = 0.5
_CIRCLE_POINTS = 73
_CIRCLE_COLOR = (0.2, 0.4, 1.0, 0.6)
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
    result : Result
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


@dataclasses.dataclass(frozen=True)
class FingerPlacement:
    """
    Where a finger is clamped on the palm, and the rigid transform of its frame.

    The palm frame has its origin at the palm centre, x and y in the palm plane (mount
    angle 0 along x) and z along the palm normal, towards the object. The finger frame's
    origin is the clamp edge at `palm_radius` and `mount_angle`; its X axis is the palm
    normal and its Z axis points radially outwards, so its Y axis is Z x X.

    Attributes
    ----------
    palm_radius : float
        Palm centre to the clamp edge [m].
    mount_angle : float
        Azimuth of the finger [rad].

    """

    palm_radius: float
    mount_angle: float

    @property
    def rotation(self):
        """Rotation matrix (3, 3) whose columns are the finger axes in the palm frame."""
        c, s = math.cos(self.mount_angle), math.sin(self.mount_angle)
        return np.array([[0.0, s, c], [0.0, -c, s], [1.0, 0.0, 0.0]])

    @property
    def translation(self):
        """Finger frame origin in the palm frame (3,) [m]."""
        return self.palm_radius * np.array(
            [math.cos(self.mount_angle), math.sin(self.mount_angle), 0.0])

    @property
    def quaternion(self):
        """Rotation of the finger frame: the unit quaternion [x, y, z, w] with w >= 0."""
        return _quaternion(self.rotation)

    def to_palm(self, points):
        """
        Map finger-frame midplane points to the palm frame.

        Parameters
        ----------
        points : array_like, shape (M, 2)
            (X, Z) in the finger frame [m]; Y is 0 on the midplane.

        Returns
        -------
        ndarray, shape (M, 3)
            (x, y, z) in the palm frame [m].

        """
        xz = np.asarray(points, dtype=float).reshape(-1, 2)
        xyz = np.column_stack([xz[:, 0], np.zeros(len(xz)), xz[:, 1]])
        return xyz @ self.rotation.T + self.translation


def _quaternion(rotation):
    """Return the unit quaternion (x, y, z, w), w >= 0, of a rotation matrix (Shepperd)."""
    m = rotation
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    k = int(np.argmax([trace, m[0, 0], m[1, 1], m[2, 2]]))
    if k == 0:
        w = 0.5 * math.sqrt(1.0 + trace)
        q = ((m[2, 1] - m[1, 2]) / (4 * w), (m[0, 2] - m[2, 0]) / (4 * w),
             (m[1, 0] - m[0, 1]) / (4 * w), w)
    else:
        i, j, n = k - 1, k % 3, (k + 1) % 3
        r = 0.5 * math.sqrt(1.0 + m[i, i] - m[j, j] - m[n, n])
        q = [0.0, 0.0, 0.0, (m[n, j] - m[j, n]) / (4 * r)]
        q[i] = r
        q[j] = (m[j, i] + m[i, j]) / (4 * r)
        q[n] = (m[n, i] + m[i, n]) / (4 * r)
    q = np.array(q)
    return q if q[3] >= 0.0 else -q


class _MarkerParts(NamedTuple):
    """What a gripper marker holds; the rest of ``visualization_msgs/Marker`` stays default."""

    frame_id: str
    stamp_ns: int
    namespace: str
    marker_id: int
    kind: int
    color: tuple
    scale: float
    position: tuple = (0.0, 0.0, 0.0)
    points: np.ndarray = None
    delete: bool = False


def _to_marker(parts):
    """Build the ``Marker`` object of `_MarkerParts`."""
    marker = Marker()
    marker.header.stamp = ns_to_time(parts.stamp_ns)
    marker.header.frame_id = parts.frame_id
    marker.ns = parts.namespace
    marker.id = int(parts.marker_id)
    marker.type = parts.kind
    marker.action = Marker.DELETE if parts.delete else Marker.ADD
    marker.pose.position = Point(x=parts.position[0], y=parts.position[1],
                                 z=parts.position[2])
    marker.pose.orientation.w = 1.0
    marker.scale.x = marker.scale.y = marker.scale.z = float(parts.scale)
    color = parts.color
    marker.color = ColorRGBA(r=float(color[0]), g=float(color[1]), b=float(color[2]),
                             a=float(color[3]))
    marker.frame_locked = True
    if parts.points is not None:
        marker.points = [Point(x=x, y=y, z=z) for x, y, z in parts.points.tolist()]
    return marker


class _Cdr:
    """Little-endian CDR (XCDR1) into a buffer; alignment counts from the payload start."""

    def __init__(self):
        self.buffer = bytearray()

    def pack(self, fmt, size, *values):
        self.buffer += bytes(-len(self.buffer) % size)
        self.buffer += struct.pack(fmt, *values)

    def header(self, stamp_ns, frame_id):
        """Append a ``std_msgs/Header``, 4-aligned, as `_cdr_header` encodes it."""
        self.buffer += bytes(-len(self.buffer) % 4)
        self.buffer += _cdr_header(stamp_ns, frame_id)

    def string(self, text):
        data = text.encode('utf-8') + b'\x00'
        self.pack('<I', 4, len(data))
        self.buffer += data

    def doubles(self, values):
        self.buffer += bytes(-len(self.buffer) % 8)
        self.buffer += np.ascontiguousarray(values, dtype='<f8').tobytes()


def _marker_cdr(parts, cdr):
    """Append the CDR of the ``Marker`` of `_MarkerParts`, as `_to_marker` builds it."""
    cdr.header(parts.stamp_ns, parts.frame_id)
    cdr.string(parts.namespace)
    cdr.pack('<iii', 4, int(parts.marker_id), parts.kind,
             Marker.DELETE if parts.delete else Marker.ADD)
    scale = float(parts.scale)
    cdr.pack('<10d', 8, *(float(v) for v in parts.position), 0.0, 0.0, 0.0, 1.0,
             scale, scale, scale)
    # Lifetime 0 s, then frame_locked.
    cdr.pack('<4fiI?', 4, *(float(v) for v in parts.color), 0, 0, True)
    count = 0 if parts.points is None else len(parts.points)
    cdr.pack('<I', 4, count)
    if count:
        cdr.doubles(parts.points)
    # The rest, empty: colors, texture_resource, texture (stamp, frame_id, format, data),
    # uv_coordinates, text, mesh_resource, mesh_file (filename, data),
    # mesh_use_embedded_materials. Each empty string is 5 bytes, so the counts after it pad.
    cdr.pack('<I', 4, 0)
    cdr.string('')
    cdr.pack('<iI', 4, 0, 0)
    cdr.string('')
    cdr.string('')
    cdr.pack('<I', 4, 0)
    cdr.pack('<I', 4, 0)
    cdr.string('')
    cdr.string('')
    cdr.string('')
    cdr.pack('<I', 4, 0)
    cdr.pack('<?', 1, False)


def _serialized_marker_array(parts_list):
    """CDR bytes of the ``visualization_msgs/MarkerArray`` of `_MarkerParts`."""
    cdr = _Cdr()
    cdr.pack('<I', 4, len(parts_list))
    for parts in parts_list:
        _marker_cdr(parts, cdr)
    return _CDR_LE + bytes(cdr.buffer)


def _shape_marker_parts(result, frame_id, stamp_ns, marker_id, color, width, placement,
                        namespace):
    xz = np.asarray(result.points, dtype=float).reshape(-1, 2)
    if placement is None:
        points = np.column_stack([xz[:, 0], np.zeros(len(xz)), xz[:, 1]])
    else:
        points = placement.to_palm(xz)
    return _MarkerParts(frame_id, stamp_ns, namespace, marker_id, Marker.LINE_STRIP, color,
                        width, points=points)


def shape_marker(result, frame_id, stamp_ns, marker_id, color=(0.1, 0.7, 0.2, 1.0),
                 width=0.002, placement=None, namespace=SHAPE_MARKER_NAMESPACE):
    """
    Build a LINE_STRIP marker of a finger's midplane for RViz or Foxglove.

    Parameters
    ----------
    result : Result
        Uses ``points`` (M, 2) [m], drawn at (X, 0, Z) in the finger frame.
    frame_id : str
        The finger frame, or the palm frame when `placement` is given.
    stamp_ns : int
        Header stamp [ns].
    marker_id : int
        Marker id within `namespace`, the finger index.
    color : (float, float, float, float)
        RGBA in [0, 1].
    width : float
        Line width [m].
    placement : FingerPlacement, optional
        Draw the midplane in the palm frame, the finger placed by its clamp.
    namespace : str
        Marker namespace.

    Returns
    -------
    visualization_msgs.msg.Marker
        Frame-locked, no lifetime, identity pose.

    """
    return _to_marker(_shape_marker_parts(result, frame_id, stamp_ns, marker_id, color,
                                          width, placement, namespace))


def serialized_shape_markers(fingers, palm_frame, width=0.002):
    """
    Serialize the ``markers`` MarkerArray, every finger's `shape_marker` in the palm frame.

    The bytes decode to the message of `shape_marker` objects (the tests check it) at some
    1/20 of their cost; ``Publisher.publish`` accepts them.

    Parameters
    ----------
    fingers : iterable of tuple
        As for `gripper_shape_markers`.
    palm_frame : str
        Frame id of the palm.
    width : float
        Line width [m].

    Returns
    -------
    bytes
        CDR of a ``visualization_msgs/MarkerArray``, one marker per finger, its index as id.

    """
    return _serialized_marker_array([
        _shape_marker_parts(result, palm_frame, stamp_ns, index, color, width, placement,
                            SHAPE_MARKER_NAMESPACE)
        for index, result, stamp_ns, placement, color in fingers])


def _gripper_shape_parts(fingers, palm_frame, width, tip_diameter):
    # The model core (numba) loads only where circles are drawn, not with every fpc-mcap.
    from ..model.analysis import fit_circle

    names = GRIPPER_SHAPE_NAMESPACES
    out = []
    for index, result, stamp_ns, placement, color in fingers:
        out.append(_shape_marker_parts(result, palm_frame, stamp_ns, index, color, width,
                                       placement, names['midplane']))
        tip = placement.to_palm(np.asarray(result.points, dtype=float)[-1:])[0]
        out.append(_MarkerParts(palm_frame, stamp_ns, names['tip'], index, Marker.SPHERE,
                                color, tip_diameter, position=tuple(tip.tolist())))
        fit = fit_circle(result.points)
        radius = abs(1.0 / fit.curvature) if fit.curvature else math.inf
        if np.all(np.isfinite(fit.center)) and radius <= MAX_CIRCLE_RADIUS:
            angle = np.linspace(0.0, 2.0 * math.pi, _CIRCLE_POINTS)
            ring = fit.center + radius * np.column_stack([np.cos(angle), np.sin(angle)])
            points, delete = placement.to_palm(ring), False
        else:
            points, delete = None, True
        out.append(_MarkerParts(palm_frame, stamp_ns, names['circle'], index,
                                Marker.LINE_STRIP, _CIRCLE_COLOR, 0.5 * width,
                                points=points, delete=delete))
    return out


def gripper_shape_markers(fingers, palm_frame, width=0.002, tip_diameter=0.006):
    """
    Build the ``gripper_shape`` markers: every finger's midplane, tip and fitted circle.

    All are in the palm frame, each finger placed by its clamp, so that a viewer with
    the palm as fixed frame shows the whole gripper without tf.

    Parameters
    ----------
    fingers : iterable of tuple
        ``(index, result, stamp_ns, placement, color)`` of every finger with a state:
        ``result.points`` (M, 2) [m] and ``result.curvature`` [1/m].
    palm_frame : str
        Frame id of the palm.
    width : float
        Line width [m].
    tip_diameter : float
        Diameter of the tip spheres [m].

    Returns
    -------
    list of visualization_msgs.msg.Marker
        Per finger, in the namespaces of `GRIPPER_SHAPE_NAMESPACES` with the finger index
        as id: a LINE_STRIP midplane, a SPHERE at the tip, and a LINE_STRIP of the fitted
        circle (in the finger's plane), or a DELETE of it when the circle is larger than
        `MAX_CIRCLE_RADIUS` or undefined (a flat finger).

    """
    return [_to_marker(parts)
            for parts in _gripper_shape_parts(fingers, palm_frame, width, tip_diameter)]


def serialized_gripper_shape(fingers, palm_frame, width=0.002, tip_diameter=0.006):
    """
    Serialize the MarkerArray of `gripper_shape_markers` straight to CDR bytes.

    Parameters and markers as for `gripper_shape_markers`, at some 1/20 of its cost.

    Returns
    -------
    bytes
        CDR of a ``visualization_msgs/MarkerArray``; ``Publisher.publish`` accepts them.

    """
    return _serialized_marker_array(
        _gripper_shape_parts(fingers, palm_frame, width, tip_diameter))
