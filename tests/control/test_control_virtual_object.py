"""Virtual cylinder: contact forces against independent solves of the finger model."""

from control_sim import fresh_solver, PALM_RADIUS
import numpy as np
import pytest

from fpc_gripper.control.inverse import InverseModel
from fpc_gripper.control.virtual_object import VirtualCylinder
from fpc_gripper.model import ActuatorDesign

DESIGN = ActuatorDesign.paper(prestrain=0.25)
D = 0.040


@pytest.fixture(scope='module')
def model():
    return InverseModel(DESIGN, PALM_RADIUS, 400.0e3)


@pytest.fixture(scope='module')
def solver():
    return fresh_solver(DESIGN)


@pytest.fixture(scope='module')
def cylinder(model):
    return VirtualCylinder(D, model)


def rho_of(solver, pressure, tip_force=(0.0, 0.0)):
    result = solver.solve(pressure, tip_force=tip_force)
    assert result.success, result.message
    return PALM_RADIUS + result.tip[1]


@pytest.mark.parametrize('pressure', [0.0, 50.0e3, 120.0e3])
def test_exact_force_puts_the_loaded_tip_on_the_surface(cylinder, solver, pressure):
    force = cylinder.exact_force(pressure)
    assert force > 0.0
    assert rho_of(solver, pressure, (0.0, force)) == pytest.approx(D / 2, abs=1e-6)


def test_touch_pressure_and_no_force_outside(cylinder, solver):
    assert rho_of(solver, cylinder.touch_pressure) == pytest.approx(D / 2, abs=1e-6)
    assert cylinder.force(cylinder.touch_pressure + 1.0e3) == 0.0
    assert cylinder.force(300.0e3) == 0.0
    contact = cylinder.contact(300.0e3)
    assert not contact.in_contact and contact.penetration < 0.0


def test_table_follows_the_exact_force(cylinder):
    pressures = np.linspace(0.0, cylinder.touch_pressure, 17)[1:-1] + 1234.5
    table = [cylinder.force(p) for p in pressures]
    exact = [cylinder.exact_force(p) for p in pressures]
    # 5e-4 N: next to the touch pressure the adaptive model switches from the unloaded
    # scene's discretisation (where the table ends at 0 N) to a loaded one.
    np.testing.assert_allclose(table, exact, atol=5e-4)
    assert np.all(np.diff(table) < 0.0)       # less pressure, a harder push on the object


def test_contact_state(cylinder):
    contact = cylinder.contact(80.0e3)
    assert contact.in_contact and contact.penetration > 0.0
    assert contact.rho == pytest.approx(D / 2)
    assert contact.tip_force == (0.0, contact.force)


def test_penalty_contact_is_a_consistent_compliant_equilibrium(model, solver):
    stiffness = 100.0
    soft = VirtualCylinder(D, model, method='penalty', stiffness=stiffness)
    pressure = 80.0e3
    force = soft.exact_force(pressure)
    rho = rho_of(solver, pressure, (0.0, force))
    assert force == pytest.approx(stiffness * (D / 2 - rho), abs=1e-6)
    assert 0.0 < force < VirtualCylinder(D, model).exact_force(pressure)


def test_objects_out_of_reach(model):
    assert VirtualCylinder(0.002, model).force(0.0) == 0.0       # inside the closed tips
    wide = VirtualCylinder(0.190, model)                          # wider than fully open
    assert wide.touch_pressure == model.max_pressure
    assert wide.force(model.max_pressure) > 0.0


@pytest.mark.parametrize('kwargs, word', [
    ({'diameter': 0.0}, 'diameter'), ({'method': 'penalty', 'stiffness': -1.0}, 'stiffness'),
    ({'table_step': 0.0}, 'table_step'),
])
def test_bad_arguments(model, kwargs, word):
    args = {'diameter': D, **kwargs}
    with pytest.raises(ValueError, match=word):
        VirtualCylinder(model=model, **args)
