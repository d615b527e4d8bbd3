"""The QoS of the gripper's topics; writers keep enough history for a recorder that stalls."""

import math

from rclpy.qos import DurabilityPolicy
from rclpy.qos import HistoryPolicy
from rclpy.qos import QoSProfile
from rclpy.qos import ReliabilityPolicy

__all__ = ['MAX_STREAM_HZ', 'RECORDER_STALL_S', 'RELIABLE_QOS', 'STATE_QOS', 'TF_QOS',
           'TF_STATIC_QOS', 'writer_qos']

#: Commands, tip forces, controller outputs and diagnostics: reliable, the newest 10 kept
#: (a reader that falls further behind wants the newest, not a backlog).
RELIABLE_QOS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                          reliability=ReliabilityPolicy.RELIABLE)
#: The model's state (shape, curvature, rigidity, markers): a late joiner gets the newest
#: one from the publisher's history.
STATE_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: tf2_ros's TransformBroadcaster publisher on /tf (Jazzy: QoSProfile(depth=100)).
TF_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                    reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE)
#: tf2_ros's StaticTransformBroadcaster publisher on /tf_static.
TF_STATIC_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                           reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: The longest a reliable reader (the recorder) may stall without losing a message [s].
#: A reliable writer resends only what its keep-last history still holds: with depth 1
#: (the state's) a reader 5 ms behind a 200 Hz stream loses samples. In the saturated
#: 30-minute soak of separate processes the recorder stalled for up to about 120 ms.
RECORDER_STALL_S = 0.5
#: The highest rate a writer's history is sized for, and the rate where a writer does not
#: know its own (tip forces answer each measured pressure, at the bridge's rate) [Hz].
#: It bounds the history's memory: a shape is 10 KB, so 500 of them per finger at most.
MAX_STREAM_HZ = 1000.0


def writer_qos(profile, rate_hz):
    """
    Return `profile` for a writer of up to `rate_hz` [Hz]: a history of `RECORDER_STALL_S`.

    Rates above `MAX_STREAM_HZ` get its history.

    Readers keep their own depth (a reader with depth 1 still gets the newest sample; a
    transient-local one joining late gets the newest samples its depth holds), so only a
    reader that fell behind sees a difference: the samples it missed are resent instead
    of lost. The depth never goes below `profile`'s.
    """
    if not (isinstance(rate_hz, (int, float)) and math.isfinite(rate_hz) and rate_hz > 0.0):
        raise ValueError(f'rate_hz must be a positive number [Hz], got {rate_hz!r}')
    depth = max(profile.depth, math.ceil(min(rate_hz, MAX_STREAM_HZ) * RECORDER_STALL_S))
    return QoSProfile(depth=depth, history=profile.history, reliability=profile.reliability,
                      durability=profile.durability)
