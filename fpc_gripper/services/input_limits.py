"""Checks of what a node receives, free of ROS: header stamps and frames, pressures, forces."""

import dataclasses
import enum
import math
import numbers

from fpc_gripper.model.validation import ArgumentError
from fpc_gripper.model.validation import ATMOSPHERIC_RANGE
from fpc_gripper.model.validation import check_force
from fpc_gripper.model.validation import ENVELOPE
from fpc_gripper.model.validation import InputLimits
from fpc_gripper.model.validation import integer
from fpc_gripper.model.validation import STANDARD_ATMOSPHERE
from fpc_gripper.services.logs import bounded

__all__ = ['BOUND_NAMES', 'DEFAULT_BOUNDS', 'InputBounds', 'InputCheck', 'MAX_STAMP_NS',
           'MAX_STAMP_SEC', 'Rejection', 'atmospheric_pressure_row', 'check_absolute_pressure',
           'check_frame', 'check_stamp', 'check_tip_force_value', 'checked_bounds',
           'input_bound_table', 'lost_detail', 'real_or_none', 'stale_detail']

#: Largest ``builtin_interfaces/Time.sec`` (an int32) [s].
MAX_STAMP_SEC = 2 ** 31 - 1
_NS = 1_000_000_000
#: Latest time a header can carry [ns].
MAX_STAMP_NS = MAX_STAMP_SEC * _NS + _NS - 1
#: Characters of an offending string shown in a message.
_SHOWN = 64


class Rejection(enum.Enum):
    """Why an input message was ignored."""

    NOT_FINITE = 'not finite'
    BELOW_VACUUM = 'below vacuum'
    OVER_LIMIT = 'over the pressure limit'
    OVER_FORCE = 'over the force limit'
    OUT_OF_RANGE = 'out of range'
    WRONG_FRAME = 'wrong frame'
    LONG_FRAME = 'frame_id too long'
    BAD_STAMP = 'invalid stamp'
    FUTURE = 'stamped in the future'
    STALE = 'stale'
    OVERSIZED = 'payload too large'
    MALFORMED = 'malformed payload'
    LOST = 'messages lost'


@dataclasses.dataclass(frozen=True)
class InputCheck:
    """
    Outcome of checking one input message.

    Attributes
    ----------
    value : object
        What the input means once checked: a gauge pressure [Pa], a tip force (f0, p0)
        [N], a stamp [ns] or a goal; meaningful when accepted.
    rejection : Rejection or None
        None when the input is accepted.
    detail : str
        What was wrong, with values and units ('' when accepted); bounded in length.
    clamped : bool
        A gauge pressure below atmosphere was raised to 0 Pa.

    """

    value: object
    rejection: Rejection = None
    detail: str = ''
    clamped: bool = False

    @property
    def accepted(self):
        """True when the input may be used."""
        return self.rejection is None

    def headline(self, where):
        """Name a refused input of `where`: '<where> rejected (<why>)', or '(messages lost)'."""
        verb = '' if self.rejection is Rejection.LOST else ' rejected'
        return f'{where}{verb} ({self.rejection.value})'


def real_or_none(value):
    """Return a real number as a float (NaN and infinities included), anything else as None."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return None
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf
    except (TypeError, ValueError):
        return None


def _shown(text):
    """Return a string as a message shows it: its repr, cut to a few dozen characters."""
    return bounded(repr(text), _SHOWN)


def _positive_int(name, value, low, unit):
    return integer(name, value, low, unit=unit)


@dataclasses.dataclass(frozen=True)
class InputBounds:
    """
    Bounds a node puts on its inputs, before any solve or serialisation.

    Attributes
    ----------
    min_absolute_pressure : float
        Smallest plausible absolute pressure [Pa]: below it a message is vacuum or was
        never filled in (a default-constructed FluidPressure reads 0 Pa), not a command
        or a reading; it must lie under any atmosphere a node accepts (30 kPa).
    max_tip_force : float
        Largest magnitude of a tip force [N], at most the model's envelope (5 N).
    max_frame_id_length : int
        Longest header frame_id [characters].
    max_payload_bytes : int
        Largest serialized message [bytes]; a larger one is not deserialised.

    """

    min_absolute_pressure: float = 1.0e4
    max_tip_force: float = ENVELOPE.max_tip_force
    max_frame_id_length: int = 256
    max_payload_bytes: int = 4096

    def __post_init__(self):
        value = real_or_none(self.min_absolute_pressure)
        if value is None or not 0.0 <= value <= 3.0e4:
            raise ValueError('`min_absolute_pressure` must be in [0, 30000] [Pa], got '
                             f'{self.min_absolute_pressure!r}')
        object.__setattr__(self, 'min_absolute_pressure', value)
        # InputLimits holds the envelope: a bound above it is refused there.
        limits = InputLimits(max_tip_force=self.max_tip_force)
        object.__setattr__(self, 'max_tip_force', limits.max_tip_force)
        _positive_int('max_frame_id_length', self.max_frame_id_length, 1, '[characters]')
        _positive_int('max_payload_bytes', self.max_payload_bytes, 64, '[bytes]')

    @property
    def limits(self):
        """The model's `InputLimits` with this tip-force bound."""
        return InputLimits(max_tip_force=self.max_tip_force)

    def replace(self, **changes):
        """Return a copy with some bounds changed (checked)."""
        return dataclasses.replace(self, **changes)


#: The bounds the nodes start with.
DEFAULT_BOUNDS = InputBounds()
#: The node parameters named as the `InputBounds` fields.
BOUND_NAMES = tuple(f.name for f in dataclasses.fields(InputBounds))


def input_bound_table(names=BOUND_NAMES):
    """
    Return the parameter-table rows of the input bounds in `names`, ranges as pairs.

    Every node that takes a bound declares it with the same description and range.
    """
    rows = {
        'min_absolute_pressure': (
            DEFAULT_BOUNDS.min_absolute_pressure,
            'Pressures below this absolute value are rejected [Pa]: vacuum, or a message '
            'whose pressure was never set (a default FluidPressure reads 0 Pa).',
            {'floating_point_range': (0.0, 3.0e4)}),
        'max_tip_force': (
            DEFAULT_BOUNDS.max_tip_force,
            'Tip forces of a larger magnitude are rejected [N]; at most the model envelope, '
            '5 N.', {'floating_point_range': (1.0e-3, DEFAULT_BOUNDS.max_tip_force)}),
        'max_frame_id_length': (
            DEFAULT_BOUNDS.max_frame_id_length,
            'Inputs whose header frame_id is longer are rejected [characters]; at least the '
            'longest finger frame.', {'integer_range': (1, 65536)}),
        'max_payload_bytes': (
            DEFAULT_BOUNDS.max_payload_bytes,
            'Input messages whose serialized size is larger are rejected undecoded [bytes].',
            {'integer_range': (64, 1 << 24)}),
    }
    return tuple((name, *rows[name]) for name in names)


def atmospheric_pressure_row():
    """
    Return the parameter-table row of ``atmospheric_pressure``, its range as a pair.

    Every node that converts between absolute pressures on its topics and gauge pressures
    declares it so.
    """
    return ('atmospheric_pressure', STANDARD_ATMOSPHERE,
            'Atmospheric pressure [Pa]: gauge = absolute - atmospheric_pressure.',
            {'floating_point_range': ATMOSPHERIC_RANGE})


def checked_bounds(bounds, frames=()):
    """
    Return `bounds` if it is an `InputBounds` under which every frame of `frames` passes.

    Raises
    ------
    TypeError
        If `bounds` is no InputBounds.
    ValueError
        If ``max_frame_id_length`` is shorter than the longest of `frames` (the frames
        the node expects), naming it.

    """
    if not isinstance(bounds, InputBounds):
        raise TypeError(f'`bounds` must be an InputBounds, got {type(bounds).__name__}')
    longest = max((len(frame) for frame in frames), default=0)
    if bounds.max_frame_id_length < longest:
        raise ValueError(f'`max_frame_id_length` must be >= {longest} [characters], the '
                         f'longest finger frame, got {bounds.max_frame_id_length}')
    return bounds


def lost_detail(count, total, what='message'):
    """Say that the middleware lost `count` of an input's `what`s, `total` so far."""
    return f'{count} {what}(s) lost ({total} in all): the middleware could not deliver them'


def stale_detail(stamp_ns, now_ns, stale_after_s):
    """
    Explain why a header stamp is stale, or return None when it is not.

    A zero stamp (an unstamped message) and a zero `now_ns` (a simulated clock that has not
    started) carry no age and are never stale; stamps in the future are not stale either.

    Parameters
    ----------
    stamp_ns : int
        Header stamp [ns].
    now_ns : int
        Current time of the node clock [ns].
    stale_after_s : float
        Largest accepted age [s]; 0 disables the check.

    Returns
    -------
    str or None

    """
    if stale_after_s <= 0.0 or stamp_ns == 0 or now_ns <= 0:
        return None
    age = (now_ns - stamp_ns) * 1e-9
    if age <= stale_after_s:
        return None
    return f'header stamp is {age:.3f} s old, more than stale_after_s = {stale_after_s:g} s'


def _stamp_ns(stamp):
    """Return (stamp [ns], None) or (None, why it is no valid header stamp)."""
    if isinstance(stamp, (tuple, list)) and len(stamp) == 2:
        sec, nanosec = stamp
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in stamp):
            return None, f'header stamp {_shown(stamp)} is not two integers'
        if not 0 <= sec <= MAX_STAMP_SEC:
            return None, f'header stamp sec = {sec} is outside [0, {MAX_STAMP_SEC}] [s]'
        if not 0 <= nanosec < _NS:
            return None, f'header stamp nanosec = {nanosec} is outside [0, {_NS - 1}] [ns]'
        return sec * _NS + nanosec, None
    if isinstance(stamp, int) and not isinstance(stamp, bool):
        if not 0 <= stamp <= MAX_STAMP_NS:
            return None, f'header stamp {stamp} ns is outside [0, {MAX_STAMP_NS}] [ns]'
        return stamp, None
    return None, f'header stamp {_shown(stamp)} is not a time'


def check_stamp(stamp, now_ns=0, *, stale_after_s=0.0, future_limit_s=0.0):
    """
    Check a header stamp: a valid time, not too old and not too far in the future.

    Parameters
    ----------
    stamp : int or (int, int)
        The stamp [ns], or the message's (sec, nanosec): sec in [0, 2^31 - 1] [s] and
        nanosec in [0, 10^9) [ns] (a normalised ``builtin_interfaces/Time``; negative
        times are no ROS time). 0 means unstamped.
    now_ns : int
        Node clock [ns]; 0 (a simulated clock that has not started) skips the age checks.
    stale_after_s : float
        Largest accepted age [s]; 0 disables the check.
    future_limit_s : float
        Largest accepted lead over the node clock [s]; 0 disables the check.

    Returns
    -------
    InputCheck
        ``value`` is the stamp [ns] when accepted.

    """
    stamp_ns, problem = _stamp_ns(stamp)
    if problem is not None:
        return InputCheck(stamp, Rejection.BAD_STAMP, problem)
    stale = stale_detail(stamp_ns, now_ns, stale_after_s)
    if stale is not None:
        return InputCheck(stamp_ns, Rejection.STALE, stale)
    if future_limit_s > 0.0 and stamp_ns != 0 and now_ns > 0:
        lead = (stamp_ns - now_ns) * 1e-9
        if lead > future_limit_s:
            return InputCheck(stamp_ns, Rejection.FUTURE,
                              f'header stamp is {lead:.3f} s ahead of the node clock, more '
                              f'than future_limit_s = {future_limit_s:g} s')
    return InputCheck(stamp_ns)


def check_frame(frame_id, expected=None, *, max_length=DEFAULT_BOUNDS.max_frame_id_length):
    """
    Check a header frame_id: a string of at most `max_length` characters, `expected` if given.

    Parameters
    ----------
    frame_id : str
        The header's frame_id.
    expected : str, optional
        The one frame accepted; None accepts any.
    max_length : int
        Longest frame_id [characters].

    Returns
    -------
    InputCheck
        ``value`` is the frame_id when accepted.

    """
    if not isinstance(frame_id, str):
        return InputCheck(None, Rejection.WRONG_FRAME,
                          f'frame_id {_shown(frame_id)} is not a string')
    if len(frame_id) > max_length:
        return InputCheck(None, Rejection.LONG_FRAME,
                          f'frame_id of {len(frame_id)} characters ({_shown(frame_id)}) is '
                          f'longer than max_frame_id_length = {max_length}')
    if expected is not None and frame_id != expected:
        return InputCheck(frame_id, Rejection.WRONG_FRAME,
                          f'frame_id {_shown(frame_id)} is not {expected!r}')
    return InputCheck(frame_id)


def check_absolute_pressure(absolute, *, atmospheric_pressure, max_pressure=math.inf,
                            min_absolute_pressure=DEFAULT_BOUNDS.min_absolute_pressure,
                            name='fluid_pressure'):
    """
    Check an absolute pressure and convert it to gauge.

    Parameters
    ----------
    absolute : float
        Absolute pressure [Pa].
    atmospheric_pressure : float
        Gauge reference [Pa].
    max_pressure : float
        Largest accepted gauge pressure [Pa]; exactly the limit is accepted.
    min_absolute_pressure : float
        Smallest plausible absolute pressure [Pa] (see `InputBounds`).
    name : str
        Field name for the messages.

    Returns
    -------
    InputCheck
        ``value`` is the gauge pressure [Pa], negative below atmosphere.

    """
    value = real_or_none(absolute)
    if value is None:
        return InputCheck(None, Rejection.NOT_FINITE, f'{name} {_shown(absolute)} is no number')
    if not math.isfinite(value):
        return InputCheck(value, Rejection.NOT_FINITE, f'{name} {value} Pa is not finite')
    if value < min_absolute_pressure:
        why = 'below vacuum' if value < 0.0 else (
            f'below min_absolute_pressure = {min_absolute_pressure:.0f} Pa: near vacuum, or '
            'a message whose pressure was never set')
        return InputCheck(value, Rejection.BELOW_VACUUM,
                          f'{name} {value:.1f} Pa absolute is {why}')
    gauge = value - float(atmospheric_pressure)
    if gauge > max_pressure:
        return InputCheck(gauge, Rejection.OVER_LIMIT,
                          f'{name} {value:.1f} Pa absolute is {gauge:.1f} Pa gauge, over the '
                          f'limit {max_pressure:.1f} Pa gauge')
    return InputCheck(gauge)


def check_tip_force_value(fx, fz, *, limits=ENVELOPE):
    """
    Check a force (x, z) [N]: two finite numbers whose magnitude is inside `limits`.

    Parameters
    ----------
    fx, fz : float
        Components [N].
    limits : InputLimits
        ``max_tip_force`` is the largest magnitude [N] (`InputBounds.limits`).

    Returns
    -------
    InputCheck
        ``value`` is (fx, fz) as floats when accepted.

    """
    force = (real_or_none(fx), real_or_none(fz))
    if None in force:
        return InputCheck(None, Rejection.NOT_FINITE,
                          f'force (x, z) = ({_shown(fx)}, {_shown(fz)}) is no number')
    if not all(math.isfinite(f) for f in force):
        return InputCheck(force, Rejection.NOT_FINITE,
                          f'force (x, z) = ({force[0]}, {force[1]}) N is not finite')
    try:
        check_force('force', force, limits)
    except ArgumentError:
        return InputCheck(force, Rejection.OVER_FORCE,
                          f'force (x, z) = ({force[0]:.6g}, {force[1]:.6g}) N has magnitude '
                          f'{math.hypot(*force):.6g} N, over max_tip_force = '
                          f'{limits.max_tip_force:g} N')
    return InputCheck(force)
