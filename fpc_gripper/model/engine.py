"""The one equilibrium engine: damped Newton, continuation and displacement control."""

from dataclasses import dataclass
import enum
import math
import pathlib
import typing

import numba
from numba import types
from numba.extending import overload, register_jitable
import numpy as np

from . import kernels

__all__ = ['SolverStatus', 'NewtonOptions', 'NewtonOutcome', 'newton', 'solve', 'rigidity',
           'linear_step', 'linear_solve', 'BorderedOutcome', 'solve_batch', 'rigidity_batch',
           'BatchOutcome', 'sensitivity']


class SolverStatus(enum.IntEnum):
    """Outcome of a solve; only SUCCESS has success=True."""

    SUCCESS = 0
    MAX_ITERATIONS = 1
    LINE_SEARCH_FAILED = 2
    NOT_FINITE = 3
    UNSTABLE = 4
    CONTINUATION_FAILED = 5


# The loops below compare plain ints: numba compiles them as constants.
_SUCCESS = int(SolverStatus.SUCCESS)
_MAX_ITERATIONS = int(SolverStatus.MAX_ITERATIONS)
_LINE_SEARCH_FAILED = int(SolverStatus.LINE_SEARCH_FAILED)
_NOT_FINITE = int(SolverStatus.NOT_FINITE)
_UNSTABLE = int(SolverStatus.UNSTABLE)
_CONTINUATION_FAILED = int(SolverStatus.CONTINUATION_FAILED)


@dataclass(frozen=True)
class NewtonOptions:
    """
    Tolerances and safeguards of the damped Newton, in a discretisation's scaled unknowns.

    Attributes
    ----------
    max_iterations : int
        Newton iterations per (sub)solve.
    gtol : float
        Largest max|gradient| / gradient_scale at convergence (inf: not checked).
    xtol : float
        Largest final Newton step, max|dx| [scaled units].
    max_step : float or ndarray
        Cap on each component of a step (broadcast to the unknowns): Newton stays local,
        where the quintic PEMC energy (unbounded below at large tension) is meaningful.
    flat_slope : float
        Near the solution the energy change is below round-off: a full step is taken
        when -slope <= flat_slope * (|E| + energy_scale).
    energy_scale : float
        Energy scale of that test [J].
    armijo : float
        Sufficient-decrease constant of the backtracking line search.

    """

    max_iterations: int = 60
    gtol: float = math.inf
    xtol: float = 1e-9
    max_step: object = 0.5
    flat_slope: float = 1e-13
    energy_scale: float = 1.0
    armijo: float = 1e-4

    def packed(self, gradient_scale, shape):
        """Return the options as the loops take them: a tuple and the step cap of `shape`."""
        cap = np.ascontiguousarray(np.broadcast_to(np.asarray(self.max_step, dtype=float),
                                                   shape))
        return (int(self.max_iterations), float(self.gtol), float(self.xtol),
                float(self.flat_slope), float(self.energy_scale), float(self.armijo),
                float(gradient_scale)), cap


class NewtonOutcome(typing.NamedTuple):
    """State and figures of one Newton run (internal: solvers build their results from it)."""

    x: np.ndarray
    status: SolverStatus
    iterations: int
    gradient: float
    step: float
    min_eig: float = math.nan
    fraction: float = 1.0


#: SolverStatus by code, without the enum's own lookup on every solve.
_STATUS = tuple(SolverStatus)


@dataclass(frozen=True)
class BorderedOutcome:
    """Loaded state of a displacement-controlled solve (internal)."""

    x: np.ndarray
    force: float
    success: bool
    iterations: int
    fraction: float
    stable: bool
    gradient: float


def linear_step(grad, hess, floor=kernels.EIGEN_FLOOR):
    """
    Newton step -H^-1 g, and the smallest eigenvalue's sign (1.0 when positive definite).

    Where H is not positive definite its eigenvalues are mirrored (|lambda|, floored at
    `floor` times the largest) so that the step still descends; the smallest eigenvalue
    is returned. H is dense (n, n), or (N, m, m) blocks for g of shape (N, m). Compiled
    (`kernels.newton_step`).
    """
    return kernels.newton_step(grad, hess, floor)


def linear_solve(hess, rhs):
    """Solve H x = rhs for a dense (n, n) or block (N, m, m) H; LinAlgError if singular."""
    if hess.ndim == 3:
        return np.linalg.solve(hess, rhs[:, :, None])[:, :, 0]
    return np.linalg.solve(hess, rhs.ravel()).reshape(rhs.shape)


# -- the discretisation interface ----------------------------------------------------------
# A discretisation is either a Python object with methods (the loops then run interpreted)
# or a namedtuple of arrays whose class carries `_kernels`, a dict of compiled functions of
# the same names taking the namedtuple first (the loops then run compiled, for that
# namedtuple type). These five functions are that interface; the loops call nothing else.
def _loads(nodes, forces):
    return [(int(node), forces[k]) for k, node in enumerate(nodes)]


def _derivatives(problem, x, pressure, nodes, forces):
    """Energy [J], gradient (shape of x) and Hessian (opaque to the engine) at x."""
    return problem.derivatives(x, pressure, _loads(nodes, forces))


def _energy(problem, x, pressure, nodes, forces):
    """Total potential [J] at x."""
    return problem.energy(x, pressure, _loads(nodes, forces))


def _step(problem, grad, hess):
    """Newton step (shape of grad) and the smallest eigenvalue (1.0 when H is PD)."""
    return problem.step(grad, hess)


def _solve_linear(problem, hess, rhs):
    """Solve H x = rhs: (x, True), or (anything, False) where H is singular."""
    try:
        return problem.solve_linear(hess, rhs), True
    except np.linalg.LinAlgError:
        return rhs, False


def _node_jacobian(problem, x, node):
    """Position (2,) of a node [m] and its derivatives, shape (2,) + x.shape."""
    return problem.node_jacobian(x, node)


def _kernel(problem, name):
    """Return the compiled `name` of a namedtuple discretisation type, None for others."""
    if isinstance(problem, types.BaseNamedTuple):
        return getattr(problem.instance_class, '_kernels', {}).get(name)
    return None


@overload(_derivatives, jit_options={'nogil': True})
def _derivatives_compiled(problem, x, pressure, nodes, forces):
    kernel = _kernel(problem, 'derivatives')
    if kernel is not None:
        return lambda problem, x, pressure, nodes, forces: kernel(problem, x, pressure, nodes,
                                                                  forces)
    return None


@overload(_energy, jit_options={'nogil': True})
def _energy_compiled(problem, x, pressure, nodes, forces):
    kernel = _kernel(problem, 'energy')
    if kernel is not None:
        return lambda problem, x, pressure, nodes, forces: kernel(problem, x, pressure, nodes,
                                                                  forces)
    return None


@overload(_step, jit_options={'nogil': True})
def _step_compiled(problem, grad, hess):
    kernel = _kernel(problem, 'step')
    if kernel is not None:
        return lambda problem, grad, hess: kernel(problem, grad, hess)
    return None


@overload(_solve_linear, jit_options={'nogil': True})
def _solve_linear_compiled(problem, hess, rhs):
    kernel = _kernel(problem, 'solve_linear')
    if kernel is not None:
        return lambda problem, hess, rhs: kernel(problem, hess, rhs)
    return None


@overload(_node_jacobian, jit_options={'nogil': True})
def _node_jacobian_compiled(problem, x, node):
    kernel = _kernel(problem, 'node_jacobian')
    if kernel is not None:
        return lambda problem, x, node: kernel(problem, x, node)
    return None


# Reductions of the loops: numpy when interpreted, allocation-free loops when compiled.
def _max_abs(a):
    """Return max |a|, 0 for an empty array."""
    return float(np.abs(a).max()) if a.size else 0.0


def _max_ratio(a, cap):
    """Return max |a| / cap, cap elementwise of a's shape; 0 for an empty array."""
    return float((np.abs(a) / cap).max()) if a.size else 0.0


def _dot(a, b):
    """Return the sum of a * b over all elements."""
    return float(np.vdot(a, b))


@overload(_max_abs, jit_options={'nogil': True})
def _max_abs_compiled(a):
    def impl(a):
        out = 0.0
        for value in a.flat:
            if value != value:
                # max() would drop a NaN: the loops test this figure for finiteness.
                return np.nan
            out = max(out, abs(value))
        return out
    return impl


@overload(_max_ratio, jit_options={'nogil': True})
def _max_ratio_compiled(a, cap):
    def impl(a, cap):
        out = 0.0
        flat_cap = cap.ravel()
        k = 0
        for value in a.flat:
            out = max(out, abs(value) / flat_cap[k])
            k += 1
        return out
    return impl


@overload(_dot, jit_options={'nogil': True})
def _dot_compiled(a, b):
    def impl(a, b):
        out = 0.0
        flat_b = b.ravel()
        k = 0
        for value in a.flat:
            out += value * flat_b[k]
            k += 1
        return out
    return impl


# -- the loops: each written once, run compiled or interpreted -----------------------------
@register_jitable
def _newton(problem, x, pressure, nodes, forces, options, cap):
    """Damped Newton: (x, status, iterations, gradient, step, min_eig); see `newton`."""
    max_iterations, gtol, xtol, flat_slope, energy_scale, armijo, scale = options
    step_norm = np.inf
    grad_rel = np.inf
    energy, grad, hess = _derivatives(problem, x, pressure, nodes, forces)
    for iteration in range(1, max_iterations + 1):
        grad_rel = _max_abs(grad) / scale
        if not (np.isfinite(energy) and np.isfinite(grad_rel)):
            return x, _NOT_FINITE, iteration, grad_rel, step_norm, np.nan
        step, min_eig = _step(problem, grad, hess)
        step_norm = _max_abs(step)
        if not np.isfinite(step_norm):
            return x, _NOT_FINITE, iteration, grad_rel, step_norm, np.nan
        if grad_rel <= gtol and step_norm <= xtol:
            status = _SUCCESS if min_eig > 0.0 else _UNSTABLE
            return x + step, status, iteration, grad_rel, step_norm, min_eig
        ratio = _max_ratio(step, cap)
        if ratio > 1.0:
            step = step / ratio
        slope = _dot(grad, step)
        if not slope < 0.0:
            step = -grad / scale
            slope = -_dot(grad, grad) / scale
        trial = x + step
        e_trial, g_trial, h_trial = _derivatives(problem, trial, pressure, nodes, forces)
        flat = -slope <= flat_slope * (abs(energy) + energy_scale)
        if e_trial <= energy + armijo * slope or flat:
            x, energy, grad, hess = trial, e_trial, g_trial, h_trial
            step_norm = _max_abs(step)
            continue
        alpha = 0.5
        while True:
            trial = x + alpha * step
            if _energy(problem, trial, pressure, nodes, forces) <= energy + armijo * alpha * slope:
                break
            alpha *= 0.5
            if alpha < 1e-10:
                return x, _LINE_SEARCH_FAILED, iteration, grad_rel, step_norm, min_eig
        x = trial
        step_norm = alpha * _max_abs(step)
        energy, grad, hess = _derivatives(problem, x, pressure, nodes, forces)
    return x, _MAX_ITERATIONS, max_iterations, grad_rel, step_norm, np.nan


@register_jitable
def _solve(problem, initial, warm, flat, pressure, nodes, forces, options, cap):
    """Warm, cold, then continuation: `_newton`'s tuple and the fraction; see `solve`."""
    spent = 0
    if warm:
        x, status, its, grad, step, eig = _newton(problem, initial, pressure, nodes, forces,
                                                  options, cap)
        if status == _SUCCESS:
            return x, status, its, grad, step, eig, 1.0
        spent = its
    x, status, its, grad, step, eig = _newton(problem, flat, pressure, nodes, forces, options,
                                              cap)
    spent += its
    if status == _SUCCESS or status == _UNSTABLE:
        return x, status, spent, grad, step, eig, 1.0
    x, status, its, grad, step, eig = _newton(problem, flat, 0.0, nodes[:0], forces[:0],
                                              options, cap)
    spent += its
    if status != _SUCCESS:
        return x, _CONTINUATION_FAILED, spent, np.inf, np.inf, np.nan, 0.0
    lam = 0.0
    dlam = 0.25
    while True:
        target = min(1.0, lam + dlam)
        sub, status, its, grad, step, eig = _newton(problem, x, target * pressure, nodes,
                                                    target * forces, options, cap)
        spent += its
        if status == _SUCCESS:
            x, lam = sub, target
            dlam = min(2.0 * dlam, 1.0)
            if lam >= 1.0:
                return x, status, spent, grad, step, eig, 1.0
        else:
            dlam *= 0.5
            if dlam < 1.0 / 256:
                return x, _CONTINUATION_FAILED, spent, grad, step, np.nan, lam


@register_jitable
def _bordered_newton(problem, x, force, pressure, node, direction, target, options, cap):
    """Solve grad Pi(x; f e) = 0 and e . O_node(x) = target for (x, f): (x, f, ok, its)."""
    max_iterations, gtol, xtol, _, _, _, scale = options
    nodes = np.full(1, node)
    for iteration in range(1, max_iterations + 1):
        forces = (force * direction).reshape(1, 2)
        _, residual, hess = _derivatives(problem, x, pressure, nodes, forces)
        position, jacobian = _node_jacobian(problem, x, node)
        # The potential of a unit load along e is -e . O: its gradient borders the system.
        border = -(direction[0] * jacobian[0] + direction[1] * jacobian[1])
        gap = direction[0] * position[0] + direction[1] * position[1] - target
        a, ok_a = _solve_linear(problem, hess, -residual)
        b, ok_b = _solve_linear(problem, hess, border)
        if not (ok_a and ok_b):
            return x, force, False, iteration
        denominator = np.sum(border * b)
        if not (np.isfinite(denominator) and denominator != 0.0):
            return x, force, False, iteration
        # H dx + border df = -r and border . dx = gap.
        dforce = (np.sum(border * a) - gap) / denominator
        dx = a - dforce * b
        step = np.abs(dx).max() if dx.size else 0.0
        if not (np.isfinite(step) and np.isfinite(dforce)):
            return x, force, False, iteration
        if (np.abs(dx) / cap).max() > 1.0:
            return x, force, False, iteration
        x = x + dx
        force = force + dforce
        balanced = not np.isfinite(gtol) or np.abs(residual).max() / scale <= gtol
        if balanced and step <= xtol and abs(gap) <= 1e-12 * max(abs(target), 1e-3):
            return x, force, True, iteration
    return x, force, False, max_iterations


@register_jitable
def _rigidity(problem, x, pressure, node, direction, displacement, options, cap):
    """Displacement control: (x, force, success, its, fraction, stable, gradient)."""
    force = 0.0
    position = _node_jacobian(problem, x, node)[0]
    start = direction[0] * position[0] + direction[1] * position[1]
    done = 0.0
    iterations = 0
    increment = 1.0
    while done < 1.0:
        goal = min(1.0, done + increment)
        x_new, f_new, ok, its = _bordered_newton(problem, x, force, pressure, node, direction,
                                                 start + goal * displacement, options, cap)
        iterations += its
        if ok:
            x, force, done = x_new, f_new, goal
            increment = min(1.0, 2.0 * increment)
        else:
            increment *= 0.5
            if increment < 1.0 / 64:
                return x, force, False, iterations, done, False, np.inf
    nodes = np.full(1, node)
    forces = (force * direction).reshape(1, 2)
    _, grad, hess = _derivatives(problem, x, pressure, nodes, forces)
    min_eig = _step(problem, grad, hess)[1]
    return x, force, True, iterations, 1.0, min_eig > 0.0, np.abs(grad).max() / options[6]


def _sources_stamp():
    """(name, mtime, size) of every source of the model package."""
    here = pathlib.Path(__file__).resolve().parent
    return tuple((path.name, path.stat().st_mtime_ns, path.stat().st_size)
                 for path in sorted(here.glob('*.py')))


def _cached(dispatcher):
    """
    Make a compiled entry's disk cache stale when any model source changes, not its own only.

    numba checks the stamp of the file that defines a cached function, but the entries
    below compile in the kernels of other modules (the discretisations'): without this an
    edited kernel would keep running its old compiled code. The stamp is numba's own
    (`IndexDataCacheFile._source_stamp`, numba 0.68), extended with every model source's.
    """
    cache_file = getattr(getattr(dispatcher, '_cache', None), '_cache_file', None)
    if cache_file is not None and hasattr(cache_file, '_source_stamp'):
        cache_file._source_stamp = (cache_file._source_stamp, _sources_stamp())
    return dispatcher


# Compiled once per discretisation type and kept on disk; nogil lets callers thread them.
def _jit(function):
    return _cached(numba.njit(cache=True, nogil=True)(function))


def _jit_parallel(function):
    return _cached(numba.njit(cache=True, nogil=True, parallel=True)(function))


@_jit
def _newton_entry(problem, x, pressure, nodes, forces, options, cap):
    return _newton(problem, x, pressure, nodes, forces, options, cap)


@_jit
def _solve_entry(problem, initial, warm, flat, pressure, nodes, forces, options, cap):
    return _solve(problem, initial, warm, flat, pressure, nodes, forces, options, cap)


@_jit
def _rigidity_entry(problem, x, pressure, node, direction, displacement, options, cap):
    return _rigidity(problem, x, pressure, node, direction, displacement, options, cap)


@_jit_parallel
def _solve_batch_entry(problems, design, pressures, nodes, forces, initial, flat, options, cap,
                       tip):
    count = pressures.size
    warm = initial.shape[0] > 0
    states = np.empty((count,) + flat.shape)
    status = np.empty(count, dtype=np.int64)
    iterations = np.empty(count, dtype=np.int64)
    figures = np.empty((count, 6))
    for i in numba.prange(count):
        problem = problems[design[i]]
        start = initial[i] if warm else flat
        x, code, its, grad, step, eig, fraction = _solve(
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


@_jit_parallel
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
    for i in numba.prange(count):
        d = design[i]
        x, code, its, grad, step, eig, fraction = _solve(
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
        y, force, ok, its, done, stable, gradient = _rigidity(
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


def _packed(problem, options, shape):
    """Return the loops' options and step cap for `shape` (once per solver and options)."""
    key = (id(options), shape)
    memo = problem.__dict__.setdefault('_engine_packed', {})
    hit = memo.get(key)
    if hit is None or hit[0] is not options:
        hit = memo[key] = (options, *options.packed(problem.gradient_scale, shape))
    return hit[1], hit[2]


def _flat(problem):
    """``problem.flat()``, once per solver: the loops never write to their start (`_own`)."""
    flat = problem.__dict__.get('_engine_flat')
    if flat is None:
        flat = np.ascontiguousarray(problem.flat(), dtype=float)
        problem.__dict__['_engine_flat'] = flat
    return flat


def _own(x, problem):
    """`x`, copied if it is the solver's shared flat state (a failed first step returns it)."""
    return x.copy() if x is problem.__dict__.get('_engine_flat') else x


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

    """

    states: np.ndarray
    status: np.ndarray
    iterations: np.ndarray
    gradient: np.ndarray
    step: np.ndarray
    min_eig: np.ndarray
    fraction: np.ndarray
    tips: np.ndarray


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
        raise TypeError('`problems` must be a non-empty sequence of discretisations that run '
                        'compiled (with `kernel_data`)')
    flat = _flat(problems[0])
    opts, cap = _packed(problems[0], options, flat.shape)
    for problem, data in zip(problems, datas):
        other = _flat(problem)
        if type(data) is not type(datas[0]) or other.shape != flat.shape \
                or _packed(problem, options, flat.shape)[0] != opts \
                or not np.array_equal(_packed(problem, options, flat.shape)[1], cap):
            raise ValueError('`problems` must share one discretisation type, number of '
                             'unknowns and options')
    return numba.typed.List(datas), flat, opts, cap


def _index(design, pressures, count):
    design = np.ascontiguousarray(design, dtype=np.int64)
    pressures = np.ascontiguousarray(pressures, dtype=float)
    if design.shape != pressures.shape or design.ndim != 1:
        raise ValueError('`design` and `pressures` must be 1-d of one length, got shapes '
                         f'{design.shape} and {pressures.shape}')
    if design.size and not (0 <= design.min() and design.max() < count):
        raise ValueError(f'`design` indices must lie in [0, {count})')
    return design, pressures


def solve_batch(problems, design, pressures, nodes, forces, options, tip, initial=None):
    """
    Solves of S independent scenes in one compiled loop over both cores (`prange`).

    Scene i is `solve(problems[design[i]], pressures[i], loads_i, options, initial[i])`,
    loads_i being `forces[i]` at `nodes`: the same arithmetic, so the same answer.

    Parameters
    ----------
    problems : sequence of discretisation
        Each with ``kernel_data``; one type, unknowns' shape and options.
    design : array_like of int, shape (S,)
        Index into `problems` of every scene.
    pressures : array_like, shape (S,)
        [Pa].
    nodes : array_like of int, shape (K,)
        Loaded nodes, shared by all scenes (K = 0: unloaded).
    forces : array_like, shape (S, K, 2)
        [N].
    options : NewtonOptions
    tip : int
        Node whose position is returned.
    initial : array_like, shape (S,) + unknowns, optional
        Warm starts [scaled units]; None: every scene from the flat state.

    Returns
    -------
    BatchOutcome

    """
    design, pressures = _index(design, pressures, len(problems))
    nodes = np.ascontiguousarray(nodes, dtype=np.int64).reshape(-1)
    forces = np.ascontiguousarray(forces, dtype=float).reshape(pressures.size, nodes.size, 2)
    datas, flat, opts, cap = _batch_inputs(problems, nodes.size > 0, options)
    if initial is None:
        initial = np.zeros((0,) + flat.shape)
    else:
        initial = np.ascontiguousarray(initial, dtype=float)
        if initial.shape != (pressures.size,) + flat.shape:
            raise ValueError(f'`initial` must have shape {(pressures.size,) + flat.shape}, '
                             f'got {initial.shape}')
    states, status, iterations, figures = _solve_batch_entry(
        datas, design, pressures, nodes, forces, initial, flat, opts, cap, int(tip))
    return BatchOutcome(states, status, iterations, *figures[:, :4].T, figures[:, 4:])


def rigidity_batch(problems, design, pressures, node, direction, displacement, options):
    """
    `rigidity` of S scenes after their cold unloaded solves, compiled over both cores.

    Parameters
    ----------
    problems : sequence of discretisation
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
    out = _rigidity_batch_entry(free, loaded, design, pressures, int(node),
                                np.ascontiguousarray(direction, dtype=float),
                                float(displacement), flat, opts, cap)
    unloaded_x, status, states, iterations, figures = out
    unloaded = BatchOutcome(unloaded_x, status, iterations[:, 0], *figures[:, :4].T,
                            np.full((pressures.size, 2), np.nan))
    return BatchRigidity(unloaded, states, figures[:, 4], iterations[:, 1], figures[:, 5],
                         figures[:, 6] == 1.0, figures[:, 7], figures[:, 8:10])
