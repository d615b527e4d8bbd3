"""The one result type: every call's fields, complete when returned, read-only, to its level."""

import numpy as np
import pytest

from fpc_gripper.model import (ActuatorDesign, ArcSolver, CCMSolver, FINGER_FIELDS, fit_circle,
                               PCCSolver, Result, RodSolver)
from fpc_gripper.model.batch import GRID_FIELDS, rigidity_grid, RIGIDITY_GRID_FIELDS, solve_grid
from fpc_gripper.model.contact import Circle, CONTACT_FIELDS, solve_contact
from fpc_gripper.model.discretisations.ccm import RIGIDITY_FIELDS
from fpc_gripper.model.pipeline import contact_model, finger_model
from fpc_gripper.model.stiffness import RIGIDITY_CHECK_FIELDS

DESIGN = ActuatorDesign.paper(0.25)
RUNGS = {
    'ccm': lambda: CCMSolver(DESIGN, 8),
    'ccm_consistent': lambda: CCMSolver(DESIGN, 8, reconstruction='consistent'),
    'pcc': lambda: PCCSolver(DESIGN, 22),
    'arc': lambda: ArcSolver(DESIGN),
    'rod': lambda: RodSolver(DESIGN),
    'adaptive': lambda: finger_model(DESIGN),
}
#: The fields a level leaves out: 'tip' keeps the state, tip and validity, 'shape' all but
#: the circle fit.
SHAPE_ONLY = {'nodes', 'beta', 'theta', 'coefficients', 'energy', 'points', 'tangent',
              'strains'}
FIT_ONLY = {'curvature', 'fit_rmsd'}


@pytest.fixture(scope='module', params=sorted(RUNGS))
def solved(request):
    """(rung name, solver, {outputs: result}) at 120 kPa and a tip load."""
    solver = RUNGS[request.param]()
    return request.param, solver, {level: solver.solve(120e3, (0.1, -0.2), outputs=level)
                                   for level in ('tip', 'shape', 'all')}


def test_every_solve_returns_the_finger_fields(solved):
    _, _, results = solved
    for result in results.values():
        assert isinstance(result, Result)
        assert set(result.keys()) == set(FINGER_FIELDS)
        assert result.success, result.message


def test_a_result_is_read_only(solved):
    _, _, results = solved
    result = results['all']
    before = dict(vars(result))
    for name in FINGER_FIELDS:
        getattr(result, name)                 # reading computes nothing and changes nothing
    assert vars(result) == before
    with pytest.raises(AttributeError, match='read-only'):
        result.tip = np.zeros(2)
    with pytest.raises(AttributeError, match='read-only'):
        del result.curvature
    with pytest.raises(AttributeError):
        result.not_a_field


def test_each_level_holds_what_it_says_and_the_same_answer(solved):
    name, _, results = solved
    tip, shape, full = results['tip'], results['shape'], results['all']
    for field in SHAPE_ONLY | FIT_ONLY:
        assert getattr(tip, field) is None, field
    for field in FIT_ONLY:
        assert getattr(shape, field) is None, field
    for field in SHAPE_ONLY - {'coefficients', 'strains'}:
        assert getattr(shape, field) is not None, field
    # The level changes what is computed, never the answer: the same state and tip.
    for other in (tip, shape):
        assert other.iterations == full.iterations and other.status is full.status
        np.testing.assert_array_equal(_flat(other.state), _flat(full.state))
        np.testing.assert_allclose(other.tip, full.tip, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(shape.points, full.points)
    # The tip is the last node and the last sample.
    np.testing.assert_allclose(full.nodes[-1], full.tip, rtol=0, atol=1e-15)
    np.testing.assert_allclose(full.points[-1], full.tip, rtol=0, atol=1e-15)
    # The curvature is the circle fit of the result's own samples.
    fit = fit_circle(full.points)
    assert full.curvature == pytest.approx(fit.curvature, rel=1e-12)
    assert full.fit_rmsd == pytest.approx(fit.rmsd, rel=1e-9, abs=1e-18)
    # theta is the running sum of beta; the last sample's tangent is the tip's angle.
    np.testing.assert_allclose(full.theta, np.concatenate([[0.0], np.cumsum(full.beta)[:-1]]),
                               rtol=0, atol=1e-14)
    assert (full.coefficients is None) == (name == 'rod')
    assert (full.strains is None) == name.startswith('ccm')
    # A result's position_at lands on its own samples.
    s = np.linspace(0.0, DESIGN.free_length, 5)
    np.testing.assert_allclose(full.position_at(s)[-1], full.tip, rtol=0, atol=1e-12)


def _flat(state):
    """A state as one array (the rod's is a pair)."""
    parts = state if isinstance(state, tuple) else (state,)
    return np.concatenate([np.ravel(part) for part in parts])


def test_outputs_must_be_a_level_name(solved):
    _, solver, _ = solved
    for bad in ('everything', None, 2):
        with pytest.raises(ValueError, match='`outputs`'):
            solver.solve(0.0, outputs=bad)


def test_rigidity_results():
    solver = CCMSolver(DESIGN, 8)
    k = solver.rigidity(0.0, 'x')
    assert isinstance(k, Result) and set(k.keys()) == set(RIGIDITY_FIELDS)
    assert k.value == pytest.approx(1.636e-3, rel=1e-3)          # SPEC's reference
    # The nested results are the default 'tip' level; 'all' asks for their shapes.
    assert k.loaded.points is None and k.unloaded.curvature is None
    full = solver.rigidity(0.0, 'x', outputs='all')
    assert full.value == k.value and full.loaded.points.shape == (129, 2)
    np.testing.assert_array_equal(full.loaded.tip, k.loaded.tip)
    # The loaded state's tip moved by the displacement along X.
    assert full.loaded.tip[0] - full.unloaded.tip[0] == pytest.approx(0.010, rel=1e-9)


def test_grid_and_contact_results():
    grid = solve_grid(DESIGN, [0.0, 1e5], outputs='all')
    assert set(grid.keys()) == set(GRID_FIELDS)
    assert set(grid.result(0, 1).keys()) == set(FINGER_FIELDS)
    k = rigidity_grid(DESIGN, [0.0])
    assert set(k.keys()) == set(RIGIDITY_GRID_FIELDS)
    assert set(k.result(0, 0).keys()) == set(RIGIDITY_FIELDS) | set(RIGIDITY_CHECK_FIELDS)
    contact = solve_contact(contact_model(DESIGN), 1e5, [Circle((0.04, -0.06), 0.02)])
    assert set(contact.keys()) == set(CONTACT_FIELDS) | {'success', 'status', 'message',
                                                         'iterations'}
    assert set(contact.finger.keys()) == set(FINGER_FIELDS)
    np.testing.assert_array_equal(contact.tip, contact.finger.tip)
