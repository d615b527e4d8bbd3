"""The struct decoders of the per-command inputs against rclpy's own decoder."""

import math
import struct

from geometry_msgs.msg import WrenchStamped
from hypothesis import given, settings, strategies as st
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import FluidPressure

from fpc_gripper.io import cdr
from fpc_gripper.nodes.guard import decode

SETTINGS = dict(derandomize=True, database=None, deadline=None, print_blob=False)
# Any double, as bits: NaNs with payloads, infinities, signed zeros, subnormals.
DOUBLES = st.integers(0, 2**64 - 1).map(lambda b: struct.unpack('<d', struct.pack('<Q', b))[0])
FRAMES = st.text(max_size=40)
STAMPS = st.tuples(st.integers(-2**31, 2**31 - 1), st.integers(0, 2**32 - 1))


def _bits(value):
    return struct.pack('<d', value)


def _pressure(stamp, frame_id, pressure, variance):
    msg = FluidPressure()
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    msg.header.frame_id = frame_id
    msg.fluid_pressure, msg.variance = pressure, variance
    return msg


def _wrench(stamp, frame_id, values):
    msg = WrenchStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    msg.header.frame_id = frame_id
    force, torque = msg.wrench.force, msg.wrench.torque
    force.x, force.y, force.z, torque.x, torque.y, torque.z = values
    return msg


def _same_header(fields, msg):
    assert (fields.header.stamp.sec, fields.header.stamp.nanosec) == (
        msg.header.stamp.sec, msg.header.stamp.nanosec)
    assert fields.header.frame_id == msg.header.frame_id


def _same_pressure(fields, msg):
    _same_header(fields, msg)
    assert _bits(fields.fluid_pressure) == _bits(msg.fluid_pressure)
    assert _bits(fields.variance) == _bits(msg.variance)


def _same_wrench(fields, msg):
    _same_header(fields, msg)
    for ours, theirs in ((fields.wrench.force, msg.wrench.force),
                         (fields.wrench.torque, msg.wrench.torque)):
        assert [_bits(v) for v in ours] == [_bits(getattr(theirs, a)) for a in 'xyz']


@settings(max_examples=300, **SETTINGS)
@given(stamp=STAMPS, frame_id=FRAMES, pressure=DOUBLES, variance=DOUBLES)
def test_fluid_pressure_reads_what_rclpy_reads(stamp, frame_id, pressure, variance):
    payload = serialize_message(_pressure(stamp, frame_id, pressure, variance))
    fields = cdr.fluid_pressure(payload)
    # rclpy's encoder cuts a frame at its first NUL; the rest must take the fast path.
    assert fields is not None or '\x00' in frame_id
    if fields is not None:
        _same_pressure(fields, deserialize_message(payload, FluidPressure))


@settings(max_examples=300, **SETTINGS)
@given(stamp=STAMPS, frame_id=FRAMES, values=st.lists(DOUBLES, min_size=6, max_size=6))
def test_wrench_stamped_reads_what_rclpy_reads(stamp, frame_id, values):
    payload = serialize_message(_wrench(stamp, frame_id, values))
    fields = cdr.wrench_stamped(payload)
    assert fields is not None or '\x00' in frame_id
    if fields is not None:
        _same_wrench(fields, deserialize_message(payload, WrenchStamped))


def _mutations():
    base = serialize_message(_pressure((12, 34), 'finger_0', 2.5e5, 0.0))
    flips = st.tuples(st.integers(0, len(base) - 1), st.integers(0, 255))
    return st.one_of(
        st.lists(flips, min_size=1, max_size=4).map(
            lambda edits: _edited(base, edits)),
        st.integers(0, len(base) - 1).map(lambda n: base[:n]),
        st.binary(min_size=1, max_size=8).map(lambda tail: base + tail),
        st.binary(max_size=64))


def _edited(base, edits):
    out = bytearray(base)
    for index, value in edits:
        out[index] = value
    return bytes(out)


@settings(max_examples=600, **SETTINGS)
@given(payload=_mutations())
def test_a_damaged_payload_is_declined_or_read_as_rclpy_reads_it(payload):
    fields = cdr.fluid_pressure(payload)
    if fields is None:
        return
    # Accepted: rclpy must read the same payload, and read the same values.
    _same_pressure(fields, deserialize_message(payload, FluidPressure))


@pytest.mark.parametrize('payload', [
    b'\x00\x00\x00\x00' + bytes(40),     # big-endian encapsulation: rclpy's to read
    bytes(3),                              # shorter than any header
])
def test_what_the_fast_path_declines_still_gets_rclpys_verdict(payload):
    assert cdr.fluid_pressure(payload) is None
    message, check = decode(payload, FluidPressure)
    reference = None
    try:
        reference = deserialize_message(payload, FluidPressure)
    except Exception:  # noqa: B902 -- whatever rclpy raises, decode must refuse
        assert message is None and check is not None
        return
    assert check is None and message == reference


def test_the_guard_decodes_commands_by_struct():
    payload = serialize_message(_pressure((1_796_579_597, 5), 'finger_2', 1.2e5, 3.0))
    message, check = decode(payload, FluidPressure)
    assert check is None
    assert isinstance(message, cdr.FluidPressureFields)
    assert message.header.frame_id == 'finger_2'
    assert message.fluid_pressure == pytest.approx(1.2e5, rel=0, abs=0)
    assert not math.isnan(message.variance)


# -- the header stamp of any stamped message (what mcap_recorder reads) ----------------------

def test_the_header_stamp_of_a_serialised_message_is_read_without_decoding():
    data = serialize_message(_pressure((1_700_000_000, 123_456_789), 'finger_0', 1.0e5, 0.0))
    assert cdr.header_stamp(data) == 1_700_000_000_123_456_789


def test_a_big_endian_header_stamp_is_read_too():
    data = b'\x00\x00\x00\x00' + struct.pack('>iI', 12, 34) + b'\x00' * 8
    assert cdr.header_stamp(data) == 12_000_000_034


# The soak's probe tells these apart by the same rule, so it injects the extremes too.
@pytest.mark.parametrize('sec, nanosec', [(-1, 0), (5, 1_000_000_000), (1, 1_000_000_000),
                                          (2147483647, 4_000_000_000),
                                          (-2147483648, 999_999_999)])
def test_a_header_stamp_that_is_no_time_is_told_apart(sec, nanosec):
    data = b'\x00\x01\x00\x00' + struct.pack('<iI', sec, nanosec) + b'\x00' * 8
    assert cdr.header_stamp(data) is cdr.INVALID_STAMP


@pytest.mark.parametrize('sec, nanosec', [(0, 0), (2147483647, 999_999_999)])
def test_a_header_stamp_at_the_ends_of_time_is_a_time(sec, nanosec):
    data = serialize_message(_pressure((sec, nanosec), 'f', 1.0, 0.0))
    assert cdr.header_stamp(data) == sec * 1_000_000_000 + nanosec


def test_data_too_short_for_a_stamp_has_none():
    assert cdr.header_stamp(b'\x00\x01\x00\x00\x01\x00\x00') == 0
