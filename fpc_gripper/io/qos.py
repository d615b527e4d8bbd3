"""The QoS profiles of the gripper's topics, each defined once, and the writers' history."""

import math
import os

from rclpy.qos import DurabilityPolicy
from rclpy.qos import HistoryPolicy
from rclpy.qos import QoSProfile
from rclpy.qos import ReliabilityPolicy

__all__ = ['LATEST_QOS', 'MAX_STREAM_HZ', 'MAX_WRITER_HISTORY_S', 'RELIABLE_QOS', 'STATE_QOS',
           'TF_QOS', 'TF_STATIC_QOS', 'WRITER_HISTORY_ENV', 'writer_history_s', 'writer_qos']

#: Commands, tip forces, controller outputs and diagnostics: reliable, the newest 10 kept
#: (a reader that falls further behind wants the newest, not a backlog).
RELIABLE_QOS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                          reliability=ReliabilityPolicy.RELIABLE)
#: The model's state (shape, curvature, rigidity, markers): a late joiner gets the newest
#: one from the publisher's history.
STATE_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: A reader that uses only the newest sample of a stream and has no use for a resend (the
#: demo's virtual object reading shapes): best effort, so the samples a writer keeps for a
#: recorder that stalls are never resent to it. On a saturated machine those resends are
#: more than such a reader can take, and rclpy's EventsExecutor queues one event for each
#: one, without a bound (docs/soak.md, "Deeper writer histories").
LATEST_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                        reliability=ReliabilityPolicy.BEST_EFFORT,
                        durability=DurabilityPolicy.VOLATILE)
#: tf2_ros's TransformBroadcaster publisher on /tf (Jazzy: QoSProfile(depth=100)).
TF_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                    reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE)
#: tf2_ros's StaticTransformBroadcaster publisher on /tf_static.
TF_STATIC_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                           reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: Set to a number of seconds to give every writer of a recorded stream that much history
#: at its rate (`writer_qos`); unset or 0 keeps the conventions' depths above. A reliable
#: writer resends only what its keep-last history still holds, so the writer's depth, not
#: the recorder's keep-all reader, decides what a recorder that stalls loses. The cost
#: under saturation is measured in docs/soak.md ("Writer histories as an option"): behind
#: such writers Fast DDS 2.14's keep-last readers leak the older samples resent to them
#: until their pools are full, then refuse samples when they fall behind (stop 54), so it
#: is for short recordings.
WRITER_HISTORY_ENV = 'FPC_GRIPPER_WRITER_HISTORY_S'
#: The most history the variable may ask for [s]: 10 s of 10 KB shapes at 200 Hz is 20 MB
#: per finger.
MAX_WRITER_HISTORY_S = 10.0
#: The highest rate a writer's history is sized for, and the rate where a writer does not
#: know its own (tip forces answer each measured pressure, at the bridge's rate) [Hz].
#: It bounds the history's memory: at 0.5 s, 500 samples per writer at most.
MAX_STREAM_HZ = 1000.0


def writer_history_s(environ=None):
    """
    Return the seconds of history writers keep, from `WRITER_HISTORY_ENV` (0.0 if unset).

    A value that is no number of seconds in [0, `MAX_WRITER_HISTORY_S`] is refused with a
    ValueError naming the variable, the value and the unit.
    """
    environ = os.environ if environ is None else environ
    text = environ.get(WRITER_HISTORY_ENV, '').strip()
    if not text:
        return 0.0
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0.0 <= value <= MAX_WRITER_HISTORY_S:
        raise ValueError(f'{WRITER_HISTORY_ENV} must be a number of seconds in '
                         f'[0, {MAX_WRITER_HISTORY_S:g}] [s], got {text!r}')
    return value


def writer_qos(profile, rate_hz, history_s=None):
    """
    Return `profile` for a writer of up to `rate_hz` [Hz], with `history_s` of history.

    `history_s` [s] defaults to `writer_history_s` (the environment's; 0: `profile` as it
    is). Rates above `MAX_STREAM_HZ` get its history, and the depth never goes below
    `profile`'s. Readers keep their own depth (a reader with depth 1 still gets the newest
    sample; a transient-local one joining late gets the newest samples its depth holds), so
    only a reader that fell behind sees a difference: the samples it missed are resent
    instead of lost.
    """
    if not (isinstance(rate_hz, (int, float)) and math.isfinite(rate_hz) and rate_hz > 0.0):
        raise ValueError(f'rate_hz must be a positive number [Hz], got {rate_hz!r}')
    history_s = writer_history_s() if history_s is None else history_s
    depth = max(profile.depth, math.ceil(min(rate_hz, MAX_STREAM_HZ) * history_s))
    return QoSProfile(depth=depth, history=profile.history, reliability=profile.reliability,
                      durability=profile.durability)
