"""The engine's one loop, compiled and interpreted: same answers, real kernels, honest cache."""

import copy
import importlib
import pathlib
import re

from helpers import deviation, fd_derivative
import numba
import numpy as np
import pytest

from fpc_gripper.model import ActuatorDesign, CCMSolver, compiled, engine
from fpc_gripper.model.discretisations.pcc import PCCSolver
from fpc_gripper.model.engine import SolverStatus
from fpc_gripper.model.kernels import chain, linear

#: Compiled against interpreted: the same loop over the same kernels. The Newton steps
#: come out bitwise equal or nearly (seen <= 3e-14 on a failed continuation's last
#: iterate, <= 6e-15 on a rigidity, where the interpreted CCM solves by LU and the
#: compiled one by Cholesky).
RTOL = 1e-12
#: Warm against cold: both converged to xtol = 1e-9 (scaled units) of the one equilibrium.
WARM_RTOL = 1e-9
MODEL = pathlib.Path(engine.__file__).resolve().parents[1]


class Interpreted:
    """
    A discretisation that is not a `CompiledProblem`: the engine runs its loops in Python.

    Every hook forwards to the wrapped solver's methods, so the physics is the solver's
    and only the loop's execution differs.
    """

    def __init__(self, solver):
        self._solver = solver
        self.gradient_scale = solver.gradient_scale
        self.calls = 0

    def flat(self):
        return self._solver.flat()

    def derivatives(self, x, pressure, loads):
        self.calls += 1
        return self._solver.derivatives(x, pressure, loads)

    def energy(self, x, pressure, loads):
        return self._solver.energy(x, pressure, loads)

    def step(self, grad, hess):
        return self._solver.step(grad, hess)

    def solve_linear(self, hess, rhs):
        return self._solver.solve_linear(hess, rhs)

    def node_jacobian(self, x, node):
        return self._solver.node_jacobian(x, node)


def _tip(solver):
    return solver.n_segments


def _loads(solver, force):
    return [(_tip(solver), np.array(force, dtype=float))] if any(force) else []


def _cold_newton_fails(solver, pressure, loads):
    out = engine.newton(solver.engine_problem, solver.flat(), pressure, loads, solver._options)
    return out.status not in (SolverStatus.SUCCESS, SolverStatus.UNSTABLE)


# (solver, pressure [Pa], tip force [N], what the solve must go through). 'continuation':
# Newton from flat fails and the marched loading succeeds; 'failed': it stalls part way.
CCM_SCENES = {
    'unloaded': (lambda: CCMSolver(ActuatorDesign.paper(0.25), 8), 150e3, (0.0, 0.0),
                 'newton'),
    'loaded': (lambda: CCMSolver(ActuatorDesign.paper(0.25), 8), 100e3, (0.3, -0.2),
               'newton'),
    'consistent': (lambda: CCMSolver(ActuatorDesign.paper(0.40), 8,
                                     reconstruction='consistent'), 200e3, (-0.1, 0.1),
                   'newton'),
    'continuation': (lambda: CCMSolver(ActuatorDesign.paper(0.15), 8, max_iterations=8),
                     0.0, (-30.0, 0.0), 'continuation'),
    'failed': (lambda: CCMSolver(ActuatorDesign.paper(0.15), 8, max_iterations=6), 0.0,
               (-1000.0, 0.0), 'failed'),
}
PCC_SCENES = {
    'unloaded': (lambda: PCCSolver(ActuatorDesign.paper(0.40), 22), 150e3, (0.0, 0.0),
                 'newton'),
    'loaded': (lambda: PCCSolver(ActuatorDesign.paper(0.40), 22), 100e3, (0.3, -0.2),
               'newton'),
    # 20 N of compression buckles the finger: Newton meets indefinite Hessians.
    'buckling': (lambda: PCCSolver(ActuatorDesign.paper(0.15), 64), 200e3, (-20.0, 0.0),
                 'newton'),
    'continuation': (lambda: PCCSolver(ActuatorDesign.paper(0.40), 22), 0.0, (0.0, 30.0),
                     'continuation'),
    'failed': (lambda: PCCSolver(ActuatorDesign.paper(0.40), 22), 0.0, (1000.0, 0.0),
               'failed'),
}
SCENES = {**{f'ccm-{k}': v for k, v in CCM_SCENES.items()},
          **{f'pcc-{k}': v for k, v in PCC_SCENES.items()}}


@pytest.mark.parametrize('name', sorted(SCENES))
def test_compiled_and_interpreted_loops_agree(name):
    make, pressure, force, path = SCENES[name]
    solver = make()
    loads = _loads(solver, force)
    python = Interpreted(solver)
    compiled = engine.solve(solver.engine_problem, pressure, loads, solver._options)
    interpreted = engine.solve(python, pressure, loads, solver._options)
    assert python.calls > 0                        # the wrapper really ran the loop
    # The scene goes where it was picked to go.
    if path == 'newton':
        assert compiled.status is SolverStatus.SUCCESS and not _cold_newton_fails(
            solver, pressure, loads)
    elif path == 'continuation':
        assert _cold_newton_fails(solver, pressure, loads)
        assert compiled.status is SolverStatus.SUCCESS
        assert compiled.iterations > solver._options.max_iterations
    else:
        assert compiled.status is SolverStatus.CONTINUATION_FAILED
        assert 0.0 < compiled.fraction < 1.0
    assert interpreted.status is compiled.status
    assert interpreted.iterations == compiled.iterations
    assert interpreted.fraction == compiled.fraction    # a dyadic fraction of the loading
    assert deviation(interpreted.x, compiled.x) <= RTOL
    tip_c = solver.node_jacobian(compiled.x, _tip(solver))[0]
    tip_i = solver.node_jacobian(interpreted.x, _tip(solver))[0]
    assert deviation(tip_i, tip_c) <= RTOL


@pytest.mark.parametrize('axis', ['x', 'z'])
@pytest.mark.parametrize('make', [
    lambda: CCMSolver(ActuatorDesign.paper(0.25), 8),
    lambda: CCMSolver(ActuatorDesign.paper(0.25), 8, reconstruction='consistent'),
    lambda: PCCSolver(ActuatorDesign.paper(0.25), 22),
], ids=['ccm', 'ccm_consistent', 'pcc'])
def test_compiled_and_interpreted_rigidity_agree(make, axis):
    solver = make()
    direction = {'x': np.array([1.0, 0.0]), 'z': np.array([0.0, 1.0])}[axis]
    free = engine.solve(solver.engine_problem, 30e3, [], solver._options)
    assert free.status is SolverStatus.SUCCESS
    python = Interpreted(solver)
    compiled = engine.rigidity(solver.engine_problem, 30e3, _tip(solver), direction, 0.010,
                               solver._options, initial=free.x)
    interpreted = engine.rigidity(python, 30e3, _tip(solver), direction, 0.010,
                                  solver._options, initial=free.x)
    assert python.calls > 0
    assert interpreted.unloaded.iterations == compiled.unloaded.iterations
    assert deviation(interpreted.unloaded.x, compiled.unloaded.x) <= RTOL
    assert compiled.success and interpreted.success
    assert interpreted.iterations == compiled.iterations
    assert interpreted.stable == compiled.stable
    assert abs(interpreted.force - compiled.force) <= RTOL * abs(compiled.force)
    assert deviation(interpreted.x, compiled.x) <= RTOL
    # Both met the displacement, measured independently of either loop.
    j = 0 if axis == 'x' else 1
    for out in (compiled, interpreted):
        moved = solver.node_jacobian(out.x, _tip(solver))[0][j] - \
            solver.node_jacobian(out.unloaded.x, _tip(solver))[0][j]
        assert abs(moved - 0.010) <= 1e-9 * 0.010


def test_a_compiled_problem_never_calls_back_into_its_solver():
    # The compiled path never calls the solver's Python hooks: make them fail.
    solver = CCMSolver(ActuatorDesign.paper(0.25), 8)
    problem = solver.engine_problem
    loads = _loads(solver, (0.2, 0.1))
    reference = engine.solve(problem, 80e3, loads, solver._options)
    rates = np.ones((2,) + reference.x.shape)
    before = engine.sensitivity(problem, reference.x, 80e3, loads, rates)[0]

    def broken(*args):
        raise AssertionError('the Python hook was called')
    for name in ('derivatives', 'energy', 'step', 'solve_linear', 'node_jacobian', 'flat'):
        setattr(solver, name, broken)
    assert not any(value is solver for value in vars(problem).values())
    again = engine.solve(problem, 80e3, loads, solver._options)
    assert again.iterations == reference.iterations
    assert deviation(again.x, reference.x) <= RTOL
    after = engine.sensitivity(problem, reference.x, 80e3, loads, rates)[0]
    assert deviation(after, before) <= RTOL
    free = engine.solve(problem, 80e3, [], solver._options)
    assert engine.rigidity(problem, 80e3, 8, np.array([1.0, 0.0]), 0.01, solver._options,
                           initial=free.x).success
    with pytest.raises(AssertionError, match='Python hook'):
        engine.solve(Interpreted(solver), 80e3, [], solver._options)
    assert not numba.config.DISABLE_JIT


def _hook_arguments(solver, data, loaded):
    """(x, pressure, nodes, forces) of a converged loaded or unloaded state of `solver`."""
    force = (0.3, -0.2) if loaded else (0.0, 0.0)
    loads = _loads(solver, force)
    out = engine.solve(solver.engine_problem, 100e3, loads, solver._options)
    assert out.status is SolverStatus.SUCCESS
    nodes, forces = chain.load_arrays(loads)
    x = out.x + 0.01                      # off the equilibrium: a gradient worth solving
    return x, 100e3, nodes, forces


@pytest.mark.parametrize('kind, loaded', [('CCMData', False), ('CCMData', True),
                                          ('PCCData', False)])
def test_every_hook_is_a_compiled_kernel(kind, loaded):
    design = ActuatorDesign.paper(0.25)
    solver = PCCSolver(design, 22) if kind == 'PCCData' else CCMSolver(design, 8)
    data = solver.engine_problem.data[loaded]
    assert type(data).__name__ == kind
    hooks = engine.hooks_of(type(data))
    base = ['derivatives', 'energy', 'node_jacobian', 'outputs', 'solve_linear', 'step']
    # The PCC has face points too (contact): docs/physics.md, section 15.2.
    points = ['point_derivatives', 'point_jacobian', 'point_positions']
    assert sorted(hooks) == sorted(base + (points if kind == 'PCCData' else []))
    x, pressure, nodes, forces = _hook_arguments(solver, data, loaded)
    energy, grad, hess = hooks['derivatives'](data, x, pressure, nodes, forces)
    # The line search compares this energy with the derivatives' one: the same formula.
    assert hooks['energy'](data, x, pressure, nodes, forces) == energy
    if kind == 'CCMData' and not loaded:
        assert data.dense is False and hess[0].shape == (8, 4, 4)
        dense = np.zeros((grad.size, grad.size))
        for i, block in enumerate(hess[0]):
            dense[4 * i:4 * i + 4, 4 * i:4 * i + 4] = block
    elif kind == 'CCMData':
        assert data.dense is True and hess[0].shape == (1, 32, 32)
        dense = hess[0][0]
    else:
        dense = linear._dense_from_band(hess[0])
    assert np.linalg.eigvalsh(dense).min() > 0.0          # the Cholesky paths
    step, min_eig = hooks['step'](data, grad, hess)
    assert min_eig == 1.0
    np.testing.assert_allclose(step.ravel(), np.linalg.solve(dense, -grad.ravel()),
                               rtol=1e-9, atol=1e-9 * np.abs(step).max())
    rhs = np.random.default_rng(0).normal(size=grad.shape)
    solution, ok = hooks['solve_linear'](data, hess, rhs)
    assert ok
    np.testing.assert_allclose(solution.ravel(), np.linalg.solve(dense, rhs.ravel()),
                               rtol=1e-9, atol=1e-9 * np.abs(solution).max())
    position, jacobian = hooks['node_jacobian'](data, x, _tip(solver))
    assert deviation(position, solver.node_jacobian(x, _tip(solver))[0]) <= RTOL
    assert jacobian.shape == (2,) + x.shape
    # The outputs: the chain ends at the node Jacobian's tip, the samples at the tip, and
    # the energy is the energy hook's; without samples, no sample rows.
    chain_nodes, beta, theta, _, valid, out_energy, points, tangent, _ = hooks['outputs'](
        data, x, pressure, nodes, forces, True)
    np.testing.assert_allclose(theta, np.concatenate([[0.0], np.cumsum(beta)[:-1]]), atol=1e-14)
    assert deviation(chain_nodes[-1], position) <= RTOL and np.all(chain_nodes[0] == 0.0)
    assert deviation(points[-1], position) <= RTOL and points.shape[0] == tangent.size > 2
    assert out_energy == pytest.approx(energy, rel=1e-12) and valid
    assert beta.size == chain_nodes.shape[0] - 1
    assert hooks['outputs'](data, x, pressure, nodes, forces, False)[6].shape == (0, 2)
    if kind == 'PCCData':
        # Face points: the compiled hooks against the solver's methods (the same kernels).
        seg, off = np.array([3, 21]), np.array([0.5, 1.0]) * solver.lengths[[3, 21]]
        z, push = np.array([-0.5, 0.5]) * design.H, np.array([[0.1, -0.2], [0.0, 0.3]])
        positions = hooks['point_positions'](data, x, seg, off, z)
        assert deviation(positions, solver.point_positions(x, seg, off, z)) <= RTOL
        point, jac = hooks['point_jacobian'](data, x, seg[1], off[1], z[1])
        assert deviation(point, positions[1]) <= RTOL
        assert deviation(jac, solver.point_jacobian(x, seg[1], off[1], z[1])[1]) <= RTOL
        got = hooks['point_derivatives'](data, x, pressure, nodes, forces, seg, off, z, push)
        # The module, not `engine.newton` (the function of that name).
        hooks_module = importlib.import_module('fpc_gripper.model.engine.newton')
        loads = hooks_module._loads(nodes, forces)
        want = solver.point_derivatives(x, pressure, loads, seg, off, z, push)
        assert got[0] == pytest.approx(want[0], rel=1e-12)
        assert deviation(got[1], want[1]) <= RTOL
    for name, hook in hooks.items():
        assert isinstance(hook, numba.core.registry.CPUDispatcher), name
        assert hook.signatures and hook.targetoptions['nopython'], name
    # The engine's entries compiled for this namedtuple type.
    engine.solve(solver.engine_problem, 50e3, _loads(solver, (0.1, 0.0) if loaded else (0.0, 0.0)),
                 solver._options)
    signatures = engine.solves._solve_entry.signatures
    types = {getattr(sig[0].item_type, 'instance_class', None) for sig in signatures}
    assert type(data) in types


# -- the consistent CCM with point loads: dense compiled Hessian against differences ----
def _consistent_solver():
    return CCMSolver(ActuatorDesign.paper(0.3), n_segments=6, reconstruction='consistent',
                     load_points=(0.05,))


@pytest.mark.parametrize('tip, point', [((0.0, 0.0), None), ((0.7, -1.3), None),
                                        ((0.7, -1.3), (0.05, -0.4, 0.9))],
                         ids=['unloaded', 'tip', 'tip-and-point'])
def test_consistent_derivatives_match_finite_differences(tip, point):
    # test_ladder checks the consistent CCM's dense Hessian with a tip load on uniform
    # segments; here the unloaded blocks and an intermediate point load too, through
    # CCMSolver.derivatives (the compiled hooks), against fourth-order differences.
    solver = _consistent_solver()
    loads = solver._loads(tip, [point] if point else [])
    n = solver.n_segments
    x = np.random.default_rng(11).normal(scale=0.15, size=4 * n)

    def energy(v):
        return np.array(solver.energy(v.reshape(n, 4), 150e3, loads))

    def gradient(v):
        return solver.derivatives(v.reshape(n, 4), 150e3, loads)[1].ravel()

    _, grad, hess = solver.derivatives(x.reshape(n, 4), 150e3, loads)
    if not loads:
        assert hess.shape == (n, 4, 4)
        blocks, hess = hess, np.zeros((4 * n, 4 * n))
        for i in range(n):
            hess[4 * i:4 * i + 4, 4 * i:4 * i + 4] = blocks[i]
    else:
        assert hess.shape == (4 * n, 4 * n)
    g_fd = fd_derivative(energy, x, 1e-4)
    h_fd = fd_derivative(gradient, x, 1e-4)
    assert deviation(grad.ravel(), g_fd) <= 1e-8
    assert deviation(hess, h_fd) <= 1e-8
    assert deviation(hess, hess.T) <= 1e-13
    if not loads:
        return
    # The loads' part on its own scale: beside the segments' stiffness (1e4 times
    # larger here) an error in it would hide in the totals' tolerance.
    _, free_grad, free_blocks = solver.derivatives(x.reshape(n, 4), 150e3, [])
    free_hess = np.zeros_like(hess)
    for i in range(n):
        free_hess[4 * i:4 * i + 4, 4 * i:4 * i + 4] = free_blocks[i]

    def load_energy(v):
        return energy(v) - solver.energy(v.reshape(n, 4), 150e3, [])

    def load_gradient(v):
        return gradient(v) - solver.derivatives(v.reshape(n, 4), 150e3, [])[1].ravel()

    assert deviation((grad - free_grad).ravel(), fd_derivative(load_energy, x, 1e-4)) <= 1e-8
    assert deviation(hess - free_hess, fd_derivative(load_gradient, x, 1e-4)) <= 1e-8


def test_dense_hook_factor_is_the_cholesky_factor_of_its_hessian():
    # The compiled loop steps and solves with the factor the dense hook returns; the
    # Python hooks never see it. It must factor H where H is definite, and say so.
    solver = _consistent_solver()
    data = solver.engine_problem.data[True]
    n = solver.n_segments
    rng = np.random.default_rng(5)
    seen = set()
    for force, scale in (((0.3, -0.2), 0.05), ((-40.0, 0.0), 0.05), ((0.5, 0.5), 0.4)):
        nodes, forces = chain.load_arrays(solver._loads(force, []))
        for _ in range(3):
            q = rng.normal(scale=scale, size=(n, 4))
            _, _, (matrix, low, definite) = engine.hooks_of(type(data))['derivatives'](
                data, q, 50e3, nodes, forces)
            matrix = matrix[0]                                  # (1, 4N, 4N): the one matrix
            lam = np.linalg.eigvalsh(matrix)
            assert definite == (lam.min() > 0.0)
            seen.add(bool(definite))
            if definite:
                assert np.all(np.triu(low, 1) == 0.0)      # lower triangular: exact zeros
                assert deviation(low @ low.T, matrix) <= 1e-13
    assert seen == {True, False}


# -- the disk cache and warm starts ---------------------------------------------------------
ENTRIES = ('_solve_entry', '_rigidity_entry', '_contact_entry')


@pytest.mark.parametrize('entry', ENTRIES)
def test_cache_stamp_covers_every_compiled_source(entry):
    # Each entry inlines kernels of other modules: its stamp is all of their content.
    dispatcher = getattr(engine.solves, entry)
    assert dispatcher._cache._cache_file._source_stamp == compiled.sources_stamp(MODEL)
    assert isinstance(dispatcher._cache, compiled._Cache)


def test_the_stamp_follows_content_not_mtimes(tmp_path):
    # A copy into an install (new mtimes) keeps the stamp; an edit of any kernel source,
    # even one byte of a comment, changes it.
    copy_dir = tmp_path / 'model'
    copy_dir.mkdir()
    for path in MODEL.rglob('*.py'):
        target = copy_dir / path.relative_to(MODEL)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(path.read_bytes())
    assert compiled.sources_stamp(copy_dir) == compiled.sources_stamp(MODEL)
    # Python around the compiled calls (the build's driver, the default model's choice,
    # the batches' bookkeeping) is not stamped: an edit there keeps the build.
    for name in ('build.py', 'selection.py', 'batch.py', 'pipeline.py'):
        source = copy_dir / name
        source.write_bytes(source.read_bytes() + b'# edited\n')
        assert compiled.sources_stamp(copy_dir) == compiled.sources_stamp(MODEL), name
    # Each place compiled code comes from is: one byte of a comment changes the stamp.
    for name in ('compiled.py', 'kernels/pcc.py', 'engine/newton.py', 'discretisations/ccm.py'):
        source = copy_dir / name
        before = compiled.sources_stamp(copy_dir)
        source.write_bytes(source.read_bytes() + b'# edited\n')
        assert compiled.sources_stamp(copy_dir) != before, name


def test_only_stamped_sources_hold_compiled_code():
    # A jitted function outside COMPILED_FROM would go stale unnoticed: the text of every
    # other model source is searched for numba's decorators.
    marks = re.compile(r'^\s*@(\w+\.)*(jit|_jit|njit|register_jitable|overload\w*|jitclass)\b',
                       re.MULTILINE)
    outside = [path.relative_to(MODEL).as_posix() for path in sorted(MODEL.rglob('*.py'))
               if path.relative_to(MODEL).parts[0] not in compiled.COMPILED_FROM
               and marks.search(path.read_text())]
    assert outside == []
    inside = [path for path in (MODEL / 'kernels').glob('*.py') if marks.search(path.read_text())]
    assert len(inside) >= 8                      # the search itself finds the kernels' marks


def test_cache_index_goes_stale_when_a_kernel_source_changes():
    # numba compares the stamp stored in the index with the dispatcher's: the build's
    # entries load, and an index read under another stamp (an edited source) is empty.
    solver = CCMSolver(ActuatorDesign.paper(0.25), 8)
    engine.solve(solver.engine_problem, 10e3, [], solver._options)
    cache_file = engine.solves._solve_entry._cache._cache_file
    assert cache_file._load_index()                       # built: entries found
    stale = copy.copy(cache_file)
    stale._source_stamp = compiled.sources_stamp(MODEL) + '-edited'
    assert stale._load_index() == {}


WARM_CASES = {
    'ccm': (lambda: CCMSolver(ActuatorDesign.paper(0.25), 8), 120e3, (0.1, -0.2),
            [(110e3, (0.0, 0.0)), (300e3, (0.5, 0.5)), (0.0, (-2.0, 0.0))]),
    'ccm_consistent': (lambda: CCMSolver(ActuatorDesign.paper(0.40), 8,
                                         reconstruction='consistent'),
                       200e3, (0.0, 0.0), [(190e3, (0.0, 0.0)), (0.0, (0.3, 0.3))]),
    'pcc': (lambda: PCCSolver(ActuatorDesign.paper(0.25), 22), 120e3, (0.1, -0.2),
            [(110e3, (0.0, 0.0)), (300e3, (0.5, 0.5)), (0.0, (-2.0, 0.0))]),
    # A buckled state under 20 N of compression warm-starts the slightly loaded finger.
    'pcc_buckled': (lambda: PCCSolver(ActuatorDesign.paper(0.15), 64), 200e3, (-1.0, 0.0),
                    [(200e3, (-20.0, 0.0)), (0.0, (0.0, 0.0))]),
}


@pytest.mark.parametrize('name', sorted(WARM_CASES))
def test_warm_start_never_changes_the_answer(name):
    make, pressure, force, history = WARM_CASES[name]
    solver = make()
    loads = _loads(solver, force)
    cold = engine.solve(solver.engine_problem, pressure, loads, solver._options)
    assert cold.status is SolverStatus.SUCCESS
    tip = solver.node_jacobian(cold.x, _tip(solver))[0]
    starts = [engine.solve(solver.engine_problem, p, _loads(solver, f), solver._options).x
              for p, f in history]
    spent = set()
    for start in starts:
        warm = engine.solve(solver.engine_problem, pressure, loads, solver._options, initial=start)
        assert warm.status is cold.status
        assert deviation(solver.node_jacobian(warm.x, _tip(solver))[0], tip) <= WARM_RTOL
        spent.add(warm.iterations)
    assert spent - {cold.iterations}             # some start really was used
    # A start Newton cannot converge from: the solve begins again from flat, and spends
    # the warm attempt's iterations on top of the cold ones.
    bad = solver.flat() + 5.0
    attempt = engine.newton(solver.engine_problem, bad, pressure, loads, solver._options)
    assert attempt.status is not SolverStatus.SUCCESS
    fallback = engine.solve(solver.engine_problem, pressure, loads, solver._options, initial=bad)
    assert fallback.status is cold.status
    assert fallback.iterations == attempt.iterations + cold.iterations
    # From flat again: the cold solve's arithmetic (round-off apart, see RTOL).
    assert deviation(fallback.x, cold.x) <= RTOL


def test_register_names_a_missing_or_unknown_hook():
    import collections
    fake = collections.namedtuple('FakeData', ('a',))
    hooks = dict(engine.hooks_of(type(CCMSolver(ActuatorDesign.paper(0.25), 4)
                                      .engine_problem.data[False])))
    del hooks['energy']
    with pytest.raises(ValueError, match=r"FakeData.*missing \['energy'\], unknown \[\]"):
        engine.register(fake, hooks)
    hooks['energy'] = hooks['derivatives']
    hooks['gradient'] = hooks['derivatives']
    with pytest.raises(ValueError, match=r"missing \[\], unknown \['gradient'\]"):
        engine.register(fake, hooks)
    with pytest.raises(KeyError):
        engine.hooks_of(fake)                   # neither attempt registered it


@pytest.mark.parametrize('make', [lambda d: CCMSolver(d, 8), lambda d: PCCSolver(d, 22)],
                         ids=['ccm8', 'pcc22'])
def test_undispatched_solves_equal_dispatched_ones(make):
    # After a frame's first solve, `engine.solve` calls the compiled overload directly:
    # bit-for-bit what numba's dispatcher gives, warm and cold, loaded and unloaded.
    from fpc_gripper.model.engine import solves
    solver = make(ActuatorDesign.paper(0.25))
    problem, options = solver.engine_problem, solver._options
    base = engine.solve(problem, 50e3, [], options)
    tip = solver.n_segments
    scenes = [(60e3, [], base.x), (0.0, [], None), (80e3, [(tip, np.array([0.1, 0.2]))], None),
              (90e3, [(tip, np.array([0.0, 0.3]))], base.x)]
    for pressure, loads, initial in scenes:
        for _ in range(2):
            direct = engine.solve(problem, pressure, loads, options, initial, engine.ALL)
        frame = solves._frame(problem, options, bool(loads))
        assert frame[-1][0], 'no direct entry was resolved'
        start = (np.ascontiguousarray(initial)[None] if initial is not None
                 else frame[5])
        nodes, forces = chain.load_arrays(loads)
        dispatched = solves._scene(solves._solve_entry(
            frame[4], solves._SCENE, np.array([pressure]), nodes, forces[None], start,
            frame[1], frame[2], frame[3], solves.SOLVE, engine.ALL), 0, engine.ALL)
        assert np.array_equal(direct.x, dispatched.x)
        assert direct.iterations == dispatched.iterations
        for mine, theirs in zip(direct.fields, dispatched.fields):
            assert np.array_equal(mine, theirs) if mine is not None else theirs is None


def test_an_initial_state_of_another_shape_is_refused():
    solver = CCMSolver(ActuatorDesign.paper(0.25), 8)
    with pytest.raises(ValueError, match=r'`initial` has shape \(7, 4\)'):
        engine.solve(solver.engine_problem, 1e3, [], solver._options, np.zeros((7, 4)))
