"""The topics' QoS: writers keep RECORDER_STALL_S of their stream, within MAX_STREAM_HZ."""

import math

import pytest
from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy

from fpc_gripper.io.qos import MAX_STREAM_HZ, RECORDER_STALL_S, RELIABLE_QOS, STATE_QOS, \
    TF_QOS, writer_qos


@pytest.mark.parametrize('profile, rate_hz, depth', [
    (STATE_QOS, 200.0, 100),            # 0.5 s of model_node's default rate
    (STATE_QOS, 30.0, 15),              # markers
    (STATE_QOS, 0.5, 1),                # never below the profile's own depth
    (RELIABLE_QOS, 10.0, 10),
    (RELIABLE_QOS, 50.0, 25),           # the controller's default rate
    (TF_QOS, 600.0, 300),               # 3 tips at 200 Hz
    (STATE_QOS, 10_000.0, 500),         # capped at MAX_STREAM_HZ
])
def test_writer_depth_is_the_stall_at_the_rate(profile, rate_hz, depth):
    assert (RECORDER_STALL_S, MAX_STREAM_HZ) == (0.5, 1000.0)
    qos = writer_qos(profile, rate_hz)
    assert qos.depth == depth
    # Everything else is the profile's: readers and writers still match.
    assert (qos.history, qos.reliability, qos.durability) == (
        profile.history, profile.reliability, profile.durability)


def test_the_profiles_are_the_conventions():
    assert (STATE_QOS.depth, STATE_QOS.reliability, STATE_QOS.durability) == (
        1, ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL)
    assert (RELIABLE_QOS.depth, RELIABLE_QOS.history, RELIABLE_QOS.durability) == (
        10, HistoryPolicy.KEEP_LAST, DurabilityPolicy.VOLATILE)
    assert TF_QOS.depth == 100


@pytest.mark.parametrize('rate_hz', [0.0, -5.0, math.inf, math.nan, '200', None])
def test_a_rate_that_is_no_positive_number_is_refused(rate_hz):
    with pytest.raises(ValueError, match='rate_hz must be a positive number'):
        writer_qos(STATE_QOS, rate_hz)
