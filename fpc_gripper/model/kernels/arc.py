"""Compiled (numba) kernels of the arc rung: the whole finger as one arc of uniform strain."""

import collections
import math

import numpy as np

from .pcc_section import _section_energy, _section_slopes, _sinc0
from ..compiled import jit

__all__ = ['ArcData', 'arc_integrals', 'arc_derivatives', 'arc_energy', 'arc_step',
           'arc_solve_linear', 'arc_node_jacobian']

# Built at install (`compiled`), once per argument types; nogil lets a caller thread them.
_jit = jit
#: Mirrored eigenvalues of the 3 x 3 Hessian are floored at this times max |lambda|.
_FLOOR = 1e-10

#: The arc as `engine` runs it compiled: its one-type section law (`section_arrays`), k_p,
#: the free length L [m], the scale (1, L, 1) of the unknowns (eps, kappa L, c1), the
#: Gauss rule (t_q, w_q) on [0, 1] of the arc integrals and the number of output samples.
ArcData = collections.namedtuple('ArcData', ('stiffness', 'gas', 'pemc',
                                             'pressure_coefficient', 'length', 'scale',
                                             'arc_t', 'arc_w', 'samples'))


@_jit
def arc_integrals(phi, t, w):
    """
    I_k = int_0^1 t^k (cos, sin)(phi t) dt for k = 0, 1, 2 by the Gauss rule (t, w).

    Returns
    -------
    ndarray, shape (3, 2)

    """
    out = np.zeros((3, 2))
    for q in range(t.size):
        c, s = math.cos(phi * t[q]), math.sin(phi * t[q])
        weight = w[q]
        for k in range(3):
            out[k, 0] += weight * c
            out[k, 1] += weight * s
            weight *= t[q]
    return out


@_jit
def _total_force(forces):
    fx = 0.0
    fz = 0.0
    for k in range(forces.shape[0]):
        fx += forces[k, 0]
        fz += forces[k, 1]
    return fx, fz


@_jit
def arc_derivatives(p, x, pressure, nodes, forces):
    """
    Energy [J], gradient (3,) and Hessian (3, 3) of the arc in x = (eps, kappa L, c1).

    The arc of uniform strain y = (eps, kappa, c1) over the free length L has the
    energy L W(y) and the tip (1 + eps) L (I_0c, I_0s)(kappa L); a tip force F adds
    -F . tip (docs/physics.md, section 11.3).
    """
    sc = p.scale
    length = p.length
    eps, kappa, c1 = x[0] / sc[0], x[1] / sc[1], x[2] / sc[2]
    work = p.pressure_coefficient * pressure
    g = np.empty(3)
    h = np.empty((3, 3))
    energy = length * _section_energy(p.stiffness, p.gas, p.pemc, 0, eps, kappa, c1, work)
    _section_slopes(p.stiffness, p.gas, p.pemc, 0, eps, kappa, c1, work, g, h)
    g *= length
    h *= length
    fx, fz = _total_force(forces)
    if fx != 0.0 or fz != 0.0:
        i = arc_integrals(kappa * length, p.arc_t, p.arc_w)
        stretch = 1.0 + eps
        f_base = fx * i[0, 0] + fz * i[0, 1]
        f_d1 = fx * -i[1, 1] + fz * i[1, 0]
        f_d2 = fx * -i[2, 0] + fz * -i[2, 1]
        energy -= stretch * length * f_base
        g[0] -= length * f_base
        g[1] -= stretch * length ** 2 * f_d1
        h[0, 1] -= length ** 2 * f_d1
        h[1, 0] -= length ** 2 * f_d1
        h[1, 1] -= stretch * length ** 3 * f_d2
    for a in range(3):
        g[a] /= sc[a]
        for b in range(3):
            h[a, b] /= sc[a] * sc[b]
    return energy, g, h


@_jit
def arc_energy(p, x, pressure, nodes, forces):
    """Total potential [J] of the arc at x = (eps, kappa L, c1)."""
    return arc_derivatives(p, x, pressure, nodes, forces)[0]


@_jit
def arc_step(p, grad, hess):
    """Newton step of the 3 x 3 system (eigenvalues mirrored where indefinite)."""
    low, definite = _cholesky3(hess)
    if definite:
        return _substitute3(low, -grad), 1.0
    lam, vec = np.linalg.eigh(hess)
    floor = _FLOOR * np.abs(lam).max()
    step = np.zeros(3)
    for k in range(3):
        coef = 0.0
        for a in range(3):
            coef -= grad[a] * vec[a, k]
        coef /= max(abs(lam[k]), floor)
        for a in range(3):
            step[a] += vec[a, k] * coef
    return step, lam.min()


@_jit
def _cholesky3(a):
    low = np.zeros((3, 3))
    for i in range(3):
        for j in range(i + 1):
            acc = a[i, j]
            for k in range(j):
                acc -= low[i, k] * low[j, k]
            if i == j:
                if not acc > 0.0:
                    return low, False
                low[i, i] = math.sqrt(acc)
            else:
                low[i, j] = acc / low[j, j]
    return low, True


@_jit
def _substitute3(low, rhs):
    out = np.empty(3)
    for i in range(3):
        acc = rhs[i]
        for k in range(i):
            acc -= low[i, k] * out[k]
        out[i] = acc / low[i, i]
    for i in range(2, -1, -1):
        acc = out[i]
        for k in range(i + 1, 3):
            acc -= low[k, i] * out[k]
        out[i] = acc / low[i, i]
    return out


@_jit
def arc_solve_linear(p, hess, rhs):
    """Solve H x = rhs (3,): (x, True), or (rhs, False) where H is singular."""
    try:
        return np.linalg.solve(hess, rhs), True
    except Exception:
        return rhs.copy(), False


@_jit
def arc_node_jacobian(p, x, node):
    """Tip (2,) [m] and its derivatives in x, (2, 3); node 0 is the clamp."""
    sc = p.scale
    length = p.length
    position = np.zeros(2)
    jac = np.zeros((2, 3))
    if node == 0:
        return position, jac
    eps, kappa = x[0] / sc[0], x[1] / sc[1]
    i = arc_integrals(kappa * length, p.arc_t, p.arc_w)
    stretch = 1.0 + eps
    for k in range(2):
        position[k] = stretch * length * i[0, k]
        jac[k, 0] = length * i[0, k] / sc[0]
    jac[0, 1] = stretch * length ** 2 * -i[1, 1] / sc[1]
    jac[1, 1] = stretch * length ** 2 * i[1, 0] / sc[1]
    return position, jac


# -- the outputs of a state ---------------------------------------------------------------
@_jit
def arc_outputs(p, x, pressure, nodes, forces, samples):
    """
    Return `engine.newton.OUTPUT_FIELDS` of an arc state x = (eps, kappa L, c1).

    Its samples lie at `p.samples` evenly spaced s.

    The point at s is (1 + eps) s S(kappa s) along (cos, sin)(kappa s / 2), exactly on the
    arc; the tip (the last sample) is the engine's (`arc_node_jacobian`). coefficients are
    the CCM's of one segment with the same uniform strain: (eps, -2 d^2/3, c1, d), d =
    kappa / 2.

    References
    ----------
    docs/physics.md, sections 11.2 and 11.3.
    """
    length = p.length
    eps, kappa, c1 = x[0] / p.scale[0], x[1] / p.scale[1], x[2] / p.scale[2]
    chain_nodes = np.zeros((2, 2))
    tip = arc_node_jacobian(p, x, 1)[0]
    chain_nodes[1, 0], chain_nodes[1, 1] = tip[0], tip[1]
    beta = np.full(1, kappa * length)
    d = 0.5 * kappa
    coefficients = np.empty((1, 4))
    coefficients[0, 0], coefficients[0, 1] = eps, -2.0 * d * d / 3.0
    coefficients[0, 2], coefficients[0, 3] = c1, d
    theta = np.zeros(1)
    if not samples:
        return (chain_nodes, beta, theta, coefficients, True, np.nan, np.empty((0, 2)),
                np.empty(0), np.empty((0, 3)))
    energy = arc_energy(p, x, pressure, nodes, forces)
    m = p.samples
    points = np.empty((m, 2))
    tangent = np.empty(m)
    strains = np.empty((m, 3))
    for k in range(m):
        s = length * k / (m - 1)
        turn = kappa * s
        reach = ((1.0 + eps) * s) * _sinc0(turn)
        points[k, 0] = reach * math.cos(0.5 * turn)
        points[k, 1] = reach * math.sin(0.5 * turn)
        tangent[k] = turn
        strains[k, 0], strains[k, 1], strains[k, 2] = eps, kappa, c1
    points[m - 1, 0], points[m - 1, 1] = tip[0], tip[1]
    return chain_nodes, beta, theta, coefficients, True, energy, points, tangent, strains


#: The arc's hooks, by the engine's names (`engine.register` takes them).
ARC_HOOKS = {'derivatives': arc_derivatives, 'energy': arc_energy, 'step': arc_step,
             'solve_linear': arc_solve_linear, 'node_jacobian': arc_node_jacobian,
             'outputs': arc_outputs}
