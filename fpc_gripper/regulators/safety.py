"""Per-channel command supervision: clamp, rate limit, watchdog and safe state (ROS-free)."""

import dataclasses
import enum
import math
import typing

DEFAULT_MAX_PRESSURE = 4.0e5
"""Largest setpoint unless a caller configures another one [Pa gauge]."""

DEFAULT_RATE_LIMIT = 1.0e6
"""Default setpoint slew limit [Pa/s]."""

DEFAULT_COMMAND_TIMEOUT = 0.5
"""Default command watchdog period [s]."""


class SafeState(str, enum.Enum):
    """What a channel does when it stops trusting its commands."""

    HOLD = 'hold'
    """Keep the last setpoint sent to the regulator."""
    VENT = 'vent'
    """Go to 0 Pa gauge at once."""


class SupervisorMode(enum.IntEnum):
    """State of a :class:`ChannelSupervisor`."""

    IDLE = 0
    """No command yet (or none since :meth:`ChannelSupervisor.start`); setpoint held."""
    TRACKING = 1
    """Following commands through the clamp and the rate limit."""
    WATCHDOG = 2
    """No command for longer than ``command_timeout_s``: safe state."""
    FAULT = 3
    """The backend reported a fault: safe state until a fresh command after it clears."""
    STOPPED = 4
    """Stopped by the owner (e.g. lifecycle deactivation): safe state."""


SAFE_MODES = frozenset((SupervisorMode.WATCHDOG, SupervisorMode.FAULT, SupervisorMode.STOPPED))


@dataclasses.dataclass(frozen=True)
class CommandResult:
    """
    Outcome of :meth:`ChannelSupervisor.command`.

    Attributes
    ----------
    accepted : bool
        False while a backend fault is active or the supervisor is stopped.
    clamped : bool
        True when the command was outside [0, max_pressure].
    target : float
        The clamped command [Pa gauge].
    """

    accepted: bool
    clamped: bool
    target: float


@dataclasses.dataclass(frozen=True)
class SupervisorOutput:
    """
    Outcome of :meth:`ChannelSupervisor.update`.

    Attributes
    ----------
    setpoint : float
        Setpoint to send to the regulator [Pa gauge], always in [0, max_pressure].
    target : float
        Last accepted, clamped command [Pa gauge].
    command : float or None
        Last raw command [Pa gauge] (None before the first one).
    mode : SupervisorMode
        Current mode.
    clamped : bool
        True when the last command was clamped.
    command_age : float or None
        Time since the last command [s] (None before the first one).
    reason : str
        Why the channel is in its mode, in words.
    """

    setpoint: float
    target: float
    command: typing.Optional[float]
    mode: SupervisorMode
    clamped: bool
    command_age: typing.Optional[float]
    reason: str

    @property
    def in_safe_state(self):
        """True when the setpoint is the safe state rather than the command."""
        return self.mode in SAFE_MODES


class MonotonicTime:
    """
    Map readings of a clock that may jump back onto a time that never does [s].

    A backward jump counts as no time: later readings are shifted by the jump, so a
    period measured across it (a watchdog, a retry interval) keeps running instead of
    waiting for the clock to catch up. A forward jump counts as elapsed time, so it
    can only make a watchdog expire early, towards the safe state.
    """

    def __init__(self):
        self._last = None
        self._shift = 0.0

    def __call__(self, now):
        """Return the mapped time of a clock reading `now` [s] (finite)."""
        now = _check_time(now)
        if self._last is not None and now + self._shift < self._last:
            self._shift = self._last - now
        self._last = now + self._shift
        return self._last


class ChannelSupervisor:
    """
    Guard one pressure channel between its command topic and its regulator.

    Every command is clamped to [0, ``max_pressure``]; the setpoint moves
    towards it at most ``rate_limit_pa_s``; when no command arrives for longer
    than ``command_timeout_s``, or a backend fault is reported, or
    :meth:`stop` is called, the setpoint goes to ``safe_state`` ('hold' keeps
    the last setpoint, 'vent' goes to 0 at once, without rate limit). Time is
    always passed in (``now`` [s]), so the class is a deterministic function of its
    inputs; a clock that jumps back counts as standing still (`MonotonicTime`).

    Parameters
    ----------
    max_pressure : float
        Largest setpoint [Pa gauge], >= 0; default :data:`DEFAULT_MAX_PRESSURE`.
    rate_limit_pa_s : float
        Largest setpoint rate of change [Pa/s], > 0 (``math.inf`` disables).
    command_timeout_s : float
        Watchdog period [s], > 0.
    safe_state : {'hold', 'vent'} or SafeState
        Behaviour in the safe state.
    """

    def __init__(self, max_pressure=DEFAULT_MAX_PRESSURE, rate_limit_pa_s=DEFAULT_RATE_LIMIT,
                 command_timeout_s=DEFAULT_COMMAND_TIMEOUT, safe_state=SafeState.VENT):
        self._max_pressure = DEFAULT_MAX_PRESSURE
        self._rate_limit = DEFAULT_RATE_LIMIT
        self._timeout = DEFAULT_COMMAND_TIMEOUT
        self._safe_state = SafeState.VENT
        self.configure(max_pressure=max_pressure, rate_limit_pa_s=rate_limit_pa_s,
                       command_timeout_s=command_timeout_s, safe_state=safe_state)
        self._mode = SupervisorMode.IDLE
        self._setpoint = 0.0
        self._target = 0.0
        self._command = None
        self._clamped = False
        self._last_command_time = None
        self._last_update_time = None
        self._fault = None
        self._fault_vents = False
        self._time = MonotonicTime()

    # -- configuration ----------------------------------------------------------------------

    def configure(self, max_pressure=None, rate_limit_pa_s=None, command_timeout_s=None,
                  safe_state=None):
        """
        Change any of the limits; None keeps the current value.

        Lowering ``max_pressure`` re-clamps the target and the setpoint at once.

        Raises
        ------
        ValueError
            If a value is out of range (the message names it, its value and unit).
        """
        new_max = self._max_pressure if max_pressure is None else float(max_pressure)
        new_rate = self._rate_limit if rate_limit_pa_s is None else float(rate_limit_pa_s)
        new_timeout = self._timeout if command_timeout_s is None else float(command_timeout_s)
        new_safe = self._safe_state if safe_state is None else _safe_state(safe_state)
        if not (math.isfinite(new_max) and new_max >= 0.0):
            raise ValueError(f'`max_pressure` must be finite and >= 0 [Pa], got {max_pressure!r}')
        if math.isnan(new_rate) or new_rate <= 0.0:
            raise ValueError(f'`rate_limit_pa_s` must be > 0 [Pa/s], got {rate_limit_pa_s!r}')
        if not (math.isfinite(new_timeout) and new_timeout > 0.0):
            raise ValueError(
                f'`command_timeout_s` must be finite and > 0 [s], got {command_timeout_s!r}')
        self._max_pressure = new_max
        self._rate_limit = new_rate
        self._timeout = new_timeout
        self._safe_state = new_safe
        if hasattr(self, '_setpoint'):
            self._target = min(self._target, new_max)
            self._setpoint = min(self._setpoint, new_max)

    @property
    def max_pressure(self):
        """Largest setpoint [Pa gauge]."""
        return self._max_pressure

    @property
    def rate_limit_pa_s(self):
        """Setpoint slew limit [Pa/s]."""
        return self._rate_limit

    @property
    def command_timeout_s(self):
        """Watchdog period [s]."""
        return self._timeout

    @property
    def safe_state(self):
        """Safe-state behaviour."""
        return self._safe_state

    @property
    def mode(self):
        """Current :class:`SupervisorMode`."""
        return self._mode

    @property
    def setpoint(self):
        """Setpoint returned by the last :meth:`update` [Pa gauge]."""
        return self._setpoint

    @property
    def fault(self):
        """Return the active backend fault message, or None when it is clear."""
        return self._fault

    # -- inputs -----------------------------------------------------------------------------

    def command(self, pressure_pa_gauge, now):
        """
        Accept a new pressure command.

        Parameters
        ----------
        pressure_pa_gauge : float
            Requested pressure [Pa gauge]; clamped to [0, max_pressure].
        now : float
            Time of arrival [s].

        Returns
        -------
        CommandResult

        Raises
        ------
        ValueError
            If the command or ``now`` is not finite.
        """
        value = float(pressure_pa_gauge)
        if not math.isfinite(value):
            raise ValueError(f'`pressure_pa_gauge` must be finite [Pa], got {pressure_pa_gauge!r}')
        now = self._time(now)
        target = min(max(value, 0.0), self._max_pressure)
        clamped = target != value
        if self._fault is not None or self._mode == SupervisorMode.STOPPED:
            return CommandResult(accepted=False, clamped=clamped, target=target)
        self._command = value
        self._target = target
        self._clamped = clamped
        self._last_command_time = now
        self._mode = SupervisorMode.TRACKING
        self._fault_vents = False
        return CommandResult(accepted=True, clamped=clamped, target=target)

    def report_fault(self, reason, now, vent=False):
        """
        Enter the safe state because the backend or the channel failed (``reason`` says how).

        With ``vent`` the channel vents whatever ``safe_state`` says (over-pressure), and
        stays vented until a fresh command is accepted.
        """
        self._time(now)
        self._fault = str(reason)
        self._mode = SupervisorMode.FAULT
        self._fault_vents = self._fault_vents or bool(vent)

    def clear_fault(self, now):
        """Mark the backend healthy again; the safe state holds until the next command."""
        self._time(now)
        self._fault = None

    def stop(self, now):
        """Enter the safe state on request (e.g. lifecycle deactivation)."""
        self._time(now)
        self._mode = SupervisorMode.STOPPED

    def start(self, now):
        """Leave :attr:`SupervisorMode.STOPPED`; the setpoint is held until a command arrives."""
        now = self._time(now)
        if self._mode == SupervisorMode.STOPPED:
            self._mode = SupervisorMode.FAULT if self._fault is not None else SupervisorMode.IDLE
        self._last_update_time = now

    # -- output -----------------------------------------------------------------------------

    def update(self, now):
        """
        Advance the watchdog and the rate limiter to ``now`` and return the setpoint.

        Parameters
        ----------
        now : float
            Current time [s]. A clock that stepped back counts as standing still.

        Returns
        -------
        SupervisorOutput
        """
        now = self._time(now)
        elapsed = 0.0 if self._last_update_time is None else max(
            0.0, now - self._last_update_time)
        self._last_update_time = now
        age = None if self._last_command_time is None else max(
            0.0, now - self._last_command_time)
        if self._mode == SupervisorMode.TRACKING and age > self._timeout:
            self._mode = SupervisorMode.WATCHDOG
        if self._mode in SAFE_MODES:
            if self._safe_state == SafeState.VENT or self._fault_vents:
                self._setpoint = 0.0
        elif self._mode == SupervisorMode.TRACKING:
            step = self._rate_limit * elapsed
            delta = min(max(self._target - self._setpoint, -step), step)
            self._setpoint = min(max(self._setpoint + delta, 0.0), self._max_pressure)
        return SupervisorOutput(setpoint=self._setpoint, target=self._target,
                                command=self._command, mode=self._mode,
                                clamped=self._clamped, command_age=age,
                                reason=self._reason(age))

    def _reason(self, age):
        mode = 'vent' if self._fault_vents else self._safe_state.value
        safe = f'safe state {mode} ({self._setpoint:.0f} Pa)'
        if self._mode == SupervisorMode.IDLE:
            return 'waiting for a command'
        if self._mode == SupervisorMode.TRACKING:
            if self._clamped:
                return (f'tracking; command {self._command:.0f} Pa clamped to '
                        f'[0, {self._max_pressure:.0f}] Pa')
            return 'tracking'
        if self._mode == SupervisorMode.WATCHDOG:
            return (f'command watchdog: no command for {age:.3f} s > command_timeout_s '
                    f'{self._timeout:.3f} s; {safe}')
        if self._mode == SupervisorMode.FAULT:
            if self._fault is not None:
                return f'fault: {self._fault}; {safe}'
            return f'fault cleared, waiting for a fresh command; {safe}'
        return f'stopped; {safe}'


def _safe_state(value):
    try:
        return SafeState(value)
    except ValueError:
        choices = [s.value for s in SafeState]
        raise ValueError(f'`safe_state` must be one of {choices}, got {value!r}') from None


def _check_time(now):
    value = float(now)
    if not math.isfinite(value):
        raise ValueError(f'`now` must be finite [s], got {now!r}')
    return value
