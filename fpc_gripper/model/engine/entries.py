"""The engine's compiled entries: what Python calls, one per loop, and the batches."""

import numpy as np

from .active_set import _contact
from .bordered import _rigidity
from .interface import _node_jacobian
from .newton import _newton, _solve
from .outcomes import _SUCCESS
from ..compiled import jit


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
