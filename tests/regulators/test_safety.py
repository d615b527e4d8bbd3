"""Tests of the channel supervisor: clamp, rate limit, watchdog, faults, with a fake clock."""

import math

import numpy as np
from numpy.testing import assert_allclose
import pytest

from fpc_gripper.regulators.safety import ChannelSupervisor
from fpc_gripper.regulators.safety import DEFAULT_MAX_PRESSURE
from fpc_gripper.regulators.safety import SafeState
from fpc_gripper.regulators.safety import SupervisorMode


def run(supervisor, start, stop, dt):
    """Update every dt from start to stop (inclusive); return the last output."""
    out = None
    for t in np.arange(start, stop + 0.5 * dt, dt):
        out = supervisor.update(float(t))
    return out


def test_default_limit_is_400_kpa_and_commands_are_clamped():
    # Exact comparisons in this test and the ones below with rate_limit_pa_s=inf: clamps
    # return the bound itself, vent and idle set 0.0, and an unlimited step from 0 (or to
    # 0) computes 0 + t (or t + (0 - t)), which IEEE arithmetic gives exactly.
    sup = ChannelSupervisor(rate_limit_pa_s=math.inf, command_timeout_s=10.0)
    assert sup.max_pressure == DEFAULT_MAX_PRESSURE == 4.0e5
    sup.update(0.0)
    result = sup.command(9.0e5, 0.0)
    assert result.accepted and result.clamped and result.target == 4.0e5
    out = sup.update(0.01)
    assert out.setpoint == 4.0e5 and out.clamped and out.command == 9.0e5
    assert 'clamped' in out.reason
    low = sup.command(-2.0e4, 0.02)
    assert low.clamped and low.target == 0.0
    assert sup.update(0.03).setpoint == 0.0
    assert not sup.command(1.5e5, 0.04).clamped


@pytest.mark.parametrize('dt', [0.001, 0.02, 0.07])
def test_rate_limit_ramps_at_the_limit_whatever_the_update_period(dt):
    rate = 5.0e5
    sup = ChannelSupervisor(rate_limit_pa_s=rate, command_timeout_s=100.0)
    sup.update(0.0)
    sup.command(3.0e5, 0.0)
    ts = np.arange(dt, 0.9, dt)
    for t in ts:
        out = sup.update(float(t))
        assert_allclose(out.setpoint, min(rate * t, 3.0e5), rtol=1e-9)
    sup.command(1.0e5, float(ts[-1]))
    out = sup.update(float(ts[-1]) + 0.1)
    assert_allclose(out.setpoint, 3.0e5 - 0.1 * rate, rtol=1e-9)


@pytest.mark.parametrize('safe, expected', [('vent', 0.0), ('hold', 2.0e5)])
def test_watchdog_drives_to_the_safe_state_and_says_why(safe, expected):
    sup = ChannelSupervisor(rate_limit_pa_s=1.0e6, command_timeout_s=0.3, safe_state=safe)
    sup.update(0.0)
    sup.command(2.0e5, 0.0)
    out = run(sup, 0.01, 0.1, 0.01)         # ramped to 1.0e5 at 1 MPa/s
    assert out.mode == SupervisorMode.TRACKING
    assert_allclose(out.setpoint, 1.0e5, rtol=1e-9)
    out = sup.update(0.3)                   # exactly at the timeout: still tracking
    assert out.mode == SupervisorMode.TRACKING
    assert_allclose(out.setpoint, 2.0e5, rtol=1e-9)
    out = sup.update(0.31)
    assert out.mode == SupervisorMode.WATCHDOG and out.in_safe_state
    assert_allclose(out.setpoint, expected, atol=1e-6)
    assert 'watchdog' in out.reason and f'safe state {safe}' in out.reason
    assert_allclose(out.command_age, 0.31)
    assert_allclose(run(sup, 0.32, 2.0, 0.05).setpoint, expected, atol=1e-6)
    assert_allclose(sup.update(2.0).setpoint, expected, atol=1e-6)
    # A fresh command resumes tracking through the rate limit.
    sup.command(expected + 1.0e5, 2.0)
    out = sup.update(2.05)
    assert out.mode == SupervisorMode.TRACKING
    assert_allclose(out.setpoint, expected + 0.05 * 1.0e6, rtol=1e-9)


def test_no_command_yet_holds_zero_without_tripping_the_watchdog():
    sup = ChannelSupervisor(command_timeout_s=0.1)
    out = run(sup, 0.0, 5.0, 0.5)
    assert out.mode == SupervisorMode.IDLE and out.setpoint == 0.0 and out.command_age is None


def test_backend_fault_is_a_latched_safe_state():
    sup = ChannelSupervisor(rate_limit_pa_s=math.inf, command_timeout_s=10.0, safe_state='vent')
    sup.update(0.0)
    sup.command(2.0e5, 0.0)
    assert sup.update(0.1).setpoint == 2.0e5
    sup.report_fault('link down', 0.2)
    out = sup.update(0.2)
    assert out.mode == SupervisorMode.FAULT and out.setpoint == 0.0
    assert 'link down' in out.reason
    assert not sup.command(2.0e5, 0.3).accepted
    sup.clear_fault(0.4)
    out = sup.update(0.5)
    assert out.mode == SupervisorMode.FAULT and out.setpoint == 0.0 and sup.fault is None
    assert sup.command(1.0e5, 0.6).accepted
    assert sup.update(0.7).setpoint == 1.0e5


def test_stop_and_start():
    sup = ChannelSupervisor(rate_limit_pa_s=math.inf, safe_state=SafeState.HOLD)
    sup.update(0.0)
    sup.command(1.5e5, 0.0)
    sup.update(0.01)
    sup.stop(0.02)
    out = sup.update(0.03)
    assert out.mode == SupervisorMode.STOPPED and out.setpoint == 1.5e5
    assert not sup.command(3.0e5, 0.04).accepted
    sup.start(0.05)
    assert sup.update(0.06).mode == SupervisorMode.IDLE


def test_lowering_the_limit_reclamps_at_once():
    sup = ChannelSupervisor(max_pressure=4.0e5, rate_limit_pa_s=math.inf, command_timeout_s=10)
    sup.update(0.0)
    sup.command(3.5e5, 0.0)
    sup.update(0.01)
    sup.configure(max_pressure=2.0e5)
    assert sup.update(0.02).setpoint == 2.0e5


def test_random_commands_never_leave_the_envelope():
    rng = np.random.default_rng(3)
    limit, rate = 3.0e5, 8.0e5
    sup = ChannelSupervisor(max_pressure=limit, rate_limit_pa_s=rate, command_timeout_s=0.2,
                            safe_state='hold')
    t, last = 0.0, sup.update(0.0).setpoint
    for _ in range(3000):
        dt = float(rng.exponential(0.02))
        t += dt
        if rng.random() < 0.3:
            sup.command(float(rng.uniform(-2e5, 1e6)), t)
        out = sup.update(t)
        assert 0.0 <= out.setpoint <= limit
        assert abs(out.setpoint - last) <= rate * dt + 1e-6
        last = out.setpoint


@pytest.mark.parametrize('kwargs, match', [
    ({'max_pressure': -1.0}, 'max_pressure'),
    ({'rate_limit_pa_s': 0.0}, 'rate_limit_pa_s'),
    ({'command_timeout_s': math.inf}, 'command_timeout_s'),
    ({'safe_state': 'explode'}, "safe_state.*'hold', 'vent'"),
])
def test_bad_limits_are_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ChannelSupervisor(**kwargs)


def test_non_finite_command_raises():
    sup = ChannelSupervisor()
    with pytest.raises(ValueError, match='pressure_pa_gauge'):
        sup.command(math.nan, 0.0)
    assert sup.update(0.0).mode == SupervisorMode.IDLE
