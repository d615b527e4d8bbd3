"""Tests of the nodes' input checks, log helper and payload guard, without a ROS context."""

import math
import struct

import pytest
import rclpy.logging
from rclpy.serialization import serialize_message
from sensor_msgs.msg import FluidPressure

from fpc_gripper.model.validation import ENVELOPE, InputLimits
from fpc_gripper.nodes.guard import decode
from fpc_gripper.services.input_limits import check_absolute_pressure
from fpc_gripper.services.input_limits import check_frame
from fpc_gripper.services.input_limits import check_stamp
from fpc_gripper.services.input_limits import check_tip_force_value
from fpc_gripper.services.input_limits import InputBounds
from fpc_gripper.services.input_limits import InputCheck
from fpc_gripper.services.input_limits import MAX_STAMP_NS
from fpc_gripper.services.input_limits import Rejection
from fpc_gripper.services.logs import bounded
from fpc_gripper.services.logs import NodeLog
from fpc_gripper.services.logs import Severity

ATM = 101325.0
S = 1_000_000_000
NOW = 1_800_000_000 * S


# -- the log helper (issue 12, finding 1) ---------------------------------------------------

def test_one_call_site_at_two_severities_is_what_kills_a_node():
    """The reproducer of finding 1: rclpy keys its logger state on the call site."""
    logger = rclpy.logging.get_logger('fpc_gripper_test_call_site')

    def throttled(log, text):      # model_node's _throttled before the fix, in essence
        log(text)

    throttled(logger.warning, 'finger_0/pressure_command rejected (not finite)')
    with pytest.raises(ValueError, match='severity cannot be changed'):
        throttled(logger.error, 'finger_0: solve failed')


def test_node_log_takes_any_severity_for_any_key_and_throttles_per_pair():
    logger = rclpy.logging.get_logger('fpc_gripper_test_node_log')
    clock = [0.0]
    log = NodeLog(logger, throttle_s=2.0, clock=lambda: clock[0])
    sent = [log.warning('rejected', key=(0, 'x')), log.error('solve failed', key=(0, 'x')),
            log.info('info', key=(0, 'x')), log.debug('debug', key=(0, 'x')),
            log.warning('rejected again', key=(0, 'x')), log.warning('other key', key=(1, 'x'))]
    assert sent == [True, True, True, True, False, True]
    clock[0] = 1.999
    assert not log.error('still throttled', key=(0, 'x'))
    clock[0] = 2.0
    assert log.error('a period later', key=(0, 'x'))
    assert log.warning('unkeyed lines are never throttled')
    assert log.warning('unkeyed lines are never throttled')
    assert (log.dropped, log.suppressed) == (0, 2)


def test_node_log_bounds_lines_and_never_raises():
    lines = []

    class Recorder:
        def __getattr__(self, name):
            return lambda line: lines.append((name, line))

    log = NodeLog(Recorder(), max_chars=100)
    assert log.warning('frame_id ' + 'x' * 1_000_000)
    assert len(lines[-1][1]) < 200 and lines[-1][1].endswith('(999909 more characters)')
    assert log.log(Severity.ERROR, 'nul \x00 and a lone surrogate \ud800')
    assert lines[-1] == ('error', 'nul \\x00 and a lone surrogate \\ud800')

    class Broken:
        def warning(self, line):
            raise RuntimeError('context is shut down')

    broken = NodeLog(Broken())
    assert not broken.warning('x') and not broken.log(99, 'no such severity')
    assert broken.dropped == 2
    rclpy_log = NodeLog(rclpy.logging.get_logger('fpc_gripper_test_bounded'))
    assert rclpy_log.info('\ud800') and rclpy_log.dropped == 0
    assert bounded(object.__new__(_Unprintable)) == '<unprintable _Unprintable>'


class _Unprintable:
    def __str__(self):
        raise RuntimeError('no')


# -- stamps (finding 2) ---------------------------------------------------------------------

@pytest.mark.parametrize('stamp, text', [
    ((2147483647, 4000000000), 'nanosec = 4000000000 is outside [0, 999999999]'),
    ((-1, 0), 'sec = -1 is outside [0, 2147483647]'),
    ((2 ** 31, 0), 'sec = 2147483648 is outside'),
    ((5, 10 ** 9), 'nanosec = 1000000000'),
    ((1.5, 0), 'is not two integers'),
    (-1, 'header stamp -1 ns is outside'),
    (MAX_STAMP_NS + 1, 'is outside [0, 2147483647999999999]'),
    ('soon', 'is not a time'),
])
def test_a_stamp_that_is_no_time_is_rejected(stamp, text):
    check = check_stamp(stamp, NOW)
    assert check.rejection is Rejection.BAD_STAMP and text in check.detail


@pytest.mark.parametrize('stamp, now, stale, future, rejection', [
    ((1_800_000_000, 0), NOW, 1.0, 1.0, None),
    ((1_800_000_001, 0), NOW, 1.0, 1.0, None),              # exactly the lead allowed
    ((1_800_000_001, 1), NOW, 1.0, 1.0, Rejection.FUTURE),
    ((1_800_003_600, 0), NOW, 1.0, 0.0, None),              # future check disabled
    ((1_799_999_998, 0), NOW, 1.0, 1.0, Rejection.STALE),
    ((2147483647, 999999999), 0, 1.0, 1.0, None),           # clock not started: no age
    ((0, 0), NOW, 1.0, 1.0, None),                          # unstamped
])
def test_stamp_against_the_clock(stamp, now, stale, future, rejection):
    check = check_stamp(stamp, now, stale_after_s=stale, future_limit_s=future)
    assert check.rejection is rejection
    if rejection is None:
        assert check.value == stamp[0] * S + stamp[1]        # integers: exact
    if rejection is Rejection.FUTURE:
        assert 'ahead of the node clock, more than future_limit_s = 1 s' in check.detail


# -- frames, pressures, forces (finding 4) --------------------------------------------------

def test_a_megabyte_frame_id_is_rejected_with_a_short_message():
    check = check_frame('f' * 1_000_000, 'finger_0', max_length=256)
    assert check.rejection is Rejection.LONG_FRAME
    assert 'frame_id of 1000000 characters' in check.detail and len(check.detail) < 250
    assert check_frame('finger_0', 'finger_0', max_length=8).accepted
    assert check_frame('finger_00', None, max_length=8).rejection is Rejection.LONG_FRAME
    assert check_frame(b'finger_0', None).rejection is Rejection.WRONG_FRAME


@pytest.mark.parametrize('absolute, rejection', [
    (0.0, Rejection.BELOW_VACUUM),            # a default-constructed FluidPressure
    (9_999.0, Rejection.BELOW_VACUUM),
    (-1e-300, Rejection.BELOW_VACUUM),
    (10_000.0, None),
    (ATM - 5e3, None),
    (1e308, Rejection.OVER_LIMIT),
    (10 ** 400, Rejection.NOT_FINITE),        # an int no float holds
    ('101325', Rejection.NOT_FINITE),
    (None, Rejection.NOT_FINITE),
    (True, Rejection.NOT_FINITE),
])
def test_absolute_pressure_plausibility(absolute, rejection):
    check = check_absolute_pressure(absolute, atmospheric_pressure=ATM, max_pressure=4e5,
                                    min_absolute_pressure=1e4)
    assert check.rejection is rejection
    if rejection is None:
        assert check.value == pytest.approx(absolute - ATM, abs=1e-9)


@pytest.mark.parametrize('force, limit, rejection', [
    ((1e30, 0.0), 5.0, Rejection.OVER_FORCE),
    ((1.7e308, 1.7e308), 5.0, Rejection.OVER_FORCE),      # hypot overflows to inf
    ((3.0, 4.0), 5.0, None),                              # exactly the envelope
    ((3.0, 4.0001), 5.0, Rejection.OVER_FORCE),
    ((0.8, 0.8), 1.0, Rejection.OVER_FORCE),              # a tighter node bound
    ((math.nan, 0.0), 5.0, Rejection.NOT_FINITE),
    ((0.0, -math.inf), 5.0, Rejection.NOT_FINITE),
    (('1', 0.0), 5.0, Rejection.NOT_FINITE),
])
def test_tip_force_bound(force, limit, rejection):
    check = check_tip_force_value(*force, limits=InputLimits(max_tip_force=limit))
    assert check.rejection is rejection
    if rejection is Rejection.OVER_FORCE:
        assert f'over max_tip_force = {limit:g} N' in check.detail


def test_bounds_are_checked_and_never_wider_than_the_envelope():
    assert InputBounds().max_tip_force == ENVELOPE.max_tip_force
    for bad in ({'max_tip_force': 5.5}, {'max_tip_force': 0.0},
                {'min_absolute_pressure': -1.0}, {'min_absolute_pressure': 5e4},
                {'max_frame_id_length': 0}, {'max_payload_bytes': 10},
                {'max_frame_id_length': 2.5}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            InputBounds(**bad)


# -- payloads (finding 3) -------------------------------------------------------------------

def _valid_payload(frame='finger_0'):
    msg = FluidPressure()
    msg.header.frame_id = frame
    msg.fluid_pressure = ATM
    return serialize_message(msg)


# Named ids: rclpy leaves a payload's CDR padding uninitialised, so an id made of its bytes
# differs between processes, and pytest-xdist's workers would collect different tests.
@pytest.mark.parametrize('payload, rejection', [
    (b'', Rejection.MALFORMED),
    (b'\x00\x01\x00\x00', Rejection.MALFORMED),
    (_valid_payload()[:12] + struct.pack('<I', 0xFFFFFFF0) + _valid_payload()[16:],
     Rejection.MALFORMED),                          # a string length past the end
    (bytes(range(40)), Rejection.MALFORMED),
    (_valid_payload('f' * 5000), Rejection.OVERSIZED),
    ('a str', Rejection.MALFORMED),
    (None, Rejection.MALFORMED),
], ids=['empty', 'encapsulation only', 'string past the end', 'counting bytes', 'oversized',
        'a str', 'None'])
def test_decode_refuses_what_is_no_message(payload, rejection):
    message, check = decode(payload, FluidPressure, 4096)
    assert message is None and check.rejection is rejection


def test_decode_gives_the_message():
    message, check = decode(_valid_payload(), FluidPressure, 4096)
    assert check is None
    assert message.header.frame_id == 'finger_0' and message.fluid_pressure == ATM


def test_a_loss_is_named_as_a_loss_and_a_refusal_as_a_refusal():
    assert InputCheck(None, Rejection.LOST, '3 lost').headline('finger_0/pressure') == \
        'finger_0/pressure (messages lost)'
    assert InputCheck(None, Rejection.STALE, 'old').headline('finger_0/pressure') == \
        'finger_0/pressure rejected (stale)'
