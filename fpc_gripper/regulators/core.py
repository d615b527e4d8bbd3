"""ROS-free control step of the regulator bridge: supervision, backend I/O and channel health."""

import dataclasses
import math

from fpc_gripper.model.validation import STANDARD_ATMOSPHERE
from fpc_gripper.regulators.base import BackendFault
from fpc_gripper.regulators.safety import ChannelSupervisor
from fpc_gripper.regulators.safety import MonotonicTime
from fpc_gripper.regulators.safety import SupervisorMode
from fpc_gripper.services.health import Level
from fpc_gripper.services.input_limits import check_absolute_pressure
from fpc_gripper.services.input_limits import check_frame
from fpc_gripper.services.input_limits import checked_bounds
from fpc_gripper.services.input_limits import DEFAULT_BOUNDS
from fpc_gripper.services.input_limits import InputCheck
from fpc_gripper.services.input_limits import lost_detail
from fpc_gripper.services.input_limits import Rejection
from fpc_gripper.services.logs import bounded

__all__ = ['ChannelReport', 'Level', 'MonitorSettings', 'RegulatorCore', 'Sample', 'StepResult',
           'check_readback']

_WATCHDOG_WORDS = {SupervisorMode.IDLE: 'waiting', SupervisorMode.WATCHDOG: 'expired'}


@dataclasses.dataclass(frozen=True)
class MonitorSettings:
    """
    What the core watches on each channel's readback, beyond the supervisor's limits.

    Attributes
    ----------
    tracking_tolerance_pa : float
        Largest |measured - setpoint| that counts as following [Pa].
    tracking_timeout_s : float
        How long the measurement may stay off the setpoint before the channel is in
        fault (a leak the valve cannot make up, a blocked valve, a stuck sensor) [s];
        0 disables the check. Longer than a full-scale ramp plus the regulator's settling.
    overpressure_margin_pa : float
        A measurement above ``max_pressure`` plus this vents the channel at once [Pa].
    reconnect_interval_s : float
        Least time between two reconnection attempts of a disconnected backend [s].
    atmospheric_pressure : float
        A gauge reading below minus this is below vacuum: not a measurement [Pa].

    """

    tracking_tolerance_pa: float = 2.0e4
    tracking_timeout_s: float = 2.0
    overpressure_margin_pa: float = 5.0e4
    reconnect_interval_s: float = 1.0
    atmospheric_pressure: float = STANDARD_ATMOSPHERE

    def __post_init__(self):
        for field in dataclasses.fields(self):
            value = float(getattr(self, field.name))
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f'`{field.name}` must be finite and >= 0, got '
                                 f'{getattr(self, field.name)!r}')
            object.__setattr__(self, field.name, value)


@dataclasses.dataclass(frozen=True)
class Sample:
    """A pressure measured this step, to publish: channel, gauge value [Pa], variance [Pa²]."""

    channel: int
    pressure: float
    variance: float


@dataclasses.dataclass(frozen=True)
class ChannelReport:
    """
    Health of one channel after a step.

    Attributes
    ----------
    level : Level
    mode : SupervisorMode
    message : str
        Why the channel is at its level, in words.
    values : dict of str to str
        The diagnostics key/values (setpoint, measurement, fault, ...).

    """

    level: Level
    mode: SupervisorMode
    message: str
    values: dict


@dataclasses.dataclass(frozen=True)
class StepResult:
    """
    Outcome of `RegulatorCore.step`.

    Attributes
    ----------
    samples : tuple of Sample
        Every pressure read and accepted this step: the only ones to publish.
    reports : tuple of ChannelReport
        One per channel.
    events : tuple of (Level, str)
        Changes worth a log line (a fault appears, persists or clears).

    """

    samples: tuple
    reports: tuple
    events: tuple


def check_readback(value, variance, low=-math.inf, high=math.inf):
    """
    Return why a readback is not a measurement, or None when it is one.

    Parameters
    ----------
    value, variance : float
        As the backend returned them [Pa gauge], [Pa²].
    low, high : float
        What the sensor can represent [Pa gauge]: a value outside is an over- or
        under-range code (or a broken wire), not a pressure.

    Returns
    -------
    str or None

    """
    try:
        value, variance = float(value), float(variance)
    except (TypeError, ValueError, OverflowError):
        return f'readback {value!r} is not a number'
    if not math.isfinite(value):
        return f'readback {value} is not finite'
    if not (math.isfinite(variance) and variance >= 0.0):
        return f'readback variance {variance} is not finite and >= 0'
    if not low <= value <= high:
        return (f'readback {value:.1f} Pa is outside the sensor range [{low:.1f}, {high:.1f}] '
                'Pa (over-range or broken sensor)')
    return None


class _Channel:
    """Per-channel state of the core: supervisor, last measurement, monitors."""

    def __init__(self, limits):
        self.supervisor = ChannelSupervisor(**limits)
        self.measured = math.nan
        self.readback_fault = None
        self.overpressure = None
        self.tracking_fault = None
        self.off_since = None
        self.own_fault = None
        self.written = None
        # The newest command's rejection (cleared by a good command), and counts.
        self.rejection = None
        self.last_rejection = 'none'
        self.rejected = 0
        self.lost = 0


class RegulatorCore:
    """
    The regulator bridge's control step without ROS: what the node runs on its timer.

    Each step updates every channel's supervisor, writes its setpoint, reads the
    pressure and checks it: a readback that is not finite, below vacuum or outside
    the sensor's range is not published and puts the channel in fault until a good
    readback; a measurement above ``max_pressure`` plus a margin vents it, and one that
    stays off the setpoint longer than ``tracking_timeout_s`` puts it in its safe state,
    both latched until `start` (reactivation): a leak or a stuck sensor does not heal
    itself. A backend fault puts every channel in fault until the backend answers
    again. In fault a channel goes to its safe state (``vent`` always for
    over-pressure) and reports ERROR; once the cause clears it reports WARN until a
    fresh command. Time is passed in (``now`` [s]); a clock that jumps back counts as
    standing still.

    Parameters
    ----------
    backend : RegulatorBackend
        Connected backend; ``readback_range(channel)`` is used when it has one.
    n_channels : int
        Channels used, 0 .. n_channels - 1.
    limits : dict
        ``ChannelSupervisor`` arguments (max_pressure, rate_limit_pa_s,
        command_timeout_s, safe_state).
    monitor : MonitorSettings
    bounds : InputBounds
        What `offer_command` accepts (``min_absolute_pressure``, ``max_frame_id_length``).

    """

    def __init__(self, backend, n_channels, limits, monitor=MonitorSettings(),
                 bounds=DEFAULT_BOUNDS):
        self.backend = backend
        self.monitor = monitor
        self.bounds = checked_bounds(bounds)
        self._channels = [_Channel(limits) for _ in range(int(n_channels))]
        self._time = MonotonicTime()
        self._backend_fault = None
        self._last_reconnect = None
        ranges = getattr(backend, 'readback_range', None)
        self._ranges = [ranges(i) if ranges is not None else (-math.inf, math.inf)
                        for i in range(len(self._channels))]
        watchdog_s = getattr(backend, 'device_watchdog_s', None)
        self._device_watchdog = 'none' if watchdog_s is None else f'{watchdog_s:g}'

    @property
    def supervisors(self):
        """The channel supervisors, in channel order."""
        return tuple(c.supervisor for c in self._channels)

    @property
    def measured(self):
        """Last accepted measurement of every channel [Pa gauge] (NaN before the first)."""
        return tuple(c.measured for c in self._channels)

    def configure(self, **limits):
        """Change supervisor limits of every channel (see `ChannelSupervisor.configure`)."""
        for channel in self._channels:
            channel.supervisor.configure(**limits)

    def command(self, index, pressure_pa_gauge, now):
        """Pass a command [Pa gauge] to one channel's supervisor; return its CommandResult."""
        return self._channels[index].supervisor.command(pressure_pa_gauge, now)

    def offer_command(self, index, absolute, now, *, atmospheric_pressure, frame_id=''):
        """
        Check a command message of a channel (absolute [Pa]); pass it on when it is good.

        A command that is not a finite number, below ``bounds.min_absolute_pressure`` (a
        vacuum, or a message never filled in) or with an over-long frame_id changes
        nothing; the channel reports WARN until its next good command. A good one goes
        to the supervisor (which clamps it to [0, max_pressure]).

        Parameters
        ----------
        index : int
            Channel.
        absolute : float
            Commanded absolute pressure [Pa].
        now : float
            Time of arrival [s].
        atmospheric_pressure : float
            Gauge reference [Pa].
        frame_id : str
            The message's frame (any, of bounded length).

        Returns
        -------
        (InputCheck, CommandResult or None)
            The check (``value``: the gauge command [Pa]) and the supervisor's answer,
            None when rejected.

        """
        channel = self._channels[index]
        check = check_frame(frame_id, max_length=self.bounds.max_frame_id_length)
        if check.accepted:
            check = check_absolute_pressure(
                absolute, atmospheric_pressure=atmospheric_pressure,
                min_absolute_pressure=self.bounds.min_absolute_pressure)
        if not check.accepted:
            self._reject(channel, check)
            return check, None
        channel.rejection = None
        return check, channel.supervisor.command(check.value, now)

    def reject(self, index, rejection, detail):
        """Record a command of a channel refused before it became a value; return the check."""
        check = InputCheck(None, Rejection(rejection), bounded(detail))
        self._reject(self._channels[index], check)
        return check

    def lost(self, index, count):
        """Record `count` commands the middleware lost on a channel; a WARN until a good one."""
        channel = self._channels[index]
        count = max(int(count), 0)
        channel.lost += count
        check = InputCheck(None, Rejection.LOST, lost_detail(count, channel.lost, 'command'))
        channel.rejection = channel.last_rejection = f'{check.rejection.value}: {check.detail}'
        return check

    @staticmethod
    def _reject(channel, check):
        channel.rejection = channel.last_rejection = bounded(
            f'command rejected ({check.rejection.value}): {check.detail}')
        channel.rejected += 1

    def start(self, now):
        """Leave the stopped state (lifecycle activation); acknowledge latched faults."""
        for channel in self._channels:
            channel.overpressure = channel.tracking_fault = channel.off_since = None
            channel.supervisor.start(now)

    def stop(self, now):
        """Enter the safe state on request (lifecycle deactivation)."""
        for channel in self._channels:
            channel.supervisor.stop(now)

    def release(self, now):
        """Stop, send every safe setpoint (best effort); return the channels it failed on."""
        failed = []
        for i, channel in enumerate(self._channels):
            channel.supervisor.stop(now)
            try:
                self.backend.set_pressure(i, channel.supervisor.update(now).setpoint)
            except BackendFault as exc:
                failed.append((i, str(exc)))
        return failed

    def step(self, now):
        """
        Run one control step at `now` [s].

        Returns
        -------
        StepResult

        """
        mono = self._time(now)
        backend_fault, samples = None, []
        for i, channel in enumerate(self._channels):
            setpoint = channel.supervisor.update(now).setpoint
            # What the regulator has been driving towards since the last step: the reading
            # answers that, not the setpoint written now.
            held = channel.written
            try:
                self.backend.set_pressure(i, setpoint)
                channel.written = setpoint
            except BackendFault as exc:
                backend_fault = backend_fault or str(exc)
                channel.written = None
            try:
                value, variance = self.backend.read_pressure(i)
            except BackendFault as exc:
                backend_fault = backend_fault or str(exc)
                channel.off_since = None
                continue
            if self._accept(i, channel, value, variance, held, mono):
                samples.append(Sample(i, float(value), float(variance)))
        status = self.backend.status()
        if backend_fault is None and not status.ok:
            backend_fault = status.fault or 'backend not ok'
            backend_fault = self._reconnect(status, mono) or backend_fault
        events = self._apply_faults(backend_fault, now)
        reports = tuple(self._report(i, c, c.supervisor.update(now), status)
                        for i, c in enumerate(self._channels))
        return StepResult(tuple(samples), reports, tuple(events))

    # -- internals ---------------------------------------------------------------------------

    def _accept(self, index, channel, value, variance, held, mono):
        """
        Check a readback; update the channel's monitors; return whether it is published.

        `held` is the setpoint the regulator had until this step (None if unknown).
        """
        low, high = self._ranges[index]
        reason = check_readback(value, variance, max(low, -self.monitor.atmospheric_pressure),
                                high)
        channel.readback_fault = reason
        if reason is not None:
            return False
        channel.measured = value = float(value)
        limit = channel.supervisor.max_pressure + self.monitor.overpressure_margin_pa
        if value > limit and channel.overpressure is None:
            channel.overpressure = (f'over-pressure: measured {value:.0f} Pa > max_pressure + '
                                    f'margin = {limit:.0f} Pa; vented until reactivated')
        timeout = self.monitor.tracking_timeout_s
        if held is None or abs(value - held) <= self.monitor.tracking_tolerance_pa \
                or timeout <= 0.0:
            channel.off_since = None
        elif channel.off_since is None:
            channel.off_since = mono
        elif mono - channel.off_since > timeout and channel.tracking_fault is None:
            channel.tracking_fault = (
                f'measured {value:.0f} Pa stayed more than '
                f'{self.monitor.tracking_tolerance_pa:.0f} Pa off the setpoint {held:.0f} Pa '
                f'for {mono - channel.off_since:.2f} s > {timeout:g} s (leak, blocked valve or '
                'stuck sensor); safe state until reactivated')
        return True

    def _reconnect(self, status, mono):
        """Try to reconnect a disconnected backend once per interval; return the error."""
        if status.connected:
            return None
        last = self._last_reconnect
        if last is not None and mono - last < self.monitor.reconnect_interval_s:
            return None
        self._last_reconnect = mono
        try:
            self.backend.connect()
        except BackendFault as exc:
            return str(exc)
        return None

    def _apply_faults(self, backend_fault, now):
        events = []
        if backend_fault is not None:
            if self._backend_fault is None:
                events.append((Level.ERROR, 'backend fault, all channels to safe state: '
                                            f'{backend_fault}'))
        elif self._backend_fault is not None:
            events.append((Level.OK, 'backend healthy again; channels stay in the safe state '
                                     'until the next command'))
        self._backend_fault = backend_fault
        for i, channel in enumerate(self._channels):
            own = channel.readback_fault or channel.overpressure or channel.tracking_fault
            if own != channel.own_fault:
                events.append((Level.ERROR, f'channel {i} to safe state: {own}') if own else
                              (Level.OK, f'channel {i}: fault cleared; safe state until the '
                                         'next command'))
                channel.own_fault = own
            fault = f'backend: {backend_fault}' if backend_fault is not None else own
            if fault is not None:
                channel.supervisor.report_fault(fault, now, vent=channel.overpressure is not None)
            elif channel.supervisor.fault is not None:
                channel.supervisor.clear_fault(now)
        return events

    def _report(self, index, channel, output, status):
        supervisor = channel.supervisor
        if output.mode == SupervisorMode.FAULT and supervisor.fault is not None:
            level = Level.ERROR
        elif output.mode in (SupervisorMode.WATCHDOG, SupervisorMode.FAULT) \
                or channel.rejection is not None:
            level = Level.WARN
        else:
            level = Level.OK
        age = output.command_age
        values = {
            'setpoint_pa_gauge': f'{output.setpoint:.1f}',
            'setpoint_written': str(channel.written is not None
                                    and channel.written == output.setpoint),
            'measured_pa_gauge': f'{channel.measured:.1f}',
            'command_pa_gauge': 'none' if output.command is None else f'{output.command:.1f}',
            'clamped': str(output.clamped),
            'watchdog': _WATCHDOG_WORDS.get(output.mode, 'ok'),
            'mode': output.mode.name.lower(),
            'command_age_s': 'none' if age is None else f'{age:.6f}',
            'safe_state': supervisor.safe_state.value,
            'max_pressure_pa_gauge': f'{supervisor.max_pressure:.1f}',
            'backend_fault': supervisor.fault or (status.fault or 'none'),
            'rejected_commands': str(channel.rejected),
            'lost_commands': str(channel.lost),
            'last_rejection': channel.last_rejection,
            'device_watchdog_s': self._device_watchdog,
        }
        message = output.reason if channel.rejection is None else \
            f'{output.reason}; {channel.rejection}'
        return ChannelReport(level, output.mode, message, values)
