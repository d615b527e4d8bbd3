"""The engine's front: its compiled entries, and Newton, solve, rigidity and sensitivity."""

import threading
import weakref

import numpy as np

from .active_set import _contact
from .bordered import _rigidity
from .newton import _derivatives, _newton, _node_jacobian, _solve, _solve_linear
from .outcomes import _STATUS, _SUCCESS, BorderedOutcome, NewtonOutcome
from ..compiled import jit
from ..kernels import ccm as kernels


# -- the compiled entries: what Python calls, one per loop, and the batches -----------------
@jit
def _newton_entry(problem, x, pressure, nodes, forces, options, cap):
    return _newton(problem, x, pressure, nodes, forces, options, cap)


@jit
def _solve_entry(problem, initial, warm, flat, pressure, nodes, forces, options, cap):
    return _solve(problem, initial, warm, flat, pressure, nodes, forces, options, cap)


@jit
def _rigidity_entry(problem, x, pressure, node, direction, displacement, options, cap):
    return _rigidity(problem, x, pressure, node, direction, displacement, options, cap)


# numpy's error model (a division by zero gives inf or nan, which the loops test for) keeps
# the many divisions of the contact code free of exception paths: it compiles in less time.
@jit(error_model='numpy')
def _contact_entry(problem, x, lam, status, depth, pressure, nodes, forces, con, options, cap,
                   grow):
    return _contact(problem, x, lam, status, depth, pressure, nodes, forces, con, options, cap,
                    grow)


# The batches call the single entries, compiled functions of their own, so that each loop
# compiles once per discretisation type whether one scene or a grid runs it.
@jit
def _solve_batch_entry(problems, design, pressures, nodes, forces, initial, flat, options, cap,
                       tip):
    count = pressures.size
    warm = initial.shape[0] > 0
    states = np.empty((count,) + flat.shape)
    status = np.empty(count, dtype=np.int64)
    iterations = np.empty(count, dtype=np.int64)
    figures = np.empty((count, 6))
    for i in range(count):
        problem = problems[design[i]]
        start = initial[i] if warm else flat
        x, code, its, grad, step, eig, fraction = _solve_entry(
            problem, start, warm, flat, pressures[i], nodes, forces[i], options, cap)
        states[i] = x
        status[i] = code
        iterations[i] = its
        position = _node_jacobian(problem, x, tip)[0]
        figures[i, 0] = grad
        figures[i, 1] = step
        figures[i, 2] = eig
        figures[i, 3] = fraction
        figures[i, 4] = position[0]
        figures[i, 5] = position[1]
    return states, status, iterations, figures


@jit
def _rigidity_batch_entry(unloaded, loaded, design, pressures, node, direction, displacement,
                          flat, options, cap):
    count = pressures.size
    free = np.empty((count,) + flat.shape)
    states = np.empty((count,) + flat.shape)
    status = np.empty(count, dtype=np.int64)
    iterations = np.empty((count, 2), dtype=np.int64)
    figures = np.empty((count, 10))
    nodes = np.zeros(0, dtype=np.int64)
    forces = np.zeros((0, 2))
    for i in range(count):
        d = design[i]
        x, code, its, grad, step, eig, fraction = _solve_entry(
            unloaded[d], flat, False, flat, pressures[i], nodes, forces, options, cap)
        free[i] = x
        status[i] = code
        iterations[i, 0] = its
        figures[i, 0] = grad
        figures[i, 1] = step
        figures[i, 2] = eig
        figures[i, 3] = fraction
        figures[i, 4:] = np.nan
        iterations[i, 1] = 0
        states[i] = x
        if code != _SUCCESS:
            continue
        y, force, ok, its, done, stable, gradient = _rigidity_entry(
            loaded[d], x, pressures[i], node, direction, displacement, options, cap)
        position = _node_jacobian(loaded[d], y, node)[0]
        states[i] = y
        iterations[i, 1] = its
        figures[i, 4] = force if ok else np.nan
        figures[i, 5] = done
        figures[i, 6] = 1.0 if stable else 0.0
        figures[i, 7] = gradient
        figures[i, 8] = position[0]
        figures[i, 9] = position[1]
    return free, status, states, iterations, figures


# -- the engine's Python entry points -------------------------------------------------------
def _compiled(problem, loaded):
    """Return the namedtuple a discretisation runs compiled as (`kernel_data`), or None."""
    make = getattr(problem, 'kernel_data', None)
    return None if make is None else make(loaded)


#: What the engine derives once per discretisation (its flat state, its packed options),
#: kept here and not on the discretisation: the engine never writes into a solver. Weak
#: keys, so a solver's entry goes with it.
_DERIVED = weakref.WeakKeyDictionary()
_DERIVED_LOCK = threading.Lock()


def _derived(problem):
    memo = _DERIVED.get(problem)
    if memo is None:
        with _DERIVED_LOCK:
            memo = _DERIVED.setdefault(problem, {'flat': None, 'packed': {}})
    return memo


def _packed(problem, options, shape):
    """Return the loops' options and step cap for `shape` (once per solver and options)."""
    key = (id(options), shape)
    memo = _derived(problem)['packed']
    hit = memo.get(key)
    if hit is None or hit[0] is not options:
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


def _outcome(out, problem, fraction=1.0):
    x, status, iterations, grad, step, eig = out[:6]
    return NewtonOutcome(_own(x, problem), _STATUS[status], iterations, grad, step, eig,
                         out[6] if len(out) > 6 else fraction)


def newton(problem, x, pressure, loads, options):
    """
    Damped Newton on the total potential of a discretisation.

    The loop (`_newton`) is written once: compiled for a discretisation that has
    ``kernel_data(loaded)`` (a namedtuple whose class carries its compiled kernels),
    interpreted with the discretisation's methods otherwise.

    Parameters
    ----------
    problem : discretisation
        Has ``derivatives(x, pressure, loads) -> (energy, gradient, hessian)``,
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
    nodes, forces = kernels.load_arrays(loads)
    opts, cap = _packed(problem, options, x.shape)
    data = _compiled(problem, bool(loads))
    if data is None:
        return _outcome(_newton(problem, x, pressure, nodes, forces, opts, cap), problem)
    return _outcome(_newton_entry(data, x, float(pressure), nodes, forces, opts, cap), problem)


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
    problem : discretisation
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
    flat = _flat(problem)
    warm = initial is not None
    start = np.ascontiguousarray(initial, dtype=float) if warm else flat
    nodes, forces = kernels.load_arrays(loads)
    opts, cap = _packed(problem, options, flat.shape)
    data = _compiled(problem, bool(loads))
    if data is None:
        out = _solve(problem, start, warm, flat, pressure, nodes, forces, opts, cap)
    else:
        out = _solve_entry(data, start, warm, flat, float(pressure), nodes, forces, opts, cap)
    return _outcome(out, problem)


def rigidity(problem, unloaded_x, pressure, node, direction, displacement, options):
    """
    Displacement control: the force along `direction` that moves node `node` by `displacement`.

    A bordered Newton system in (x, f), the force magnitude being the Lagrange
    multiplier of e . O_node = e . O_node(unloaded) + delta, marched in fractions of the
    displacement (whole first, halved on failure down to 1/64).

    Parameters
    ----------
    problem : discretisation
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
    data = _compiled(problem, True)
    if data is None:
        out = _rigidity(problem, x, pressure, int(node), direction, float(displacement), opts,
                        cap)
    else:
        out = _rigidity_entry(data, x, float(pressure), int(node), direction,
                              float(displacement), opts, cap)
    x, force, success, iterations, fraction, stable, gradient = out
    return BorderedOutcome(x, float(force), bool(success), int(iterations), float(fraction),
                           bool(stable), float(gradient))


def sensitivity(problem, x, pressure, loads, control=None):
    """
    Parameter sensitivities of an equilibrium by the implicit function theorem.

    At an equilibrium g(x; theta) = 0 with a non-singular Hessian H, the state moves
    with the parameters as dx/dtheta = -H^-1 dg/dtheta; dg/dtheta is the
    discretisation's ``parameter_gradient(x, pressure, loads)`` (the loads do not depend
    on theta). Under displacement control (`rigidity`'s bordered system: the gradient
    g - f grad c with c = e . O_node, and c(x) = target), the force f moves too:

        H dx - f' grad c = -dg/dtheta,    grad c . dx = d target / d theta,

    so with u = H^-1 dg/dtheta and v = H^-1 grad c, f' = (target' + grad c . u) /
    (grad c . v) and dx = f' v - u. H is the Hessian of the loaded potential there, as
    the bordered Newton uses it.

    Parameters
    ----------
    problem : discretisation
        As for `rigidity`, with ``parameter_gradient(x, pressure, loads) -> (P,) + x.shape``.
    x : ndarray
        The equilibrium [scaled units].
    pressure : float
        [Pa].
    loads : sequence of (int, ndarray (2,))
        The loads of that equilibrium (under displacement control: the found force at
        the node, ``[(node, f e)]``).
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
    nodes, forces = kernels.load_arrays(loads)
    _, _, hess = _derivatives(problem, x, pressure, nodes, forces)
    rates = np.asarray(problem.parameter_gradient(x, pressure, loads), dtype=float)
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
