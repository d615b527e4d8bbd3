"""The engine's Python front for batches: S independent scenes on both cores."""

from dataclasses import dataclass

import numba
import numpy as np

from .solves import (_compiled, _CONTROL, _flat, _one, _packed, _rigidity_entry, _solve_entry,
                     _WIDE, CHAIN, NO_ROWS, SOLVE, TIP)
from ..compiled import over_cores


# -- batches -------------------------------------------------------------------------------
@dataclass(frozen=True)
class BatchOutcome:
    """
    Equilibria of S independent scenes (internal: `batch` builds its results from it).

    Attributes
    ----------
    states : ndarray, shape (S,) + unknowns
    status : ndarray of int, shape (S,)
        `SolverStatus` codes.
    iterations : ndarray of int, shape (S,)
    gradient, step, min_eig, fraction : ndarray, shape (S,)
        As in `NewtonOutcome`.
    tips : ndarray, shape (S, 2)
        Position of the tip node [m].
    valid : ndarray of bool, shape (S,)
    energy, curvature, fit_rmsd : ndarray, shape (S,)
        NaN below the call's level (`solves.OUTPUTS`).

    """

    states: np.ndarray
    status: np.ndarray
    iterations: np.ndarray
    gradient: np.ndarray
    step: np.ndarray
    min_eig: np.ndarray
    fraction: np.ndarray
    tips: np.ndarray
    valid: np.ndarray = None
    energy: np.ndarray = None
    curvature: np.ndarray = None
    fit_rmsd: np.ndarray = None


@dataclass(frozen=True)
class BatchRigidity:
    """
    Displacement-controlled solves of S scenes (internal; see `rigidity_batch`).

    Attributes
    ----------
    unloaded : BatchOutcome
        The unloaded solves (`tips` of the unloaded states).
    states : ndarray, shape (S,) + unknowns
        Loaded states (the unloaded one where that failed).
    force : ndarray, shape (S,)
        End load magnitude along the direction [N]; NaN where not found.
    iterations : ndarray of int, shape (S,)
        Bordered Newton iterations.
    fraction : ndarray, shape (S,)
        Fraction of the displacement reached.
    stable : ndarray of bool, shape (S,)
        Loaded state stable under force control.
    gradient : ndarray, shape (S,)
        Relative gradient of the loaded state.
    tips : ndarray, shape (S, 2)
        Loaded tip [m]; NaN where not found.

    """

    unloaded: BatchOutcome
    states: np.ndarray
    force: np.ndarray
    iterations: np.ndarray
    fraction: np.ndarray
    stable: np.ndarray
    gradient: np.ndarray
    tips: np.ndarray


def _batch_inputs(problems, loaded, options):
    """Typed list of compiled discretisations, flat state, options and cap; checks them."""
    datas = [_compiled(problem, loaded) for problem in problems]
    if not datas or any(data is None for data in datas):
        raise TypeError('`problems` must be a non-empty sequence of `CompiledProblem`s')
    flat = _flat(problems[0])
    opts, cap = _packed(problems[0], options, flat.shape)
    for problem, data in zip(problems, datas):
        other = _flat(problem)
        if type(data) is not type(datas[0]) or other.shape != flat.shape \
                or _packed(problem, options, flat.shape)[0] != opts \
                or not np.array_equal(_packed(problem, options, flat.shape)[1], cap):
            raise ValueError('`problems` must share one discretisation type, number of '
                             'unknowns and options')
    # One problem's list is built once (building a typed list costs 0.3-0.5 ms).
    datas = _one(problems[0], loaded) if len(problems) == 1 else numba.typed.List(datas)
    return datas, flat, opts, cap


def batch_key(problem, options, loaded):
    """
    Return what scenes must share to be solved in one batch: a hashable key of a problem.

    (data type, unknowns' shape, packed options, step cap) of `problem` under `options`,
    loaded or not; `solve_batch` takes problems of one key.
    """
    data = _compiled(problem, loaded)
    flat = _flat(problem)
    opts, cap = _packed(problem, options, flat.shape)
    return type(data), flat.shape, opts, cap.tobytes()


def _index(design, pressures, count):
    design = np.ascontiguousarray(design, dtype=np.int64)
    pressures = np.ascontiguousarray(pressures, dtype=float)
    if design.shape != pressures.shape or design.ndim != 1:
        raise ValueError('`design` and `pressures` must be 1-d of one length, got shapes '
                         f'{design.shape} and {pressures.shape}')
    if design.size and not (0 <= design.min() and design.max() < count):
        raise ValueError(f'`design` indices must lie in [0, {count})')
    return design, pressures


def solve_batch(problems, design, pressures, nodes, forces, options, initial=None, level=TIP,
                chain=False, wait=True):
    """
    Solves of S independent scenes in compiled loops over both cores (`over_cores`).

    Scene i is `solve(problems[design[i]], pressures[i], loads_i, options, initial[i], level)`,
    loads_i being `forces[i]` at `nodes`: the same arithmetic, so the same answer. With
    `chain`, consecutive scenes of one problem and the same loads form a chain, solved in
    order: each is warm-started from the states of the (up to three) successful scenes
    before it on its chain, extrapolated to its pressure (a quadratic in pressure), and
    solved as `solve` with that warm start (so from flat again where Newton from there
    fails). A warm start changes the iterations, not the answer: it is the same to
    round-off, whatever else the batch holds or however it is split over the cores.

    Parameters
    ----------
    problems : sequence of CompiledProblem
        Of one data type, unknowns' shape and options.
    design : array_like of int, shape (S,)
        Index into `problems` of every scene.
    pressures : array_like, shape (S,)
        [Pa].
    nodes : array_like of int, shape (K,)
        Loaded nodes, shared by all scenes (K = 0: unloaded).
    forces : array_like, shape (S, K, 2)
        [N].
    options : NewtonOptions
    initial : array_like, shape (S,) + unknowns, optional
        Warm starts [scaled units]; None: every scene from the flat state.
    level : {TIP, SHAPE, ALL}
        The outputs of every state (`solves.OUTPUTS`); TIP, the default, costs least.
    chain : bool
        Solve the scenes along their chains, as above (`initial` must then be None);
        the caller orders each chain, by pressure for the fewest iterations.
    wait : bool
        False: return at once, with a function that returns the BatchOutcome when the
        compiled loops, running on other threads meanwhile, are done (`over_cores`).

    Returns
    -------
    BatchOutcome, or a function that returns it

    """
    design, pressures = _index(design, pressures, len(problems))
    nodes = np.ascontiguousarray(nodes, dtype=np.int64).reshape(-1)
    forces = np.ascontiguousarray(forces, dtype=float).reshape(pressures.size, nodes.size, 2)
    datas, flat, opts, cap = _batch_inputs(problems, nodes.size > 0, options)
    if initial is None:
        initial = np.zeros((0,) + flat.shape)
    elif chain:
        raise ValueError('`initial` must be None with `chain`: a chain starts its own scenes')
    else:
        initial = np.ascontiguousarray(initial, dtype=float)
        if initial.shape != (pressures.size,) + flat.shape:
            raise ValueError(f'`initial` must have shape {(pressures.size,) + flat.shape}, '
                             f'got {initial.shape}')
    warm = initial.shape[0] > 0
    starts = _chain_starts(design, forces) if chain else None

    def run(lo, hi):
        return _solve_entry(datas, design[lo:hi], pressures[lo:hi], nodes, forces[lo:hi],
                            initial[lo:hi] if warm else initial, flat, opts, cap,
                            CHAIN if chain else SOLVE, int(level) + NO_ROWS)
    out = over_cores(run, pressures.size, starts, wait)
    return _outcome(*out) if wait else lambda: _outcome(*out())


def _outcome(states, figures, shapes):
    """Return the BatchOutcome of a `_solve_entry` call (its flat output rows: none)."""
    return BatchOutcome(states, figures[:, 10].astype(np.int64),
                        figures[:, 11].astype(np.int64), *figures[:, :4].T, figures[:, 4:6],
                        figures[:, 7] == 1.0, *figures[:, [6, 8, 9]].T)


def _chain_starts(design, forces):
    """Return the scenes that start a chain (`solve_batch`): a new problem or new loads."""
    new = np.ones(design.size, dtype=bool)
    new[1:] = (design[1:] != design[:-1]) | np.any(forces[1:] != forces[:-1], axis=(1, 2))
    return np.flatnonzero(new)


def rigidity_batch(problems, design, pressures, node, direction, displacement, options):
    """
    `rigidity` of S scenes after their cold unloaded solves, compiled over both cores.

    Parameters
    ----------
    problems : sequence of CompiledProblem
        As for `solve_batch`.
    design : array_like of int, shape (S,)
    pressures : array_like, shape (S,)
        [Pa].
    node : int
        Loaded node (the tip).
    direction : array_like (2,)
        Unit load and displacement direction.
    displacement : float
        [m].
    options : NewtonOptions

    Returns
    -------
    BatchRigidity

    """
    design, pressures = _index(design, pressures, len(problems))
    free, flat, opts, cap = _batch_inputs(problems, False, options)
    loaded = _batch_inputs(problems, True, options)[0]
    direction = np.ascontiguousarray(direction, dtype=float)
    cold = np.zeros((0,) + flat.shape)

    def run(lo, hi):
        return _rigidity_entry(free, loaded, design[lo:hi], pressures[lo:hi], int(node),
                               direction, float(displacement), cold, flat, opts, cap, TIP)
    unloaded_x, states, figures, _ = over_cores(run, pressures.size)
    free = figures[:, _CONTROL:_CONTROL + _WIDE]
    unloaded = BatchOutcome(unloaded_x, free[:, 10].astype(np.int64),
                            free[:, 11].astype(np.int64), *free[:, :4].T, free[:, 4:6],
                            free[:, 7] == 1.0)
    force = np.where(figures[:, 6] == 1.0, figures[:, 0], np.nan)
    return BatchRigidity(unloaded, states, force, figures[:, 7].astype(np.int64),
                         figures[:, 1], figures[:, 2] == 1.0, figures[:, 3], figures[:, 4:6])
