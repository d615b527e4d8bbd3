"""The damped Newton and its continuation in pressure: each loop once, compiled or not."""

from numba.extending import register_jitable
import numpy as np

from .interface import _derivatives, _dot, _energy, _max_abs, _max_ratio, _step
from .outcomes import (_CONTINUATION_FAILED, _LINE_SEARCH_FAILED, _MAX_ITERATIONS, _NOT_FINITE,
                       _SUCCESS, _UNSTABLE)


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
