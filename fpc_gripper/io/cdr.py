"""Read the nodes' per-command inputs and any header stamp straight from CDR bytes."""

import struct
from typing import NamedTuple

__all__ = ['INVALID_STAMP', 'FluidPressureFields', 'Header', 'Time', 'Vector3', 'Wrench',
           'WrenchStampedFields', 'fluid_pressure', 'header_stamp', 'wrench_stamped']

#: Encapsulation of little-endian plain CDR (XCDR1), which every ROS 2 middleware writes.
_CDR_LE = b'\x00\x01'
_ENCAPSULATION = 4
_STAMP = struct.Struct('<iII')
_TWO = struct.Struct('<2d')
_SIX = struct.Struct('<6d')
#: What `header_stamp` returns for a stamp that is not a valid time.
INVALID_STAMP = object()


class Time(NamedTuple):
    """The fields of a ``builtin_interfaces/Time``."""

    sec: int
    nanosec: int


class Header(NamedTuple):
    """The fields of a ``std_msgs/Header``."""

    stamp: Time
    frame_id: str


class FluidPressureFields(NamedTuple):
    """The fields of a ``sensor_msgs/FluidPressure``, read-only."""

    header: Header
    fluid_pressure: float
    variance: float


class Vector3(NamedTuple):
    """The fields of a ``geometry_msgs/Vector3``."""

    x: float
    y: float
    z: float


class Wrench(NamedTuple):
    """The fields of a ``geometry_msgs/Wrench``."""

    force: Vector3
    torque: Vector3


class WrenchStampedFields(NamedTuple):
    """The fields of a ``geometry_msgs/WrenchStamped``, read-only."""

    header: Header
    wrench: Wrench


def _header(payload):
    """Return a payload's Header and the offset of the 8-aligned field after it, or None."""
    if len(payload) < 16 or payload[:2] != _CDR_LE:
        return None
    sec, nanosec, length = _STAMP.unpack_from(payload, _ENCAPSULATION)
    end = 16 + length
    # Decline what the middleware's own decoder would not read as this plain string (it
    # cuts the text at an inner NUL, and replaces invalid UTF-8): it decides those.
    if length == 0 or end > len(payload) or payload[end - 1] != 0:
        return None
    text = payload[16:end - 1]
    if 0 in text:
        return None
    try:
        frame_id = text.decode('utf-8')
    except UnicodeDecodeError:
        return None
    # CDR aligns a double to 8 bytes from the end of the encapsulation.
    return Header(Time(sec, nanosec), frame_id), end + (-(end - _ENCAPSULATION) % 8)


def _fields(payload, layout):
    """Return (Header, the doubles after it) when the payload ends right after them."""
    try:
        payload = bytes(payload)
    except TypeError:
        return None
    head = _header(payload)
    if head is None or len(payload) != head[1] + layout.size:
        return None
    return head[0], layout.unpack_from(payload, head[1])


def fluid_pressure(payload):
    """
    Decode a ``sensor_msgs/FluidPressure`` payload, or decline it.

    Gives the fields `rclpy.serialization.deserialize_message` gives, in about a tenth of
    its time (at every command of every finger, in the model node and the bridge).

    Parameters
    ----------
    payload : bytes
        Serialized message, as a raw subscription delivers it.

    Returns
    -------
    FluidPressureFields or None
        None for anything but little-endian CDR of an exact length with a plain UTF-8
        frame_id: the caller then decodes with the middleware's decoder, which decides.

    """
    fields = _fields(payload, _TWO)
    return None if fields is None else FluidPressureFields(fields[0], *fields[1])


def wrench_stamped(payload):
    """
    Decode a ``geometry_msgs/WrenchStamped`` payload, or decline it; see `fluid_pressure`.

    Returns
    -------
    WrenchStampedFields or None

    """
    fields = _fields(payload, _SIX)
    if fields is None:
        return None
    values = fields[1]
    return WrenchStampedFields(fields[0], Wrench(Vector3(*values[:3]), Vector3(*values[3:])))


def header_stamp(data):
    """
    Return the header stamp [ns] of a serialised message that starts with a std_msgs/Header.

    CDR: a 4-byte encapsulation header (byte 1 is 1 for little endian), then the
    stamp's int32 sec and uint32 nanosec. Returns 0 if the data is too short, and
    `INVALID_STAMP` for negative seconds or nanoseconds of a second or more: no valid
    builtin_interfaces/Time (an MCAP time is an unsigned 64-bit count).
    """
    if len(data) < 12:
        return 0
    sec, nanosec = struct.unpack_from('<iI' if data[1] == 1 else '>iI', data, 4)
    if sec < 0 or nanosec >= 1_000_000_000:
        return INVALID_STAMP
    return sec * 1_000_000_000 + nanosec
