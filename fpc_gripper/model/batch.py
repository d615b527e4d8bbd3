"""Many independent scenes at once: designs x pressures x tip forces on the compiled engine."""

import functools

import numba
import numpy as np

from . import engine
from .analysis import flexural_rigidity
from .compiled import over_cores
from .design import ActuatorDesign
from .discretisations.ccm import (AXES, CCMResult, CCMSolver, check_rigidity, rigidity_result,
                                  SolverStatus)
from .discretisations.pcc import PCCSolver
from .kernels import shapes as shape_kernels
from .pipeline import finger_model, model_label, ModelSettings, rung_label, solver_label
from .selection import AdaptiveSolver
from .validation import check_load

__all__ = ['solve_grid', 'rigidity_grid', 'GridResult', 'RigidityGrid', 'check_pressures']


def _designs(designs):
    designs = [designs] if isinstance(designs, ActuatorDesign) else list(designs)
    for k, design in enumerate(designs):
        if not isinstance(design, ActuatorDesign):
            raise TypeError(f'`designs[{k}]` must be an ActuatorDesign, got '
                            f'{type(design).__name__}')
    if not designs:
        raise ValueError('`designs` must hold at least one ActuatorDesign')
    return designs


def check_pressures(pressures):
    """Return gauge pressures as a 1-d float array; ValueError naming a bad one [Pa]."""
    values = np.atleast_1d(np.asarray(pressures, dtype=float))
    if values.ndim != 1 or not values.size:
        raise ValueError(f'`pressures` must be a non-empty 1-d sequence [Pa], got shape '
                         f'{values.shape}')
    bad = ~(np.isfinite(values) & (values >= 0.0))
    if bad.any():
        raise ValueError(f'`pressures` must be finite and >= 0 (gauge) [Pa], got '
                         f'{values[bad][0]!r} at index {int(np.argmax(bad))}')
    return values


def _tip_forces(tip_forces):
    values = np.asarray(tip_forces, dtype=float)
    if values.shape == (2,):
        values = values[None, :]
    if values.ndim != 2 or values.shape[1] != 2 or not values.shape[0]:
        raise ValueError(f'`tip_forces` must be a non-empty sequence of (f0, p0) [N], got '
                         f'shape {values.shape}')
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        raise ValueError(f'`tip_forces` must be finite [N], got {values[bad][0].tolist()} at '
                         f'index {int(np.argmax(bad))}')
    return values


def _in_envelope(designs, pressures, forces):
    """Refuse a grid with a scene outside the envelope, as each single solve would."""
    with np.errstate(over='ignore'):
        # A force beyond 1e154 N overflows hypot to inf, which still picks it out.
        worst = forces[int(np.argmax(np.hypot(forces[:, 0], forces[:, 1])))]
    for design in designs:
        check_load(float(pressures.max()), (float(worst[0]), float(worst[1])),
                   design.max_pressure)


def _settings(settings):
    if not isinstance(settings, ModelSettings):
        raise TypeError(f'`settings` must be a ModelSettings, got {type(settings).__name__}')
    return settings


def _compiled(solver):
    """Whether a rung runs compiled (a batch can take it), not interpreted (the rod)."""
    return isinstance(solver.engine_problem, engine.CompiledProblem)


class _Groups:
    """
    Scenes grouped by the compiled batch that solves them.

    A group has one discretisation type, size and options, and one loading (loaded or
    not); it lists its distinct solvers.
    """

    def __init__(self):
        self.groups = {}
        self._keys = {}

    def _key(self, solver, loaded):
        memo = (id(solver), loaded)
        key = self._keys.get(memo)
        if key is None:
            problem = solver.engine_problem
            flat = engine.solves._flat(problem)
            opts, cap = engine.solves._packed(problem, solver._options, flat.shape)
            key = self._keys[memo] = (type(problem.data[loaded]), flat.shape, opts,
                                      cap.tobytes(), loaded, solver.n_segments)
        return key

    def add(self, solver, loaded, scenes):
        """Add scenes (indices) that `solver` solves, loaded or not."""
        group = self.groups.setdefault(self._key(solver, loaded),
                                       {'solvers': [], 'slot': {}, 'scenes': [], 'slots': []})
        slot = group['slot'].setdefault(id(solver), len(group['solvers']))
        if slot == len(group['solvers']):
            group['solvers'].append(solver)
        group['scenes'].append(np.asarray(scenes, dtype=np.int64))
        group['slots'].append(np.full(len(scenes), slot, dtype=np.int64))

    def __iter__(self):
        for key, group in self.groups.items():
            yield key[4], group['solvers'], np.concatenate(group['scenes']), \
                np.concatenate(group['slots'])


class GridResult:
    """
    Equilibria of every design x pressure x tip force, as arrays of shape (D, P, F).

    Every scene is solved cold, exactly as ``finger_model(design, settings).solve(p, f)``
    solves it alone (the same model and arithmetic, so the same answer); only the
    order of work differs.

    Attributes
    ----------
    designs : list of ActuatorDesign
    pressures : ndarray, shape (P,)
        [Pa].
    tip_forces : ndarray, shape (F, 2)
        [N].
    settings : ModelSettings
    success : ndarray of bool, shape (D, P, F)
    status : ndarray of int, shape (D, P, F)
        `SolverStatus` codes.
    iterations : ndarray of int, shape (D, P, F)
    tip : ndarray, shape (D, P, F, 2)
        Global (X, Z) of the tip [m].
    models : ndarray of str, shape (D, P, F)
        Model of every scene, as `pipeline.model_label` names it.
    curvature, fit_rmsd : ndarray, shape (D, P, F)
        Signed curvature [1/m] and RMSD [m] of every scene's circle fit, equal to its
        result's `curvature` and `fit_rmsd` (the same samples and fit, compiled over
        both cores); computed on first use.
    valid : ndarray of bool, shape (D, P, F)
        Every scene's result's `valid` (the CCM's small-rotation rule).

    """

    def __init__(self, designs, pressures, tip_forces, settings):
        self.designs = designs
        self.pressures = pressures
        self.tip_forces = tip_forces
        self.settings = settings
        self.shape = (len(designs), pressures.size, tip_forces.shape[0])
        count = int(np.prod(self.shape))
        self.success = np.zeros(count, dtype=bool)
        self.status = np.zeros(count, dtype=np.int64)
        self.iterations = np.zeros(count, dtype=np.int64)
        self.tip = np.full((count, 2), np.nan)
        self.models = np.empty(count, dtype=object)
        # Where each scene's full result comes from: a batch row or a single solve.
        self._batch = np.full(count, -1, dtype=np.int64)
        self._row = np.zeros(count, dtype=np.int64)
        self._batches = []
        self._singles = {}
        self._models = [None] * len(designs)
        self._choices = {}

    def _spec(self, scene):
        """(model, choice, pressure [Pa], tip force [N]) of a flat scene index."""
        d, p, f = np.unravel_index(scene, self.shape)
        force = self.tip_forces[f]
        return (self._models[d], self._choices.get(scene), float(self.pressures[p]),
                (float(force[0]), float(force[1])))

    def _finish(self):
        for name in ('success', 'status', 'iterations', 'models'):
            setattr(self, name, getattr(self, name).reshape(self.shape))
        self.tip = self.tip.reshape(self.shape + (2,))
        return self

    def _single(self, scene, result):
        self.success[scene], self.status[scene] = result.success, int(result.status)
        self.iterations[scene], self.tip[scene] = result.iterations, result.tip
        self.models[scene] = model_label(result)
        self._singles[scene] = result
        self._batch[scene] = -1

    @functools.cached_property
    def _circles(self):
        """(curvature, rmsd), shape (D, P, F) each: every scene's samples and circle fit."""
        out = np.full((self._batch.size, 2), np.nan)
        for b, (batch, solvers, slots, loaded) in enumerate(self._batches):
            scenes = np.flatnonzero(self._batch == b)
            if scenes.size:
                out[scenes] = self._batch_circles(scenes, batch, solvers, slots)
        for scene, result in self._singles.items():
            out[scene] = result.curvature, result.fit_rmsd
        return out[:, 0].reshape(self.shape), out[:, 1].reshape(self.shape)

    def _batch_circles(self, scenes, batch, solvers, slots):
        """Circle fits (S, 2) of a batch's scenes: compiled for the CCM and the PCC."""
        rows = self._row[scenes]
        solver = solvers[0]
        if isinstance(solver, CCMSolver) and all(
                s.samples_per_segment == solver.samples_per_segment for s in solvers):
            lengths = np.array([s.segments.lengths for s in solvers])
            states, slots = batch.states[rows], slots[rows]
            return over_cores(lambda lo, hi: shape_kernels.ccm_circles(
                states[lo:hi], lengths, slots[lo:hi], solver.samples_per_segment), rows.size)
        if isinstance(solver, PCCSolver):
            _, p, f = np.unravel_index(scenes, self.shape)
            datas = numba.typed.List([s.engine_problem.data[False] for s in solvers])
            segment = np.array([s._sample_segment for s in solvers])
            offset = np.array([s._sample_offset for s in solvers])
            states, slots = batch.states[rows], slots[rows]
            pressures = self.pressures[p]
            forces = np.ascontiguousarray(self.tip_forces[f])
            return over_cores(lambda lo, hi: shape_kernels.pcc_circles(
                states[lo:hi], datas, segment, offset, slots[lo:hi], pressures[lo:hi],
                forces[lo:hi]), rows.size)
        # Another discretisation: each scene's own result.
        out = np.empty((scenes.size, 2))
        for k, scene in enumerate(scenes):
            result = self.result(*np.unravel_index(scene, self.shape))
            out[k] = result.curvature, result.fit_rmsd
        return out

    @functools.cached_property
    def valid(self):
        """
        Whether every scene's state obeys its model's small-rotation rule, shape (D, P, F).

        As each result's `valid`: |2 d L_i| < 1 in every CCM segment; always True for the
        geometrically exact rungs.
        """
        out = np.ones(self._batch.size, dtype=bool)
        for b, (batch, solvers, _, _) in enumerate(self._batches):
            scenes = np.flatnonzero(self._batch == b)
            if scenes.size and isinstance(solvers[0], CCMSolver):
                out[scenes] = CCMResult.small_rotations(batch.states[self._row[scenes]])
        for scene, result in self._singles.items():
            out[scene] = result.valid
        return out.reshape(self.shape)

    @property
    def curvature(self):
        """Signed circle-fit curvature of every scene [1/m], shape (D, P, F)."""
        return self._circles[0]

    @property
    def fit_rmsd(self):
        """RMSD of every scene's samples from its circle [m], shape (D, P, F)."""
        return self._circles[1]

    def result(self, design, pressure, force=0):
        """
        Return the full result of one scene, as a single solve returns it (built on demand).

        Parameters
        ----------
        design, pressure, force : int
            Indices into `designs`, `pressures` and `tip_forces`.

        """
        scene = int(np.ravel_multi_index((design, pressure, force), self.shape))
        if scene in self._singles:
            return self._singles[scene]
        batch, solvers, slots, loaded = self._batches[self._batch[scene]]
        k = int(self._row[scene])
        model, choice, pressure_pa, tip_force = self._spec(scene)
        solver = solvers[slots[k]]
        loads = [(solver.n_segments, np.array(tip_force))] if loaded else []
        result = solver._result(batch.states[k], SolverStatus(int(batch.status[k])),
                                int(batch.iterations[k]), float(batch.gradient[k]),
                                float(batch.step[k]), float(batch.min_eig[k]),
                                float(batch.fraction[k]), pressure_pa, loads, tip_force)
        return result if choice is None else model._labelled(result, choice,
                                                             choice.n_segments)

    def __repr__(self):
        return (f'GridResult(shape={self.shape}, success={int(self.success.sum())}/'
                f'{self.success.size})')


def _choices(model, pressures, forces):
    """Return the solver each scene's single solve uses first, and its model choice."""
    if isinstance(model, AdaptiveSolver):
        choices = model.choose_many(pressures, forces)
        return [model.solver_for(c.rung, c.n_segments) for c in choices], choices
    return [model] * len(pressures), [None] * len(pressures)


def solve_grid(designs, pressures, tip_forces=((0.0, 0.0),), settings=ModelSettings()):
    """
    Solve every design x pressure x tip force on the compiled engine, over both cores.

    Each scene gets the model `finger_model(design, settings)` gives it (the default:
    the cheapest rung that meets 0.05 mm; ``ModelSettings(tolerance=0)``: the paper
    CCM8). Scenes are grouped by discretisation and solved in compiled batches
    (`engine.solve_batch`); a scene whose adaptive model refines (a CCM rung whose
    first solve fails or breaks the small-rotation rule), or whose model does not run
    compiled, is finished by the single solve, which does exactly that.

    Parameters
    ----------
    designs : ActuatorDesign or sequence of ActuatorDesign
    pressures : array_like, shape (P,)
        Gauge pressures >= 0 [Pa].
    tip_forces : array_like, shape (F, 2) or (2,)
        Tip forces (f0, p0) [N].
    settings : ModelSettings

    Returns
    -------
    GridResult

    Raises
    ------
    TypeError, ValueError
        On bad designs, non-finite or negative pressures, non-finite forces, naming the
        argument, value and unit.

    """
    designs = _designs(designs)
    pressures = check_pressures(pressures)
    forces = _tip_forces(tip_forces)
    _in_envelope(designs, pressures, forces)
    settings = _settings(settings)
    out = GridResult(designs, pressures, forces, settings)
    n_p, n_f = pressures.size, forces.shape[0]
    per_design = n_p * n_f
    scene_p = [float(p) for p in np.repeat(pressures, n_f)]
    scene_f = [(float(f[0]), float(f[1])) for f in np.tile(forces, (n_p, 1))]
    scene_loaded = np.tile(np.any(forces != 0.0, axis=1), n_p)
    groups = _Groups()
    for d, design in enumerate(designs):
        model = out._models[d] = finger_model(design, settings)
        base = d * per_design
        if not isinstance(model, AdaptiveSolver) and not _compiled(model):
            # A fixed rung that does not run compiled (the rod): its own solves.
            for k in range(per_design):
                out._single(base + k, model.solve(scene_p[k], scene_f[k]))
            continue
        if not isinstance(model, AdaptiveSolver):
            # One solver for the whole design: its loaded and unloaded scenes as two blocks.
            for loaded in (False, True):
                block = base + np.flatnonzero(scene_loaded == loaded)
                if block.size:
                    groups.add(model, loaded, block)
            continue
        blocks = {}
        for k, (solver, choice) in enumerate(zip(*_choices(model, scene_p, scene_f))):
            scene = base + k
            out._choices[scene] = choice
            if _compiled(solver):
                blocks.setdefault((id(solver), bool(scene_loaded[k])), (solver, []))[1] \
                    .append(scene)
            else:
                # A rung that does not run compiled (the rod): its own solve.
                out._single(scene, model.solve(scene_p[k], scene_f[k]))
        for (_, loaded), (solver, scenes) in blocks.items():
            groups.add(solver, loaded, scenes)
    for loaded, solvers, index, slots in groups:
        local = index % per_design
        pressure = np.repeat(pressures, n_f)[local]
        force = np.tile(forces, (n_p, 1))[local].reshape(index.size, 1, 2)
        tip = solvers[0].n_segments
        nodes = np.array([tip] if loaded else [], dtype=np.int64)
        batch = engine.solve_batch([s.engine_problem for s in solvers], slots, pressure, nodes,
                                   force if loaded else force[:, :0], solvers[0]._options, tip)
        out._batches.append((batch, solvers, slots, loaded))
        out._batch[index] = len(out._batches) - 1
        out._row[index] = np.arange(index.size)
        out.status[index] = batch.status
        out.success[index] = batch.status == int(SolverStatus.SUCCESS)
        out.iterations[index] = batch.iterations
        out.tip[index] = batch.tips
        adaptive = [k for k, scene in enumerate(index) if scene in out._choices]
        if len(adaptive) < index.size:
            out.models[index] = solver_label(solvers[0])
        if not adaptive:
            continue
        valid = (CCMResult.small_rotations(batch.states) if isinstance(solvers[0], CCMSolver)
                 else np.ones(index.size, dtype=bool))
        for k in adaptive:
            scene = index[k]
            model, choice = out._models[scene // per_design], out._choices[scene]
            if model.refines(choice.rung, choice.n_segments,
                             _Verdict(out.success[scene], valid[k])):
                out._single(scene, model.solve(*out._spec(scene)[2:]))
            else:
                out.models[scene] = rung_label(choice.rung, choice.n_segments)
    return out._finish()


class _Verdict:
    """What `AdaptiveSolver.refines` reads of a result: success and validity."""

    def __init__(self, success, valid):
        self.success = bool(success)
        self.valid = bool(valid)


class RigidityGrid:
    """
    Flexural rigidity of every design x pressure, as arrays of shape (D, P).

    Each scene is ``finger_model(design, settings).rigidity(p, axis, displacement)``
    solved cold (the same model and arithmetic, so the same answer).

    Attributes
    ----------
    designs : list of ActuatorDesign
    pressures : ndarray, shape (P,)
        [Pa].
    axis : {'x', 'z'}
    displacement : float
        [m].
    value : ndarray, shape (D, P)
        K_x or K_z [N m^2]; NaN where not found.
    force : ndarray, shape (D, P)
        End load that produces the displacement [N].
    lever : ndarray, shape (D, P)
        Lever arm in the loaded state [m].
    success : ndarray of bool, shape (D, P)
    iterations : ndarray of int, shape (D, P)
        Unloaded plus bordered Newton iterations.
    models : ndarray of str, shape (D, P)

    """

    def __init__(self, designs, pressures, axis, displacement):
        self.designs = designs
        self.pressures = pressures
        self.axis = axis
        self.displacement = displacement
        self.shape = (len(designs), pressures.size)
        count = int(np.prod(self.shape))
        self.value = np.full(count, np.nan)
        self.force = np.full(count, np.nan)
        self.lever = np.full(count, np.nan)
        self.success = np.zeros(count, dtype=bool)
        self.iterations = np.zeros(count, dtype=np.int64)
        self.models = np.empty(count, dtype=object)
        self._scenes = [None] * count

    def _finish(self):
        for name in ('value', 'force', 'lever', 'success', 'iterations', 'models'):
            setattr(self, name, getattr(self, name).reshape(self.shape))
        return self

    def result(self, design, pressure):
        """Return the RigidityResult of one scene, as a single solve returns it."""
        scene = self._scenes[int(np.ravel_multi_index((design, pressure), self.shape))]
        return scene() if callable(scene) else scene

    def __repr__(self):
        return (f'RigidityGrid(shape={self.shape}, axis={self.axis!r}, '
                f'success={int(self.success.sum())}/{self.success.size})')


def rigidity_grid(designs, pressures, axis='x', displacement=0.010, settings=ModelSettings()):
    """
    Flexural rigidity (eq. 22) of every design x pressure, compiled over both cores.

    Parameters
    ----------
    designs : ActuatorDesign or sequence of ActuatorDesign
    pressures : array_like, shape (P,)
        Gauge pressures >= 0 [Pa].
    axis : {'x', 'z'}
    displacement : float
        Tip displacement delta > 0 [m] (the paper's protocol: 10 mm).
    settings : ModelSettings
        The model of each scene, as for `solve_grid` (the unloaded scene's choice).

    Returns
    -------
    RigidityGrid

    """
    designs = _designs(designs)
    pressures = check_pressures(pressures)
    _in_envelope(designs, pressures, np.zeros((1, 2)))
    delta = check_rigidity(axis, displacement)
    settings = _settings(settings)
    out = RigidityGrid(designs, pressures, axis, delta)
    groups = _Groups()
    scenes = []
    scene_p = [float(p) for p in pressures]
    for design in designs:
        model = finger_model(design, settings)
        solvers, choices = _choices(model, scene_p, [(0.0, 0.0)] * len(scene_p))
        blocks = {}
        for solver, choice, pressure in zip(solvers, choices, scene_p):
            scene = len(scenes)
            scenes.append((solver, pressure, choice))
            if _compiled(solver):
                blocks.setdefault(id(solver), (solver, []))[1].append(scene)
            else:
                _store_rigidity(out, scene, solver.rigidity(pressure, axis, delta), choice,
                                solver)
        for solver, block in blocks.values():
            groups.add(solver, False, block)
    k = 0 if axis == 'x' else 1
    for _, solvers, index, slots in groups:
        pressure = np.array([scenes[i][1] for i in index])
        batch = engine.rigidity_batch([s.engine_problem for s in solvers], slots, pressure,
                                      solvers[0].n_segments, AXES[axis], delta,
                                      solvers[0]._options)
        found = (batch.unloaded.status == int(SolverStatus.SUCCESS)) & np.isfinite(batch.force)
        lever = np.abs(batch.tips[:, 1 - k])
        for j, scene in enumerate(index):
            solver, p, choice = scenes[scene]
            out.iterations[scene] = batch.unloaded.iterations[j] + batch.iterations[j]
            out.models[scene] = _label(solver, choice)
            out._scenes[scene] = _rigidity_builder(solver, axis, delta, p, batch, j)
            if found[j]:
                out.success[scene] = True
                out.force[scene] = batch.force[j]
                out.lever[scene] = lever[j]
                out.value[scene] = flexural_rigidity(batch.force[j], lever[j], delta)
    return out._finish()


def _label(solver, choice):
    return rung_label(choice.rung, choice.n_segments) if choice is not None \
        else solver_label(solver)


def _store_rigidity(out, scene, result, choice, solver):
    out.success[scene] = result.success
    out.value[scene], out.force[scene], out.lever[scene] = result.value, result.force, \
        result.lever
    out.iterations[scene] = result.iterations
    out.models[scene] = _label(solver, choice)
    out._scenes[scene] = result


def _rigidity_builder(solver, axis, delta, pressure, batch, j):
    """Return a function that builds scene j's RigidityResult as the single solve does."""
    def build():
        free = batch.unloaded
        status = SolverStatus(int(free.status[j]))
        unloaded = solver._result(free.states[j], status, int(free.iterations[j]),
                                  float(free.gradient[j]), float(free.step[j]),
                                  float(free.min_eig[j]), float(free.fraction[j]), pressure,
                                  [], (0.0, 0.0))
        if not unloaded.success:
            return rigidity_result(solver, axis, delta, pressure, unloaded)
        out = engine.BorderedOutcome(batch.states[j], float(batch.force[j]),
                                     bool(np.isfinite(batch.force[j])),
                                     int(batch.iterations[j]), float(batch.fraction[j]),
                                     bool(batch.stable[j]), float(batch.gradient[j]),
                                     batch.tips[j])
        return rigidity_result(solver, axis, delta, pressure, unloaded, out)
    return build
