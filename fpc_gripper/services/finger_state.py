"""ROS-free inputs of one finger of the model service: their checks, state and status."""

import dataclasses
import math

import numpy as np

from fpc_gripper.services.health import Level
from fpc_gripper.services.input_limits import check_absolute_pressure
from fpc_gripper.services.input_limits import check_frame
from fpc_gripper.services.input_limits import check_stamp
from fpc_gripper.services.input_limits import check_tip_force_value
from fpc_gripper.services.input_limits import DEFAULT_BOUNDS
from fpc_gripper.services.input_limits import InputCheck
from fpc_gripper.services.input_limits import Rejection

__all__ = ['FingerState', 'FingerStatus', 'Level', 'RATE_BURST', 'Update', 'check_pressure',
           'check_tip_force', 'real_in_range']

#: Capacity of each finger's solve-rate token bucket: sustained rate <= max_rate_hz, bursts
#: of at most this many back-to-back solves [solves].
RATE_BURST = 2.0


def _in_order(value, stamp, *checks):
    """
    Reject `value` for the first failed check, or return None when every one passed.

    A stamp that is no valid time goes first (nothing else is worth reading), then
    `checks` in order, then the stamp's age against the clock.
    """
    invalid = stamp.rejection is Rejection.BAD_STAMP
    for check in (stamp,) * invalid + checks + (stamp,):
        if not check.accepted:
            return InputCheck(value, check.rejection, check.detail)
    return None


def check_pressure(absolute, *, atmospheric_pressure, max_pressure, stamp_ns=0, now_ns=0,
                   stale_after_s=0.0, future_limit_s=0.0, frame_id='', bounds=DEFAULT_BOUNDS):
    """
    Check an absolute pressure message and convert it to gauge.

    The header first (a valid stamp, a frame_id of bounded length), then the pressure
    (`check_absolute_pressure`), then the stamp against the clock (`check_stamp`).

    Parameters
    ----------
    absolute : float
        ``sensor_msgs/FluidPressure.fluid_pressure``, absolute [Pa].
    atmospheric_pressure : float
        Gauge reference [Pa].
    max_pressure : float
        Largest accepted gauge pressure [Pa]; exactly the limit is accepted.
    stamp_ns : int or (int, int)
        Header stamp [ns], or its (sec, nanosec); 0 when unstamped.
    now_ns : int
        Node clock [ns].
    stale_after_s, future_limit_s : float
        Largest accepted age and lead of the stamp [s]; 0 disables the check.
    frame_id : str
        Header frame (any frame, of bounded length).
    bounds : InputBounds
        ``min_absolute_pressure`` and ``max_frame_id_length`` are used.

    Returns
    -------
    InputCheck
        ``value`` is the gauge pressure [Pa]. Absolute pressures between
        ``bounds.min_absolute_pressure`` and atmosphere are accepted and clamped to 0 Pa
        gauge (``clamped`` True): the model covers inflation only, and a vented channel
        reads a little below atmosphere.

    """
    stamp = check_stamp(stamp_ns, now_ns, stale_after_s=stale_after_s,
                        future_limit_s=future_limit_s)
    pressure = check_absolute_pressure(absolute, atmospheric_pressure=atmospheric_pressure,
                                       max_pressure=max_pressure,
                                       min_absolute_pressure=bounds.min_absolute_pressure)
    rejected = _in_order(pressure.value, stamp,
                         check_frame(frame_id, max_length=bounds.max_frame_id_length), pressure)
    if rejected is not None:
        return rejected
    if pressure.value < 0.0:
        return InputCheck(0.0, clamped=True)
    return pressure


def check_tip_force(f0, p0, frame_id, *, expected_frame, stamp_ns=0, now_ns=0,
                    stale_after_s=0.0, future_limit_s=0.0, bounds=DEFAULT_BOUNDS):
    """
    Check a tip force message.

    Parameters
    ----------
    f0, p0 : float
        Force along the finger's X and Z axes [N].
    frame_id : str
        Header frame; must equal `expected_frame`. An empty frame is rejected too: the
        components mean nothing without their frame.
    expected_frame : str
        The finger frame, ``finger_<i>``.
    stamp_ns : int or (int, int)
        Header stamp [ns], or its (sec, nanosec); 0 when unstamped.
    now_ns : int
        Node clock [ns].
    stale_after_s, future_limit_s : float
        Largest accepted age and lead of the stamp [s]; 0 disables the check.
    bounds : InputBounds
        ``max_tip_force`` (the magnitude, within the model's 5 N envelope) and
        ``max_frame_id_length`` are used.

    Returns
    -------
    InputCheck
        ``value`` is (f0, p0) [N].

    """
    stamp = check_stamp(stamp_ns, now_ns, stale_after_s=stale_after_s,
                        future_limit_s=future_limit_s)
    force = check_tip_force_value(f0, p0, limits=bounds.limits)
    frame = check_frame(frame_id, expected_frame, max_length=bounds.max_frame_id_length)
    return _in_order(force.value, stamp, frame, force) or force


@dataclasses.dataclass(eq=False)
class FingerState:
    """
    Inputs, last good state and counters of one finger.

    Attributes
    ----------
    name : str
        Finger name and frame, ``finger_<i>``.
    design : ActuatorDesign
        The finger's design.
    max_pressure : float
        Largest accepted gauge pressure [Pa].
    solver : object
        The finger's solver (shared by fingers of equal design).
    gauge : float
        Newest accepted gauge pressure [Pa].
    tip_force : tuple of float
        Newest accepted (f0, p0) [N].
    stamp_ns : int
        Stamp given to the next update [ns]: the newest accepted input's, else its arrival.
    has_pressure : bool
        A pressure was accepted; until then the finger is waiting and solves nothing.
    pending : bool
        Accepted input not yet solved.
    result : Result or None
        Last good state (successful solve), the one published.
    result_key : tuple or None
        `key` of the input `result` answers (its solver first).
    result_stamp_ns : int
        Stamp of `result` [ns].
    failure : str or None
        Message of the solve that failed for the current input, cleared by a success.
    rejection : Rejection or None
        Kind of the last rejected input; cleared by the next accepted one.
    last_rejection : str
        Topic and detail of the last rejection ('none' before any).
    rejected : int
        Inputs rejected, malformed payloads included.
    lost : int
        Messages the middleware reported lost on the finger's inputs.

    """

    name: str
    design: object
    max_pressure: float
    solver: object = None
    gauge: float = 0.0
    tip_force: tuple = (0.0, 0.0)
    stamp_ns: int = 0
    has_pressure: bool = False
    pending: bool = False
    result: object = None
    result_key: tuple = None
    result_stamp_ns: int = 0
    failure: str = None
    rejection: Rejection = None
    last_rejection: str = 'none'
    rejected: int = 0
    lost: int = 0
    clamped: int = 0
    coalesced: int = 0
    solves: int = 0
    shared: int = 0
    failures: int = 0
    iterations: int = 0
    solve_time_s: float = 0.0
    tokens: float = RATE_BURST
    tokens_ns: int = None
    failed: tuple = None

    @property
    def key(self):
        """Identity of the current input: (solver, gauge [Pa], f0 [N], p0 [N])."""
        return (self.solver, self.gauge) + tuple(self.tip_force)

    @property
    def ready(self):
        """Input waits to be solved: something new since the last solve, and a pressure."""
        return self.pending and self.has_pressure


@dataclasses.dataclass(frozen=True)
class Update:
    """
    What one `ModelCore.process` did for one finger.

    Attributes
    ----------
    index : int
        Finger index.
    result : Result or None
        New good state to publish; None when the solve failed (publish nothing).
    stamp_ns : int
        Stamp of the new state [ns].
    solved : bool
        This finger's update ran the solver (False: it reused an identical state).
    failure : str or None
        Solver message when it failed.

    """

    index: int
    result: object
    stamp_ns: int
    solved: bool
    failure: str = None


@dataclasses.dataclass(frozen=True)
class FingerStatus:
    """Diagnostic summary of one finger: level, message and key values (strings)."""

    level: Level
    message: str
    values: dict


def real_in_range(name, value, low, high, unit):
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f'`{name}` must be a real number {unit}, got {value!r}')
    value = float(value)
    if not (math.isfinite(value) and low <= value <= high):
        raise ValueError(f'`{name}` must be in [{low:g}, {high:g}] {unit}, got {value}')
    return value
