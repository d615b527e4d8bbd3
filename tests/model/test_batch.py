"""Batched solves (model.batch, engine.solve_batch) equal the single solves, scene by scene."""

import itertools

from helpers import deviation
import numpy as np
import pytest

from fpc_gripper.model import ActuatorDesign, CCMSolver, engine
from fpc_gripper.model.batch import rigidity_grid, solve_grid
from fpc_gripper.model.discretisations.pcc import PCCSolver
from fpc_gripper.model.engine import SolverStatus
from fpc_gripper.model.pipeline import finger_model, model_label, ModelSettings, rung_label
from fpc_gripper.model.stiffness import checked_rigidity, RigidityStatus

#: A scene of a batch runs the single solve's arithmetic on the same model; only the
#: order of work differs. Seen bitwise equal; 1e-12 leaves room for BLAS round-off.
RTOL = 1e-12
PRESSURES = (0.0, 100e3, 200e3, 300e3)
FORCES = ((0.0, 0.0), (0.3, 0.0), (0.0, -0.2), (-0.1, 0.1))
#: Per setting, an extra tip force [N] and why: 2 N lies beyond the error model's load
#: range (the default model then takes the rod, which is not batched), 5 N is the edge of
#: the model's envelope, and (-3, 4) N stalls the SRM's continuation at prestrain 0.15.
SETTINGS = {
    'default': (ModelSettings(), (0.0, -2.0)),
    'paper': (ModelSettings(tolerance=0.0), (5.0, 0.0)),
    'srm': (ModelSettings(tolerance=0.0, n_segments=1), (-3.0, 4.0)),
    # A coarse tolerance takes the arc and CCM rungs of few segments; two of them break
    # the small-rotation rule at N = 2 and are refined by the single solve.
    'coarse': (ModelSettings(tolerance=2e-2), (0.0, -2.0)),
}


@pytest.fixture(scope='module')
def designs():
    """Three paper prestrains and one narrower channel (a non-paper geometry)."""
    out = [ActuatorDesign.paper(prestrain) for prestrain in (0.15, 0.25, 0.40)]
    return out + [ActuatorDesign.paper(0.25).replace(Cy=0.024)]


@pytest.fixture(scope='module', params=sorted(SETTINGS))
def grid(request, designs):
    """(settings, forces, {chain: grid}, single cold solves keyed by (d, p, f))."""
    settings, extra = SETTINGS[request.param]
    forces = FORCES + (extra,)
    out = {chain: solve_grid(designs, PRESSURES, forces, settings, outputs='all', chain=chain)
           for chain in (False, True)}
    singles = {}
    for (d, design), (p, pressure), (f, force) in itertools.product(
            enumerate(designs), enumerate(PRESSURES), enumerate(forces)):
        singles[d, p, f] = finger_model(design, settings).solve(pressure, force)
    return request.param, forces, out, singles


def _state(result):
    """The unknowns of a result as one flat array (the rod's state is a pair of arrays)."""
    state = result.state
    if isinstance(state, tuple):
        return np.concatenate([np.ravel(part) for part in state])
    return state


def _assert_same_result(got, want, cold=True):
    """A result built from a batch against the single solve's, field by field."""
    assert got.status is want.status and got.success == want.success
    # A warm start (`cold` False) changes the iterations, never the answer.
    assert got.iterations == want.iterations or not cold
    assert got.valid == want.valid
    assert model_label(got) == model_label(want)
    assert deviation(_state(got), _state(want)) <= RTOL
    assert deviation(got.tip, want.tip) <= RTOL
    for field in ('nodes', 'beta', 'points', 'tangent', 'coefficients', 'energy'):
        assert (getattr(got, field) is None) == (getattr(want, field) is None), field
    if want.points is not None:
        assert deviation(got.nodes, want.nodes) <= RTOL
        assert deviation(got.points, want.points) <= RTOL
        assert abs(got.energy - want.energy) <= RTOL * abs(want.energy)
    if want.curvature is not None:
        assert abs(got.curvature - want.curvature) <= RTOL * abs(want.curvature)
    assert got.pressure == want.pressure and got.tip_force == want.tip_force


@pytest.mark.parametrize('chain', [False, True], ids=['cold', 'chained'])
def test_grid_equals_single_solves(grid, designs, chain):
    name, forces, grids, singles = grid
    out = grids[chain]
    shape = (len(designs), len(PRESSURES), len(forces))
    assert out.success.shape == out.status.shape == out.iterations.shape == shape
    assert out.models.shape == shape and out.tip.shape == shape + (2,)
    for key, single in singles.items():
        assert out.status[key] == int(single.status), key
        assert out.success[key] == single.success, key
        assert out.iterations[key] == single.iterations or chain, key
        assert out.models[key] == model_label(single), key
        assert deviation(out.tip[key], single.tip) <= RTOL, key
        assert out.valid[key] == single.valid, key
        assert abs(out.curvature[key] - single.curvature) <= RTOL * abs(single.curvature), key
        # An arc's samples lie on its circle: the RMSD is round-off, 1e-18 m cold (the same
        # arithmetic), a few times that from another start.
        assert abs(out.fit_rmsd[key] - single.fit_rmsd) <= 1e-9 * single.fit_rmsd + (
            1e-15 if chain else 1e-18), key
        _assert_same_result(out.result(*key), single, cold=not chain)


def test_grid_holds_the_cases_it_is_meant_to(grid, designs):
    # The grids are picked to hold several models, refined and failed scenes: check
    # that they do, on the single solves, so that the comparison above covers them.
    name, forces, grids, singles = grid
    out = grids[True]
    labels = {model_label(result) for result in singles.values()}
    if name == 'default':
        assert {'rod', 'pcc N=22'} <= labels
    if name == 'srm':
        failed = [key for key, result in singles.items() if not result.success]
        assert failed and all(key[2] == len(forces) - 1 for key in failed)
        assert {singles[key].status for key in failed} == {SolverStatus.CONTINUATION_FAILED}
        assert not out.success[0, :, -1].any()
    if name == 'coarse':
        refined = [key for key, result in singles.items()
                   if result.model_choice.n_segments != finger_model(
                       designs[key[0]], SETTINGS[name][0]).choose(
                           PRESSURES[key[1]], forces[key[2]]).n_segments]
        assert refined
        assert {model_label(singles[key]) for key in refined} == {'ccm N=4'}
        assert any(label.startswith('arc') for label in labels)
        assert len({label.split()[0] for label in labels}) >= 4, labels


def test_grid_of_one_design_and_one_force():
    design = ActuatorDesign.paper(0.30)
    out = solve_grid(design, [150e3], (0.2, -0.1), ModelSettings(tolerance=0.0))
    assert out.shape == (1, 1, 1)
    single = CCMSolver(design, 8).solve(150e3, (0.2, -0.1))
    _assert_same_result(out.result(0, 0, 0), single)
    assert out.curvature is None and out.energy is None      # outputs 'tip', the default
    assert repr(out).startswith('Result(') and 'shape=(1, 1, 1)' in repr(out)
    with pytest.raises(AttributeError, match='read-only'):
        out.success = None


# -- chains along pressure ------------------------------------------------------------------
#: A design sweep's pressures (fpc-design: every 5 kPa; here every 10) [Pa].
SWEEP = np.linspace(0.0, 400e3, 41)


@pytest.fixture(scope='module')
def sweep_designs():
    """The sweep's extremes: the least and most prestrained, channels narrow and wide."""
    return [ActuatorDesign.paper(0.15).replace(Cy=0.022, h3a=-0.0005),
            ActuatorDesign.paper(0.40).replace(Cy=0.030, h3a=0.0015)]


@pytest.mark.parametrize('name', ['default', 'paper'])
def test_a_chained_row_is_the_row_solved_alone(sweep_designs, name):
    # Warm starts change the iterations, never the answer: a row of a chained sweep, the
    # same row as a grid of its own, and the cold single solve agree to 1e-12 m.
    settings = SETTINGS[name][0]
    chained = solve_grid(sweep_designs, SWEEP, settings=settings, outputs='all')
    cold = solve_grid(sweep_designs, SWEEP, settings=settings, outputs='all', chain=False)
    assert chained.success.all() and (chained.models == cold.models).all()
    # The chains pay: the 2 Newton iterations of a predicted start against 5-8 cold.
    assert chained.iterations.sum() < 0.5 * cold.iterations.sum()
    for d, design in enumerate(sweep_designs):
        model = finger_model(design, settings)
        for p in range(0, SWEEP.size, 5):
            single = model.solve(float(SWEEP[p]))
            alone = solve_grid(design, SWEEP[p:p + 1], settings=settings, outputs='all')
            # Alone, a row starts its own chain: cold, as the single solve.
            assert alone.iterations[0, 0, 0] == single.iterations
            for got in (chained.result(d, p), alone.result(0, 0)):
                assert got.model == single.model
                assert np.abs(got.tip - single.tip).max() <= 1e-12
                assert np.abs(got.points - single.points).max() <= 1e-12
            assert chained.curvature[d, p, 0] == pytest.approx(single.curvature, rel=1e-9)


def test_a_chain_runs_by_pressure_whatever_order_they_are_given_in(sweep_designs):
    forward = solve_grid(sweep_designs, SWEEP)
    order = np.random.default_rng(5).permutation(SWEEP.size)
    shuffled = solve_grid(sweep_designs, SWEEP[order])
    np.testing.assert_array_equal(shuffled.iterations, forward.iterations[:, order])
    np.testing.assert_allclose(shuffled.tip, forward.tip[:, order], rtol=0, atol=1e-12)


def test_loads_beyond_the_unique_load_are_not_chained(sweep_designs):
    # Beyond 1.5 N a compressive load can hold two stable branches: those scenes start
    # cold, as their single solves do, with the same iterations.
    design = sweep_designs[1]
    settings = SETTINGS['paper'][0]
    forces = [(0.0, -0.5), (-2.0, 0.0)]
    out = solve_grid(design, SWEEP[::4], forces, settings)
    cold = solve_grid(design, SWEEP[::4], forces, settings, chain=False)
    np.testing.assert_array_equal(out.iterations[..., 1], cold.iterations[..., 1])
    assert out.iterations[..., 0].sum() < cold.iterations[..., 0].sum()
    np.testing.assert_allclose(out.tip, cold.tip, rtol=0, atol=1e-12)


def test_a_chained_batch_takes_no_warm_starts():
    problem = PCCSolver(ActuatorDesign.paper(0.25), 22)
    with pytest.raises(ValueError, match='`initial`'):
        engine.solve_batch([problem.engine_problem], [0, 0], [0.0, 5e3], [],
                           np.zeros((2, 0, 2)), problem._options,
                           initial=np.zeros((2,) + problem.flat().shape), chain=True)


# -- flexural rigidity ------------------------------------------------------------------
RIGIDITY_PRESSURES = (0.0, 55.2e3, 200e3)


@pytest.mark.parametrize('axis', ['x', 'z'])
@pytest.mark.parametrize('name', ['default', 'paper'])
def test_rigidity_grid_equals_single_rigidity(designs, name, axis):
    settings = SETTINGS[name][0]
    out = rigidity_grid(designs, RIGIDITY_PRESSURES, axis, 0.010, settings)
    assert out.value.shape == (len(designs), len(RIGIDITY_PRESSURES))
    for (d, design), (p, pressure) in itertools.product(enumerate(designs),
                                                        enumerate(RIGIDITY_PRESSURES)):
        model = finger_model(design, settings)
        single = model.rigidity(pressure, axis, 0.010)
        if 'rigidity_status' not in single:     # a rung's own: eq. 22 as SPEC, unchecked
            single = checked_rigidity(model, single)
        assert single.rigidity_status is not RigidityStatus.FAILED, single.message
        assert out.success[d, p] == single.success
        assert out.rigidity_status[d, p] == single.rigidity_status
        assert out.iterations[d, p] == single.iterations
        assert abs(out.direct_stiffness[d, p] - single.direct_stiffness) \
            <= RTOL * abs(single.direct_stiffness)
        for field in ('value', 'force', 'lever'):
            got, want = getattr(out, field)[d, p], getattr(single, field)
            assert abs(got - want) <= RTOL * abs(want), (field, d, p)
        got = out.result(d, p)
        assert got.success == single.success and got.message == single.message
        assert got.axis == axis and got.rigidity_status == single.rigidity_status
        assert got.iterations == single.iterations
        for field in ('value', 'force', 'lever', 'displacement'):
            assert abs(getattr(got, field) - getattr(single, field)) \
                <= RTOL * abs(getattr(single, field)), field
        for part in ('unloaded', 'loaded'):
            _assert_same_result(getattr(got, part), getattr(single, part))
        # The model of the unloaded scene (single rigidity results carry no label).
        assert out.models[d, p] == _chosen_label(finger_model(design, settings), pressure)


def _chosen_label(model, pressure):
    """Label of the model a single unloaded solve takes: the choice, or the fixed CCM."""
    if isinstance(model, CCMSolver):
        return f'ccm N={model.n_segments}'
    choice = model.choose(pressure, (0.0, 0.0))
    return rung_label(choice.rung, choice.n_segments)


def test_rigidity_result_is_labelled_with_its_model(designs):
    # AdaptiveSolver.rigidity's results carry no `model_choice`: `model_label` must name
    # them by their solver's rung (it once called every such result 'ccm N=<n>').
    settings = ModelSettings()
    out = rigidity_grid(designs[1], [0.0], 'x', 0.010, settings)
    single = finger_model(designs[1], settings).rigidity(0.0, 'x', 0.010)
    assert out.models[0, 0] == 'pcc N=22'
    assert model_label(single.unloaded) == out.models[0, 0]
    assert model_label(out.result(0, 0).unloaded) == out.models[0, 0]


def test_spec_rigidity_through_the_batch():
    # SPEC "Reference values" (as in test_reference.py): K_x of the paper finger at
    # prestrain 0.25, CCM8, delta = 10 mm along +X, to 0.1 %.
    out = rigidity_grid(ActuatorDesign.paper(0.25), [0.0, 55.2e3], 'x', 0.010,
                        ModelSettings(tolerance=0.0))
    assert out.success.all()
    assert out.value[0, 0] == pytest.approx(1.636e-3, rel=1e-3)
    assert out.force[0, 0] == pytest.approx(0.2591, rel=1e-3)
    assert out.lever[0, 0] == pytest.approx(57.43e-3, rel=1e-3)
    assert out.value[0, 1] == pytest.approx(1.396e-3, rel=1e-3)
    # Eq. (22) from the batch's own force and lever.
    assert out.value[0, 0] == pytest.approx(
        out.force[0, 0] * out.lever[0, 0] ** 3 / (3 * 0.010), rel=1e-12)


# -- bad input ----------------------------------------------------------------------------
@pytest.mark.parametrize('call, exc, match', [
    (lambda d: solve_grid(d, [-1.0]), ValueError, '`pressures`'),
    (lambda d: solve_grid(d, [0.0, float('nan')]), ValueError, '`pressures`'),
    (lambda d: solve_grid(d, [float('inf')]), ValueError, '`pressures`'),
    (lambda d: solve_grid(d, []), ValueError, '`pressures`'),
    (lambda d: solve_grid(d, [0.0], [(0.1, float('nan'))]), ValueError, '`tip_forces`'),
    (lambda d: solve_grid(d, [0.0], [(float('inf'), 0.0)]), ValueError, '`tip_forces`'),
    (lambda d: solve_grid(d, [0.0], [(0.1, 0.2, 0.3)]), ValueError, '`tip_forces`'),
    (lambda d: solve_grid([], [0.0]), ValueError, '`designs`'),
    (lambda d: solve_grid([d, 'paper'], [0.0]), TypeError, r'`designs\[1\]`'),
    (lambda d: solve_grid(d, [0.0], settings=0.0), TypeError, '`settings`'),
    (lambda d: rigidity_grid(d, [-5.0]), ValueError, '`pressures`'),
    (lambda d: rigidity_grid(d, [float('nan')]), ValueError, '`pressures`'),
    (lambda d: rigidity_grid([], [0.0]), ValueError, '`designs`'),
    (lambda d: rigidity_grid([{'Lx': 0.1}], [0.0]), TypeError, r'`designs\[0\]`'),
    (lambda d: rigidity_grid(d, [0.0], axis='y'), ValueError, '`axis`'),
    (lambda d: rigidity_grid(d, [0.0], displacement=0.0), ValueError, '`displacement`'),
    (lambda d: rigidity_grid(d, [0.0], displacement=-0.01), ValueError, '`displacement`'),
    (lambda d: rigidity_grid(d, [0.0], displacement=float('nan')), ValueError,
     '`displacement`'),
    (lambda d: rigidity_grid(d, [0.0], settings='paper'), TypeError, '`settings`'),
])
def test_grid_bad_input_names_the_argument(call, exc, match):
    with pytest.raises(exc, match=match):
        call(ActuatorDesign.paper(0.25))


# -- the engine's batches ---------------------------------------------------------------------
def _engine(solvers):
    """What each solver hands the engine (an object without one: itself)."""
    return [getattr(solver, 'engine_problem', solver) for solver in solvers]


def _problems():
    """CCM8 of two designs, paper and consistent: one type, size and options."""
    return [CCMSolver(ActuatorDesign.paper(0.15), 8, max_iterations=8),
            CCMSolver(ActuatorDesign.paper(0.40), 8, max_iterations=8,
                      reconstruction='consistent'),
            CCMSolver(ActuatorDesign.paper(0.25), 8, max_iterations=8)]


def _check_batch_scenes(problems, design, pressures, forces, tip):
    """engine.solve_batch against engine.solve, scene by scene; return the statuses."""
    nodes = [tip] if forces is not None else []
    batch_forces = (np.asarray(forces, dtype=float).reshape(len(design), 1, 2)
                    if forces is not None else np.zeros((len(design), 0, 2)))
    out = engine.solve_batch(_engine(problems), design, pressures, nodes, batch_forces,
                             problems[0]._options, level=engine.ALL)
    statuses = []
    for i, (d, pressure) in enumerate(zip(design, pressures)):
        problem = problems[d]
        loads = [(tip, np.array(forces[i], dtype=float))] if forces is not None else []
        single = engine.solve(problem.engine_problem, pressure, loads, problem._options)
        assert out.status[i] == int(single.status), i
        assert out.iterations[i] == single.iterations, i
        assert out.fraction[i] == single.fraction, i          # a dyadic fraction
        assert deviation(out.states[i], single.x) <= RTOL, i
        tip_position = problem.node_jacobian(single.x, tip)[0]
        assert deviation(out.tips[i], tip_position) <= RTOL, i
        for field in ('gradient', 'step', 'min_eig'):
            got, want = getattr(out, field)[i], getattr(single, field)
            assert (np.isnan(got) and np.isnan(want)) or abs(got - want) <= RTOL * max(
                abs(want), 1e-300), (field, i)
        for field in ('energy', 'curvature', 'fit_rmsd'):
            got, want = getattr(out, field)[i], getattr(single.fields, field)
            assert abs(got - want) <= RTOL * abs(want) + 1e-18, (field, i)
        statuses.append(single.status)
    return statuses


def test_solve_batch_equals_single_solves_through_continuation_and_failure():
    # max_iterations = 8: 30 N of compression needs continuation, 1000 N stalls it.
    problems = _problems()
    design = [0, 1, 2, 0, 2, 1, 0, 0]
    pressures = [0.0, 200e3, 100e3, 300e3, 0.0, 0.0, 0.0, 0.0]
    forces = [(0.3, -0.2), (0.0, 0.0), (-0.1, 0.1), (0.0, -0.2), (-30.0, 0.0),
              (1000.0, 0.0), (-30.0, 0.0), (0.0, 0.0)]
    statuses = _check_batch_scenes(problems, design, pressures, forces, 8)
    assert SolverStatus.CONTINUATION_FAILED in statuses
    assert statuses.count(SolverStatus.SUCCESS) == len(statuses) - 1
    # The continuation scenes: Newton from flat alone fails there.
    cold = engine.newton(problems[0].engine_problem, problems[0].flat(), 0.0,
                         [(8, np.array([-30.0, 0.0]))], problems[0]._options)
    assert cold.status is SolverStatus.MAX_ITERATIONS
    # Unloaded scenes take the block-Hessian discretisation.
    _check_batch_scenes(problems, [2, 1, 0], [0.0, 150e3, 300e3], None, 8)


def test_pcc_solve_batch_equals_single_solves():
    problems = [PCCSolver(ActuatorDesign.paper(prestrain), 22) for prestrain in (0.25, 0.40)]
    # (0, 30) N on the 0.40 finger needs continuation; 1000 N stalls it.
    design = [0, 1, 1, 0, 1]
    pressures = [100e3, 0.0, 0.0, 300e3, 200e3]
    forces = [(0.3, -0.2), (0.0, 30.0), (1000.0, 0.0), (-0.1, 0.1), (0.0, 0.0)]
    statuses = _check_batch_scenes(problems, design, pressures, forces, 22)
    assert statuses[2] is SolverStatus.CONTINUATION_FAILED
    assert statuses.count(SolverStatus.SUCCESS) == 4


@pytest.mark.parametrize('axis', ['x', 'z'])
def test_rigidity_batch_equals_single_rigidity(axis):
    problems = _problems()
    direction = {'x': np.array([1.0, 0.0]), 'z': np.array([0.0, 1.0])}[axis]
    design = [2, 0, 1, 2]
    pressures = [0.0, 100e3, 200e3, 55.2e3]
    out = engine.rigidity_batch(_engine(problems), design, pressures, 8, direction, 0.010,
                                problems[0]._options)
    for i, (d, pressure) in enumerate(zip(design, pressures)):
        problem = problems[d]
        free = engine.solve(problem.engine_problem, pressure, [], problem._options)
        single = engine.rigidity(problem.engine_problem, pressure, 8, direction, 0.010,
                                 problem._options)
        assert single.unloaded.iterations == free.iterations
        assert out.unloaded.status[i] == int(free.status)
        assert out.unloaded.iterations[i] == free.iterations
        assert deviation(out.unloaded.states[i], free.x) <= RTOL
        assert single.success and np.isfinite(out.force[i])
        assert abs(out.force[i] - single.force) <= RTOL * abs(single.force)
        assert out.iterations[i] == single.iterations
        assert out.stable[i] == single.stable and out.fraction[i] == single.fraction
        assert deviation(out.states[i], single.x) <= RTOL
        assert deviation(out.tips[i], problem.node_jacobian(single.x, 8)[0]) <= RTOL


@pytest.mark.parametrize('design, pressures, match', [
    ([0, 3], [0.0, 0.0], '`design`'),
    ([0, -1], [0.0, 0.0], '`design`'),
    ([0, 1], [0.0], '`design` and `pressures`'),
    ([[0, 1]], [[0.0, 0.0]], '`design` and `pressures`'),
])
def test_engine_batches_reject_bad_indices(design, pressures, match):
    problems = _problems()[:2]
    forces = np.zeros((len(np.ravel(pressures)), 1, 2))
    with pytest.raises(ValueError, match=match):
        engine.solve_batch(_engine(problems), design, pressures, [8], forces,
                           problems[0]._options)
    with pytest.raises(ValueError, match=match):
        engine.rigidity_batch(_engine(problems), design, pressures, 8, [1.0, 0.0], 0.01,
                              problems[0]._options)


class _NotCompiled:
    """A discretisation that runs interpreted: the engine can run it, a batch cannot."""

    def __init__(self, solver):
        self.gradient_scale = solver.gradient_scale
        self.flat = solver.flat


@pytest.mark.parametrize('make, exc, match', [
    (lambda d: [CCMSolver(d, 8), CCMSolver(d, 6)], ValueError, '`problems` must share'),
    (lambda d: [CCMSolver(d, 22), PCCSolver(d, 22)], ValueError, '`problems` must share'),
    # A narrower channel: another gradient scale, so other packed options.
    (lambda d: [CCMSolver(d, 8), CCMSolver(d.replace(Cy=0.024), 8)], ValueError, 'options'),
    (lambda d: [CCMSolver(d, 8), _NotCompiled(CCMSolver(d, 8))], TypeError, 'CompiledProblem'),
    (lambda d: [], TypeError, 'CompiledProblem'),
])
def test_engine_batches_reject_mixed_problems(make, exc, match):
    problems = make(ActuatorDesign.paper(0.25))
    options = problems[0]._options if problems else CCMSolver(
        ActuatorDesign.paper(0.25), 8)._options
    design = [0, len(problems) - 1] if problems else []
    pressures = [0.0] * len(design)
    with pytest.raises(exc, match=match):
        engine.solve_batch(_engine(problems), design, pressures, [],
                           np.zeros((len(design), 0, 2)), options)
    with pytest.raises(exc, match=match):
        engine.rigidity_batch(_engine(problems), design, pressures, 8, [1.0, 0.0], 0.01,
                              options)


@pytest.mark.parametrize('rung, n, label', [
    ('ccm', 8, 'ccm N=8'), ('ccm_consistent', 8, 'ccm_consistent N=8'),
    ('ccm_aligned', 22, 'ccm_aligned N=22'), ('pcc', 22, 'pcc N=22'), ('arc', 1, 'arc'),
])
def test_model_label_names_the_rung_of_an_unlabelled_result(rung, n, label):
    result = finger_model(ActuatorDesign.paper(0.25),
                          ModelSettings(rung=rung, n_segments=n)).solve(50e3)
    assert result.model_choice is None
    assert model_label(result) == label
