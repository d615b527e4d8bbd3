"""SPEC's reference values: curvature table, tip position and flexural rigidity."""

import numpy as np
import pytest

from fpc_gripper.model import ActuatorDesign, CCMSolver

# SPEC "Reference values" (default design, CCM8, adiabatic), signed curvature [1/m].
TABLE = {
    0.15: (14.98, 0.82, -12.14),
    0.25: (26.38, 9.17, -6.06),
    0.40: (45.69, 22.98, 3.74),
}
PRESSURES = (0.0, 200e3, 400e3)


@pytest.fixture(scope='module', params=sorted(TABLE))
def solver(request):
    return CCMSolver(ActuatorDesign.paper(prestrain=request.param), n_segments=8)


@pytest.mark.parametrize('column', range(3))
def test_curvature_table(solver, column):
    result = solver.solve(pressure=PRESSURES[column])
    assert result.success, result.message
    assert result.valid
    expected = TABLE[solver.design.prestrain][column]
    assert result.curvature == pytest.approx(expected, abs=0.02)


def test_tip_at_prestrain_040_and_400_kpa():
    result = CCMSolver(ActuatorDesign.paper(prestrain=0.40), 8).solve(400e3)
    np.testing.assert_allclose(result.tip * 1e3, (87.3, -12.6), atol=0.1)


@pytest.mark.parametrize('pressure, value, force, lever', [
    (0.0, 1.636e-3, 0.2591, 57.43e-3),
    (55.2e3, 1.396e-3, None, None),
])
def test_rigidity_reference(pressure, value, force, lever):
    k = CCMSolver(ActuatorDesign.paper(prestrain=0.25), 8).rigidity(pressure, 'x', 0.010)
    assert k.success, k.message
    assert k.value == pytest.approx(value, rel=1e-3)
    if force is not None:
        assert k.force == pytest.approx(force, rel=1e-3)
        assert k.lever == pytest.approx(lever, rel=1e-3)


@pytest.mark.parametrize('axis', ['x', 'z'])
def test_rigidity_meets_displacement_and_formula(axis):
    k = CCMSolver(ActuatorDesign.paper(prestrain=0.25), 8).rigidity(30e3, axis, 0.010)
    assert k.success, k.message
    j = 0 if axis == 'x' else 1
    moved = k.loaded.tip[j] - k.unloaded.tip[j]
    assert abs(moved - 0.010) <= 1e-9 * 0.010
    # The loaded state is an equilibrium under that tip force, found independently.
    force = (k.force, 0.0) if axis == 'x' else (0.0, k.force)
    check = CCMSolver(ActuatorDesign.paper(prestrain=0.25), 8).solve(
        30e3, tip_force=force, initial=k.loaded)
    np.testing.assert_allclose(check.tip, k.loaded.tip, atol=1e-10)
    lever = abs(k.loaded.tip[1 - j])
    assert k.value == pytest.approx(k.force * lever ** 3 / (3 * 0.010), rel=1e-12)
