"""Many independent scenes at once: designs x pressures x tip forces on the compiled engine."""

import numpy as np

from . import engine
from .analysis import flexural_rigidity
from .design import ActuatorDesign
from .pipeline import finger_model, model_label, ModelSettings, rung_label
from .selection import AdaptiveSolver
from .solver import AXES, CCMResult, CCMSolver, check_rigidity, rigidity_result, SolverStatus

__all__ = ['solve_grid', 'rigidity_grid', 'GridResult', 'RigidityGrid']


def _designs(designs):
    designs = [designs] if isinstance(designs, ActuatorDesign) else list(designs)
    for k, design in enumerate(designs):
        if not isinstance(design, ActuatorDesign):
            raise TypeError(f'`designs[{k}]` must be an ActuatorDesign, got '
                            f'{type(design).__name__}')
    if not designs:
        raise ValueError('`designs` must hold at least one ActuatorDesign')
    return designs


def _pressures(pressures):
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


def _settings(settings):
    if not isinstance(settings, ModelSettings):
        raise TypeError(f'`settings` must be a ModelSettings, got {type(settings).__name__}')
    return settings


def _group_key(solver, loaded):
    """Scenes solved in one compiled batch share the discretisation type, size and options."""
    data = solver.kernel_data(loaded)
    opts, cap = engine._packed(solver, solver._options, engine._flat(solver).shape)
    return type(data), engine._flat(solver).shape, opts, cap.tobytes(), loaded, \
        solver.n_segments


class _Groups:
    """Scenes grouped by the batch they are solved in, each with its distinct solvers."""

    def __init__(self):
        self.groups = {}

    def add(self, solver, loaded, scene):
        key = _group_key(solver, loaded)
        group = self.groups.setdefault(key, {'solvers': [], 'index': {}, 'scenes': []})
        slot = group['index'].setdefault(id(solver), len(group['solvers']))
        if slot == len(group['solvers']):
            group['solvers'].append(solver)
        group['scenes'].append((scene, slot))

    def __iter__(self):
        for key, group in self.groups.items():
            scenes = np.array([scene for scene, _ in group['scenes']], dtype=np.int64)
            slots = np.array([slot for _, slot in group['scenes']], dtype=np.int64)
            yield key[4], group['solvers'], scenes, slots


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
        self._scenes = [None] * count

    def _finish(self):
        for name in ('success', 'status', 'iterations', 'models'):
            setattr(self, name, getattr(self, name).reshape(self.shape))
        self.tip = self.tip.reshape(self.shape + (2,))
        return self

    def result(self, design, pressure, force=0):
        """
        Return the full result of one scene, as a single solve returns it (built on demand).

        Parameters
        ----------
        design, pressure, force : int
            Indices into `designs`, `pressures` and `tip_forces`.

        """
        flat = int(np.ravel_multi_index((design, pressure, force), self.shape))
        scene = self._scenes[flat]
        return scene() if callable(scene) else scene

    def __repr__(self):
        return (f'GridResult(shape={self.shape}, success={int(self.success.sum())}/'
                f'{self.success.size})')


def _scene_solver(model, pressure, force):
    """The solver a scene's single solve uses first, and its AdaptiveSolver choice."""
    if isinstance(model, AdaptiveSolver):
        choice = model.choose(pressure, force)
        return model.solver_for(choice.rung, choice.n_segments), choice
    return model, None


def solve_grid(designs, pressures, tip_forces=((0.0, 0.0),), settings=ModelSettings()):
    """
    Solve every design x pressure x tip force on the compiled engine, over both cores.

    Each scene gets the model `finger_model(design, settings)` gives it (the default:
    the cheapest rung that meets 0.05 mm; ``ModelSettings(tolerance=0)``: the paper
    CCM8). Scenes are grouped by discretisation and solved in compiled batches
    (`engine.solve_batch`); a scene whose adaptive model refines (a CCM rung whose
    first solve fails or breaks the small-rotation rule) is finished by the single
    solve, which does exactly that.

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
    pressures = _pressures(pressures)
    forces = _tip_forces(tip_forces)
    settings = _settings(settings)
    out = GridResult(designs, pressures, forces, settings)
    groups = _Groups()
    choices = {}
    scenes = []
    loaded_force = [bool(f[0] or f[1]) for f in forces]
    for d, design in enumerate(designs):
        model = finger_model(design, settings)
        for p, pressure in enumerate(pressures):
            for f, force in enumerate(forces):
                spec = (float(pressure), (float(force[0]), float(force[1])))
                solver, choice = _scene_solver(model, *spec)
                scene = len(scenes)
                scenes.append((model, solver) + spec)
                choices[scene] = choice
                if hasattr(solver, 'kernel_data'):
                    groups.add(solver, loaded_force[f], scene)
                else:
                    # A rung that does not run compiled (the arc, the rod): its own solve.
                    _store_result(out, scene, model.solve(*spec))
    for loaded, solvers, index, slots in groups:
        pressure = np.array([scenes[i][2] for i in index])
        force = np.array([scenes[i][3] for i in index]).reshape(index.size, 1, 2)
        tip = solvers[0].n_segments
        nodes = np.array([tip] if loaded else [], dtype=np.int64)
        batch = engine.solve_batch(solvers, slots, pressure, nodes,
                                   force if loaded else force[:, :0], solvers[0]._options, tip)
        valid = (CCMResult.small_rotations(batch.states) if isinstance(solvers[0], CCMSolver)
                 else np.ones(index.size, dtype=bool))
        for k, scene in enumerate(index):
            _store(out, scene, scenes[scene], choices[scene], batch, k, valid[k], loaded)
    return out._finish()


def _store(out, scene, spec, choice, batch, k, valid, loaded):
    """Fill one scene of `out` from a batch, or from its single solve where that refines."""
    model, solver, pressure, force = spec
    status = SolverStatus(int(batch.status[k]))
    success = status is SolverStatus.SUCCESS
    if choice is not None and model.refines(choice.rung, choice.n_segments,
                                            _Verdict(success, valid)):
        _store_result(out, scene, model.solve(pressure, force))
        return
    out.success[scene] = success
    out.status[scene] = int(status)
    out.iterations[scene] = batch.iterations[k]
    out.tip[scene] = batch.tips[k]
    loads = [(solver.n_segments, np.array(force))] if loaded else []
    args = (batch.states[k], status, int(batch.iterations[k]), float(batch.gradient[k]),
            float(batch.step[k]), float(batch.min_eig[k]), float(batch.fraction[k]), pressure,
            loads, force)

    def build():
        result = solver._result(*args)
        return result if choice is None else model._labelled(result, choice,
                                                             choice.n_segments)
    out._scenes[scene] = build
    out.models[scene] = (rung_label(choice.rung, choice.n_segments) if choice is not None
                         else f'ccm N={solver.n_segments}')


def _store_result(out, scene, result):
    """Fill one scene of `out` from a result of a single solve."""
    out.success[scene], out.status[scene] = result.success, int(result.status)
    out.iterations[scene], out.tip[scene] = result.iterations, result.tip
    out.models[scene] = model_label(result)
    out._scenes[scene] = result


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
    pressures = _pressures(pressures)
    delta = check_rigidity(axis, displacement)
    settings = _settings(settings)
    out = RigidityGrid(designs, pressures, axis, delta)
    groups = _Groups()
    scenes = []
    for design in designs:
        model = finger_model(design, settings)
        for pressure in pressures:
            solver, choice = _scene_solver(model, float(pressure), (0.0, 0.0))
            scene = len(scenes)
            scenes.append((solver, float(pressure), choice))
            if hasattr(solver, 'kernel_data'):
                groups.add(solver, False, scene)
            else:
                _store_rigidity(out, scene, solver.rigidity(float(pressure), axis, delta),
                                choice, solver)
    k = 0 if axis == 'x' else 1
    for _, solvers, index, slots in groups:
        pressure = np.array([scenes[i][1] for i in index])
        batch = engine.rigidity_batch(solvers, slots, pressure, solvers[0].n_segments,
                                      AXES[axis], delta, solvers[0]._options)
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
        else f'ccm N={solver.n_segments}'


def _store_rigidity(out, scene, result, choice, solver):
    out.success[scene] = result.success
    out.value[scene], out.force[scene], out.lever[scene] = result.value, result.force, \
        result.lever
    out.iterations[scene] = result.iterations
    out.models[scene] = _label(solver, choice)
    out._scenes[scene] = result


def _rigidity_builder(solver, axis, delta, pressure, batch, j):
    """A function that builds scene j's RigidityResult as the single solve does."""
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
                                     bool(batch.stable[j]), float(batch.gradient[j]))
        return rigidity_result(solver, axis, delta, pressure, unloaded, out)
    return build
