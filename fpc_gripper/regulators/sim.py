"""A simulated multi-channel pressure regulator with first-order dynamics and faults."""

import math
import time

import numpy as np

from fpc_gripper.regulators.base import BackendFault
from fpc_gripper.regulators.base import BackendStatus
from fpc_gripper.regulators.base import check_channel
from fpc_gripper.regulators.base import check_pressure

FAULT_KINDS = ('leak', 'stuck_sensor', 'bad_readback', 'disconnect')

# Enough for the monotone walk through the at most six pieces of the vector field.
_MAX_PIECES = 16


def _rates(y, target, leak_rate, time_constant, slew_rate, deadband):
    """
    Return ``(a, b)`` such that dy/dt = a y + b on the open piece that contains ``y``.

    The regulator drives its output y [Pa] towards ``target`` [Pa]:
    dy/dt = c(e) - leak_rate with e = target - y, c(e) = 0 for |e| <= deadband
    and c(e) = clip(e / time_constant, -slew_rate, slew_rate) otherwise.
    """
    error = target - y
    if abs(error) <= deadband:
        return 0.0, -leak_rate
    if error > slew_rate * time_constant:
        return 0.0, slew_rate - leak_rate
    if error < -slew_rate * time_constant:
        return 0.0, -slew_rate - leak_rate
    return -1.0 / time_constant, target / time_constant - leak_rate


def _advance(y, duration, target, leak_rate, time_constant, slew_rate, deadband):
    """
    Integrate the regulator output exactly over ``duration`` [s].

    The vector field of :func:`_rates` is piecewise affine in y with
    breakpoints target ± deadband, target ± slew_rate·time_constant and a wall
    at y = 0 (the output vents to atmosphere, it cannot go below 0 gauge).
    In one dimension the trajectory is monotone, so it is integrated piece by
    piece in closed form (linear or exponential) until the time is used up or
    it reaches a rest point (an equilibrium, a deadband edge it slides on, or
    the wall).

    Parameters
    ----------
    y : float
        Output at the start [Pa gauge], >= 0.
    duration : float
        Time to advance [s], >= 0.
    target : float
        Saturated setpoint [Pa gauge], >= 0.
    leak_rate : float
        Leak outflow [Pa/s], >= 0.
    time_constant : float
        First-order time constant [s], > 0.
    slew_rate : float
        Largest |dy/dt| the valve can produce [Pa/s], > 0 (may be inf).
    deadband : float
        Error below which the valve does not act [Pa], >= 0.

    Returns
    -------
    float
        Output at the end [Pa gauge].
    """
    args = (target, leak_rate, time_constant, slew_rate, deadband)
    span = slew_rate * time_constant
    points = {0.0, target - deadband, target + deadband}
    if math.isfinite(span):
        points.update((target - span, target + span))
    breaks = sorted(p for p in points if p >= 0.0)
    remaining = float(duration)
    for _ in range(_MAX_PIECES):
        if remaining <= 0.0:
            break
        upper = next((p for p in breaks if p > y), math.inf)
        if y in breaks:
            lower = next((p for p in reversed(breaks) if p < y), None)
            a_r, b_r = _rates(y + 1.0 if math.isinf(upper) else 0.5 * (y + upper), *args)
            if a_r * y + b_r > 0.0:
                a, b, bound = a_r, b_r, upper
            elif lower is not None and y > 0.0:
                a, b = _rates(0.5 * (lower + y), *args)
                if a * y + b >= 0.0:
                    break
                bound = lower
            else:
                break
        else:
            lower = next((p for p in reversed(breaks) if p < y), 0.0)
            a, b = _rates(y, *args)
            rate = a * y + b
            if rate == 0.0:
                break
            bound = upper if rate > 0.0 else lower
        if a == 0.0:
            if b == 0.0:
                break
            t_hit = (bound - y) / b if math.isfinite(bound) else math.inf
            if t_hit >= remaining:
                return y + b * remaining
        else:
            y_eq = -b / a
            if min(y, bound) <= y_eq <= max(y, bound):
                # The equilibrium is inside this piece: exponential approach, never leaves it.
                return y_eq + (y - y_eq) * math.exp(a * remaining)
            t_hit = math.log((bound - y_eq) / (y - y_eq)) / a
            if t_hit >= remaining:
                return y_eq + (y - y_eq) * math.exp(a * remaining)
        y = bound
        remaining -= t_hit
    return y


class SimulatedRegulator:
    """
    A simulated multi-channel electro-pneumatic pressure regulator.

    Each channel's output y follows its setpoint with a first-order lag of
    time constant ``time_constant_s``, limited to ``slew_rate_pa_s``, inactive
    while |setpoint - y| <= ``deadband_pa``, and saturated to
    [0, ``max_output_pa``]. The readback adds seeded Gaussian noise and is
    quantised by an ``adc_bits`` converter spanning [0, ``full_scale_pa``].
    Time comes from ``clock`` and the dynamics are integrated exactly between
    two clock readings (:func:`_advance`), so a fake clock gives reproducible,
    step-size independent results.

    Parameters
    ----------
    n_channels : int
        Number of channels, >= 1.
    time_constant_s : float
        First-order time constant [s], > 0.
    slew_rate_pa_s : float
        Largest rate of change of the output [Pa/s], > 0 (``math.inf`` disables).
    deadband_pa : float
        Regulation deadband [Pa], >= 0.
    max_output_pa : float
        Supply-limited largest output [Pa gauge], > 0.
    adc_bits : int
        Readback resolution [bit], 1..32.
    full_scale_pa : float
        Readback full scale [Pa gauge], > 0.
    noise_std_pa : float
        Standard deviation of the readback noise [Pa], >= 0.
    seed : int
        Seed of the noise generator.
    clock : callable
        Returns the current time [s]; ``time.monotonic`` by default.

    Notes
    -----
    Faults are injected with :meth:`inject_fault`: ``'leak'`` (an outflow of
    ``rate`` [Pa/s] the valve has to make up), ``'stuck_sensor'`` (the readback
    freezes), ``'bad_readback'`` (the readback is any float, NaN and over-range
    included: a broken sensor or converter) and ``'disconnect'`` (every call but
    :meth:`status` and :meth:`close` raises :class:`BackendFault`). All but the
    disconnect are silent, as on real hardware: :meth:`status` does not report them.
    """

    def __init__(self, n_channels, time_constant_s=0.15, slew_rate_pa_s=2.0e6,
                 deadband_pa=500.0, max_output_pa=7.0e5, adc_bits=12, full_scale_pa=1.0e6,
                 noise_std_pa=300.0, seed=0, clock=time.monotonic):
        if isinstance(n_channels, bool) or not hasattr(n_channels, '__index__') \
                or int(n_channels) < 1:
            raise ValueError(f'`n_channels` must be an int >= 1, got {n_channels!r}')
        _check_positive('time_constant_s', time_constant_s, '[s]')
        _check_positive('slew_rate_pa_s', slew_rate_pa_s, '[Pa/s]', allow_inf=True)
        _check_non_negative('deadband_pa', deadband_pa, '[Pa]')
        _check_positive('max_output_pa', max_output_pa, '[Pa]')
        _check_positive('full_scale_pa', full_scale_pa, '[Pa]')
        _check_non_negative('noise_std_pa', noise_std_pa, '[Pa]')
        if isinstance(adc_bits, bool) or not hasattr(adc_bits, '__index__') \
                or not 1 <= int(adc_bits) <= 32:
            raise ValueError(f'`adc_bits` must be an int in [1, 32] [bit], got {adc_bits!r}')
        if not callable(clock):
            raise TypeError(f'`clock` must be callable returning seconds, got {clock!r}')
        self.n_channels = int(n_channels)
        self.time_constant_s = float(time_constant_s)
        self.slew_rate_pa_s = float(slew_rate_pa_s)
        self.deadband_pa = float(deadband_pa)
        self.max_output_pa = float(max_output_pa)
        self.adc_bits = int(adc_bits)
        self.full_scale_pa = float(full_scale_pa)
        self.noise_std_pa = float(noise_std_pa)
        self.lsb_pa = self.full_scale_pa / (2 ** self.adc_bits - 1)
        self._clock = clock
        self._rng = np.random.default_rng(seed)
        self._time = float(clock())
        self._output = [0.0] * self.n_channels
        self._setpoint = [0.0] * self.n_channels
        self._leak = [0.0] * self.n_channels
        self._stuck = [None] * self.n_channels
        self._bad = [None] * self.n_channels
        self._disconnected = False
        self._connected = False

    # -- RegulatorBackend -------------------------------------------------------------------

    def connect(self):
        """Open the (simulated) link; raises :class:`BackendFault` while disconnected."""
        self._check_link()
        self._connected = True

    def close(self):
        """Close the link; the valves keep their last setpoint."""
        self._connected = False

    def set_pressure(self, channel, pressure_pa_gauge):
        """
        Command one channel [Pa gauge]; the target saturates to [0, ``max_output_pa``].

        Raises
        ------
        BackendFault
            If not connected or the link is down.
        """
        index = check_channel(channel, self.n_channels)
        value = check_pressure(pressure_pa_gauge)
        self._check_usable()
        self._advance_to_now()
        self._setpoint[index] = value

    def read_pressure(self, channel):
        """
        Read one channel.

        Returns
        -------
        value : float
            Quantised, noisy output [Pa gauge].
        variance : float
            noise_std_pa² + lsb²/12 [Pa²].
        """
        index = check_channel(channel, self.n_channels)
        self._check_usable()
        self._advance_to_now()
        variance = self.noise_std_pa ** 2 + self.lsb_pa ** 2 / 12.0
        if self._bad[index] is not None:
            return self._bad[index], variance
        if self._stuck[index] is not None:
            return self._stuck[index], variance
        noise = self._rng.normal(0.0, self.noise_std_pa) if self.noise_std_pa > 0.0 else 0.0
        return self._quantise(self._output[index] + noise), variance

    def readback_range(self, channel):
        """Return the (low, high) pressures the readback can represent [Pa gauge]."""
        check_channel(channel, self.n_channels)
        return 0.0, self.full_scale_pa

    def status(self):
        """Return the link state; leaks and stuck sensors are not visible here."""
        if self._disconnected:
            fault = 'disconnect: regulator does not respond (injected fault)'
        elif not self._connected:
            fault = 'not connected'
        else:
            fault = None
        return BackendStatus(ok=fault is None, fault=fault, connected=self._connected,
                             n_channels=self.n_channels)

    # -- fault injection and introspection --------------------------------------------------

    def inject_fault(self, kind, channel=None, rate=None, value=None):
        """
        Inject a fault.

        Parameters
        ----------
        kind : {'leak', 'stuck_sensor', 'bad_readback', 'disconnect'}
            Fault to inject.
        channel : int, optional
            Affected channel (required for all but 'disconnect').
        rate : float, optional
            Leak outflow [Pa/s], > 0 (required for 'leak').
        value : float, optional
            Frozen readback [Pa gauge] for 'stuck_sensor' (default the noise-free,
            quantised output at the moment of injection); for 'bad_readback' the
            value returned, any float (required).
        """
        if kind not in FAULT_KINDS:
            raise ValueError(f'`kind` must be one of {FAULT_KINDS}, got {kind!r}')
        self._advance_to_now()
        if kind == 'disconnect':
            self._disconnected = True
            return
        index = check_channel(channel, self.n_channels)
        if kind == 'leak':
            if rate is None:
                raise ValueError("`rate` [Pa/s] is required for kind='leak'")
            _check_positive('rate', rate, '[Pa/s]')
            self._leak[index] = float(rate)
        elif kind == 'bad_readback':
            if value is None:
                raise ValueError("`value` [Pa] is required for kind='bad_readback'")
            self._bad[index] = float(value)
        else:
            frozen = self._output[index] if value is None else check_pressure(value)
            self._stuck[index] = self._quantise(frozen)

    def clear_faults(self):
        """Remove every injected fault (the dynamics up to now use the old faults)."""
        self._advance_to_now()
        self._leak = [0.0] * self.n_channels
        self._stuck = [None] * self.n_channels
        self._bad = [None] * self.n_channels
        self._disconnected = False

    @property
    def faults(self):
        """Return the injected faults as ``{kind: {channel: detail}}``."""
        out = {}
        if self._disconnected:
            out['disconnect'] = {}
        leaks = {i: r for i, r in enumerate(self._leak) if r > 0.0}
        if leaks:
            out['leak'] = leaks
        for kind, values in (('stuck_sensor', self._stuck), ('bad_readback', self._bad)):
            chosen = {i: v for i, v in enumerate(values) if v is not None}
            if chosen:
                out[kind] = chosen
        return out

    def true_pressure(self, channel):
        """Return the noise-free, unquantised output of one channel now [Pa gauge]."""
        index = check_channel(channel, self.n_channels)
        self._advance_to_now()
        return self._output[index]

    def setpoint(self, channel):
        """Return the last commanded (unsaturated) setpoint of one channel [Pa gauge]."""
        return self._setpoint[check_channel(channel, self.n_channels)]

    # -- internals ---------------------------------------------------------------------------

    def _check_link(self):
        if self._disconnected:
            raise BackendFault('regulator does not respond (disconnected)')

    def _check_usable(self):
        self._check_link()
        if not self._connected:
            raise BackendFault('regulator not connected: call connect() first')

    def _quantise(self, pressure):
        clipped = min(max(pressure, 0.0), self.full_scale_pa)
        return round(clipped / self.lsb_pa) * self.lsb_pa

    def _advance_to_now(self):
        now = float(self._clock())
        duration = now - self._time
        if duration <= 0.0:
            # A clock that stands still or steps back does not move the model.
            return
        for i in range(self.n_channels):
            target = min(max(self._setpoint[i], 0.0), self.max_output_pa)
            self._output[i] = _advance(self._output[i], duration, target, self._leak[i],
                                       self.time_constant_s, self.slew_rate_pa_s,
                                       self.deadband_pa)
        self._time = now


def _check_positive(name, value, unit, allow_inf=False):
    number = float(value)
    if not number > 0.0 or (math.isinf(number) and not allow_inf) or math.isnan(number):
        raise ValueError(f'`{name}` must be > 0 {unit}, got {value!r}')


def _check_non_negative(name, value, unit):
    number = float(value)
    if not (number >= 0.0 and math.isfinite(number)):
        raise ValueError(f'`{name}` must be finite and >= 0 {unit}, got {value!r}')
