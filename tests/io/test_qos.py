"""The topics' QoS profiles, and the writers' history from FPC_GRIPPER_WRITER_HISTORY_S."""

import math

import pytest
from rclpy.qos import DurabilityPolicy, HistoryPolicy, qos_check_compatible, \
    QoSCompatibility, ReliabilityPolicy

from fpc_gripper.io import messages, tf
from fpc_gripper.io.qos import LATEST_QOS, MAX_STREAM_HZ, RELIABLE_QOS, STATE_QOS, TF_QOS, \
    TF_STATIC_QOS, WRITER_HISTORY_ENV, writer_history_s, writer_qos


@pytest.mark.parametrize('profile, rate_hz, depth', [
    (STATE_QOS, 200.0, 100),            # 0.5 s of model_node's default rate
    (STATE_QOS, 30.0, 15),              # markers
    (STATE_QOS, 0.5, 1),                # never below the profile's own depth
    (RELIABLE_QOS, 10.0, 10),
    (RELIABLE_QOS, 50.0, 25),           # the controller's default rate
    (TF_QOS, 600.0, 300),               # 3 tips at 200 Hz
    (STATE_QOS, 10_000.0, 500),         # capped at MAX_STREAM_HZ
])
def test_writer_depth_is_the_history_at_the_rate(profile, rate_hz, depth):
    assert MAX_STREAM_HZ == 1000.0
    qos = writer_qos(profile, rate_hz, history_s=0.5)
    assert qos.depth == depth
    # Everything else is the profile's: readers and writers still match.
    assert (qos.history, qos.reliability, qos.durability) == (
        profile.history, profile.reliability, profile.durability)


def test_the_profiles_are_the_conventions():
    assert (STATE_QOS.depth, STATE_QOS.reliability, STATE_QOS.durability) == (
        1, ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL)
    assert (RELIABLE_QOS.depth, RELIABLE_QOS.history, RELIABLE_QOS.reliability,
            RELIABLE_QOS.durability) == (10, HistoryPolicy.KEEP_LAST,
                                         ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE)
    # tf2_ros's broadcasters' own profiles.
    assert (TF_QOS.depth, TF_QOS.durability) == (100, DurabilityPolicy.VOLATILE)
    assert (TF_STATIC_QOS.depth, TF_STATIC_QOS.durability) == (
        1, DurabilityPolicy.TRANSIENT_LOCAL)


def test_the_old_import_paths_name_the_same_profiles():
    assert messages.STATE_QOS is STATE_QOS
    assert tf.TF_QOS is TF_QOS and tf.TF_STATIC_QOS is TF_STATIC_QOS


def test_the_history_comes_from_the_environment_and_is_none_without_it(monkeypatch):
    monkeypatch.delenv(WRITER_HISTORY_ENV, raising=False)
    assert writer_history_s() == 0.0
    assert writer_qos(STATE_QOS, 200.0).depth == 1
    assert writer_qos(RELIABLE_QOS, 200.0).depth == 10
    monkeypatch.setenv(WRITER_HISTORY_ENV, ' 0.5 ')
    assert writer_qos(STATE_QOS, 200.0).depth == 100
    # An explicit history wins over the environment's.
    assert writer_qos(STATE_QOS, 200.0, history_s=0.0).depth == 1
    assert writer_history_s({WRITER_HISTORY_ENV: '0'}) == 0.0
    assert writer_history_s({WRITER_HISTORY_ENV: '10'}) == 10.0


@pytest.mark.parametrize('text', ['abc', '-0.1', 'nan', 'inf', '10.5', '1e9', '0.5s'])
def test_a_history_that_is_no_number_of_seconds_in_range_is_refused(text):
    with pytest.raises(ValueError) as error:
        writer_history_s({WRITER_HISTORY_ENV: text})
    message = str(error.value)
    assert WRITER_HISTORY_ENV in message and repr(text) in message and '[s]' in message


@pytest.mark.parametrize('rate_hz', [0.0, -5.0, math.inf, math.nan, '200', None])
def test_a_rate_that_is_no_positive_number_is_refused(rate_hz):
    with pytest.raises(ValueError, match='rate_hz must be a positive number'):
        writer_qos(STATE_QOS, rate_hz)


def test_a_latest_only_reader_is_best_effort_and_matches_the_state_writers():
    assert (LATEST_QOS.depth, LATEST_QOS.history, LATEST_QOS.reliability,
            LATEST_QOS.durability) == (1, HistoryPolicy.KEEP_LAST, ReliabilityPolicy.BEST_EFFORT,
                                       DurabilityPolicy.VOLATILE)
    # A writer of the state, sized for a stalling recorder, still matches it (rclpy warns
    # only that the system-default liveliness cannot be checked).
    writer = writer_qos(STATE_QOS, 200.0, history_s=0.5)
    compatibility, reason = qos_check_compatible(writer, LATEST_QOS)
    assert compatibility != QoSCompatibility.ERROR, reason
    # The check itself can fail: a transient-local reader does not match a volatile writer.
    assert qos_check_compatible(LATEST_QOS, STATE_QOS)[0] == QoSCompatibility.ERROR
