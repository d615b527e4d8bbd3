"""Model selection on the ladder (arc, CCM-N, rod) and automatic segment refinement."""

import bisect
import collections
import dataclasses
from dataclasses import dataclass
import functools
import json
import math
import pathlib

import numpy as np

from . import engine
from .design import ActuatorDesign
from .discretisations.arc import ArcSolver
from .discretisations.ccm import CCMSolver, SolverStatus
from .discretisations.pcc import PCCSolver
from .discretisations.rod import RodSolver
from .reference import CONTINUUM_FLOOR, rod_tolerance
from .section.law import station_layout
from .section.segments import interval_of, uniform_edges
from .stiffness import checked_rigidity
from .validation import check_load, check_pressure_model, real_number

__all__ = ['Scene', 'ModelChoice', 'RUNGS', 'choose_model', 'load_error_model', 'make_solver',
           'scene_turning', 'a_posteriori_error', 'aligned_edges', 'AdaptiveSolver']

#: Rungs of the ladder: uniform arc (a), CCM with the paper's reconstruction, CCM with the
#: consistent reconstruction (uniform segments, or 'ccm_aligned': segment edges on every
#: section change -- rib edges and channel end), the piecewise-constant-strain rod ('pcc',
#: exact arcs between the section changes) and the geometrically exact rod (d).
RUNGS = ('arc', 'ccm', 'ccm_consistent', 'ccm_aligned', 'pcc', 'rod')
_DATA = pathlib.Path(__file__).resolve().parents[1] / 'data' / 'error_model.json'


@dataclass(frozen=True)
class Scene:
    """
    One loading case of one finger.

    Parameters
    ----------
    design : ActuatorDesign
        The finger (its prestrain included).
    pressure : float
        Gauge pressure [Pa].
    tip_force : (float, float)
        (f0, p0) along global X and Z [N].
    pressure_model : {'design', 'adiabatic', 'isobaric'}
        'design' (or None, the default): the design's `pressure_work_factor`.

    """

    design: ActuatorDesign
    pressure: float = 0.0
    tip_force: tuple = (0.0, 0.0)
    pressure_model: str = 'design'

    def __post_init__(self):
        if not isinstance(self.design, ActuatorDesign):
            raise TypeError(f'`design` must be an ActuatorDesign, got '
                            f'{type(self.design).__name__}')
        pressure, force = check_load(self.pressure, self.tip_force, self.design.max_pressure)
        object.__setattr__(self, 'pressure', pressure)
        object.__setattr__(self, 'tip_force', force)
        object.__setattr__(self, 'pressure_model', check_pressure_model(self.pressure_model))

    @property
    def load(self):
        """Magnitude of the tip force [N]."""
        return float(math.hypot(*self.tip_force))


@dataclass(frozen=True)
class ModelChoice:
    """
    The rung and segment count picked for a scene.

    Attributes
    ----------
    rung : str
        One of `RUNGS`.
    n_segments : int
        Segments of the CCM rungs (1 for the arc, element count for the rod).
    predicted_error : float
        Bound on the tip-position error against the rod [m].
    reason : str
        Why this model was chosen.
    cost : float
        Static cost of the model: unknowns x median Newton iterations of its cold solves
        on the ladder scenes (bench/bench_ladder.py); the same on every machine.

    """

    rung: str
    n_segments: int
    predicted_error: float
    reason: str
    cost: float = float('nan')


def make_solver(rung, n_segments, design, pressure_model=None):
    """
    Build the solver of a rung: the factory behind `pipeline.finger_model`.

    Consumers build a finger with `finger_model(design, ModelSettings(rung=...))`; this
    is what it and `AdaptiveSolver` call.

    Parameters
    ----------
    rung : str
        One of `RUNGS`.
    n_segments : int
        Segments of the CCM and PCC rungs (ignored by the arc and the rod).
    design : ActuatorDesign
    pressure_model : {None, 'design', 'adiabatic', 'isobaric'}
        None or 'design': the design's `pressure_work_factor`.

    """
    if rung == 'arc':
        return ArcSolver(design, pressure_model=pressure_model)
    if rung == 'ccm':
        return CCMSolver(design, n_segments=int(n_segments), pressure_model=pressure_model)
    if rung == 'ccm_consistent':
        return CCMSolver(design, n_segments=int(n_segments), pressure_model=pressure_model,
                         reconstruction='consistent')
    if rung == 'ccm_aligned':
        return CCMSolver(design, segment_edges=aligned_edges(design, n_segments),
                         pressure_model=pressure_model, reconstruction='consistent',
                         rung='ccm_aligned')
    if rung == 'pcc':
        return PCCSolver(design, n_segments=int(n_segments), pressure_model=pressure_model)
    if rung == 'rod':
        return RodSolver(design, pressure_model=pressure_model)
    raise ValueError(f'`rung` must be one of {RUNGS}, got {rung!r}')


def aligned_edges(design, n_segments):
    """
    Segment edges on every section change (rib edges, channel end), N segments in all.

    A CCM segment has one curvature, so a segment that straddles a rib edge
    mixes two very different sections; its error then falls only as 1/N. With
    edges on the section changes the consistent CCM converges as 1/N^2.

    Parameters
    ----------
    design : ActuatorDesign
    n_segments : int
        Total N, at least the number of constant-section intervals (22 for the paper).

    Returns
    -------
    ndarray, shape (N + 1,)
        Edges [m].

    """
    breaks = station_layout(design, ribs='exact')[0]
    return uniform_edges(design.free_length, int(n_segments), breaks[1:-1])


@functools.lru_cache(maxsize=4)
def _load_cached(path):
    return json.loads(pathlib.Path(path).read_text())


def load_error_model(path=None):
    """
    Read the measured error model written by bench/bench_ladder.py.

    Parameters
    ----------
    path : str or Path, optional
        Default: the package's data/error_model.json.

    Returns
    -------
    dict
        See `choose_model` for the layout.

    """
    path = pathlib.Path(_DATA if path is None else path)
    if not path.is_file():
        raise ValueError(f'error model {path} does not exist; run bench/bench_ladder.py')
    return _load_cached(str(path))


#: Pressure spacing of the unloaded feature table [Pa].
_FEATURE_STEP = 5e3
_FEATURE_CACHE = 256


#: A piecewise cubic as scipy's PPoly holds it: breakpoints x (K + 1,) and coefficients
#: c (4, K), highest power first, in powers of the distance from each interval's start.
_Pieces = collections.namedtuple('_Pieces', ('x', 'c'))


def _pchip(x, y):
    """
    Return scipy's PchipInterpolator(x, y) as `_Pieces`: the same operations, the same bits.

    scipy builds it in about 250 us, most of it checks and array dispatch; these are its
    derivatives (`_find_derivatives`, with the one-sided ends of `_edge_case`) and its
    Hermite coefficients (`CubicHermiteSpline`), for 1-d float x (increasing) and y.
    """
    h = x[1:] - x[:-1]
    m = (y[1:] - y[:-1]) / h
    d = np.zeros_like(y)
    if y.size == 2:
        d[:] = m[0]
    else:
        sign = np.sign(m)
        flat = (sign[1:] != sign[:-1]) | (m[1:] == 0) | (m[:-1] == 0)
        w1 = 2 * h[1:] + h[:-1]
        w2 = h[1:] + 2 * h[:-1]
        # The slopes' weighted harmonic mean; where one is 0 it is not used (`flat`).
        with np.errstate(divide='ignore', invalid='ignore'):
            mean = (w1 / m[:-1] + w2 / m[1:]) / (w1 + w2)
        d[1:-1][~flat] = 1.0 / mean[~flat]
        d[0] = _pchip_end(h[0], h[1], m[0], m[1])
        d[-1] = _pchip_end(h[-1], h[-2], m[-1], m[-2])
    dx = np.diff(x)
    slope = np.diff(y) / dx
    t = (d[:-1] + d[1:] - 2 * slope) / dx
    return _Pieces(x, np.stack((t / dx, (slope - d[:-1]) / dx - t, d[:-1], y[:-1])))


def _pchip_end(h0, h1, m0, m1):
    """Return PCHIP's end derivative: the one-sided three-point estimate, shape-preserving."""
    d = ((2 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
    if np.sign(d) != np.sign(m0):
        return 0.0
    if np.sign(m0) != np.sign(m1) and abs(d) > 3.0 * abs(m0):
        return 3.0 * m0
    return d


class _Cubic:
    """
    A piecewise cubic (scipy's PPoly, as PCHIP builds it: `_pchip`) at one point, in floats.

    scipy's own call costs 17-19 us, of which the arithmetic is nothing; this one finds the
    interval as scipy's `find_interval` does (closed on the right at the last breakpoint)
    and sums the same terms in the same order (its `evaluate_poly1`), so it gives the same
    bits, in about 1 us.
    """

    def __init__(self, ppoly):
        # tolist: the same values as Python floats, in one call.
        self.x = ppoly.x.tolist()
        self.c = [tuple(column) for column in ppoly.c.T.tolist()]

    def __call__(self, xval):
        """Return the cubic at `xval`, a float inside the breakpoints."""
        x = self.x
        i = min(max(bisect.bisect_right(x, xval) - 1, 0), len(x) - 2)
        return _horner(*self.c[i], xval - x[i])

    def many(self, xvals):
        """Return the cubic at every point of `xvals` (an array inside the breakpoints)."""
        x = np.asarray(self.x)
        i = interval_of(x, xvals)
        return _horner(*np.asarray(self.c)[i].T, xvals - x[i])


def _horner(c0, c1, c2, c3, s):
    """Sum a cubic's terms as scipy's `evaluate_poly1` does (floats or arrays: the same bits)."""
    res = 0.0 + c3 * 1.0 * 1.0
    z = s
    res = res + c2 * z * 1.0
    z = z * s
    res = res + c1 * z * 1.0
    z = z * s
    return res + c0 * z * 1.0


class _ArcFeature:
    """
    The scene feature of `choose_model` for one design: the arc rung's turning |kappa L|.

    Unloaded, it is read from a table of arc solves every 5 kPa over the error model's
    pressure range, interpolated by PCHIP (3e-8 rad from a direct solve). Loaded, the arc
    is solved from the table state nearest in pressure. Both are functions of the scene
    alone: the table is built the same way every time, and a warm start never changes the
    converged answer, so every caller that asks for a scene gets the same feature.
    """

    def __init__(self, design, pressure_model, top):
        self.arc = ArcSolver(design, pressure_model=pressure_model)
        self.grid = np.linspace(0.0, top, int(round(top / _FEATURE_STEP)) + 1)
        self.states = self._table_states()
        # Signed: |beta| has a kink where the finger passes flat.
        self.table = None
        if all(x is not None for x in self.states):
            # The turning from the state, as the result's beta[0]: no samples are built (the
            # states as columns: every pressure's in one call, by the same operations).
            self.table = _Cubic(_pchip(
                self.grid, self.arc.turning(self.arc._unpack(np.array(self.states)).T)))
        self._loaded = {}

    def _table_states(self):
        """
        Packed unloaded arc states at the table's pressures (None where none was found).

        All of them from flat as one compiled batch (10 iterations each: 0.8 ms a design,
        against 3.3 ms for a chain of single solves); only when one of those fails is the
        table built again as a chain, each pressure warm from the one before. Either way
        it is a function of the design alone, and the two agree to 1.4e-14 rad on the
        design sweep's 125 fingers.
        """
        n = self.grid.size
        out = engine.solve_batch([self.arc.engine_problem], np.zeros(n, dtype=np.int64),
                                 self.grid, [self.arc.tip_node], np.zeros((n, 1, 2)),
                                 self.arc._options)
        if np.all(out.status == int(SolverStatus.SUCCESS)):
            return list(out.states)
        state, states = None, []
        for pressure in self.grid:
            state = self.arc.solve(pressure, (0.0, 0.0), initial=state, outputs='tip')
            state = state if state.success else None
            states.append(None if state is None else self.arc._pack(state.state))
        return states

    def _tabled(self, pressure, tip_force):
        return self.table is not None and tip_force == (0.0, 0.0) and pressure <= self.grid[-1]

    def _nearest(self, pressure):
        """Warm start of a loaded arc solve: the table state nearest in pressure, or None."""
        state = self.states[int(np.argmin(np.abs(self.grid - pressure)))]
        return None if state is None else state.copy()

    def _turning(self, x, status):
        if status is not SolverStatus.SUCCESS:
            return math.inf
        return abs(float(self.arc.turning(self.arc._unpack(x))))

    def turning(self, pressure, tip_force):
        """Return |kappa L| of the arc rung [rad]; inf when the arc has no equilibrium."""
        if self._tabled(pressure, tip_force):
            return abs(self.table(pressure))
        key = (pressure,) + tuple(tip_force)
        if key not in self._loaded:
            out = engine.solve(self.arc.engine_problem, pressure, self.arc.tip_loads(tip_force),
                               self.arc._options, self._nearest(pressure), engine.TIP)
            if len(self._loaded) >= _FEATURE_CACHE:
                self._loaded.clear()
            self._loaded[key] = self._turning(out.x, out.status)
        return self._loaded[key]

    def turnings(self, pressures, tip_forces):
        """
        Return `turning` of many scenes: their loaded arcs solved as one compiled batch.

        Parameters
        ----------
        pressures : sequence of float
            [Pa].
        tip_forces : sequence of (float, float)
            [N].

        Returns
        -------
        list of float
            Equal to `turning` of each scene: the same solves (warm from the same table
            states) in a batch.

        """
        out = [None] * len(pressures)
        index, starts = [], []
        tabled = [k for k, (p, f) in enumerate(zip(pressures, tip_forces)) if self._tabled(p, f)]
        if tabled:
            values = np.abs(self.table.many(np.array([pressures[k] for k in tabled]))).tolist()
            for k, value in zip(tabled, values):
                out[k] = value
        for k, (pressure, force) in enumerate(zip(pressures, tip_forces)):
            if out[k] is not None:
                continue
            start = self._nearest(pressure) if any(force) else None
            if start is None:
                # Unloaded beyond the table, or no table state to start from: as `turning`.
                out[k] = self.turning(pressure, force)
            else:
                index.append(k)
                starts.append(start)
        if index:
            batch = engine.solve_batch(
                [self.arc.engine_problem], np.zeros(len(index), dtype=np.int64),
                [pressures[k] for k in index], [self.arc.tip_node],
                np.array([tip_forces[k] for k in index], dtype=float).reshape(-1, 1, 2),
                self.arc._options, initial=np.array(starts))
            for j, k in enumerate(index):
                out[k] = self._turning(batch.states[j], SolverStatus(int(batch.status[j])))
        return out


@functools.lru_cache(maxsize=16)
def _arc_feature(design, pressure_model, top):
    return _ArcFeature(design, pressure_model, top)


def scene_turning(scene, error_model=None):
    """
    Return the feature `choose_model` bins a scene by: the arc rung's turning [rad].

    Parameters
    ----------
    scene : Scene
    error_model : dict, optional
        Default: `load_error_model()`; its pressure range sets the unloaded table.

    Returns
    -------
    float
        |kappa L| of the arc rung [rad]; inf if the arc finds no equilibrium.

    """
    model = load_error_model() if error_model is None else error_model
    feature = _arc_feature(scene.design, scene.pressure_model,
                           float(model['ranges']['pressure'][1]))
    return feature.turning(scene.pressure, scene.tip_force)


def choose_model(scene, tolerance, error_model=None, reference='rod'):
    """
    Pick the cheapest rung and segment count whose tip error meets a tolerance.

    The error model (bench/bench_ladder.py) stores, for every rung and N, the
    largest measured tip-position error against the rod in bins of the scene's
    turning |kappa L| (`scene_turning`, from the arc rung) and of the tip-load
    magnitude, made non-decreasing in both, and whether any scene of the bin broke
    the CCM's small-rotation rule. A model is eligible in a bin that has data, no
    invalid state and bound * safety <= tolerance; the eligible model of least
    static cost (unknowns x iterations, ties broken by rung and N) wins. Scenes
    outside the measured ranges (prestrain, pressure, load, turning) get the rod.
    The choice is a function of (design, scene, tolerance) alone: no timing, call
    history or cache enters it.

    Parameters
    ----------
    scene : Scene
    tolerance : float
        Tip-position tolerance [m], > 0.
    error_model : dict, optional
        Default: `load_error_model()`.
    reference : {'rod', 'continuum'}
        What the tolerance is measured against (`reference.rod_tolerance`): the rod (the
        error model's own reference), or the 2-D continuum, for unpressurised scenes and
        tolerances above the beam floor `reference.CONTINUUM_FLOOR` (else ValueError).

    Returns
    -------
    ModelChoice
        Its `predicted_error` and `reason` against `reference`.

    References
    ----------
    docs/physics.md, section 11.5.

    """
    if not isinstance(scene, Scene):
        raise TypeError(f'`scene` must be a Scene, got {type(scene).__name__}')
    tolerance = real_number('tolerance', tolerance, '[m]')
    if tolerance <= 0.0:
        raise ValueError(f'`tolerance` must be > 0 [m], got {tolerance}')
    against_rod = rod_tolerance(tolerance, reference, scene.pressure)
    model = load_error_model() if error_model is None else error_model
    choice = _choose(model, _scene_bin(model, scene.design.prestrain, scene.pressure,
                                       scene.load, scene_turning(scene, model)), against_rod)
    if reference == 'rod':
        return choice
    return dataclasses.replace(
        choice, predicted_error=choice.predicted_error + CONTINUUM_FLOOR,
        reason=f'against the continuum (beam floor {CONTINUUM_FLOOR:g} m + error against '
               f'the rod): {choice.reason}')


def _scene_bin(model, prestrain, pressure, load, turning):
    """
    Return the error-model cell of a scene: (turning bin, load bin), or why it is outside.

    Two scenes in the same cell get the same choice for any tolerance.
    """
    ranges = model['ranges']
    outside = []
    if not ranges['prestrain'][0] <= prestrain <= ranges['prestrain'][1]:
        outside.append(f'prestrain {prestrain:g}')
    if not pressure <= ranges['pressure'][1]:
        outside.append(f'pressure {pressure:g} Pa')
    load_edges = model['load_bins']
    if load > load_edges[-1] * (1 + 1e-12):
        outside.append(f'load {load:g} N')
    turn_edges = model['turning_bins']
    if turning > turn_edges[-1]:
        outside.append(f'turning {turning:.3g} rad')
    if outside:
        return tuple(outside)
    # bisect_left on the sorted edges is searchsorted(side='left') without an array copy.
    return (bisect.bisect_left(turn_edges, turning),
            bisect.bisect_left(load_edges, load * (1 - 1e-12)))


def _scene_bins(model, prestrain, pressures, loads, turnings):
    """
    Return `_scene_bin` of many scenes (sequences of floats), those inside the ranges at once.

    Inside, a cell is the same two bisections, done by searchsorted on arrays; a scene
    outside (or with a turning that is not finite) gets `_scene_bin` itself.
    """
    ranges = model['ranges']
    turn_edges, load_edges = model['turning_bins'], model['load_bins']
    pressure, load, turning = (np.asarray(v, dtype=float)
                               for v in (pressures, loads, turnings))
    inside = (ranges['prestrain'][0] <= prestrain <= ranges['prestrain'][1]) \
        & (pressure <= ranges['pressure'][1]) & (load <= load_edges[-1] * (1 + 1e-12)) \
        & np.isfinite(turning) & (turning <= turn_edges[-1])
    t_bin = np.searchsorted(turn_edges, turning, side='left').tolist()
    l_bin = np.searchsorted(load_edges, load * (1 - 1e-12), side='left').tolist()
    return [(t_bin[k], l_bin[k]) if inside[k] else
            _scene_bin(model, prestrain, pressures[k], loads[k], turnings[k])
            for k in range(pressure.size)]


def _static_cost(entry):
    """Sort key of a model: its static cost, then its rung and N (never a measured time)."""
    if 'cost' not in entry:
        raise ValueError('the error model has no static costs; run bench/bench_ladder.py '
                         '--costs-only')
    return float(entry['cost']), RUNGS.index(entry['rung']), int(entry['n_segments'])


def _choose(model, cell, tolerance):
    """Return the cheapest model whose measured bound in `cell` meets `tolerance`."""
    rod_cost = next((_static_cost(m)[0] for m in model['models'] if m['rung'] == 'rod'),
                    float('nan'))
    if isinstance(cell[0], str):
        return ModelChoice('rod', 0, 0.0, 'outside the measured envelope ('
                           + ', '.join(cell) + '): geometrically exact rod', rod_cost)
    t_bin, l_bin = cell
    where = (f"turning bin {t_bin} (<= {model['turning_bins'][t_bin]:.2f} rad) and load bin "
             f"{l_bin} (<= {model['load_bins'][l_bin]:g} N)")
    safety = float(model['safety'])
    for entry in sorted(model['models'], key=_static_cost):
        if entry['rung'] == 'rod':
            continue
        bound = entry['bound'][l_bin][t_bin]
        if bound is None or entry['invalid'][l_bin][t_bin]:
            continue
        if bound * safety <= tolerance:
            return ModelChoice(entry['rung'], int(entry['n_segments']), float(bound * safety),
                               f'cheapest measured model with bound {bound * safety:.2e} m '
                               f'<= {tolerance:g} m at {where}', float(entry['cost']))
    return ModelChoice('rod', 0, 0.0, f'no cheaper model meets {tolerance:g} m at {where}',
                       rod_cost)


#: `_choose` by (error model, cell, tolerance), shared by every solver: a choice depends on
#: these alone (error models are read-only), and a sweep's many fresh solvers meet the same
#: few cells. Each entry keeps its error model, so that its id stays its own.
_CHOSEN = {}
#: Entries of `_CHOSEN` before it starts again (cells outside the ranges are many).
_CHOSEN_LIMIT = 4096


def _chosen(model, cell, tolerance):
    """Return `_choose(model, cell, tolerance)`, computed once."""
    key = (id(model), cell, tolerance)
    hit = _CHOSEN.get(key)
    if hit is None or hit[0] is not model:
        if len(_CHOSEN) >= _CHOSEN_LIMIT:
            _CHOSEN.clear()
        hit = _CHOSEN[key] = (model, _choose(model, cell, tolerance))
    return hit[1]


def a_posteriori_error(scene, rung, n_segments):
    """
    Estimate the tip error of a CCM rung from solves at N and 2N [m].

    The consistent CCM converges to the rod, at second order where segment
    edges fall on section changes and at first order across ribs, so
    |tip_N - tip_2N| is a first-order (conservative) estimate. The paper's CCM
    converges to another limit; its estimate adds |tip_2N(paper) -
    tip_2N(consistent)|, the reconstruction difference.

    Returns
    -------
    float
        Estimated tip-position error [m]; inf if a solve fails or is invalid.

    """
    if rung not in ('ccm', 'ccm_consistent'):
        raise ValueError(f"`rung` must be 'ccm' or 'ccm_consistent', got {rung!r}")
    design, p, f = scene.design, scene.pressure, scene.tip_force
    results = [make_solver(rung, n, design, scene.pressure_model).solve(p, f)
               for n in (n_segments, 2 * n_segments)]
    if rung == 'ccm':
        results.append(make_solver('ccm_consistent', 2 * n_segments, design,
                                   scene.pressure_model).solve(p, f))
    if not all(r.success and r.valid for r in results):
        return math.inf
    estimate = float(np.linalg.norm(results[0].tip - results[1].tip))
    if rung == 'ccm':
        estimate += float(np.linalg.norm(results[1].tip - results[2].tip))
    return estimate


class AdaptiveSolver:
    """
    Solver that models no more than a scene needs, with CCMSolver's interface.

    Each solve picks the cheapest rung and N that `choose_model` predicts to meet
    `tolerance` for that pressure and tip force, and doubles N while a segment
    breaks the small-rotation rule or the solve fails. Unloaded scenes get
    coarser models than loaded, strongly curled ones. The choice is exactly the
    one `choose_model` makes for the scene: a pure function of (design, scene,
    tolerance), whatever was solved before.

    Parameters
    ----------
    design : ActuatorDesign
    tolerance : float
        Tip-position tolerance against the geometrically exact rod [m], > 0.
    pressure_model : {None, 'design', 'adiabatic', 'isobaric'}
        None or 'design' (the default): the design's `pressure_work_factor`.
    max_segments : int
        Largest N that refinement may reach.
    error_model : dict, optional
        Default: `load_error_model()`.

    """

    def __init__(self, design, tolerance=0.5e-3, pressure_model=None, max_segments=128,
                 error_model=None):
        if not isinstance(design, ActuatorDesign):
            raise TypeError(f'`design` must be an ActuatorDesign, got {type(design).__name__}')
        self.tolerance = real_number('tolerance', tolerance, '[m]')
        if self.tolerance <= 0.0:
            raise ValueError(f'`tolerance` must be > 0 [m], got {self.tolerance}')
        self.design = design
        self.pressure_model = check_pressure_model(pressure_model)
        self.max_segments = int(max_segments)
        self._model = load_error_model() if error_model is None else error_model
        # `scene_turning`'s feature, held: a solve then hashes no design. Built here so that
        # the first solve does not pay for the unloaded feature table.
        self._feature = _arc_feature(design, self.pressure_model,
                                     float(self._model['ranges']['pressure'][1]))
        self._feature.turning(0.0, (0.0, 0.0))
        self._solvers = {}
        self._choices = {}

    def choose(self, pressure, tip_force):
        """
        Return the ModelChoice for a scene: ``choose_model(Scene(...), tolerance)``.

        Choices are cached per error-model cell, which the choice is a function of.
        """
        pressure, force = check_load(pressure, tip_force, self.design.max_pressure)
        return self._choice(pressure, force, self._feature.turning(pressure, force))

    def choose_many(self, pressures, tip_forces):
        """
        Return `choose` of many scenes: the same choices, for less than a `choose` each.

        Their features come together (`_ArcFeature.turnings`: the table read at once, the
        loaded arcs solved as one batch), and so do the cells (`_scene_bins`).
        """
        scenes = [check_load(p, f, self.design.max_pressure)
                  for p, f in zip(pressures, tip_forces)]
        if not scenes:
            return []
        forces = [f for _, f in scenes]
        turnings = self._feature.turnings([p for p, _ in scenes], forces)
        cells = _scene_bins(self._model, self.design.prestrain, [p for p, _ in scenes],
                            [math.hypot(*f) for f in forces], turnings)
        return [self._cell_choice(cell) for cell in cells]

    def _choice(self, pressure, force, turning):
        return self._cell_choice(_scene_bin(self._model, self.design.prestrain, pressure,
                                            math.hypot(*force), turning))

    def _cell_choice(self, cell):
        choice = self._choices.get(cell)
        if choice is None:
            choice = self._choices[cell] = _chosen(self._model, cell, self.tolerance)
        return choice

    def solver_for(self, rung, n_segments):
        """Return the (cached) solver of a rung and N."""
        key = (rung, int(n_segments))
        if key not in self._solvers:
            self._solvers[key] = make_solver(rung, n_segments, self.design, self.pressure_model)
        return self._solvers[key]

    @staticmethod
    def _warm(solver, initial):
        """Return `initial` where it is that solver's own result (a warm start), else None."""
        return initial if initial is not None and initial.segment_edges is solver.edges \
            else None

    def solve(self, pressure=0.0, tip_force=(0.0, 0.0), initial=None, *, outputs='all'):
        """
        Solve with the model the scene needs; see `CCMSolver.solve`.

        `initial` warm-starts only a result of the same underlying solver; a model
        change starts from the flat state. The result's `model_choice` is the choice,
        with the N actually used after refinement.
        """
        choice = self.choose(pressure, tip_force)
        rung, n = choice.rung, choice.n_segments
        while True:
            solver = self.solver_for(rung, n)
            label = choice if n == choice.n_segments else ModelChoice(
                rung, n, choice.predicted_error, f'{choice.reason}; refined to N = {n}',
                choice.cost)
            result = solver.solve(pressure, tip_force, initial=self._warm(solver, initial),
                                  outputs=outputs, model_choice=label)
            if not self.refines(rung, n, result):
                return result
            n *= 2

    def refines(self, rung, n_segments, result):
        """Whether `solve` goes on from `result` of (rung, N) to twice the N."""
        return (rung.startswith('ccm') and 2 * n_segments <= self.max_segments
                and not (result.success and result.valid))

    def rigidity(self, pressure=0.0, axis='x', displacement=0.010, initial=None, *,
                 outputs='tip'):
        """
        Flexural rigidity with the model the unloaded scene needs; see `CCMSolver`.

        Checked where eq. 22 breaks (`stiffness.checked_rigidity`): a lever shorter than
        the displacement or a loaded state off the unloaded branch has its own
        `rigidity_status` and ``success=False``; `direct_stiffness` is dF/d delta.
        """
        choice = self.choose(pressure, (0.0, 0.0))
        solver = self.solver_for(choice.rung, choice.n_segments)
        return checked_rigidity(solver, solver.rigidity(
            pressure, axis, displacement, initial=self._warm(solver, initial),
            outputs=outputs))
