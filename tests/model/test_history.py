"""History independence: after any sequence of scenes, every solver answers as a fresh one."""

import functools
import math
from typing import NamedTuple

from hypothesis import example, given, HealthCheck, note, settings
import hypothesis.strategies as st
import numpy as np
from scipy.optimize import brentq

from fpc_gripper.control.inverse import InverseModel
from fpc_gripper.model import (ActuatorDesign, AdaptiveSolver, ArcSolver, CCMSolver,
                               choose_model, RodSolver, Scene)
from fpc_gripper.model.selection import load_error_model

# SPEC: "Every solver is a pure function of its inputs: a warm start (`initial`) may change
# the iteration count, never the answer, the model chosen or N."
#
# Pattern of every property: a history of scenes is run on ONE object, each solve warm-started
# from the last good (successful) result, as model_core does -- a failed solve does not
# replace the warm start, the next scene starts from the last success (or from flat before
# any); the target is then solved on that object from the last good result and compared with
# the same call on a FRESH object built for this example (initial=None). Nothing is shared
# between examples, so a failure is reproducible and hypothesis never reports it as flaky.

#: Relative agreement of states, coefficients and rigidities.
RTOL = 1e-10
#: Absolute floor in the dimensionless unknowns (strains, rotations in rad, d L, b3 L^2): a
#: rotation error of 1e-12 rad moves a 90 mm tip by 1e-13 m, so this floor is far below the
#: tip tolerance and only matters for entries that are zero to round-off.
STATE_ATOL = 1e-12
#: Tip agreement [m]; converged Newton states agree to round-off, about 1e-16 m here.
TIP_ATOL = 1e-12
#: InverseModel: pressure agreement [Pa], far below its brentq xtol of 1e-3 Pa; rho [m].
PRESSURE_ATOL = 1e-6
RHO_ATOL = 1e-12

#: Pressures [Pa], tip-load components [N] and prestrains of the scenes.
MAX_PRESSURE = 400e3
MAX_LOAD = 1.0
PRESTRAINS = st.floats(0.15, 0.40)
#: InverseModel(palm_radius=0.062, max_pressure=300 kPa) needs a tip radius that increases
#: with pressure up to 300 kPa; the paper's finger has it up to a prestrain of about 0.26.
INVERSE_PRESTRAINS = st.floats(0.15, 0.26)
INVERSE_MAX_PRESSURE = 300e3
PALM_RADIUS = 0.062

SETTINGS = dict(derandomize=True, database=None, deadline=None, print_blob=False,
                suppress_health_check=[HealthCheck.too_slow])

SOLVERS = {
    'ccm_paper': lambda design: CCMSolver(design, n_segments=8),
    'ccm_consistent': lambda design: CCMSolver(design, 8, reconstruction='consistent'),
    'arc': ArcSolver,
    'rod': RodSolver,
    'adaptive_5e-4': lambda design: AdaptiveSolver(design, tolerance=5e-4),
    'adaptive_5e-5': lambda design: AdaptiveSolver(design, tolerance=5e-5),
}


class Load(NamedTuple):
    """One scene of a finger: gauge pressure [Pa] and tip force (f0, p0) [N]."""

    pressure: float
    tip_force: tuple


class Case(NamedTuple):
    """A finger, the scenes solved before, and the scene compared with a fresh solve."""

    prestrain: float
    history: tuple
    target: Load


# -- strategies -----------------------------------------------------------------------------
# Components are often exactly zero: unloaded scenes are the common case on the robot and take
# a different path in AdaptiveSolver (its turning table).
_COMPONENTS = st.one_of(st.just(0.0), st.floats(-MAX_LOAD, MAX_LOAD))


def _clip(value, low, high):
    return float(min(max(value, low), high))


@st.composite
def loads(draw, max_pressure=MAX_PRESSURE):
    """Draw a scene with pressure in [0, max_pressure] and each load component in +-1 N."""
    return Load(draw(st.floats(0.0, max_pressure)), (draw(_COMPONENTS), draw(_COMPONENTS)))


@st.composite
def near(draw, base, max_pressure=MAX_PRESSURE):
    """
    Draw a scene close to `base`: within 20 kPa and 30 mN, often the same load.

    Nodes see slowly changing inputs, and every cache or warm start keyed by a neighbourhood
    (1 kPa / 5 mN arc buckets, 4 kPa / 30 mN linearisations, 20 kPa warm starts) is only
    exercised by scenes that close.
    """
    dp = draw(st.one_of(st.floats(-1e3, 1e3), st.floats(-20e3, 20e3)))
    if draw(st.booleans()):
        force = base.tip_force
    else:
        force = tuple(_clip(f + draw(st.floats(-0.03, 0.03)), -MAX_LOAD, MAX_LOAD)
                      for f in base.tip_force)
    return Load(_clip(base.pressure + dp, 0.0, max_pressure), force)


#: AdaptiveSolver and choose_model bin a scene by the arc rung's turning |kappa L|; the choice
#: jumps where the turning crosses a bin edge, so that is where a cached or interpolated
#: feature can change the model.
TURNING_EDGES = tuple(load_error_model()['turning_bins'][:-1])


def _arc_turning(arc, pressure, force):
    result = arc.solve(pressure, force)
    return abs(float(result.beta[0])) if result.success else math.nan


@functools.lru_cache(maxsize=256)
def choice_boundaries(prestrain, force):
    """
    Return the pressures in [0, 400 kPa] where the model choice can jump at this load [Pa].

    They are where a cold arc solve (what choose_model does) has a turning on a bin edge;
    the arc is the oracle here, not the object under test. Cached: shrinking asks again.
    """
    arc = ArcSolver(ActuatorDesign.paper(prestrain=prestrain))
    grid = np.linspace(0.0, MAX_PRESSURE, 9)
    turning = [_arc_turning(arc, p, force) for p in grid]
    found = []
    for lo, hi, t_lo, t_hi in zip(grid, grid[1:], turning, turning[1:]):
        for edge in TURNING_EDGES:
            if (t_lo - edge) * (t_hi - edge) < 0.0:
                found.append(float(brentq(lambda p: _arc_turning(arc, p, force) - edge,
                                          lo, hi, xtol=1e-7)))
    return tuple(found)


#: Offsets of scenes from a choice boundary [Pa]: within the 1 kPa bucket of the cached arc
#: feature, or within the millipascals where the unloaded turning table is off by its
#: interpolation error (about 3e-8 rad).
_BOUNDARY_OFFSETS = st.one_of(st.floats(-1e3, 1e3), st.floats(-0.01, 0.01))


@st.composite
def cases(draw, max_history=4, prestrains=PRESTRAINS, max_pressure=MAX_PRESSURE,
          boundaries=False):
    """
    Draw a prestrain, a history of 1..max_history scenes and a target scene.

    The target is independent of the history or near one of its scenes; with `boundaries`,
    it can also sit next to a model-choice boundary with one more history scene at the same
    load on the other side (the scenes of a slow pressure ramp).
    """
    prestrain = draw(prestrains)
    history = tuple(draw(st.lists(loads(max_pressure), min_size=1, max_size=max_history)))
    modes = ['independent', 'near'] + (['boundary'] if boundaries else [])
    mode = draw(st.sampled_from(modes))
    if mode == 'boundary':
        force = (draw(_COMPONENTS), draw(_COMPONENTS))
        edges = choice_boundaries(prestrain, force)
        if edges:
            edge = draw(st.sampled_from(edges))
            history += (Load(_clip(edge + draw(_BOUNDARY_OFFSETS), 0.0, max_pressure),
                             force),)
            return Case(prestrain, history,
                        Load(_clip(edge + draw(_BOUNDARY_OFFSETS), 0.0, max_pressure), force))
        mode = 'independent'
    if mode == 'near':
        target = draw(near(draw(st.sampled_from(history)), max_pressure))
    else:
        target = draw(loads(max_pressure))
    return Case(prestrain, history, target)


@st.composite
def single_scenes(draw):
    """Draw a prestrain and one scene (empty history), often next to a choice boundary."""
    case = draw(cases(max_history=1, boundaries=True))
    return Case(case.prestrain, (), case.target)


class Call(NamedTuple):
    """
    One InverseModel call.

    `argument` is a pressure [Pa] or, for pressure_for_rho, the position of the target
    radius in the unloaded range (0 at 0 Pa, 1 at max_pressure).
    """

    method: str
    argument: float
    tip_force: tuple


_METHODS = ('pressure_for_rho', 'rho', 'estimate')


@st.composite
def inverse_calls(draw):
    """Draw one InverseModel call."""
    method = draw(st.sampled_from(_METHODS))
    force = (draw(_COMPONENTS), draw(_COMPONENTS))
    if method == 'pressure_for_rho':
        return Call(method, draw(st.floats(-0.1, 1.1)), force)
    return Call(method, draw(st.floats(0.0, INVERSE_MAX_PRESSURE)), force)


class InverseCase(NamedTuple):
    """A finger, the InverseModel calls made before, and the call compared with a fresh one."""

    prestrain: float
    history: tuple
    target: Call


@st.composite
def inverse_cases(draw, max_history=4):
    """Draw a prestrain, a history of InverseModel calls and a target call, often nearby."""
    prestrain = draw(INVERSE_PRESTRAINS)
    history = tuple(draw(st.lists(inverse_calls(), min_size=1, max_size=max_history)))
    if draw(st.booleans()):
        base = draw(st.sampled_from(history))
        method = draw(st.sampled_from(_METHODS))
        if method == 'pressure_for_rho':
            position = base.argument if base.method == method else 0.5
            argument = _clip(position + draw(st.floats(-0.05, 0.05)), -0.1, 1.1)
        else:
            pressure = base.argument if base.method != 'pressure_for_rho' else 150e3
            argument = _clip(pressure + draw(st.one_of(st.floats(-4e3, 4e3),
                                                       st.floats(-20e3, 20e3))),
                             0.0, INVERSE_MAX_PRESSURE)
        force = base.tip_force
        if draw(st.booleans()):
            force = tuple(_clip(f + draw(st.floats(-0.03, 0.03)), -MAX_LOAD, MAX_LOAD)
                          for f in force)
        target = Call(method, argument, force)
    else:
        target = draw(inverse_calls())
    return InverseCase(prestrain, history, target)


# -- comparison -----------------------------------------------------------------------------
def _state(result):
    """Return the solver's unknowns, dimensionless, as one flat array."""
    state = result.state
    if isinstance(state, tuple):                       # rod: theta [rad], (eps, c1) [-]
        return np.concatenate([np.ravel(part) for part in state])
    if result.rung == 'arc':                           # (eps, kappa, c1): kappa L
        return np.asarray(state) * np.array([1.0, result.segment_edges[-1], 1.0])
    # CCM (b1, b3 L_i^2, c1, d L_i) and PCC (theta_i, eps_i, c1_i): dimensionless
    return np.asarray(state).ravel()


def _describe(result):
    choice = getattr(result, 'model_choice', None)
    model = '' if choice is None else f' {choice.rung} N={choice.n_segments}'
    return (f'{result.model}{model} success={result.success} '
            f'tip={np.asarray(result.tip).tolist()}')


def assert_same_result(got, want):
    """Assert that a result after a history is the fresh result (SPEC: pure function)."""
    note(f'after history: {_describe(got)}')
    note(f'fresh:         {_describe(want)}')
    assert got.success == want.success, \
        f'success {got.success} after the history, {want.success} fresh'
    if not want.success:
        return
    choice, fresh_choice = getattr(got, 'model_choice', None), getattr(want, 'model_choice', None)
    if fresh_choice is not None:
        assert (choice.rung, choice.n_segments) == (fresh_choice.rung, fresh_choice.n_segments), \
            (f'model {choice.rung} N={choice.n_segments} after the history, '
             f'{fresh_choice.rung} N={fresh_choice.n_segments} fresh')
    assert got.rung == want.rung
    tip_gap = float(np.abs(np.asarray(got.tip) - np.asarray(want.tip)).max())
    state, fresh_state = _state(got), _state(want)
    assert state.shape == fresh_state.shape
    np.testing.assert_allclose(state, fresh_state, rtol=RTOL, atol=STATE_ATOL,
                               err_msg=f'state differs (tip differs by {tip_gap:.3e} m)')
    if want.coefficients is not None:
        # Coefficients in SI, made dimensionless per column by the mean segment length.
        n = want.coefficients.shape[0]
        seg = want.segment_edges[-1] / n
        unit = np.array([1.0, seg ** -2, 1.0, seg ** -1])
        np.testing.assert_allclose(got.coefficients / unit, want.coefficients / unit,
                                   rtol=RTOL, atol=STATE_ATOL, err_msg='coefficients differ')
    np.testing.assert_allclose(got.tip, want.tip, rtol=0.0, atol=TIP_ATOL,
                               err_msg=f'tip differs by {tip_gap:.3e} m')


def run_history(solver, history):
    """Solve the scenes in order, warm-starting from the last good result; return it."""
    warm = None
    for scene in history:
        result = solver.solve(scene.pressure, scene.tip_force, initial=warm)
        note(f'history {scene}: {_describe(result)}')
        if result.success:
            warm = result
    return warm


def check_solve_after_history(kind, case):
    """Solve the target after the history on one object, and fresh on another; compare."""
    design = ActuatorDesign.paper(prestrain=case.prestrain)
    solver = SOLVERS[kind](design)
    warm = run_history(solver, case.history)
    target = case.target
    got = solver.solve(target.pressure, target.tip_force, initial=warm)
    want = SOLVERS[kind](design).solve(target.pressure, target.tip_force, initial=None)
    assert_same_result(got, want)


# From the bug report: fresh, AdaptiveSolver(tolerance=0.5 mm) takes the aligned consistent CCM
# with N = 44 at 142.51 kPa and p0 = 0.3 N; right after 143.49 kPa it took N = 32 (both scenes
# fall in the same 1 kPa bucket of the cached arc feature).
REPORTED = Case(0.25, (Load(143490.0, (0.0, 0.3)),), Load(142510.0, (0.0, 0.3)))
# Found by these properties on the code of 5303984 (hypothesis' shrunk examples), kept as
# regressions. 0.5 mm: N = 32 after the first scene, 44 fresh (tips 1.6 um apart).
COARSE_RAMP = Case(0.25, (Load(0.0, (0.0, 0.0)), Load(201714.33530148867, (1.0, 0.0))),
                   Load(201713.33530148867, (1.0, 0.0)))
# 0.05 mm: the aligned CCM with N = 64 after the first scene, the rod fresh (tips 1.9 um apart).
FINE_RAMP = Case(0.25, (Load(0.0, (0.0, 0.0)), Load(126044.07849976404, (0.0, 0.5))),
                 Load(126043.07849976404, (0.0, 0.5)))
# Unloaded, 0.05 mm: the interpolated turning table says bin 1 (N = 32), choose_model's arc
# solve says bin 2 (N = 64); and at 0.40, the table's N = 64 against choose_model's rod.
TABLE_EDGE = Case(0.25, (), Load(169493.28792835987, (0.0, 0.0)))
TABLE_EDGE_ROD = Case(0.4, (), Load(169657.2413, (0.0, 0.0)))


# -- solve after a history ------------------------------------------------------------------
@settings(max_examples=300, **SETTINGS)
@given(case=cases())
def test_ccm_paper_solve_after_history_equals_fresh(case):
    """CCMSolver(d, 8), paper reconstruction: after a history it solves as a fresh one."""
    check_solve_after_history('ccm_paper', case)


@settings(max_examples=300, **SETTINGS)
@given(case=cases())
def test_ccm_consistent_solve_after_history_equals_fresh(case):
    """CCMSolver(d, 8, reconstruction='consistent'): after a history it solves as a fresh one."""
    check_solve_after_history('ccm_consistent', case)


@settings(max_examples=300, **SETTINGS)
@given(case=cases())
def test_arc_solve_after_history_equals_fresh(case):
    """ArcSolver(d): after a history it solves as a fresh one."""
    check_solve_after_history('arc', case)


@settings(max_examples=60, **SETTINGS)
@given(case=cases(max_history=3))
def test_rod_solve_after_history_equals_fresh(case):
    """RodSolver(d), about 10 ms a solve: after a history it solves as a fresh one."""
    check_solve_after_history('rod', case)


@settings(max_examples=60, **SETTINGS)
@given(case=cases(boundaries=True))
@example(case=REPORTED)
@example(case=COARSE_RAMP)
def test_adaptive_coarse_solve_after_history_equals_fresh(case):
    """AdaptiveSolver(d, 0.5 mm): same model, N and state after a history as fresh."""
    check_solve_after_history('adaptive_5e-4', case)


@settings(max_examples=60, **SETTINGS)
@given(case=cases(boundaries=True))
@example(case=FINE_RAMP)
def test_adaptive_fine_solve_after_history_equals_fresh(case):
    """AdaptiveSolver(d, 0.05 mm): same model, N and state after a history as fresh."""
    check_solve_after_history('adaptive_5e-5', case)


# -- idempotence ----------------------------------------------------------------------------
@settings(max_examples=100, **SETTINGS)
@given(kind=st.sampled_from(sorted(SOLVERS)), prestrain=PRESTRAINS, scene=loads())
def test_repeated_solve_is_idempotent(kind, prestrain, scene):
    """The same call on the same object, and a warm start from its own answer, change nothing."""
    solver = SOLVERS[kind](ActuatorDesign.paper(prestrain=prestrain))
    first = solver.solve(scene.pressure, scene.tip_force)
    again = solver.solve(scene.pressure, scene.tip_force)
    assert_same_result(again, first)
    if first.success:
        from_itself = solver.solve(scene.pressure, scene.tip_force, initial=first)
        assert_same_result(from_itself, first)


# -- rigidity -------------------------------------------------------------------------------
@settings(max_examples=100, **SETTINGS)
@given(kind=st.sampled_from(sorted(SOLVERS)), case=cases(max_history=2))
def test_rigidity_with_initial_equals_fresh(kind, case):
    """K_x at the target pressure, warm-started from a history, equals a fresh K_x."""
    design = ActuatorDesign.paper(prestrain=case.prestrain)
    solver = SOLVERS[kind](design)
    warm = run_history(solver, case.history)
    got = solver.rigidity(case.target.pressure, axis='x', initial=warm)
    want = SOLVERS[kind](design).rigidity(case.target.pressure, axis='x', initial=None)
    note(f'after history: {got!r}')
    note(f'fresh:         {want!r}')
    assert got.success == want.success
    if want.success:
        np.testing.assert_allclose([got.value, got.force, got.lever],
                                   [want.value, want.force, want.lever], rtol=RTOL, atol=0.0,
                                   err_msg='(K_x, force, lever) differ')


# -- model choice ---------------------------------------------------------------------------
@settings(max_examples=60, **SETTINGS)
@given(case=cases(boundaries=True), tolerance=st.sampled_from([5e-4, 5e-5]))
@example(case=REPORTED, tolerance=5e-4)
@example(case=COARSE_RAMP, tolerance=5e-4)
@example(case=FINE_RAMP, tolerance=5e-5)
def test_choose_after_history_equals_fresh(case, tolerance):
    """AdaptiveSolver.choose after choosing for other scenes equals a fresh object's choice."""
    design = ActuatorDesign.paper(prestrain=case.prestrain)
    solver = AdaptiveSolver(design, tolerance=tolerance)
    for scene in case.history:
        solver.choose(scene.pressure, scene.tip_force)
    target = case.target
    got = solver.choose(target.pressure, target.tip_force)
    want = AdaptiveSolver(design, tolerance=tolerance).choose(target.pressure, target.tip_force)
    assert (got.rung, got.n_segments) == (want.rung, want.n_segments), \
        f'{got.rung} N={got.n_segments} after the history, {want.rung} N={want.n_segments} fresh'


@settings(max_examples=100, **SETTINGS)
@given(case=single_scenes(), tolerance=st.sampled_from([5e-4, 5e-5]))
@example(case=REPORTED._replace(history=()), tolerance=5e-4)
@example(case=TABLE_EDGE, tolerance=5e-5)
@example(case=TABLE_EDGE_ROD, tolerance=5e-5)
def test_fresh_choose_equals_choose_model(case, tolerance):
    """A fresh AdaptiveSolver picks what choose_model picks for the scene."""
    design = ActuatorDesign.paper(prestrain=case.prestrain)
    scene = case.target
    got = AdaptiveSolver(design, tolerance=tolerance).choose(scene.pressure, scene.tip_force)
    want = choose_model(Scene(design, scene.pressure, scene.tip_force), tolerance)
    assert (got.rung, got.n_segments) == (want.rung, want.n_segments), \
        f'AdaptiveSolver: {got.rung} N={got.n_segments}, choose_model: {want.rung} ' \
        f'N={want.n_segments}'


# -- InverseModel ---------------------------------------------------------------------------
def _inverse(design):
    return InverseModel(design, palm_radius=PALM_RADIUS, max_pressure=INVERSE_MAX_PRESSURE)


class Raised(NamedTuple):
    """The outcome of a call that raised: only the exception type is compared."""

    error: str


def _call(model, call):
    """
    Make one call; return its answer or, if it raised, `Raised`.

    rho and estimate raise RuntimeError when the solver fails; pressure_for_rho can raise
    brentq's ValueError for a target at the very end of the range (a bug of its own, not of
    history). Both are outcomes to compare, and must not stop the history.
    """
    try:
        if call.method == 'pressure_for_rho':
            low, high = model.rho_range
            return model.pressure_for_rho(low + call.argument * (high - low), call.tip_force)
        if call.method == 'rho':
            return model.rho(call.argument, call.tip_force)
        return model.estimate(call.argument, call.tip_force)[0]
    except (RuntimeError, ValueError) as failure:
        note(f'{call} raised {type(failure).__name__}: {failure}')
        return Raised(type(failure).__name__)


@settings(max_examples=200, **SETTINGS)
@given(case=inverse_cases())
# estimate() reuses the linearisation at f0 = 0, which has no f0 term: 0.70 mm off.
@example(case=InverseCase(0.25, (Call('estimate', 150e3, (0.0, 0.0)),),
                          Call('estimate', 150e3, (0.03, 0.0))))
# estimate() reuses a linearisation 4 kPa away: 8.3 um off.
@example(case=InverseCase(0.25, (Call('estimate', 150e3, (0.0, 0.0)),),
                          Call('estimate', 154e3, (0.0, 0.0))))
# The lowest radius: after rho(0 Pa) the warm-started residual at 0 Pa is 7e-18 m lower and
# pressure_for_rho reports SUCCESS; fresh it reports BELOW_RANGE.
@example(case=InverseCase(0.2, (Call('rho', 0.0, (0.0, 0.0)),),
                          Call('pressure_for_rho', 0.0, (0.0, 0.0))))
def test_inverse_model_after_history_equals_fresh(case):
    """
    pressure_for_rho, rho and estimate after other calls equal the call on a fresh model.

    The fresh InverseModel is built for every example (its 31-point grid costs about 11 ms):
    a module-level one would carry the history of earlier examples, and a naive reference
    (a cold CCMSolver) would only check rho, not pressure_for_rho's cache and warm starts.
    """
    design = ActuatorDesign.paper(prestrain=case.prestrain)
    model = _inverse(design)
    target = case.target
    for call in case.history:
        note(f'history {call}: {_call(model, call)!r}')
    got = _call(model, target)
    want = _call(_inverse(design), target)
    note(f'after history: {got!r}')
    note(f'fresh:         {want!r}')
    if isinstance(want, Raised) or isinstance(got, Raised):
        assert got == want, 'only one of them raised'
        return
    if target.method != 'pressure_for_rho':
        assert abs(got - want) <= RHO_ATOL, \
            f'rho differs by {got - want:.3e} m ({got!r} vs {want!r} fresh)'
        return
    assert (got.status, got.success) == (want.status, want.success)
    assert abs(got.x - want.x) <= PRESSURE_ATOL, \
        f'pressure differs by {got.x - want.x:.3e} Pa ({got.x!r} vs {want.x!r} fresh)'
    if not np.isnan(want.rho):
        assert abs(got.rho - want.rho) <= RHO_ATOL, \
            f'achieved rho differs by {got.rho - want.rho:.3e} m'
