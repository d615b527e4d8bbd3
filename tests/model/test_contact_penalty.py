"""A penalty surface on the geometrically exact rod converges to the contact constraint as 1/k."""

import numpy as np
import pytest

from fpc_gripper.model import ActuatorDesign, PCCSolver, RodSolver
from fpc_gripper.model import contact as C

DESIGN = ActuatorDesign.paper(0.25)
#: A 50 mm sphere's section, its centre 45 mm above the palm, 62 mm from the clamp.
SPHERE = C.Circle((0.045, -0.062), 0.025)
RIGID = C.ContactSettings(faces=('inner',), points_per_segment=1)
STIFFNESS = (1e3, 1e4, 1e5, 1e6)


@pytest.fixture(scope='module')
def rod():
    # Points at element ends, 3 mm apart at most (the rod has no interior face points).
    return RodSolver(DESIGN, degree=6, max_element_length=0.003)


@pytest.fixture(scope='module')
def constrained(rod):
    result = C.solve_contact(rod, 0.0, SPHERE, settings=RIGID)
    assert result.success, result.message
    assert result.normal_force_total > 0.5
    return result


@pytest.fixture(scope='module')
def penalised(rod):
    out = []
    for k in STIFFNESS:
        result = C.solve_contact(rod, 0.0, SPHERE, settings=C.ContactSettings(
            faces=('inner',), points_per_segment=1, penalty=k))
        assert result.success, result.message
        out.append(result)
    return out


def balance(rod, result):
    """Largest gradient of the rod's potential with the contact forces as dead loads [J]."""
    points = result.points
    grad = rod.point_derivatives(result.state[0], result.pressure, [], points.segment,
                                 points.offset, points.height, result.force)[1]
    return np.abs(grad).max()


def test_penalty_states_are_rod_equilibria_with_the_penalty_law(rod, penalised):
    """Checked independently of the contact solver: force balance and lambda = k max(-g, 0)."""
    for k, result in zip(STIFFNESS, penalised):
        assert balance(rod, result) <= 1e-9 * rod.gradient_scale
        np.testing.assert_allclose(result.normal_force, k * np.maximum(-result.gap, 0.0),
                                   atol=1e-9)


def test_constrained_state_is_a_rod_equilibrium_without_penetration(rod, constrained):
    assert balance(rod, constrained) <= 1e-9 * rod.gradient_scale
    assert constrained.gap.min() >= -1e-13
    assert constrained.normal_force.min() >= 0.0


def test_penalty_converges_to_the_constraint_at_first_order(constrained, penalised):
    errors = np.array([np.abs(r.tip - constrained.tip).max() for r in penalised])
    forces = np.array([r.normal_force_total for r in penalised])
    penetration = np.array([-r.gap.min() for r in penalised])
    rate = np.diff(np.log(errors)) / np.diff(np.log(STIFFNESS))
    print('penalty k [N/m]', STIFFNESS, 'tip error [m]', errors, 'observed order', -rate,
          'penetration [m]', penetration, 'force error [N]',
          forces - constrained.normal_force_total)
    assert np.all(np.diff(errors) < 0.0)
    # First order once the contact set is that of the constraint: error ~ F / k.
    assert -rate[-1] == pytest.approx(1.0, abs=0.05)
    assert errors[-1] < 2e-6
    # The penetration is the force over the stiffness.
    np.testing.assert_allclose(penetration * np.array(STIFFNESS), forces, rtol=1e-6)


def test_rod_and_pcc_agree_on_the_constrained_contact(rod, constrained):
    """The PCC on the rod's element edges (the same contact points): discretisation only."""
    solver = PCCSolver(DESIGN, rod.n_elements)
    np.testing.assert_allclose(solver.edges, rod.edges, atol=1e-15)
    pcc = C.solve_contact(solver, 0.0, SPHERE, settings=RIGID)
    assert pcc.success, pcc.message
    assert np.abs(pcc.tip - constrained.tip).max() < 20e-6
    assert pcc.normal_force_total == pytest.approx(constrained.normal_force_total, rel=0.02)
