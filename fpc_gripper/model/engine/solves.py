"""The engine's front: its compiled entries, and Newton, solve, rigidity and sensitivity."""

import threading
import weakref

import numba
import numpy as np

from .active_set import _contact
from .bordered import _rigidity
from .newton import _derivatives, _newton, _node_jacobian, _solve, _solve_linear
from .outcomes import _STATUS, _SUCCESS, BorderedOutcome, NewtonOutcome
from .problems import CompiledProblem
from ..compiled import jit
from ..kernels.chain import load_arrays


# -- the compiled entries: what Python calls, S scenes each (a single call is one scene) -----
@jit
def _solve_entry(problems, design, pressures, nodes, forces, initial, flat, options, cap, tip,
                 newton_only):
    """
    Solve scene i by `_solve` on ``problems[design[i]]``, or by `_newton` alone.

    `_newton` runs from ``initial[i]`` where `newton_only`; the tip's position is returned
    where ``tip >= 0``.
    """
    count = pressures.size
    warm = initial.shape[0] > 0
    states = np.empty((count,) + flat.shape)
    status = np.empty(count, dtype=np.int64)
    iterations = np.empty(count, dtype=np.int64)
    figures = np.full((count, 6), np.nan)
    for i in range(count):
        problem = problems[design[i]]
        start = initial[i] if warm else flat
        if newton_only:
            x, code, its, grad, step, eig = _newton(problem, start, pressures[i], nodes,
                                                    forces[i], options, cap)
            fraction = 1.0
        else:
            x, code, its, grad, step, eig, fraction = _solve(
                problem, start, warm, flat, pressures[i], nodes, forces[i], options, cap)
        states[i] = x
        status[i] = code
        iterations[i] = its
        figures[i, 0] = grad
        figures[i, 1] = step
        figures[i, 2] = eig
        figures[i, 3] = fraction
        if tip >= 0:
            position = _node_jacobian(problem, x, tip)[0]
            figures[i, 4] = position[0]
            figures[i, 5] = position[1]
    return states, status, iterations, figures


@jit
def _rigidity_entry(unloaded, loaded, design, pressures, node, direction, displacement,
                    initial, flat, options, cap):
    """Run `_rigidity` of scene i from ``initial[i]``, or from a cold unloaded `_solve`."""
    count = pressures.size
    given = initial.shape[0] > 0
    free = np.empty((count,) + flat.shape)
    states = np.empty((count,) + flat.shape)
    status = np.empty(count, dtype=np.int64)
    iterations = np.zeros((count, 2), dtype=np.int64)
    figures = np.full((count, 11), np.nan)
    nodes = np.zeros(0, dtype=np.int64)
    forces = np.zeros((0, 2))
    for i in range(count):
        d = design[i]
        if given:
            x = initial[i]
            code = _SUCCESS
        else:
            x, code, its, grad, step, eig, fraction = _solve(
                unloaded[d], flat, False, flat, pressures[i], nodes, forces, options, cap)
            iterations[i, 0] = its
            figures[i, 0] = grad
            figures[i, 1] = step
            figures[i, 2] = eig
            figures[i, 3] = fraction
        free[i] = x
        status[i] = code
        states[i] = x
        if code != _SUCCESS:
            continue
        y, force, ok, its, done, stable, gradient = _rigidity(
            loaded[d], x, pressures[i], node, direction, displacement, options, cap)
        position = _node_jacobian(loaded[d], y, node)[0]
        states[i] = y
        iterations[i, 1] = its
        figures[i, 4] = force
        figures[i, 5] = done
        figures[i, 6] = 1.0 if stable else 0.0
        figures[i, 7] = gradient
        figures[i, 8] = position[0]
        figures[i, 9] = position[1]
        figures[i, 10] = 1.0 if ok else 0.0
    return free, status, states, iterations, figures


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
    `initial` of a cold scene): one memo lookup on the per-command path instead of four.
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
        hit = frames[key] = (options, flat, opts, cap, datas, none)
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


def _scene(out):
    """Return the `NewtonOutcome` of a one-scene `_solve_entry`."""
    states, status, iterations, figures = out
    grad, step, eig, fraction = figures[0, :4].tolist()
    return NewtonOutcome(states[0], _STATUS[status.item()], iterations.item(), grad, step, eig,
                         fraction)


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
                               x[None], x, opts, cap, -1, True))


def solve(problem, pressure, loads, options, initial=None):
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

    Returns
    -------
    NewtonOutcome
        `iterations` counts every Newton iteration spent; CONTINUATION_FAILED carries the
        fraction of the loading reached.

    """
    _, flat, opts, cap, datas, none = _frame(problem, options, bool(loads))
    warm = initial is not None
    start = np.ascontiguousarray(initial, dtype=float) if warm else flat
    nodes, forces = load_arrays(loads)
    if datas is None:
        return _outcome(_solve(problem, start, warm, flat, pressure, nodes, forces, opts, cap),
                        problem)
    return _scene(_solve_entry(datas, _SCENE, np.array((float(pressure),)), nodes, forces[None],
                               start[None] if warm else none, flat, opts, cap, -1, False))


def rigidity(problem, unloaded_x, pressure, node, direction, displacement, options):
    """
    Displacement control: the force along `direction` that moves node `node` by `displacement`.

    A bordered Newton system in (x, f), the force magnitude being the Lagrange
    multiplier of e . O_node = e . O_node(unloaded) + delta, marched in fractions of the
    displacement (whole first, halved on failure down to 1/64).

    Parameters
    ----------
    problem : CompiledProblem or discretisation
        See `newton`; also ``node_jacobian(x, node) -> (position (2,), d position/dx)``
        and ``solve_linear(hessian, rhs)`` (raises LinAlgError when singular).
    unloaded_x : ndarray
        Converged unloaded state.
    pressure : float
        [Pa].
    node : int
        Loaded node (the tip).
    direction : ndarray (2,)
        Unit load and displacement direction e.
    displacement : float
        delta [m].
    options : NewtonOptions

    Returns
    -------
    BorderedOutcome

    References
    ----------
    Zhou, Headings, Dapino (2022), eq. (22); docs/physics.md, section 10.

    """
    x = np.ascontiguousarray(unloaded_x, dtype=float)
    direction = np.ascontiguousarray(direction, dtype=float)
    opts, cap = _packed(problem, options, x.shape)
    loaded = _one(problem, True)
    if loaded is None:
        out = _rigidity(problem, x, pressure, int(node), direction, float(displacement), opts,
                        cap)
        tip = np.asarray(_node_jacobian(problem, out[0], int(node))[0], dtype=float)
    else:
        _, _, states, its, figures = _rigidity_entry(
            _one(problem, False), loaded, _SCENE, np.array((float(pressure),)), int(node),
            direction, float(displacement), x[None], x, opts, cap)
        tip = figures[0, 8:10]
        figure = figures[0].tolist()
        out = (states[0], figure[4], figure[10] == 1.0, its[0, 1], figure[5], figure[6] == 1.0,
               figure[7])
    x, force, success, iterations, fraction, stable, gradient = out
    return BorderedOutcome(x, float(force), bool(success), int(iterations), float(fraction),
                           bool(stable), float(gradient), tip)


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
