"""Many independent scenes at once: designs x pressures x tip forces on the compiled engine."""

import functools
import math

import numpy as np

from . import engine
from .analysis import flexural_rigidity
from .design import ActuatorDesign
from .discretisations.ccm import AXES, check_rigidity, rigidity_result, SolverStatus
from .pipeline import finger_model, ModelSettings, rung_label, solver_label
from .result import Result
from .selection import AdaptiveSolver
from .stiffness import checked_rigidity, classify, direct_stiffness, RigidityStatus
from .validation import check_load, check_outputs, OUTPUT_LEVELS, warm_start_allowed

__all__ = ['solve_grid', 'rigidity_grid', 'check_pressures', 'GRID_FIELDS',
           'RIGIDITY_GRID_FIELDS']

#: The fields of `solve_grid`'s Result; every array has the grid's shape (D, P, F).
GRID_FIELDS = {
    'designs': 'list of ActuatorDesign', 'pressures': '(P,) [Pa]', 'tip_forces': '(F, 2) [N]',
    'settings': 'ModelSettings', 'shape': '(D, P, F)',
    'success': 'bool', 'status': '`SolverStatus` codes', 'iterations': 'int',
    'tip': '(D, P, F, 2) [m]', 'models': "every scene's model, as `pipeline.model_label`",
    'valid': "the CCM's small-rotation rule, as each result's `valid`",
    'energy': '[J] (outputs "all", else None)',
    'curvature': 'signed circle-fit curvature [1/m] (outputs "all", else None)',
    'fit_rmsd': "RMSD of the samples from the circle [m] (outputs 'all', else None)",
    'result': 'function (d, p, f=0) -> the full Result of one scene, as its single solve '
              "returns it with outputs 'all'",
}
#: The fields of `rigidity_grid`'s Result; every array has the grid's shape (D, P).
RIGIDITY_GRID_FIELDS = {
    'designs': 'list of ActuatorDesign', 'pressures': '(P,) [Pa]', 'axis': "'x' or 'z'",
    'displacement': '[m]', 'shape': '(D, P)', 'value': 'K_x or K_z [N m^2]; NaN where not found',
    'force': 'end load that produces the displacement [N]',
    'lever': 'lever arm in the loaded state [m]',
    'success': 'bool: found, and eq. 22 applies (`rigidity_status` OK)',
    'rigidity_status': '`stiffness.RigidityStatus` codes (small lever, branch change)',
    'direct_stiffness': 'dF/d delta of the displacement-control path [N/m]',
    'iterations': 'unloaded plus bordered Newton iterations', 'models': 'str',
    'result': 'function (d, p) -> the rigidity Result of one scene, as its single call '
              'returns it',
}


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


def _batched(solver, loaded):
    """
    Whether a compiled batch gives `solver`'s scenes, loaded or not, as its single solve.

    Not for a rung that runs interpreted (the rod), nor for one whose solve moves the
    engine's state afterwards (`CorrectedSolver`'s shear move under a tip load), which a
    batch row does not carry: their scenes are single solves.
    """
    if not isinstance(solver.engine_problem, engine.CompiledProblem):
        return False
    moves = getattr(solver, 'moves_after_solve', None)
    return moves is None or not moves(loaded)


#: The level of every single solve a grid makes, and of a scene's `result`.
_ALL = OUTPUT_LEVELS['all']


class _Groups:
    """
    Scenes grouped by the compiled batch that solves them.

    A group has one discretisation type, size, sample count and options, one loading
    (loaded or not) and chains or none (`engine.solve_batch`); it lists its solvers,
    once per design, so that a chain never runs from one design's scenes into another's.
    """

    def __init__(self):
        self.groups = {}
        self._keys = {}
        self.scenes = 0

    def _key(self, solver, loaded, chain):
        memo = (id(solver), loaded, chain)
        key = self._keys.get(memo)
        if key is None:
            key = self._keys[memo] = (engine.batch_key(solver.engine_problem, solver._options,
                                                       loaded), solver.n_segments,
                                      getattr(solver, 'samples', None),
                                      getattr(solver, 'samples_per_segment', None), loaded,
                                      chain)
        return key

    def add(self, solver, design, loaded, chain, scenes):
        """Add scenes (indices, in chain order) that `solver` solves for design `design`."""
        group = self.groups.setdefault(self._key(solver, loaded, chain),
                                       {'solvers': [], 'slot': {}, 'scenes': [], 'slots': []})
        slot = group['slot'].setdefault((id(solver), design), len(group['solvers']))
        if slot == len(group['solvers']):
            group['solvers'].append(solver)
        group['scenes'].append(np.asarray(scenes, dtype=np.int64))
        group['slots'].append(np.full(len(scenes), slot, dtype=np.int64))
        self.scenes += len(scenes)

    def __iter__(self):
        for key, group in self.groups.items():
            yield key[-2], key[-1], group['solvers'], np.concatenate(group['scenes']), \
                np.concatenate(group['slots'])


def _add_chains(groups, solver, design, loaded, local, base, pressures, forces, chain):
    """
    Add a design's scenes of one solver to `groups`, along pressure where `chain` allows.

    `local` are the scenes' indices p F + f in the design's block. A scene whose total load
    lets a warm start in (`validation.warm_start_allowed`, as the single solve asks) joins
    the chain of its tip force, ordered by pressure; the others are solved cold.
    """
    local = np.asarray(local, dtype=np.int64)
    p, f = np.divmod(local, forces.shape[0])
    warm = np.array([warm_start_allowed(math.hypot(*forces[k])) for k in range(forces.shape[0])])
    along = chain & warm[f]
    if along.any():
        # By force, then by pressure (stable: equal pressures keep their order).
        order = np.lexsort((pressures[p[along]], f[along]))
        groups.add(solver, design, loaded, True, base + local[along][order])
    if not along.all():
        groups.add(solver, design, loaded, False, base + local[~along])


class _Grid:
    """The arrays of a grid as its scenes are solved (`solve_grid` returns them as a Result)."""

    def __init__(self, designs, pressures, tip_forces, settings, level):
        self.designs = designs
        self.pressures = pressures
        self.tip_forces = tip_forces
        self.settings = settings
        self.level = level
        self.shape = (len(designs), pressures.size, tip_forces.shape[0])
        count = int(np.prod(self.shape))
        self.success = np.zeros(count, dtype=bool)
        self.status = np.zeros(count, dtype=np.int64)
        self.iterations = np.zeros(count, dtype=np.int64)
        self.tip = np.full((count, 2), np.nan)
        self.models = np.empty(count, dtype=object)
        self.valid = np.ones(count, dtype=bool)
        self.figures = np.full((count, 3), np.nan)          # energy, curvature, fit_rmsd
        # Where each scene's full result comes from: a batch row or a single solve.
        self.batch_of = np.full(count, -1, dtype=np.int64)
        self.row = np.zeros(count, dtype=np.int64)
        self.batches = []
        self.singles = {}
        self.models_of = [None] * len(designs)
        # Every scene's adaptive model choice (None: a model of one rung).
        self.choices = np.full(count, None, dtype=object)

    def spec(self, scene):
        """(model, choice, pressure [Pa], tip force [N]) of a flat scene index."""
        d, p, f = np.unravel_index(scene, self.shape)
        force = self.tip_forces[f]
        return (self.models_of[d], self.choices[scene], float(self.pressures[p]),
                (float(force[0]), float(force[1])))

    def single(self, scene, result):
        """Store the result of a scene's single solve (made with outputs 'all')."""
        self.success[scene], self.status[scene] = result.success, int(result.status)
        self.iterations[scene], self.tip[scene] = result.iterations, result.tip
        self.models[scene] = result.model
        self.valid[scene] = result.valid
        self.figures[scene] = result.energy, result.curvature, result.fit_rmsd
        self.singles[scene] = result
        self.batch_of[scene] = -1

    def scene_result(self, design, pressure, force=0):
        """
        Return the full Result of one scene, as its single solve returns it (outputs 'all').

        Parameters
        ----------
        design, pressure, force : int
            Indices into `designs`, `pressures` and `tip_forces`.

        """
        scene = int(np.ravel_multi_index((design, pressure, force), self.shape))
        if scene in self.singles:
            return self.singles[scene]
        batch, solvers, slots, loaded = self.batches[self.batch_of[scene]]
        k = int(self.row[scene])
        _, choice, pressure_pa, tip_force = self.spec(scene)
        solver = solvers[slots[k]]
        loads = [(solver.n_segments, np.array([tip_force]))] if loaded else []
        fields = engine.outputs(solver.engine_problem, batch.states[k:k + 1], [pressure_pa],
                                loads, _ALL)[0]
        outcome = engine.NewtonOutcome(batch.states[k], SolverStatus(int(batch.status[k])),
                                       int(batch.iterations[k]), float(batch.gradient[k]),
                                       float(batch.step[k]), float(batch.min_eig[k]),
                                       float(batch.fraction[k]), fields)
        return solver._result(outcome, pressure_pa, tip_force, model_choice=choice)

    def finish(self):
        """Return the Result (`GRID_FIELDS`)."""
        shape = self.shape
        kept = self.level >= _ALL
        energy, curvature, rmsd = (self.figures[:, k].reshape(shape) if kept else None
                                   for k in range(3))
        return Result.of({
            'designs': self.designs, 'pressures': self.pressures,
            'tip_forces': self.tip_forces, 'settings': self.settings, 'shape': shape,
            'success': self.success.reshape(shape), 'status': self.status.reshape(shape),
            'iterations': self.iterations.reshape(shape), 'tip': self.tip.reshape(shape + (2,)),
            'models': self.models.reshape(shape), 'valid': self.valid.reshape(shape),
            'energy': energy, 'curvature': curvature, 'fit_rmsd': rmsd,
            'result': self.scene_result,
        })


def _choices(model, pressures, forces):
    """Return the solver each scene's single solve uses first, and its model choice."""
    if isinstance(model, AdaptiveSolver):
        choices = model.choose_many(pressures, forces)
        # A few models for many scenes: each solver looked up once.
        solvers = {}
        for c in choices:
            if (c.rung, c.n_segments) not in solvers:
                solvers[c.rung, c.n_segments] = model.solver_for(c.rung, c.n_segments)
        return [solvers[c.rung, c.n_segments] for c in choices], choices
    return [model] * len(pressures), [None] * len(pressures)


def solve_grid(designs, pressures, tip_forces=((0.0, 0.0),), settings=ModelSettings(), *,
               outputs='tip', chain=True):
    """
    Solve every design x pressure x tip force on the compiled engine, over both cores.

    Each scene gets the model `finger_model(design, settings)` gives it (the default:
    the cheapest rung that meets 0.05 mm; ``ModelSettings(tolerance=0)``: the paper
    CCM8). Scenes are grouped by discretisation and solved in compiled batches
    (`engine.solve_batch`); a scene whose adaptive model refines (a CCM rung whose
    first solve fails or breaks the small-rotation rule), or whose model does not run
    compiled, is finished by the single solve, which does exactly that. With `chain`
    (the default) a design's scenes of one model and tip force are solved along
    pressure, lowest first, each warm-started from the ones before it (as the single
    solve's `initial`, where it allows one: up to `validation.UNIQUE_LOAD` of load):
    a third of the Newton iterations, and the answer of the cold single solve to
    round-off, whichever other scenes the grid holds. Without, every scene is solved
    cold, exactly as its single solve (the same iterations and arithmetic).

    Parameters
    ----------
    designs : ActuatorDesign or sequence of ActuatorDesign
    pressures : array_like, shape (P,)
        Gauge pressures >= 0 [Pa].
    tip_forces : array_like, shape (F, 2) or (2,)
        Tip forces (f0, p0) [N].
    settings : ModelSettings
    outputs : {'tip', 'shape', 'all'}
        'tip' (the default): the states' tips and validity; 'shape' also the energy;
        'all' also the circle fit of every scene's samples (in the same compiled calls).
    chain : bool
        Warm-start the scenes along pressure, as above; False: every scene cold.

    Returns
    -------
    Result
        `GRID_FIELDS`.

    Raises
    ------
    TypeError, ValueError
        On bad designs, non-finite or negative pressures, non-finite forces, naming the
        argument, value and unit.

    """
    level = check_outputs(outputs)
    designs = _designs(designs)
    pressures = check_pressures(pressures)
    forces = _tip_forces(tip_forces)
    _in_envelope(designs, pressures, forces)
    settings = _settings(settings)
    out = _Grid(designs, pressures, forces, settings, level)
    pending = _build(out, designs, settings, bool(chain))
    memo = {}
    for loaded, solvers, index, slots, batch in pending:
        _store(out, batch(), solvers, index, slots, loaded, memo)
    return out.finish()


#: Scenes of the designs built so far above which `solve_grid` sends them to be solved.
_FLUSH_SCENES = 160


def _build(out, designs, settings, chain):
    """
    Build every design's model and start its scenes' batches; return the pending batches.

    A scene that a batch does not give is solved alone here. The batches of every few
    designs start as soon as these are built (`_submit`): their compiled loops run on
    the batch threads while the next designs' models are built.
    """
    pressures, forces = out.pressures, out.tip_forces
    n_p, n_f = pressures.size, forces.shape[0]
    per_design = n_p * n_f
    scene_p = [float(p) for p in np.repeat(pressures, n_f)]
    scene_f = [(float(f[0]), float(f[1])) for f in np.tile(forces, (n_p, 1))]
    scene_loaded = np.tile(np.any(forces != 0.0, axis=1), n_p).tolist()
    groups = _Groups()
    pending = []
    for d, design in enumerate(designs):
        model = out.models_of[d] = finger_model(design, settings)
        base = d * per_design
        if not isinstance(model, AdaptiveSolver):
            # One solver for the whole design: its loaded and unloaded scenes as two blocks,
            # each batched, or its own solves where a batch would not give them (the rod).
            for loaded in (False, True):
                local = np.flatnonzero(np.array(scene_loaded) == loaded)
                if local.size and _batched(model, loaded):
                    _add_chains(groups, model, d, loaded, local, base, pressures, forces,
                                chain)
                    continue
                for k in local:
                    out.single(base + k, model.solve(scene_p[k], scene_f[k]))
        else:
            blocks = {}
            solvers, choices = _choices(model, scene_p, scene_f)
            out.choices[base:base + per_design] = choices
            for k, (solver, loaded) in enumerate(zip(solvers, scene_loaded)):
                block = blocks.get((id(solver), loaded))
                if block is None:
                    block = blocks[id(solver), loaded] = (solver, [], _batched(solver, loaded))
                if block[2]:
                    block[1].append(k)
                else:
                    # A rung that a batch does not give (the rod): its own solve.
                    out.single(base + k, model.solve(scene_p[k], scene_f[k]))
            for (_, loaded), (solver, local, batched) in blocks.items():
                if batched:
                    _add_chains(groups, solver, d, loaded, local, base, pressures, forces,
                                chain)
        if groups.scenes >= _FLUSH_SCENES or d == len(designs) - 1:
            pending += [_submit(group, pressures, forces, out.level) for group in groups]
            groups = _Groups()
    return pending


def _submit(group, pressures, forces, level):
    """Start the compiled batch of a group; return it with (loaded, solvers, index, slots)."""
    loaded, chained, solvers, index, slots = group
    n_f = forces.shape[0]
    local = index % (pressures.size * n_f)
    force = forces[local % n_f].reshape(index.size, 1, 2)
    nodes = np.array([solvers[0].n_segments] if loaded else [], dtype=np.int64)
    batch = engine.solve_batch([s.engine_problem for s in solvers], slots,
                               pressures[local // n_f], nodes, force if loaded else force[:, :0],
                               solvers[0]._options, level=min(level, _ALL), chain=chained,
                               wait=False)
    return loaded, solvers, index, slots, batch


def _store(out, batch, solvers, index, slots, loaded, memo):
    """Store a group's batch in the grid; a scene whose adaptive model refines is solved alone."""
    out.batches.append((batch, solvers, slots, loaded))
    out.batch_of[index] = len(out.batches) - 1
    out.row[index] = np.arange(index.size)
    out.status[index] = batch.status
    out.success[index] = batch.status == int(SolverStatus.SUCCESS)
    out.iterations[index] = batch.iterations
    out.tip[index] = batch.tips
    out.valid[index] = batch.valid
    out.figures[index] = np.stack([batch.energy, batch.curvature, batch.fit_rmsd], axis=1)
    choices = out.choices[index].tolist()
    if any(choice is None for choice in choices):
        out.models[index] = solver_label(solvers[0])
    design = (index // (out.shape[1] * out.shape[2])).tolist()
    success, valid = out.success[index].tolist(), out.valid[index].tolist()
    labelled, labels = [], []
    for k, choice in enumerate(choices):
        if choice is None:
            continue
        # The verdict depends on these alone: asked once per grid.
        key = (design[k], choice.rung, choice.n_segments, success[k], valid[k])
        verdict = memo.get(key)
        if verdict is None:
            verdict = memo[key] = (out.models_of[design[k]].refines(
                choice.rung, choice.n_segments, _Verdict(success[k], valid[k])),
                rung_label(choice.rung, choice.n_segments))
        if verdict[0]:
            scene = int(index[k])
            out.single(scene, out.models_of[design[k]].solve(*out.spec(scene)[2:]))
        else:
            labelled.append(index[k])
            labels.append(verdict[1])
    if labelled:
        out.models[labelled] = np.array(labels, dtype=object)


class _Verdict:
    """What `AdaptiveSolver.refines` reads of a result: success and validity."""

    def __init__(self, success, valid):
        self.success = bool(success)
        self.valid = bool(valid)


class _RigidityGrid:
    """The arrays of a rigidity grid (`rigidity_grid` returns them as a Result)."""

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
        self.rigidity_status = np.full(count, int(RigidityStatus.FAILED), dtype=np.int64)
        self.direct_stiffness = np.full(count, np.nan)
        self.iterations = np.zeros(count, dtype=np.int64)
        self.models = np.empty(count, dtype=object)
        self.scenes = [None] * count

    def scene_result(self, design, pressure):
        """Return the rigidity Result of one scene, as its single call returns it."""
        scene = self.scenes[int(np.ravel_multi_index((design, pressure), self.shape))]
        return scene() if callable(scene) else scene

    def finish(self):
        """Return the Result (`RIGIDITY_GRID_FIELDS`)."""
        fields = {name: getattr(self, name).reshape(self.shape) for name in (
            'value', 'force', 'lever', 'success', 'rigidity_status', 'direct_stiffness',
            'iterations', 'models')}
        return Result.of(dict(fields, designs=self.designs, pressures=self.pressures,
                              axis=self.axis, displacement=self.displacement, shape=self.shape,
                              result=self.scene_result))


def rigidity_grid(designs, pressures, axis='x', displacement=0.010, settings=ModelSettings()):
    """
    Flexural rigidity (eq. 22) of every design x pressure, compiled over both cores.

    Each scene is ``finger_model(design, settings).rigidity(p, axis, displacement)``
    solved cold (the same model and arithmetic, so the same answer).

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
    Result
        `RIGIDITY_GRID_FIELDS`.

    """
    designs = _designs(designs)
    pressures = check_pressures(pressures)
    _in_envelope(designs, pressures, np.zeros((1, 2)))
    delta = check_rigidity(axis, displacement)
    settings = _settings(settings)
    out = _RigidityGrid(designs, pressures, axis, delta)
    groups = _Groups()
    scenes = []
    scene_p = [float(p) for p in pressures]
    for d, design in enumerate(designs):
        model = finger_model(design, settings)
        solvers, choices = _choices(model, scene_p, [(0.0, 0.0)] * len(scene_p))
        blocks = {}
        for solver, choice, pressure in zip(solvers, choices, scene_p):
            scene = len(scenes)
            scenes.append((solver, pressure, choice))
            # The displacement control solves a loaded state.
            if _batched(solver, True):
                blocks.setdefault(id(solver), (solver, []))[1].append(scene)
            else:
                _store_rigidity(out, scene, checked_rigidity(
                    solver, solver.rigidity(pressure, axis, delta)), choice, solver)
        for solver, block in blocks.values():
            groups.add(solver, d, False, False, block)
    k = 0 if axis == 'x' else 1
    for _, _, solvers, index, slots in groups:
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
            out.scenes[scene] = functools.partial(_rigidity_scene, solver, axis, delta, p,
                                                  batch, j)
            if found[j]:
                status = classify(True, lever[j], delta, not batch.stable[j])
                out.rigidity_status[scene] = int(status)
                out.success[scene] = status is RigidityStatus.OK
                out.force[scene] = batch.force[j]
                out.lever[scene] = lever[j]
                out.value[scene] = flexural_rigidity(batch.force[j], lever[j], delta)
                out.direct_stiffness[scene] = direct_stiffness(solver, batch.states[j], p,
                                                               batch.force[j], axis)
    return out.finish()


def _label(solver, choice):
    return rung_label(choice.rung, choice.n_segments) if choice is not None \
        else solver_label(solver)


def _store_rigidity(out, scene, result, choice, solver):
    out.success[scene] = result.success
    out.rigidity_status[scene] = int(result.rigidity_status)
    out.direct_stiffness[scene] = result.direct_stiffness
    out.value[scene], out.force[scene], out.lever[scene] = result.value, result.force, \
        result.lever
    out.iterations[scene] = result.iterations
    out.models[scene] = _label(solver, choice)
    out.scenes[scene] = result


def _rigidity_scene(solver, axis, delta, pressure, batch, j):
    """Build scene j's rigidity Result as the single call does (outputs 'tip')."""
    free = batch.unloaded
    problem = solver.engine_problem
    unloaded = engine.NewtonOutcome(
        free.states[j], SolverStatus(int(free.status[j])), int(free.iterations[j]),
        float(free.gradient[j]), float(free.step[j]), float(free.min_eig[j]),
        float(free.fraction[j]),
        engine.outputs(problem, free.states[j:j + 1], [pressure], [], engine.TIP)[0])
    if unloaded.status is not SolverStatus.SUCCESS:
        out = engine.BorderedOutcome(unloaded.x, np.nan, False, 0, 0.0, False, np.nan,
                                     np.full(2, np.nan), unloaded)
        return checked_rigidity(solver, rigidity_result(solver, axis, delta, pressure, out,
                                                        engine.TIP))
    found = bool(np.isfinite(batch.force[j]))
    force = batch.force[j] * AXES[axis] if found else np.zeros(2)
    fields = engine.outputs(problem, batch.states[j:j + 1], [pressure],
                            [(solver.n_segments, force[None])], engine.TIP)[0]
    out = engine.BorderedOutcome(batch.states[j], float(batch.force[j]), found,
                                 int(batch.iterations[j]), float(batch.fraction[j]),
                                 bool(batch.stable[j]), float(batch.gradient[j]), batch.tips[j],
                                 unloaded, fields)
    return checked_rigidity(solver, rigidity_result(solver, axis, delta, pressure, out,
                                                    engine.TIP))
