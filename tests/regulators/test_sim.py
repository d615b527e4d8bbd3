"""Tests of the simulated regulator against closed-form and numerically integrated responses."""

import math

import numpy as np
from numpy.testing import assert_allclose
import pytest
from regulator_test_utils import FakeClock
from scipy.integrate import solve_ivp

from fpc_gripper.regulators.base import BackendFault
from fpc_gripper.regulators.base import RegulatorBackend
from fpc_gripper.regulators.sim import SimulatedRegulator


def make(clock, **kwargs):
    params = dict(n_channels=3, time_constant_s=0.15, slew_rate_pa_s=math.inf, deadband_pa=0.0,
                  max_output_pa=7.0e5, full_scale_pa=1.0e6, noise_std_pa=0.0, clock=clock)
    params.update(kwargs)
    sim = SimulatedRegulator(**params)
    sim.connect()
    return sim


def test_is_a_regulator_backend():
    assert isinstance(make(FakeClock()), RegulatorBackend)


@pytest.mark.parametrize('tau', [0.05, 0.15, 0.4])
def test_step_is_exact_first_order_for_any_clock_granularity(tau):
    target = 2.5e5
    coarse, fine = FakeClock(), FakeClock()
    sims = [make(c, time_constant_s=tau) for c in (coarse, fine)]
    for sim in sims:
        sim.set_pressure(1, target)
    times = np.array([0.01, 0.1, 0.3, 1.0])
    for t in times:
        coarse.now = 100.0 + t
        while fine.now < 100.0 + t - 1e-12:
            fine.now = min(fine.now + 0.0007, 100.0 + t)
            sims[1].true_pressure(1)
        expected = target * (1.0 - math.exp(-t / tau))
        assert_allclose(sims[0].true_pressure(1), expected, rtol=1e-12)
        assert_allclose(sims[1].true_pressure(1), expected, rtol=1e-9)
    # Exact: a channel never commanded stays at its initial 0.0.
    assert sims[0].true_pressure(0) == 0.0
    assert sims[0].true_pressure(2) == 0.0


def test_readback_is_quantised_with_twelve_bits():
    clock = FakeClock()
    sim = make(clock)
    sim.set_pressure(0, 3.0e5)
    lsb = 1.0e6 / 4095
    for t in (0.013, 0.07, 0.21, 0.9):
        clock.now = 100.0 + t
        true = 3.0e5 * (1.0 - math.exp(-t / 0.15))
        value, variance = sim.read_pressure(0)
        assert_allclose(value, round(true / lsb) * lsb, rtol=1e-12)
        assert abs(value - true) <= lsb / 2 + 1e-9
        assert_allclose(variance, lsb ** 2 / 12.0)


def test_slew_limit_gives_a_ramp_then_the_exponential():
    clock = FakeClock()
    tau, slew, target = 0.15, 1.0e6, 6.0e5
    sim = make(clock, time_constant_s=tau, slew_rate_pa_s=slew)
    sim.set_pressure(0, target)
    t_switch = (target - slew * tau) / slew        # error reaches slew·tau
    for t in (0.1, 0.2, t_switch, t_switch + 0.05, t_switch + 0.3):
        clock.now = 100.0 + t
        if t <= t_switch:
            expected = slew * t
        else:
            expected = target - slew * tau * math.exp(-(t - t_switch) / tau)
        assert_allclose(sim.true_pressure(0), expected, rtol=1e-12)


def test_deadband_stops_the_output_at_its_edge():
    clock = FakeClock()
    tau, band, target = 0.1, 2.0e3, 1.0e5
    sim = make(clock, time_constant_s=tau, deadband_pa=band)
    sim.set_pressure(0, target)
    t_stop = tau * math.log(target / band)
    clock.now = 100.0 + 0.5 * t_stop
    assert_allclose(sim.true_pressure(0), target * (1 - math.exp(-0.5 * t_stop / tau)),
                    rtol=1e-12)
    clock.now = 100.0 + t_stop + 5.0
    assert_allclose(sim.true_pressure(0), target - band, rtol=1e-12)
    # A setpoint change smaller than the deadband does not move the valve.
    sim.set_pressure(0, target - 0.5 * band)
    clock.now += 5.0
    assert_allclose(sim.true_pressure(0), target - band, rtol=1e-12)


def test_output_saturates_to_supply_and_to_zero():
    clock = FakeClock()
    sim = make(clock, max_output_pa=5.0e5)
    sim.set_pressure(0, 2.0e6)
    sim.set_pressure(1, -4.0e4)
    clock.now += 20.0
    assert_allclose(sim.true_pressure(0), 5.0e5, rtol=1e-9)
    assert sim.true_pressure(1) == 0.0       # target saturated to 0.0, never left: exact
    assert sim.setpoint(0) == 2.0e6          # stored as given: exact


def _reference(y0, duration, target, leak, tau, slew, band):
    """Integrate dy/dt = clip((u - y)/tau, ±slew)·[|u - y| > band] - leak numerically."""
    def rhs(_t, y):
        error = target - y[0]
        drive = 0.0 if abs(error) <= band else min(max(error / tau, -slew), slew)
        return [drive - leak]
    sol = solve_ivp(rhs, (0.0, duration), [y0], method='LSODA', rtol=1e-11, atol=1e-6,
                    max_step=1e-3)
    return sol.y[0, -1]


@pytest.mark.parametrize('y0, target, leak, slew, band', [
    (0.0, 4.0e5, 2.0e4, 1.0e6, 1.0e3),     # ramp, exponential, leak offset beyond the band
    (3.5e5, 5.0e4, 0.0, 8.0e5, 5.0e2),     # down-step through the slew limit
    (2.0e5, 2.0e5, 5.0e4, 2.0e6, 2.0e3),   # leak drags the output out of the deadband
])
def test_exact_integration_matches_a_numerical_ode_solution(y0, target, leak, slew, band):
    tau = 0.12
    clock = FakeClock()
    sim = make(clock, n_channels=1, time_constant_s=tau, slew_rate_pa_s=slew, deadband_pa=band)
    sim.set_pressure(0, y0)
    sim._output[0] = y0                     # start from an arbitrary state
    if leak:
        sim.inject_fault('leak', 0, rate=leak)
    sim.set_pressure(0, target)
    for duration in (0.05, 0.2, 0.6):
        clock.now = 100.0 + duration
        reference = _reference(y0, duration, target, leak, tau, slew, band)
        assert_allclose(sim.true_pressure(0), reference, atol=0.5)


def test_leak_offsets_the_steady_state_by_rate_times_tau():
    clock = FakeClock()
    tau, rate, target = 0.15, 4.0e4, 3.0e5
    sim = make(clock, time_constant_s=tau)
    sim.set_pressure(0, target)
    clock.now += 10.0
    sim.inject_fault('leak', 0, rate=rate)
    clock.now += 0.2
    expected = (target - rate * tau) + rate * tau * math.exp(-0.2 / tau)
    assert_allclose(sim.true_pressure(0), expected, rtol=1e-12)
    assert sim.status().ok, 'a leak is silent, as on real hardware'
    sim.clear_faults()
    clock.now += 10.0
    assert_allclose(sim.true_pressure(0), target, rtol=1e-9)


def test_leak_cannot_pull_the_output_below_atmosphere():
    clock = FakeClock()
    sim = make(clock, slew_rate_pa_s=1.0e5)
    sim.set_pressure(0, 1.0e5)
    clock.now += 10.0
    sim.inject_fault('leak', 0, rate=3.0e5)
    clock.now += 0.2
    assert 0.0 < sim.true_pressure(0) < 1.0e5
    clock.now += 10.0
    assert sim.true_pressure(0) == 0.0       # stops on the breakpoint 0.0 itself: exact


def test_stuck_sensor_freezes_the_readback_only():
    clock = FakeClock()
    sim = make(clock)
    sim.set_pressure(0, 2.0e5)
    clock.now += 0.1
    frozen, _ = sim.read_pressure(0)
    sim.inject_fault('stuck_sensor', 0)
    sim.set_pressure(0, 0.0)
    clock.now += 1.0
    assert sim.read_pressure(0)[0] == frozen      # the stored reading, returned: exact
    assert sim.true_pressure(0) < 0.01 * frozen
    sim.clear_faults()
    assert sim.read_pressure(0)[0] != frozen


def test_disconnect_raises_until_cleared_while_the_valve_keeps_running():
    clock = FakeClock()
    sim = make(clock)
    sim.set_pressure(0, 2.0e5)
    sim.inject_fault('disconnect')
    for call in (lambda: sim.set_pressure(0, 1.0), lambda: sim.read_pressure(0), sim.connect):
        with pytest.raises(BackendFault):
            call()
    status = sim.status()
    assert not status.ok and 'disconnect' in status.fault
    clock.now += 0.3
    sim.clear_faults()
    assert sim.status().ok
    assert_allclose(sim.true_pressure(0), 2.0e5 * (1 - math.exp(-0.3 / 0.15)), rtol=1e-12)


def test_noise_is_seeded_and_has_the_configured_spread():
    readings = []
    for seed in (7, 7, 8):
        clock = FakeClock()
        sim = make(clock, noise_std_pa=2.0e3, seed=seed)
        sim.set_pressure(0, 3.0e5)
        clock.now += 10.0
        readings.append(np.array([sim.read_pressure(0)[0] for _ in range(2000)]))
    # Exact: the same seed replays the same generator in this process, and the readings
    # are quantised; no tolerance could tell a reseeded generator from a drifting one.
    assert np.array_equal(readings[0], readings[1])
    assert not np.array_equal(readings[0], readings[2])
    lsb = 1.0e6 / 4095
    assert_allclose(np.std(readings[0]), math.hypot(2.0e3, lsb / math.sqrt(12)), rtol=0.08)
    assert_allclose(np.mean(readings[0]), 3.0e5, atol=4 * 2.0e3 / math.sqrt(2000) + lsb)
    assert_allclose(sim.read_pressure(0)[1], 2.0e3 ** 2 + lsb ** 2 / 12)


def test_clock_stepping_back_does_not_move_the_model():
    clock = FakeClock()
    sim = make(clock)
    sim.set_pressure(0, 1.0e5)
    clock.now += 0.1
    value = sim.true_pressure(0)
    clock.now -= 0.05
    assert sim.true_pressure(0) == value     # not advanced, so not recomputed: exact


def test_calls_before_connect_raise_backend_fault():
    sim = SimulatedRegulator(2, clock=FakeClock())
    assert not sim.status().ok
    with pytest.raises(BackendFault, match='connect'):
        sim.read_pressure(0)
    sim.connect()
    sim.close()
    with pytest.raises(BackendFault):
        sim.set_pressure(0, 1.0)


@pytest.mark.parametrize('kwargs, match', [
    ({'n_channels': 0}, 'n_channels'),
    ({'time_constant_s': 0.0}, 'time_constant_s'),
    ({'slew_rate_pa_s': -1.0}, 'slew_rate_pa_s'),
    ({'deadband_pa': -1.0}, 'deadband_pa'),
    ({'adc_bits': 40}, 'adc_bits'),
    ({'noise_std_pa': math.nan}, 'noise_std_pa'),
])
def test_bad_constructor_arguments_are_named(kwargs, match):
    params = dict(n_channels=1, clock=FakeClock())
    params.update(kwargs)
    with pytest.raises(ValueError, match=match):
        SimulatedRegulator(**params)


def test_bad_calls_are_named():
    sim = make(FakeClock())
    with pytest.raises(ValueError, match='channel'):
        sim.set_pressure(3, 1.0)
    with pytest.raises(ValueError, match='pressure_pa_gauge'):
        sim.set_pressure(0, math.nan)
    with pytest.raises(ValueError, match="'leak', 'stuck_sensor', 'bad_readback', 'disconnect'"):
        sim.inject_fault('burst', 0)
    with pytest.raises(ValueError, match='rate'):
        sim.inject_fault('leak', 0)
