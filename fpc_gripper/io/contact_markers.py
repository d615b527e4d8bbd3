"""RViz markers of a grasp's contact points: a sphere list per finger, in its frame."""

import numpy as np
from visualization_msgs.msg import Marker

from .messages import _MarkerParts, _to_marker

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
    touching = np.empty((0, 2)) if state is None else state.position[state.in_contact]
    points = np.column_stack([touching[:, 0], np.zeros(len(touching)), touching[:, 1]])
    return _to_marker(_MarkerParts(frame_id, stamp_ns, CONTACT_NAMESPACE, marker_id,
                                   Marker.SPHERE_LIST, _COLOR, diameter, points=points,
                                   delete=not len(touching)))
