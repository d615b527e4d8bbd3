"""RViz markers of a grasp's contact points: a sphere list per finger, in its frame."""

from geometry_msgs.msg import Point
from visualization_msgs.msg import Marker

from .messages import ns_to_time

__all__ = ['CONTACT_NAMESPACE', 'contact_marker']

#: Marker namespace of the contact points; the marker id is the finger index.
CONTACT_NAMESPACE = 'fpc_gripper/contacts'
_COLOR = (0.9, 0.1, 0.1, 1.0)


def contact_marker(state, frame_id, stamp_ns, marker_id, diameter=0.003):
    """
    Build the SPHERE_LIST of a finger's points in contact, or the DELETE of its marker.

    Parameters
    ----------
    state : Result or None
        A contact Result (``position`` (N, 2) [m] in the finger frame, ``in_contact``
        (N,)); None or no point in contact deletes the finger's marker.
    frame_id : str
        The finger frame, ``finger_<i>``.
    stamp_ns : int
        Header stamp [ns].
    marker_id : int
        The finger index.
    diameter : float
        Sphere diameter [m].

    Returns
    -------
    visualization_msgs.msg.Marker

    """
    marker = Marker()
    marker.header.stamp = ns_to_time(stamp_ns)
    marker.header.frame_id = frame_id
    marker.ns = CONTACT_NAMESPACE
    marker.id = int(marker_id)
    touching = [] if state is None else state.position[state.in_contact]
    if not len(touching):
        marker.action = Marker.DELETE
        return marker
    marker.type = Marker.SPHERE_LIST
    marker.action = Marker.ADD
    marker.pose.orientation.w = 1.0
    marker.scale.x = marker.scale.y = marker.scale.z = float(diameter)
    marker.color.r, marker.color.g, marker.color.b, marker.color.a = _COLOR
    marker.frame_locked = True
    marker.points = [Point(x=float(x), y=0.0, z=float(z)) for x, z in touching]
    return marker
