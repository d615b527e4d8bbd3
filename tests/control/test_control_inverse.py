"""Model-inverse feedforward checked against independent solves of the finger model."""

from control_sim import fresh_solver, PALM_RADIUS
import numpy as np
from numpy.testing import assert_allclose
import pytest

from fpc_gripper.control.inverse import InverseModel, InverseStatus
from fpc_gripper.model import ActuatorDesign

DESIGN = ActuatorDesign.paper(prestrain=0.25)
MAX = 400.0e3


@pytest.fixture(scope='module')
def model():
    return InverseModel(DESIGN, PALM_RADIUS, MAX)


@pytest.fixture(scope='module')
def solver():
    return fresh_solver(DESIGN)


def rho_of(solver, pressure, tip_force=(0.0, 0.0)):
    result = solver.solve(pressure, tip_force=tip_force)   # cold start: no shared state
    assert result.success, result.message
    return PALM_RADIUS + result.tip[1]


@pytest.mark.parametrize('target, tip_force', [
    (0.0050, (0.0, 0.0)), (0.020, (0.0, 0.0)), (0.050, (0.0, 0.0)), (0.085, (0.0, 0.0)),
    (0.040, (0.0, 0.2)), (0.030, (0.0, -0.1)), (0.060, (0.05, 0.1)),
])
def test_pressure_found_puts_the_tip_at_the_target(model, solver, target, tip_force):
    result = model.pressure_for_rho(target, tip_force)
    assert result.success and result.status is InverseStatus.SUCCESS, result.message
    assert 0.0 < result.x < MAX
    assert_allclose(rho_of(solver, result.x, tip_force), target, atol=1e-6, rtol=0)


def test_out_of_reach_targets_return_the_nearest_end(model, solver):
    low = model.pressure_for_rho(0.001)
    assert (low.x, low.status, low.success) == (0.0, InverseStatus.BELOW_RANGE, False)
    high = model.pressure_for_rho(0.095)
    assert (high.x, high.status) == (MAX, InverseStatus.ABOVE_RANGE)
    assert_allclose(high.rho, rho_of(solver, MAX), atol=1e-9)


def test_map_matches_the_solver(model, solver):
    for p in np.linspace(0.0, MAX, 13):
        assert model.rho_map(p) == pytest.approx(rho_of(solver, p), abs=1e-5)
        assert model.map_pressure(model.rho_map(p)) == pytest.approx(p, abs=100.0)


def test_linearisation_against_independent_differences(model, solver):
    p, force = 150.0e3, (0.0, 0.3)
    lin = model.linearise(p, force)
    assert lin.rho == pytest.approx(rho_of(solver, p, force), abs=1e-9)
    dp = (rho_of(solver, p + 2e3, force) - rho_of(solver, p - 2e3, force)) / 4e3
    df = (rho_of(solver, p, (0.0, 0.32)) - rho_of(solver, p, (0.0, 0.28))) / 0.04
    assert lin.drho_dp == pytest.approx(dp, rel=2e-3)
    assert lin.drho_dp0 == pytest.approx(df, rel=2e-3)
    # dP/dp0 at constant rho: the pressure change that keeps the tip where it is.
    assert lin.dp_dforce == pytest.approx(-df / dp, rel=3e-3)


def test_estimate_stays_close_to_the_exact_model(model, solver):
    errors = []
    for p, f in [(100e3, 0.0), (102e3, 0.0), (103.9e3, 0.01), (250e3, 0.25), (252.5e3, 0.27)]:
        rho, _ = model.estimate(p, (0.0, f))
        errors.append(rho - rho_of(solver, p, (0.0, f)))
    assert np.max(np.abs(errors)) < 2e-5


def test_non_monotone_range_is_refused():
    with pytest.raises(ValueError, match='max_pressure'):
        InverseModel(DESIGN, PALM_RADIUS, 800.0e3, grid_step=25.0e3)


@pytest.mark.parametrize('call, word', [
    (lambda m: m.pressure_for_rho(float('nan')), 'rho'),
    (lambda m: m.pressure_for_rho(0.02, (0.0,)), 'tip_force'),
])
def test_bad_input_names_the_argument(model, call, word):
    with pytest.raises(ValueError, match=word):
        call(model)


@pytest.mark.parametrize('prestrain', [0.15, 0.19195, 0.2421875])
def test_the_ends_of_the_range_are_reached_exactly(prestrain):
    """Targets at the map's ends return 0 Pa and max_pressure with success (no brentq error)."""
    model = InverseModel(ActuatorDesign.paper(prestrain), PALM_RADIUS, 300e3)
    low, high = model.rho_range
    for target, pressure in ((low, 0.0), (high, 300e3)):
        result = model.pressure_for_rho(target)
        assert result.success, result.message
        assert 0.0 <= result.x <= 300e3
        assert result.x == pytest.approx(pressure, abs=1.0)
