"""The one front end: `finger_model` builds every consumer's finger, and results stay put."""

import numpy as np
import pytest

from fpc_gripper.model import ActuatorDesign, AdaptiveSolver, ArcSolver, CCMSolver, RodSolver
from fpc_gripper.model.batch import solve_grid
from fpc_gripper.model.discretisations.pcc import PCCSolver
from fpc_gripper.model.pipeline import (contact_model, contact_segments, finger_model,
                                        MAX_RUNG_SEGMENTS, MAX_SEGMENTS,
                                        ModelSettings)


@pytest.fixture(scope='module')
def design():
    return ActuatorDesign.paper(0.25)


@pytest.mark.parametrize('rung, n, build', [
    ('ccm', 12, lambda d: CCMSolver(d, n_segments=12)),
    ('ccm_consistent', 10, lambda d: CCMSolver(d, n_segments=10, reconstruction='consistent')),
    ('pcc', 24, lambda d: PCCSolver(d, n_segments=24)),
    ('arc', 8, lambda d: ArcSolver(d)),
    ('rod', 8, lambda d: RodSolver(d)),
])
def test_a_named_rung_is_that_rung_whatever_the_tolerance(design, rung, n, build):
    # The tolerance would select the adaptive model; a named rung overrides it.
    model = finger_model(design, ModelSettings(tolerance=5e-5, rung=rung, n_segments=n))
    assert model.rung == rung and not isinstance(model, AdaptiveSolver)
    got, want = model.solve(60e3, (0.05, -0.1)), build(design).solve(60e3, (0.05, -0.1))
    assert got.success and want.success
    assert np.max(np.abs(got.points - want.points)) <= 1e-12


def test_the_aligned_ccm_is_named_as_such(design):
    model = finger_model(design, ModelSettings(rung='ccm_aligned', n_segments=44))
    assert model.rung == 'ccm_aligned' and model.n_segments == 44


def test_auto_keeps_its_meaning(design):
    assert isinstance(finger_model(design, ModelSettings()), AdaptiveSolver)
    paper = finger_model(design, ModelSettings(tolerance=0.0, n_segments=8))
    assert type(paper) is CCMSolver and paper.n_segments == 8
    assert ModelSettings().fixed is None
    assert ModelSettings(tolerance=0.0, n_segments=5).fixed == ('ccm', 5)


@pytest.mark.parametrize('fields, words', [
    (dict(rung='beam'), ['`rung`', "'beam'"]),
    (dict(rung='ccm', n_segments=MAX_RUNG_SEGMENTS + 1), ['`n_segments`', '129']),
    (dict(n_segments=MAX_SEGMENTS + 1), ['`n_segments`', str(MAX_SEGMENTS + 1)]),
    (dict(rung='pcc', n_segments=0), ['`n_segments`', '0']),
])
def test_bad_settings_name_the_argument(fields, words):
    with pytest.raises(ValueError) as info:
        ModelSettings(**fields)
    assert all(word in str(info.value) for word in words), info.value


@pytest.mark.parametrize('tolerance, n', [(5e-5, 32), (1e-5, 64), (2e-6, 128), (0.0, 32)])
def test_contact_goes_through_the_front_end(design, tolerance, n):
    model = contact_model(design, ModelSettings(tolerance=tolerance))
    assert isinstance(model, PCCSolver) and model.n_segments == n == contact_segments(tolerance)
    assert model is finger_model(design, ModelSettings(tolerance=tolerance, n_segments=n,
                                                       rung='pcc'))


def test_the_adaptive_result_is_its_rungs_result_built_with_its_choice(design, monkeypatch):
    model = AdaptiveSolver(design, tolerance=5e-5)
    choice = model.choose(40e3, (0.0, 0.0))
    rung = model.solver_for(choice.rung, choice.n_segments)
    returned = []
    solve = rung.solve
    monkeypatch.setattr(rung, 'solve', lambda *a, **k: returned.append(solve(*a, **k))
                        or returned[-1])
    outer = model.solve(40e3)
    # The rung built the result with the choice inside its call: nothing copied or changed
    # after (a Result refuses assignment).
    assert len(returned) == 1 and outer is returned[0]
    assert outer.model_choice == choice and outer.model == f'{choice.rung} N={choice.n_segments}'
    with pytest.raises(AttributeError, match='read-only'):
        outer.model_choice = None
    with pytest.raises(AttributeError, match='read-only'):
        del outer.tip
    # It warm-starts its rung.
    assert model.solve(41e3, initial=outer).iterations < model.solve(41e3).iterations


def test_a_grid_of_the_rod_is_the_rods_own_solves(design):
    grid = solve_grid([design], [0.0, 80e3], [(0.0, 0.0), (0.1, 0.0)],
                      settings=ModelSettings(rung='rod'))
    rod = RodSolver(design)
    for k, p in enumerate((0.0, 80e3)):
        for j, f in enumerate(((0.0, 0.0), (0.1, 0.0))):
            assert grid.success[0, k, j]
            assert np.max(np.abs(grid.tip[0, k, j] - rod.solve(p, f).tip)) <= 1e-12
            assert grid.models[0, k, j] == 'rod'


def _state(solver):
    """A solver's attributes, by name and identity (a new or rebound one shows)."""
    return {name: id(value) for name, value in vars(solver).items()}


@pytest.mark.parametrize('build', [
    lambda d: CCMSolver(d, n_segments=8), lambda d: PCCSolver(d, n_segments=16),
    lambda d: ArcSolver(d), lambda d: RodSolver(d)])
def test_the_engine_never_writes_into_a_solver(design, build):
    solver = build(design)
    before = _state(solver)
    first = solver.solve(50e3, (0.05, 0.0))
    solver.solve(60e3, (0.05, 0.0), initial=first)
    assert solver.rigidity(50e3).success
    assert _state(solver) == before


def test_nothing_writes_into_the_contact_model_or_the_grid_models(design):
    from fpc_gripper.model import contact as C
    model = contact_model(design)
    before = _state(model)
    result = C.solve_contact(model, 100e3, C.Circle((0.05, -0.05), 0.02))
    assert result.success, result.message
    assert _state(model) == before
    adaptive = finger_model(design, ModelSettings())
    solvers = [adaptive.solver_for(*key) for key in list(adaptive._solvers)]
    states = [_state(s) for s in solvers]
    assert solve_grid([design], [0.0, 50e3, 150e3], [(0.0, 0.0), (0.1, 0.0)]).success.all()
    assert [_state(s) for s in solvers] == states
