"""The model's envelope: absurd loads refused up front, history-free answers, honest successes."""

import math

from equilibrium_checks import GRADIENT_TOLERANCE, independent_residual, random_scenes
import numpy as np
import pytest

from fpc_gripper.model import (ActuatorDesign, AdaptiveSolver, ArcSolver, CCMSolver, PCCSolver,
                               RodSolver, Scene)
from fpc_gripper.model.batch import rigidity_grid, solve_grid
from fpc_gripper.model.pipeline import finger_model, ModelSettings
from fpc_gripper.model.validation import (ArgumentError, check_load, ENVELOPE, InputLimits,
                                          UNIQUE_LOAD)

PAPER = ActuatorDesign.paper(0.25)


@pytest.fixture(scope='module')
def solvers():
    return {'ccm': CCMSolver(PAPER, 8), 'arc': ArcSolver(PAPER), 'pcc': PCCSolver(PAPER, 22),
            'rod': RodSolver(PAPER), 'adaptive': finger_model(PAPER, ModelSettings())}


@pytest.mark.parametrize('pressure, force, words', [
    (1e5, (1.7e308, 0.0), ('`tip_force` magnitude must be <= 5 [N]', 'got 1.7e+308 N')),
    (1e5, (1.7e308, 1.7e308), ('`tip_force` magnitude', 'got inf N')),
    (1e5, (-1000.0, 0.0), ('`tip_force` magnitude must be <= 5 [N]', 'got 1000 N')),
    (1e5, (-3.6, 3.6), ('`tip_force` magnitude', 'got 5.09117 N')),
    (1e30, (0.0, 0.0), ('`pressure` must be <= 800000 (gauge) [Pa]', 'got 1e+30')),
    (800001.0, (0.0, 0.0), ('`pressure` must be <= 800000 (gauge) [Pa]', '2 x max_pressure')),
    (-1.0, (0.0, 0.0), ('`pressure` must be >= 0 (gauge) [Pa], got -1.0',)),
])
def test_every_solver_refuses_loads_outside_the_envelope(solvers, pressure, force, words):
    calls = {name: (lambda s=s: s.solve(pressure, force)) for name, s in solvers.items()}
    calls['scene'] = lambda: Scene(PAPER, pressure, force)
    for name, call in calls.items():
        with pytest.raises(ArgumentError) as error:
            call()
        assert all(word in str(error.value) for word in words), (name, str(error.value))
    # The batches refuse the same grids, by the argument's plural name where they check it.
    with pytest.raises(ValueError, match='pressure|tip_force'):
        solve_grid(PAPER, [0.0, pressure], [(0.0, 0.0), force])
    with pytest.raises(ArgumentError, match='pressure'):
        rigidity_grid(PAPER, [1e30])


def test_the_envelope_edge_is_accepted_and_limits_only_tighten():
    top = ENVELOPE.pressure_factor * PAPER.max_pressure
    # Exact: the values pass through as given.
    assert check_load(top, (3.0, -4.0), PAPER.max_pressure) == (top, (3.0, -4.0))
    tight = InputLimits(max_tip_force=1.0, pressure_factor=1.0)
    with pytest.raises(ArgumentError, match='magnitude must be <= 1 '):
        check_load(1e5, (0.0, 1.5), PAPER.max_pressure, tight)
    with pytest.raises(ArgumentError, match=r'must be <= 400000 \(gauge\)'):
        check_load(400001.0, (0.0, 0.0), PAPER.max_pressure, tight)
    for wide in ({'max_tip_force': 5.5}, {'pressure_factor': 3.0}, {'max_tip_force': 0.0}):
        with pytest.raises(ArgumentError, match='envelope of the model'):
            InputLimits(**wide)


def test_the_rod_scene_that_failed_to_unpack_now_solves():
    # `too many values to unpack` in the rod's step before the engine rewrite (ladder.py:581).
    design = ActuatorDesign.paper(prestrain=0.5044)
    for solver in (RodSolver(design), AdaptiveSolver(design, tolerance=5e-5)):
        result = solver.solve(478266, (-2.83, 2.73))
        assert result.success, result.message
        assert independent_residual(solver, result) < GRADIENT_TOLERANCE


@pytest.mark.parametrize('make', [
    lambda d: RodSolver(d), lambda d: PCCSolver(d, 22), lambda d: CCMSolver(d, 8),
    lambda d: finger_model(d, ModelSettings())], ids=['rod', 'pcc', 'ccm8', 'adaptive'])
def test_loads_beyond_unique_load_give_the_same_answer_after_any_history(make):
    # At 200 kPa a 2 N push along -X holds the 0.15 finger on two stable branches: before
    # solves above UNIQUE_LOAD started cold, a warm start from the answer at (0, 2) N put
    # the rod's tip 0.117 m from the cold answer.
    solver = make(ActuatorDesign.paper(0.15))
    scene = (200e3, (-2.0, 0.0))
    assert math.hypot(*scene[1]) > UNIQUE_LOAD
    fresh = solver.solve(*scene)
    for previous in ((0.0, 2.0), (0.0, -2.0), (2.0, 0.0), (-1.0, 0.0), (-2.0, 0.5)):
        start = solver.solve(scene[0], previous)
        again = solver.solve(*scene, initial=start)
        assert again.success == fresh.success
        # Exact: the warm start is not used, so the same arithmetic runs.
        np.testing.assert_array_equal(again.tip, fresh.tip)


def test_random_in_range_scenes_never_raise_and_successes_are_equilibria():
    # A sample of bench/sweep_solvers.py's sweep (seed 20261202, 2000 scenes there).
    seen = {'success': 0, 'failed': 0}
    for design, pressure, force in random_scenes(20261202, 40):
        for solver in (finger_model(design, ModelSettings()), CCMSolver(design, 8)):
            result = solver.solve(pressure, force)
            if result.success:
                seen['success'] += 1
                assert independent_residual(solver, result) < GRADIENT_TOLERANCE, \
                    (design.prestrain, pressure, force, result.model)
            else:
                seen['failed'] += 1
                assert result.message
    assert seen['success'] >= 70


@pytest.mark.parametrize('make, words', [
    (lambda: CCMSolver(PAPER, 0), '`n_segments` must be an integer >= 1, got 0'),
    (lambda: CCMSolver(PAPER, True), '`n_segments` must be an integer >= 1, got True'),
    (lambda: CCMSolver(PAPER, 8.0), '`n_segments` must be an integer >= 1, got 8.0'),
    (lambda: CCMSolver(PAPER, 8, max_iterations=1), '`max_iterations` must be an integer >= 2'),
    (lambda: PCCSolver(PAPER, -3), '`n_segments` must be an integer >= 1, got -3'),
    (lambda: PCCSolver(PAPER, 22, samples=2), '`samples` must be an integer >= 3, got 2'),
    (lambda: RodSolver(PAPER, degree=np.int64(1)), '`degree` must be an integer >= 2'),
    (lambda: ModelSettings(n_segments=10**6), '`n_segments` must be an integer in [1, '),
])
def test_integer_arguments_are_refused_by_name(make, words):
    with pytest.raises(ValueError) as info:
        make()
    assert words in str(info.value)


def test_numpy_integers_are_integers():
    assert CCMSolver(PAPER, np.int32(4)).n_segments == 4
    assert isinstance(ModelSettings(n_segments=np.int64(8)).n_segments, int)
