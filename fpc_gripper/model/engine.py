"""The one equilibrium engine: damped Newton, continuation and displacement control."""

from dataclasses import dataclass
import enum
import math

import numpy as np

from . import kernels

__all__ = ['SolverStatus', 'NewtonOptions', 'NewtonOutcome', 'newton', 'solve', 'rigidity',
           'linear_step', 'linear_solve', 'BorderedOutcome']


class SolverStatus(enum.IntEnum):
    """Outcome of a solve; only SUCCESS has success=True."""

    SUCCESS = 0
    MAX_ITERATIONS = 1
    LINE_SEARCH_FAILED = 2
    NOT_FINITE = 3
    UNSTABLE = 4
    CONTINUATION_FAILED = 5


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


@dataclass(frozen=True)
class NewtonOutcome:
    """State and figures of one Newton run (internal: solvers build their results from it)."""

    x: np.ndarray
    status: SolverStatus
    iterations: int
    gradient: float
    step: float
    min_eig: float = math.nan
    fraction: float = 1.0


def linear_step(grad, hess, floor=1e-8):
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


def newton(problem, x, pressure, loads, options):
    """
    Damped Newton on the total potential of a discretisation.

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

    """
    scale = problem.gradient_scale
    cap = options.max_step
    step_norm = math.inf
    grad_rel = math.inf
    energy, grad, hess = problem.derivatives(x, pressure, loads)
    for iteration in range(1, options.max_iterations + 1):
        grad_rel = float(np.abs(grad).max()) / scale if grad.size else 0.0
        if not (math.isfinite(energy) and math.isfinite(grad_rel)):
            return NewtonOutcome(x, SolverStatus.NOT_FINITE, iteration, grad_rel, step_norm)
        step, min_eig = problem.step(grad, hess)
        step_norm = float(np.abs(step).max()) if step.size else 0.0
        if not math.isfinite(step_norm):
            return NewtonOutcome(x, SolverStatus.NOT_FINITE, iteration, grad_rel, step_norm)
        if grad_rel <= options.gtol and step_norm <= options.xtol:
            status = SolverStatus.SUCCESS if min_eig > 0.0 else SolverStatus.UNSTABLE
            return NewtonOutcome(x + step, status, iteration, grad_rel, step_norm, min_eig)
        ratio = float(np.max(np.abs(step) / cap))
        if ratio > 1.0:
            step = step / ratio
        slope = float(np.vdot(grad, step))
        if not slope < 0.0:
            step, slope = -grad / scale, -float(np.vdot(grad, grad)) / scale
        trial = x + step
        e_trial, g_trial, h_trial = problem.derivatives(trial, pressure, loads)
        flat = -slope <= options.flat_slope * (abs(energy) + options.energy_scale)
        if e_trial <= energy + options.armijo * slope or flat:
            x, energy, grad, hess = trial, e_trial, g_trial, h_trial
            step_norm = float(np.abs(step).max())
            continue
        alpha = 0.5
        while True:
            trial = x + alpha * step
            if problem.energy(trial, pressure, loads) <= energy + options.armijo * alpha * slope:
                break
            alpha *= 0.5
            if alpha < 1e-10:
                return NewtonOutcome(x, SolverStatus.LINE_SEARCH_FAILED, iteration, grad_rel,
                                     step_norm, min_eig)
        x = trial
        step_norm = alpha * float(np.abs(step).max())
        energy, grad, hess = problem.derivatives(x, pressure, loads)
    return NewtonOutcome(x, SolverStatus.MAX_ITERATIONS, options.max_iterations, grad_rel,
                         step_norm)


def _scaled(loads, lam):
    return [(node, lam * np.asarray(force, dtype=float)) for node, force in loads]


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
    spent = 0
    if initial is not None:
        warm = newton(problem, initial, pressure, loads, options)
        if warm.status is SolverStatus.SUCCESS:
            return warm
        spent = warm.iterations
    flat = problem.flat()
    cold = newton(problem, flat, pressure, loads, options)
    spent += cold.iterations
    if cold.status in (SolverStatus.SUCCESS, SolverStatus.UNSTABLE):
        return _with_iterations(cold, spent)
    start = newton(problem, flat, 0.0, [], options)
    spent += start.iterations
    if start.status is not SolverStatus.SUCCESS:
        return NewtonOutcome(start.x, SolverStatus.CONTINUATION_FAILED, spent, math.inf,
                             math.inf, fraction=0.0)
    x, lam, dlam = start.x, 0.0, 0.25
    while True:
        target = min(1.0, lam + dlam)
        sub = newton(problem, x, target * pressure, _scaled(loads, target), options)
        spent += sub.iterations
        if sub.status is SolverStatus.SUCCESS:
            x, lam = sub.x, target
            dlam = min(2.0 * dlam, 1.0)
            if lam >= 1.0:
                return _with_iterations(sub, spent)
        else:
            dlam *= 0.5
            if dlam < 1.0 / 256:
                return NewtonOutcome(x, SolverStatus.CONTINUATION_FAILED, spent, sub.gradient,
                                     sub.step, fraction=lam)


def _with_iterations(outcome, iterations):
    return NewtonOutcome(outcome.x, outcome.status, iterations, outcome.gradient, outcome.step,
                         outcome.min_eig, outcome.fraction)


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


def _bordered_newton(problem, x, force, pressure, node, direction, target, options):
    """Solve grad Pi(x; f e) = 0 and e . O_node(x) = target for (x, f) by Newton."""
    scale = problem.gradient_scale
    for iteration in range(1, options.max_iterations + 1):
        _, residual, hess = problem.derivatives(x, pressure, [(node, force * direction)])
        position, jacobian = problem.node_jacobian(x, node)
        # The potential of a unit load along e is -e . O: its gradient borders the system.
        border = -np.tensordot(direction, jacobian, axes=1)
        gap = float(direction @ position) - target
        try:
            a = problem.solve_linear(hess, -residual)
            b = problem.solve_linear(hess, border)
        except np.linalg.LinAlgError:
            return x, force, False, iteration
        denominator = float(np.vdot(border, b))
        if not (math.isfinite(denominator) and denominator != 0.0):
            return x, force, False, iteration
        # H dx + border df = -r and border . dx = gap.
        dforce = (float(np.vdot(border, a)) - gap) / denominator
        dx = a - dforce * b
        step = float(np.abs(dx).max()) if dx.size else 0.0
        if not (math.isfinite(step) and math.isfinite(dforce)):
            return x, force, False, iteration
        if float(np.max(np.abs(dx) / options.max_step)) > 1.0:
            return x, force, False, iteration
        x = x + dx
        force = force + dforce
        balanced = not math.isfinite(options.gtol) or \
            float(np.abs(residual).max()) / scale <= options.gtol
        if balanced and step <= options.xtol and abs(gap) <= 1e-12 * max(abs(target), 1e-3):
            return x, force, True, iteration
    return x, force, False, options.max_iterations


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
    x, force = unloaded_x, 0.0
    start = float(direction @ problem.node_jacobian(x, node)[0])
    done, iterations, increment = 0.0, 0, 1.0
    while done < 1.0:
        goal = min(1.0, done + increment)
        x_new, f_new, ok, its = _bordered_newton(problem, x, force, pressure, node, direction,
                                                 start + goal * displacement, options)
        iterations += its
        if ok:
            x, force, done = x_new, f_new, goal
            increment = min(1.0, 2.0 * increment)
        else:
            increment *= 0.5
            if increment < 1.0 / 64:
                return BorderedOutcome(x, force, False, iterations, done, False, math.inf)
    _, grad, hess = problem.derivatives(x, pressure, [(node, force * direction)])
    _, min_eig = problem.step(grad, hess)
    return BorderedOutcome(x, force, True, iterations, 1.0, min_eig > 0.0,
                           float(np.abs(grad).max()) / problem.gradient_scale)
