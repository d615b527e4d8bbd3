"""The engine's front: its compiled entries, and Newton, solve, rigidity and sensitivity."""

import math
import threading
import weakref

import numba
from numba.extending import register_jitable
import numpy as np

from .active_set import _contact
from .bordered import _rigidity
from .newton import _derivatives, _newton, _node_jacobian, _outputs, _solve, _solve_linear
from .outcomes import (_STATUS, _SUCCESS, BorderedOutcome, Fields, NewtonOptions,
                       NewtonOutcome, SolverStatus)
from .problems import CompiledProblem
from ..compiled import jit
from ..kernels.chain import load_arrays
from ..kernels.circle import circle_fit


# -- the compiled entries: what Python calls, S scenes each (a single call is one scene) -----
#: What a call computes besides the states, in the order each adds (`OUTPUTS` names them):
#: the tip and validity; then the chain (nodes, rotations, coefficients), the energy and the
#: samples; then the samples' circle fit.
TIP, SHAPE, ALL = 0, 1, 2
OUTPUTS = ('tip', 'shape', 'all')
#: What the solve entry does with each scene: solve it (warm, cold, continuation), run Newton
#: alone from `initial`, take `initial` as the state and compute its outputs only, or solve
#: it warm from the scenes before it on its chain (`_chain_start`).
SOLVE, NEWTON, GIVEN, CHAIN = 0, 1, 2, 3
#: Added to a level: that level's figures without the flat output rows, for a batch, which
#: returns none (at 129 samples they are 7.6 kB a scene to write and throw away).
NO_ROWS = 4
#: Predecessors on a chain that a chained scene's start is extrapolated from: a quadratic
#: through three, which takes PCC-22 sweeps every 5 kPa from 4 Newton iterations to 2.
_CHAIN_ORDER = 3
#: Columns of the entries' per-scene `figures`: then, in five more, the `_output_sizes`.
FIGURES = ('gradient', 'step', 'min_eig', 'fraction', 'tip_x', 'tip_z', 'energy', 'valid',
           'curvature', 'fit_rmsd', 'status', 'iterations')
#: Width of a scene's figures: `FIGURES` and the output sizes.
_WIDE = len(FIGURES) + 5


@register_jitable
def _put_outputs(i, out, level, figures, base, shapes, offset):
    """
    Store scene i's `_outputs` from column `base` of its figures and `offset` of its shapes.

    Its figures get the tip, validity and output sizes (`_output_sizes`), from SHAPE the
    energy, from ALL the circle fit of its points; from SHAPE its arrays go flat into
    row i of `shapes` (where it has rows): nodes, beta, theta, coefficients, points,
    tangent, strains.
    """
    tip = out[0].shape[0] - 1
    figures[i, base + 4] = out[0][tip, 0]
    figures[i, base + 5] = out[0][tip, 1]
    figures[i, base + 7] = 1.0 if out[4] else 0.0
    sizes = _output_sizes(out)
    for k in range(5):
        figures[i, base + 12 + k] = sizes[k]
    if level < SHAPE:
        return
    figures[i, base + 6] = out[5]
    # A call without rows (`NO_ROWS`) has none to write.
    if shapes.shape[0] > 0:
        k = offset
        for part in (out[0].ravel(), out[1], out[2], out[3].ravel(), out[6].ravel(), out[7],
                     out[8].ravel()):
            for value in part:
                shapes[i, k] = value
                k += 1
    if level >= ALL and out[6].shape[0] >= 3:
        figures[i, base + 8], figures[i, base + 9], _, _ = circle_fit(out[6])


@register_jitable
def _output_sizes(out):
    """(nodes, segments, coefficient rows, samples, strain rows) of one scene's `_outputs`."""
    return (out[0].shape[0], out[1].size, out[3].shape[0], out[6].shape[0], out[8].shape[0])


@register_jitable
def _shape_width(out, level):
    """Return the width of a scene's flat output row (0 below SHAPE)."""
    if level < SHAPE:
        return 0
    nodes, n, rows, m, strain_rows = _output_sizes(out)
    return 2 * nodes + 2 * n + 4 * rows + 3 * m + 3 * strain_rows


@register_jitable
def _same_chain(design, forces, i):
    """Whether scene i continues the chain of scene i - 1: the same problem and loads."""
    if i == 0 or design[i] != design[i - 1]:
        return False
    for k in range(forces.shape[1]):
        if forces[i, k, 0] != forces[i - 1, k, 0] or forces[i, k, 1] != forces[i - 1, k, 1]:
            return False
    return True


@register_jitable
def _chain_start(states, pressures, i, run):
    """
    Start of chained scene i: its `run` predecessors' states extrapolated to its pressure.

    Lagrange's polynomial through (pressure, state) of scenes i - 1 .. i - run, at most
    `_CHAIN_ORDER` of them, fewer where two share a pressure; one is the state itself.
    """
    order = min(run, _CHAIN_ORDER)
    distinct = False
    while not distinct:
        distinct = True
        for a in range(1, order + 1):
            for b in range(1, a):
                if pressures[i - a] == pressures[i - b]:
                    distinct = False
        if not distinct:
            order -= 1
    start = np.zeros_like(states[i - 1])
    for a in range(1, order + 1):
        weight = 1.0
        for b in range(1, order + 1):
            if b != a:
                weight *= (pressures[i] - pressures[i - b]) / (pressures[i - a] - pressures[i - b])
        start += weight * states[i - a]
    return start


@jit
def _solve_entry(problems, design, pressures, nodes, forces, initial, flat, options, cap, mode,
                 level):
    """
    Solve scene i on ``problems[design[i]]`` as `mode` says; its outputs to `level`.

    CHAIN solves the scenes in order, each warm (`_solve`: a failed warm Newton starts
    again cold) from `_chain_start` of the scenes just before it that share its problem
    and loads and succeeded, cold where there are none. Returns the states, their
    figures (S, `_WIDE`: `FIGURES`, then the output sizes) and the flat output rows
    (`_put_outputs`; none below SHAPE, nor with `NO_ROWS` added to the level).
    """
    count = pressures.size
    warm = initial.shape[0] > 0
    rows = level < NO_ROWS
    level = level % NO_ROWS
    states = np.empty((count,) + flat.shape)
    figures = np.full((count, _WIDE), np.nan)
    shapes = np.empty((0, 0))
    run = 0
    for i in range(count):
        problem = problems[design[i]]
        start = initial[i] if warm else flat
        code, its = _SUCCESS, 0
        if mode == GIVEN:
            x = start
        elif mode == NEWTON:
            x, code, its, figures[i, 0], figures[i, 1], figures[i, 2] = _newton(
                problem, start, pressures[i], nodes, forces[i], options, cap)
            figures[i, 3] = 1.0
        else:
            chained = False
            if mode == CHAIN:
                # Successful scenes just before this one on its chain.
                run = run + 1 if _same_chain(design, forces, i) \
                    and figures[i - 1, 10] == _SUCCESS else 0
                chained = run > 0
                if chained:
                    start = _chain_start(states, pressures, i, run)
            x, code, its, figures[i, 0], figures[i, 1], figures[i, 2], figures[i, 3] = _solve(
                problem, start, warm or chained, flat, pressures[i], nodes, forces[i], options,
                cap)
        states[i] = x
        figures[i, 10] = code
        figures[i, 11] = its
        out = _outputs(problem, x, pressures[i], nodes, forces[i], level >= SHAPE)
        if i == 0:
            shapes = np.empty((count if rows and level >= SHAPE else 0,
                               _shape_width(out, level)))
        _put_outputs(i, out, level, figures, 0, shapes, 0)
    return states, figures, shapes


#: Columns of the rigidity entry's own figures, before the two states' (`_WIDE` each).
_CONTROL = 9


@jit
def _rigidity_entry(unloaded, loaded, design, pressures, node, direction, displacement,
                    initial, flat, options, cap, level):
    """
    Scene i: the unloaded `_solve` (warm from ``initial[i]`` if given), then `_rigidity`.

    Returns the unloaded and the loaded states; figures (S, 9 + 2 `_WIDE`): the
    displacement control's (force, fraction, stable, gradient, the loaded node's (X, Z),
    found, iterations, the unloaded solve's iterations), then the unloaded state's and
    the loaded one's (under the found force at `node`) as `_solve_entry`'s; and their flat
    output rows side by side, to `level`.
    """
    count = pressures.size
    warm = initial.shape[0] > 0
    free = np.empty((count,) + flat.shape)
    states = np.empty((count,) + flat.shape)
    figures = np.full((count, _CONTROL + 2 * _WIDE), np.nan)
    shapes = np.empty((0, 0))
    width = 0
    base = _CONTROL + _WIDE
    no_nodes = np.zeros(0, dtype=np.int64)
    no_forces = np.zeros((0, 2))
    tip_nodes = np.full(1, node, dtype=np.int64)
    tip_forces = np.zeros((1, 2))
    for i in range(count):
        d = design[i]
        x, code, its, figures[i, _CONTROL], figures[i, _CONTROL + 1], \
            figures[i, _CONTROL + 2], figures[i, _CONTROL + 3] = _solve(
                unloaded[d], initial[i] if warm else flat, warm, flat, pressures[i], no_nodes,
                no_forces, options, cap)
        figures[i, _CONTROL + 10] = code
        figures[i, _CONTROL + 11] = its
        figures[i, 8] = its
        free[i] = x
        states[i] = x
        out = _outputs(unloaded[d], x, pressures[i], no_nodes, no_forces, level >= SHAPE)
        if i == 0:
            width = _shape_width(out, level)
            shapes = np.empty((count if level >= SHAPE else 0, 2 * width))
        _put_outputs(i, out, level, figures, _CONTROL, shapes, 0)
        if code != _SUCCESS:
            _put_outputs(i, out, level, figures, base, shapes, width)
            continue
        y, force, ok, its, done, stable, gradient = _rigidity(
            loaded[d], x, pressures[i], node, direction, displacement, options, cap)
        position = _node_jacobian(loaded[d], y, node)[0]
        states[i] = y
        figures[i, 0] = force
        figures[i, 1] = done
        figures[i, 2] = 1.0 if stable else 0.0
        figures[i, 3] = gradient
        figures[i, 4] = position[0]
        figures[i, 5] = position[1]
        figures[i, 6] = 1.0 if ok else 0.0
        figures[i, 7] = its
        tip_forces[0, 0] = force * direction[0]
        tip_forces[0, 1] = force * direction[1]
        out = _outputs(loaded[d], y, pressures[i], tip_nodes, tip_forces, level >= SHAPE)
        _put_outputs(i, out, level, figures, base, shapes, width)
    return free, states, figures, shapes


# numpy's error model (a division by zero gives inf or nan, which the loops test for) keeps
# the many divisions of the contact code free of exception paths: it compiles in less time.
@jit(error_model='numpy')
def _contact_entry(problem, x, lam, status, depth, pressure, nodes, forces, con, options, cap,
                   grow):
    return _contact(problem, x, lam, status, depth, pressure, nodes, forces, con, options, cap,
                    grow)


# -- the engine's Python entry points -------------------------------------------------------
def _compiled(problem, loaded):
    """Return the data a `CompiledProblem` runs compiled on, or None (run interpreted)."""
    return problem.data[loaded] if isinstance(problem, CompiledProblem) else None


def _one(problem, loaded):
    """Return a one-item typed list of `_compiled` (the entries take S scenes), or None."""
    memo = _derived(problem)['lists']
    hit = memo.get(loaded)
    if hit is None:
        data = _compiled(problem, loaded)
        if data is None:
            return None
        with _DERIVED_LOCK:
            hit = memo.setdefault(loaded, numba.typed.List([data]))
    return hit


#: The options of a GIVEN call, which runs no Newton (any options of the right types).
_GIVEN_OPTIONS = NewtonOptions()
#: The design index of a one-scene call (read only by the entries).
_SCENE = np.zeros(1, dtype=np.int64)


#: What the engine derives once per discretisation (its flat state, its packed options),
#: kept here and not on the discretisation: the engine never writes into a solver. Weak
#: keys, so a solver's entry goes with it.
_DERIVED = weakref.WeakKeyDictionary()
_DERIVED_LOCK = threading.Lock()
#: Options memoised per problem before the memo starts again (they are keyed by identity).
_MEMO_LIMIT = 32


def _derived(problem):
    if type(problem) is CompiledProblem:
        # The engine's own object carries its memo: no weak reference built per call.
        return problem.derived
    memo = _DERIVED.get(problem)
    if memo is None:
        with _DERIVED_LOCK:
            memo = _DERIVED.setdefault(problem, CompiledProblem.new_memo())
    return memo


def _frame(problem, options, loaded):
    """
    Return what a one-scene `solve` passes besides its scene, once per solver and options.

    (options, flat, packed options, step cap, the one-item data list or None, the empty
    `initial` of a cold scene, and a one-item list that holds `_direct_entry`'s once
    `solve` has resolved it): one memo lookup on the per-command path instead of four.
    """
    frames = _derived(problem)['frames']
    key = (id(options), loaded)
    hit = frames.get(key)
    if hit is None or hit[0] is not options:
        flat = _flat(problem)
        opts, cap = _packed(problem, options, flat.shape)
        datas = _one(problem, loaded)
        none = _no_start(problem, flat) if datas is not None else None
        if len(frames) >= _MEMO_LIMIT:
            frames.clear()  # a caller that builds its options per call must not grow it
        hit = frames[key] = (options, flat, opts, cap, datas, none, [None])
    return hit


def _packed(problem, options, shape):
    """Return the loops' options and step cap for `shape` (once per solver and options)."""
    key = (id(options), shape)
    memo = _derived(problem)['packed']
    hit = memo.get(key)
    if hit is None or hit[0] is not options:
        if len(memo) >= _MEMO_LIMIT:
            memo.clear()
        hit = memo[key] = (options, *options.packed(problem.gradient_scale, shape))
    return hit[1], hit[2]


def _flat(problem):
    """``problem.flat()``, once per solver: the loops never write to their start (`_own`)."""
    memo = _derived(problem)
    if memo['flat'] is None:
        with _DERIVED_LOCK:
            if memo['flat'] is None:
                memo['flat'] = np.ascontiguousarray(problem.flat(), dtype=float)
    return memo['flat']


def _own(x, problem):
    """`x`, copied if it is the solver's shared flat state (a failed first step returns it)."""
    return x.copy() if x is _derived(problem)['flat'] else x


def _no_start(problem, flat):
    """Return the entries' `initial` of a cold scene: no rows."""
    memo = _derived(problem)
    if memo['none'] is None:
        memo['none'] = np.zeros((0,) + flat.shape)
    return memo['none']


def _scene(out, k=0, level=None):
    """Return the `NewtonOutcome` of scene k of a `_solve_entry` call (fields to `level`)."""
    states, figures, shapes = out
    grad, step, eig, fraction = (row := figures[k].tolist())[:4]
    return NewtonOutcome(states[k], _STATUS[int(row[10])], int(row[11]), grad, step, eig,
                         fraction, None if level is None else _fields(row, shapes[k:k + 1],
                                                                      level))


def _fields(figures, shapes, level):
    """
    Return the `Fields` of a state: its `FIGURES` and sizes (a list), and its flat outputs.

    `shapes` starts at the state's first output (the arrays are views of it).
    """
    tip, valid = np.array(figures[4:6]), figures[7] == 1.0
    if level < SHAPE:
        return Fields(tip, None, valid, None, None, None, None, None, None, None, None, None)
    energy, _, curvature, rmsd = figures[6:10]
    n_nodes, n, rows, m, strain_rows = (int(v) for v in figures[12:17])
    row = shapes.reshape(-1)
    a = 2 * n_nodes
    b = a + n
    c = b + n
    d = c + 4 * rows
    e = d + 2 * m
    f = e + m
    fit = level >= ALL
    return Fields(tip, energy, valid, curvature if fit else None, rmsd if fit else None,
                  row[:a].reshape(n_nodes, 2), row[a:b], row[b:c],
                  row[c:d].reshape(rows, 4) if rows else None, row[d:e].reshape(m, 2),
                  row[e:f], row[f:f + 3 * strain_rows].reshape(strain_rows, 3)
                  if strain_rows else None)


def _outcome(out, problem, fraction=1.0):
    x, status, iterations, grad, step, eig = out[:6]
    return NewtonOutcome(_own(x, problem), _STATUS[status], iterations, grad, step, eig,
                         out[6] if len(out) > 6 else fraction)


def newton(problem, x, pressure, loads, options):
    """
    Damped Newton on the total potential of a discretisation.

    The loop (`_newton`) is written once: compiled on a `CompiledProblem` (the data of a
    registered type), interpreted on any other object, through its methods.

    Parameters
    ----------
    problem : CompiledProblem or discretisation
        A discretisation has ``derivatives(x, pressure, loads) -> (energy, gradient, hessian)``,
        ``energy(x, pressure, loads)``, ``step(gradient, hessian) -> (dx, min_eig)`` and
        ``gradient_scale``; `x` and the gradient share a shape, the Hessian is opaque to
        the engine.
    x : ndarray
        Start [scaled units].
    pressure : float
        Gauge pressure [Pa].
    loads : sequence of (int, ndarray (2,))
        Node index and force (F_X, F_Z) [N].
    options : NewtonOptions

    Returns
    -------
    NewtonOutcome
        SUCCESS when max|g|/scale <= gtol and the last step <= xtol with a positive-definite
        Hessian (the returned state includes that last step); UNSTABLE for a converged
        saddle; otherwise why it stopped.

    References
    ----------
    docs/physics.md, section 8.

    """
    x = np.ascontiguousarray(x, dtype=float)
    nodes, forces = load_arrays(loads)
    opts, cap = _packed(problem, options, x.shape)
    datas = _one(problem, bool(loads))
    if datas is None:
        return _outcome(_newton(problem, x, pressure, nodes, forces, opts, cap), problem)
    return _scene(_solve_entry(datas, _SCENE, np.array((float(pressure),)), nodes, forces[None],
                               x[None], x, opts, cap, NEWTON, TIP))


def solve(problem, pressure, loads, options, initial=None, level=ALL):
    """
    Equilibrium at a pressure and loads: warm start, else Newton from flat, else continuation.

    A warm start only saves iterations: if Newton from it does not reach a stable
    equilibrium, the solve starts again exactly as a fresh one, so the answer never
    depends on what was solved before. A fresh solve is Newton from ``problem.flat()``;
    if that fails (neither SUCCESS nor UNSTABLE), pressure and loads are marched from
    the unloaded state to the target, doubling or halving the load fraction step (1/4
    first, 1/256 smallest).

    Parameters
    ----------
    problem : CompiledProblem or discretisation
        See `newton`; also ``flat()`` (the unstrained state).
    pressure : float
        Gauge pressure [Pa].
    loads : sequence of (int, ndarray (2,))
        Node index and force [N].
    options : NewtonOptions
    initial : ndarray, optional
        Warm start [scaled units].
    level : {TIP, SHAPE, ALL}
        The outputs computed with the state, in the same compiled call (`OUTPUTS`).

    Returns
    -------
    NewtonOutcome
        `iterations` counts every Newton iteration spent; CONTINUATION_FAILED carries the
        fraction of the loading reached. Its `fields` are the state's outputs to `level`;
        None for a problem run interpreted, whose own code computes them.

    """
    _, flat, opts, cap, datas, none, direct = _frame(problem, options, bool(loads))
    warm = initial is not None
    start = np.ascontiguousarray(initial, dtype=float) if warm else flat
    if warm and start.shape != flat.shape:
        raise ValueError(f'`initial` has shape {start.shape}; the state has {flat.shape}')
    nodes, forces = load_arrays(loads)
    if datas is None:
        return _outcome(_solve(problem, start, warm, flat, pressure, nodes, forces, opts, cap),
                        problem)
    args = (datas, _SCENE, np.array((float(pressure),)), nodes, forces[None],
            start[None] if warm else none, flat, opts, cap, SOLVE, level)
    entry = direct[0]
    if entry:
        return _scene(entry(*args), 0, level)
    out = _solve_entry(*args)
    if entry is None:
        direct[0] = _direct_entry(_solve_entry, args)
    return _scene(out, 0, level)


def _direct_entry(dispatcher, args):
    """
    Return the compiled overload of `dispatcher` for these arguments, to call undispatched.

    numba's dispatcher types every argument on every call, and the typed list of problems
    is typed in Python: about 0.9 us of a 20 us warm CCM-8 solve. `solve` builds a
    frame's arguments with the same types every call (float64 C-contiguous arrays of the
    state's shape, the frame's own list and options), so the overload that the dispatcher
    chose for them once is called directly after. False where the build has no overload
    of exactly these types (the dispatcher then keeps choosing).
    """
    compiled = dispatcher.overloads.get(tuple(dispatcher.typeof_pyval(a) for a in args))
    return False if compiled is None else compiled.entry_point


def outputs(problem, states, pressures, loads, level=ALL):
    """
    Compute the outputs of given states of a compiled problem, as `solve` does with its own.

    Parameters
    ----------
    problem : CompiledProblem
    states : ndarray, shape (S,) + unknowns
    pressures : sequence of float
        [Pa], one per state.
    loads : sequence of (int, ndarray (S, 2))
        Node index and each state's force there [N].
    level : {TIP, SHAPE, ALL}

    Returns
    -------
    list of Fields

    """
    states = np.ascontiguousarray(states, dtype=float)
    loaded = bool(loads)
    flat = _flat(problem)
    opts, cap = _packed(problem, _GIVEN_OPTIONS, flat.shape)
    count = states.shape[0]
    nodes = np.array([node for node, _ in loads], dtype=np.int64)
    forces = np.zeros((count, len(loads), 2))
    for j, (_, force) in enumerate(loads):
        forces[:, j] = force
    out = _solve_entry(_one(problem, loaded), np.zeros(count, dtype=np.int64),
                       np.asarray(pressures, dtype=float), nodes, forces, states, flat, opts, cap,
                       GIVEN, level)
    return [_fields(out[1][k].tolist(), out[2][k:k + 1], level) for k in range(count)]


def rigidity(problem, pressure, node, direction, displacement, options, initial=None,
             level=TIP):
    """
    Displacement control: the force along `direction` that moves node `node` by `displacement`.

    First the unloaded equilibrium, as `solve` finds it (from `initial` as a warm start);
    then a bordered Newton system in (x, f), the force magnitude being the Lagrange
    multiplier of e . O_node = e . O_node(unloaded) + delta, marched in fractions of the
    displacement (whole first, halved on failure down to 1/64).

    Parameters
    ----------
    problem : CompiledProblem or discretisation
        See `newton`; also ``node_jacobian(x, node) -> (position (2,), d position/dx)``
        and ``solve_linear(hessian, rhs)`` (raises LinAlgError when singular).
    pressure : float
        [Pa].
    node : int
        Loaded node (the tip).
    direction : ndarray (2,)
        Unit load and displacement direction e.
    displacement : float
        delta [m].
    options : NewtonOptions
    initial : ndarray, optional
        Warm start of the unloaded solve [scaled units].
    level : {TIP, SHAPE, ALL}
        The outputs of both states, as `solve`'s.

    Returns
    -------
    BorderedOutcome
        The loaded state, with its `unloaded` solve; `fields` (and the unloaded one's) to
        `level`, None for a problem run interpreted. Where the unloaded solve failed:
        success False, the unloaded state, and NaN force and tip.

    References
    ----------
    Zhou, Headings, Dapino (2022), eq. (22); docs/physics.md, section 10.

    """
    direction = np.ascontiguousarray(direction, dtype=float)
    _, flat, opts, cap, free, none, _ = _frame(problem, options, False)
    warm = initial is not None
    start = np.ascontiguousarray(initial, dtype=float) if warm else flat
    if free is None:
        no_nodes, no_forces = load_arrays([])
        unloaded = _outcome(_solve(problem, start, warm, flat, pressure, no_nodes, no_forces,
                                   opts, cap), problem)
        if unloaded.status is not SolverStatus.SUCCESS:
            return _not_loaded(unloaded)
        out = _rigidity(problem, unloaded.x, pressure, int(node), direction,
                        float(displacement), opts, cap)
        tip = np.asarray(_node_jacobian(problem, out[0], int(node))[0], dtype=float)
        return _bordered(out, tip, unloaded)
    out = _rigidity_entry(free, _one(problem, True), _SCENE, np.array((float(pressure),)),
                          int(node), direction, float(displacement),
                          start[None] if warm else none, flat, opts, cap, level)
    unloaded_x, states, figures, shapes = out
    row = figures[0].tolist()
    free, loaded = row[_CONTROL:_CONTROL + _WIDE], row[_CONTROL + _WIDE:]
    width = shapes.shape[1] // 2
    grad, step, eig, fraction = free[:4]
    unloaded = NewtonOutcome(unloaded_x[0], _STATUS[int(free[10])], int(free[11]), grad, step,
                             eig, fraction, _fields(free, shapes[:1, :width], level))
    if unloaded.status is not SolverStatus.SUCCESS:
        return _not_loaded(unloaded)
    force, done, stable, gradient, tip_x, tip_z, found, its, _ = row[:_CONTROL]
    return _bordered((states[0], force, found == 1.0, its, done, stable == 1.0, gradient),
                     np.array((tip_x, tip_z)), unloaded,
                     _fields(loaded, shapes[:1, width:], level))


def _not_loaded(unloaded):
    """Return the outcome of a rigidity whose unloaded solve failed."""
    return BorderedOutcome(unloaded.x, math.nan, False, 0, 0.0, False, math.nan,
                           np.full(2, np.nan), unloaded)


def _bordered(out, tip, unloaded=None, fields=None):
    x, force, success, iterations, fraction, stable, gradient = out
    return BorderedOutcome(x, float(force), bool(success), int(iterations), float(fraction),
                           bool(stable), float(gradient), tip, unloaded, fields)


def sensitivity(problem, x, pressure, loads, rates, control=None):
    """
    Parameter sensitivities of an equilibrium by the implicit function theorem.

    At an equilibrium g(x; theta) = 0 with a non-singular Hessian H, the state moves
    with the parameters as dx/dtheta = -H^-1 dg/dtheta; dg/dtheta are the `rates` (the
    discretisation's ``parameter_gradient(x, pressure, loads)``; the loads do not depend
    on theta). Under displacement control (`rigidity`'s bordered system: the gradient
    g - f grad c with c = e . O_node, and c(x) = target), the force f moves too:

        H dx - f' grad c = -dg/dtheta,    grad c . dx = d target / d theta,

    so with u = H^-1 dg/dtheta and v = H^-1 grad c, f' = (target' + grad c . u) /
    (grad c . v) and dx = f' v - u. H is the Hessian of the loaded potential there, as
    the bordered Newton uses it.

    Parameters
    ----------
    problem : CompiledProblem or discretisation
        As for `rigidity`.
    x : ndarray
        The equilibrium [scaled units].
    pressure : float
        [Pa].
    loads : sequence of (int, ndarray (2,))
        The loads of that equilibrium (under displacement control: the found force at
        the node, ``[(node, f e)]``).
    rates : ndarray, shape (P,) + x.shape
        dg/dtheta at the equilibrium [J per unit of each parameter].
    control : (int, ndarray (2,), ndarray (P,)), optional
        Displacement control: the node, the unit direction e, and d target / d theta
        (the rate of e . O_node of the unloaded state plus delta) [m per unit].

    Returns
    -------
    dx : ndarray, shape (P,) + x.shape
        d x / d theta [scaled units per unit of each parameter].
    dforce : ndarray, shape (P,) or None
        d f / d theta under displacement control [N per unit], None without.

    Raises
    ------
    numpy.linalg.LinAlgError
        Where H (or the bordered system) is singular: the equilibrium does not move
        smoothly with the parameters.

    References
    ----------
    docs/physics.md, section 14.

    """
    x = np.ascontiguousarray(x, dtype=float)
    nodes, forces = load_arrays(loads)
    _, _, hess = _derivatives(problem, x, pressure, nodes, forces)
    rates = np.asarray(rates, dtype=float)
    solved = np.empty_like(rates)
    for k, rate in enumerate(rates):
        solved[k], ok = _solve_linear(problem, hess, np.ascontiguousarray(rate))
        if not ok:
            raise np.linalg.LinAlgError('the Hessian is singular at this equilibrium')
    if control is None:
        return -solved, None
    node, direction, target_rate = control
    jacobian = _node_jacobian(problem, x, node)[1]
    grad_c = direction[0] * jacobian[0] + direction[1] * jacobian[1]
    along, ok = _solve_linear(problem, hess, np.ascontiguousarray(grad_c))
    denominator = float(np.sum(grad_c * along))
    if not (ok and np.isfinite(denominator) and denominator != 0.0):
        raise np.linalg.LinAlgError('the bordered system is singular at this equilibrium')
    axes = tuple(range(1, solved.ndim))
    dforce = (np.asarray(target_rate, dtype=float) + np.tensordot(solved, grad_c, axes=(
        axes, tuple(range(grad_c.ndim))))) / denominator
    dx = dforce.reshape((-1,) + (1,) * grad_c.ndim) * along - solved
    return dx, dforce
