"""Compiled (numba) CCM-N: the segments' energy and derivatives, and the engine's CCMData."""

import collections
import functools
import math

import numpy as np

from .chain import (consistent_strain_map_kernel, load_derivatives_kernel, load_energy_kernel,
                    node_jacobian_kernel, node_positions_kernel)
from .linear import (_cholesky_substitute, _dense_cholesky, _factored_step, EIGEN_FLOOR,
                     newton_step_blocks)
from ..compiled import jit

__all__ = ['segment_energy', 'segment_derivatives', 'segment_energy_kernel',
           'segment_derivatives_kernel', 'CCMData', 'ccm_data', 'ccm_energy', 'ccm_derivatives',
           'ccm_step', 'ccm_solve_linear', 'ccm_node_jacobian', 'CCM_HOOKS']

# Built at install (`compiled`), once per argument types; nogil lets a caller thread them.
_jit = jit
# The ten columns of the PEMC products are (1, phi_0, phi_1, phi_2, then phi_a phi_b for
# (a, b) = (0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)); they take F, sigma and sigma'.


@functools.lru_cache(maxsize=16)
def _law_matrix(emc):
    """Map strain powers s^0..s^5 to (F, sigma, sigma') of the PEMC law, shape (6, 3)."""
    a1, a2, a3, a4 = emc
    return np.array([[0.0, 0.0, a4],
                     [0.0, a4, 2.0 * a3],
                     [a4 / 2.0, a3, 3.0 * a2],
                     [a3 / 3.0, a2, 4.0 * a1],
                     [a2 / 4.0, a1, 0.0],
                     [a1 / 5.0, 0.0, 0.0]])


# -- segments -----------------------------------------------------------------------------
@_jit
def _density(law, s):
    """Return the PEMC energy density F at strain s (column 0 of `_law_matrix`), by Horner."""
    # F has no constant or linear term (`_law_matrix`): skipping those exact zeros leaves
    # the value bit-identical to the full quintic and saves work in the quadrature loops.
    return (((law[5, 0] * s + law[4, 0]) * s + law[3, 0]) * s + law[2, 0]) * s * s


@_jit
def _stress(law, s):
    """Return the PEMC stress sigma = F' at strain s (column 1 of `_law_matrix`), by Horner."""
    return (((law[4, 1] * s + law[3, 1]) * s + law[2, 1]) * s + law[1, 1]) * s


@_jit
def _tangent(law, s):
    """Return the PEMC tangent sigma' at strain s (column 2 of `_law_matrix`, a cubic)."""
    return ((law[3, 2] * s + law[2, 2]) * s + law[1, 2]) * s + law[0, 2]


@_jit
def _strain_unknowns(q, i, y):
    """Fill y = (A, B', D', C) of segment i (energy._strain_state)."""
    y[0] = q[i, 0]
    y[1] = 3.0 * q[i, 1] + 2.0 * q[i, 3] ** 2
    y[2] = q[i, 3]
    y[3] = q[i, 2]


@_jit
def _pemc_strain(basis, i, p, y, prestrain):
    """PEMC strain eps0 + A + B' xi^2 + D' z' at quadrature point p of segment i."""
    return basis[i, p, 0] * y[0] + basis[i, p, 1] * y[1] + basis[i, p, 2] * y[2] + prestrain


@_jit
def _chain_rule(g, h, jac, work, grad, hess):
    """Write grad = jac^T g and hess = jac^T h jac (4 x 4), with `work` as scratch."""
    for b in range(4):
        acc = 0.0
        for a in range(4):
            acc += g[a] * jac[a, b]
        grad[b] = acc
    for a in range(4):
        for b in range(4):
            acc = 0.0
            for c in range(4):
                acc += h[a, c] * jac[c, b]
            work[a, b] = acc
    for a in range(4):
        for b in range(4):
            acc = 0.0
            for c in range(4):
                acc += jac[c, a] * work[c, b]
            hess[a, b] = acc


@_jit
def _strain_chain_rule(g, h, q3, work, grad, hess):
    """
    `_chain_rule` for y(q) = (q0, 3 q1 + 2 q3^2, q3, q2), plus its curvature 4 g1 at (3, 3).

    The Jacobian is a permutation but for 3 and dB'/dq3 = 4 q3: written out, the products
    skip its exact zeros and ones, so grad and hess are bit-identical to `_chain_rule`'s.
    """
    slope = 4.0 * q3
    grad[0] = g[0]
    grad[1] = g[1] * 3.0
    grad[2] = g[3]
    grad[3] = g[1] * slope + g[2]
    for a in range(4):
        work[a, 0] = h[a, 0]
        work[a, 1] = h[a, 1] * 3.0
        work[a, 2] = h[a, 3]
        work[a, 3] = h[a, 1] * slope + h[a, 2]
    for b in range(4):
        hess[0, b] = work[0, b]
        hess[1, b] = 3.0 * work[1, b]
        hess[2, b] = work[3, b]
        hess[3, b] = slope * work[1, b] + work[2, b]
    hess[3, 3] += 4.0 * g[1]


@_jit
def segment_energy_kernel(q, stiffness, gas_volume, gas_moments, pemc_basis, pemc_weights,
                          prestrain, law, pressure_work):
    """
    Strain energy minus pressure work of every segment, compiled.

    Parameters
    ----------
    q : ndarray, shape (N, 4)
        Scaled unknowns (b1, b3 L^2, c1, d L).
    stiffness, gas_volume, gas_moments, pemc_basis, pemc_weights : ndarray
        The `SegmentData` arrays of the same names.
    prestrain : float
        PEMC prestrain eps0 [-].
    law : ndarray, shape (6, 3)
        Strain powers s^0..s^5 to (F, sigma, sigma') of the PEMC law
        (energy._law_matrix) [Pa].
    pressure_work : float
        k_p P [Pa].

    Returns
    -------
    ndarray, shape (N,)
        Phi_i - k_p P V_i [J].

    References
    ----------
    Zhou, Headings, Dapino (2022), eqs. (5)-(12), (19)-(20); SPEC "Energy", "Pressure work".

    """
    n = q.shape[0]
    points = pemc_basis.shape[1]
    out = np.empty(n)
    y = np.empty(4)
    for i in range(n):
        _strain_unknowns(q, i, y)
        quadratic = 0.0
        for a in range(4):
            ky = 0.0
            for b in range(4):
                ky += stiffness[i, a, b] * y[b]
            quadratic += y[a] * ky
        pemc = 0.0
        for p in range(points):
            s = _pemc_strain(pemc_basis, i, p, y, prestrain)
            pemc += pemc_weights[i, p] * _density(law, s)
        # Pi_P = -c (1 + C)(V0 + g . y3): the gas volume is bilinear in (y3, C). Grouped as
        # in `segment_derivatives_kernel`, so that the line search compares equal energies.
        lin_gas = gas_volume[i] + (gas_moments[i, 0] * y[0] + gas_moments[i, 1] * y[1]
                                   + gas_moments[i, 2] * y[2])
        work = pressure_work * (1.0 + y[3])
        out[i] = 0.5 * quadratic + pemc - work * lin_gas
    return out


@_jit
def segment_derivatives_kernel(q, stiffness, gas_volume, gas_moments, pemc_basis,
                               pemc_products, prestrain, law, pressure_work):
    """
    Energy, gradient and Hessian blocks of every segment in q, compiled.

    Parameters are those of `segment_energy_kernel`, with `pemc_products` (N, P, 10)
    in place of the weights.

    Returns
    -------
    energy : ndarray, shape (N,)
    gradient : ndarray, shape (N, 4)
    hessian : ndarray, shape (N, 4, 4)

    """
    n = q.shape[0]
    points = pemc_basis.shape[1]
    energy = np.empty(n)
    grad = np.empty((n, 4))
    hess = np.empty((n, 4, 4))
    y = np.empty(4)
    g_y = np.empty(4)
    h_y = np.empty((4, 4))
    m = np.empty((4, 4))
    for i in range(n):
        _strain_unknowns(q, i, y)
        # The products' sums in scalars, which stay in registers over the quadrature loop.
        p0 = p1 = p2 = p3 = p4 = p5 = p6 = p7 = p8 = p9 = 0.0
        for p in range(points):
            s = _pemc_strain(pemc_basis, i, p, y, prestrain)
            density = _density(law, s)
            stress = _stress(law, s)
            tangent = _tangent(law, s)
            # The (1, phi_a, phi_a phi_b) products take F, sigma and sigma' in turn.
            p0 += density * pemc_products[i, p, 0]
            p1 += stress * pemc_products[i, p, 1]
            p2 += stress * pemc_products[i, p, 2]
            p3 += stress * pemc_products[i, p, 3]
            p4 += tangent * pemc_products[i, p, 4]
            p5 += tangent * pemc_products[i, p, 5]
            p6 += tangent * pemc_products[i, p, 6]
            p7 += tangent * pemc_products[i, p, 7]
            p8 += tangent * pemc_products[i, p, 8]
            p9 += tangent * pemc_products[i, p, 9]
        quadratic = 0.0
        for a in range(4):
            ky = 0.0
            for b in range(4):
                ky += stiffness[i, a, b] * y[b]
            g_y[a] = ky
            quadratic += y[a] * ky
        lin_gas = gas_volume[i] + (gas_moments[i, 0] * y[0] + gas_moments[i, 1] * y[1]
                                   + gas_moments[i, 2] * y[2])
        work = pressure_work * (1.0 + y[3])
        energy[i] = 0.5 * quadratic + p0 - work * lin_gas
        g_y[0] += p1 - work * gas_moments[i, 0]
        g_y[1] += p2 - work * gas_moments[i, 1]
        g_y[2] += p3 - work * gas_moments[i, 2]
        g_y[3] -= pressure_work * lin_gas
        for a in range(4):
            for b in range(4):
                h_y[a, b] = stiffness[i, a, b]
        # The phi_a phi_b sums at their (a, b), in both triangles.
        h_y[0, 0] += p4
        h_y[0, 1] += p5
        h_y[1, 0] += p5
        h_y[0, 2] += p6
        h_y[2, 0] += p6
        h_y[1, 1] += p7
        h_y[1, 2] += p8
        h_y[2, 1] += p8
        h_y[2, 2] += p9
        for a in range(3):
            h_y[a, 3] -= pressure_work * gas_moments[i, a]
            h_y[3, a] -= pressure_work * gas_moments[i, a]
        _strain_chain_rule(g_y, h_y, q[i, 3], m, grad[i], hess[i])
    return energy, grad, hess


def segment_energy(q, seg, prestrain, emc, pressure_work):
    """
    Compiled `energy.segment_energy`: Phi_i - k_p P V_i of every segment, shape (N,) [J].

    Parameters
    ----------
    q : ndarray, shape (N, 4)
        Scaled unknowns (b1, b3 L^2, c1, d L).
    seg : SegmentData
        Exact integration data.
    prestrain : float
        PEMC prestrain eps0 [-].
    emc : tuple of float
        PEMC stress law (a1..a4) [Pa].
    pressure_work : float
        k_p P [Pa].

    References
    ----------
    Zhou, Headings, Dapino (2022), eqs. (5)-(12), (19)-(20); SPEC "Energy", "Pressure work".

    """
    return segment_energy_kernel(q, seg.stiffness, seg.gas_volume, seg.gas_moments,
                                 seg.pemc_basis, seg.pemc_weights, float(prestrain),
                                 _law_matrix(emc), float(pressure_work))


def segment_derivatives(q, seg, prestrain, emc, pressure_work):
    """
    Compiled `energy.segment_derivatives`: energy, gradient and Hessian blocks in q.

    Returns
    -------
    energy : ndarray, shape (N,)
    gradient : ndarray, shape (N, 4)
    hessian : ndarray, shape (N, 4, 4)

    """
    return segment_derivatives_kernel(q, seg.stiffness, seg.gas_volume, seg.gas_moments,
                                      seg.pemc_basis, seg.pemc_products, float(prestrain),
                                      _law_matrix(emc), float(pressure_work))


# -- the engine's discretisation: CCM-N as a namedtuple of arrays ----------------------------
#: CCM-N as `engine` runs it compiled. `dense` (the scene has point loads) picks the Hessian:
#: unloaded, the segments decouple into (N, 4, 4) blocks; loaded, the chained frames couple
#: every segment into one dense (4N, 4N) matrix. One type for both, so that each engine loop
#: compiles once for the CCM. The Hessian is (blocks or (1, 4N, 4N), factor, definite).
CCMData = collections.namedtuple('CCMData', (
    'stiffness', 'gas_volume', 'gas_moments', 'pemc_basis', 'pemc_weights', 'pemc_products',
    'prestrain', 'law', 'pressure_coefficient', 'lengths', 'consistent', 'dense',
    'per_segment'))
#: The factor slot of a block Hessian, which has none.
_NO_FACTOR = np.zeros((0, 0))


def ccm_data(seg, prestrain, emc, pressure_coefficient, consistent, loaded, per_segment=16):
    """
    Return the CCM as the engine's compiled discretisation (`CCMData`, dense if loaded).

    Parameters
    ----------
    seg : SegmentData
    prestrain : float
        [-].
    emc : tuple of float
        PEMC stress law (a1..a4) [Pa].
    pressure_coefficient : float
        k_p [-].
    consistent : bool
        The 'consistent' reconstruction (`consistent_strain_map`) instead of the paper's.
    loaded : bool
    per_segment : int
        Midplane samples m per segment of the outputs.

    """
    return CCMData(seg.stiffness, seg.gas_volume, seg.gas_moments, seg.pemc_basis,
                   seg.pemc_weights, seg.pemc_products, float(prestrain), _law_matrix(emc),
                   float(pressure_coefficient), seg.lengths, bool(consistent), bool(loaded),
                   int(per_segment))


@_jit
def _ccm_segment_terms(p, q, pressure):
    """Segment energy [J], gradient (N, 4) and Hessian blocks (N, 4, 4) in the unknowns q."""
    work = p.pressure_coefficient * pressure
    if not p.consistent:
        energy, grad, hess = segment_derivatives_kernel(
            q, p.stiffness, p.gas_volume, p.gas_moments, p.pemc_basis, p.pemc_products,
            p.prestrain, p.law, work)
        return energy.sum(), grad, hess
    qs, jac, hess3 = consistent_strain_map_kernel(q)
    energy, g_s, h_s = segment_derivatives_kernel(
        qs, p.stiffness, p.gas_volume, p.gas_moments, p.pemc_basis, p.pemc_products,
        p.prestrain, p.law, work)
    n = q.shape[0]
    grad = np.empty((n, 4))
    hess = np.empty((n, 4, 4))
    work = np.empty((4, 4))
    for i in range(n):
        # qs[3] is the one nonlinear component of qs(q): its curvature adds g_s3 hess3.
        _chain_rule(g_s[i], h_s[i], jac[i], work, grad[i], hess[i])
        for a in range(4):
            for b in range(4):
                hess[i, a, b] += g_s[i, 3] * hess3[i, a, b]
    return energy.sum(), grad, hess


@_jit
def ccm_energy(p, q, pressure, nodes, forces):
    """Total potential [J] of the CCM at scaled unknowns q (N, 4)."""
    qs = q if not p.consistent else consistent_strain_map_kernel(q)[0]
    energy = segment_energy_kernel(qs, p.stiffness, p.gas_volume, p.gas_moments, p.pemc_basis,
                                   p.pemc_weights, p.prestrain, p.law,
                                   p.pressure_coefficient * pressure).sum()
    return energy + load_energy_kernel(q, p.lengths, nodes, forces)


@_jit
def ccm_derivatives(p, q, pressure, nodes, forces):
    """
    Energy [J], gradient (N, 4) and Hessian of the CCM.

    The Hessian is (H, factor, definite): unloaded, H is the (N, 4, 4) blocks and there is
    no factor; with point loads (`p.dense`), H is (1, 4N, 4N) with its Cholesky factor.
    """
    energy, grad, blocks = _ccm_segment_terms(p, q, pressure)
    if not p.dense:
        return energy, grad, (blocks, _NO_FACTOR, True)
    e_load, g_load, hess = load_derivatives_kernel(q, p.lengths, nodes, forces)
    n = q.shape[0]
    for i in range(n):
        for a in range(4):
            for b in range(4):
                hess[4 * i + a, 4 * i + b] += blocks[i, a, b]
    # The Newton step and the bordered solves all need the factor: once, here.
    low, definite = _dense_cholesky(hess)
    return energy + e_load, grad + g_load, (hess.reshape(1, 4 * n, 4 * n), low, definite)


@_jit
def ccm_step(p, grad, hess):
    """Newton step (N, 4) and smallest eigenvalue (1.0 if PD) of `ccm_derivatives`' H."""
    matrix, low, definite = hess
    if not p.dense:
        return newton_step_blocks(grad, matrix, EIGEN_FLOOR)
    step, min_eig = _factored_step(grad.ravel(), matrix[0], low, definite, EIGEN_FLOOR)
    return step.reshape(grad.shape), min_eig


@_jit
def ccm_solve_linear(p, hess, rhs):
    """Solve H x = rhs (N, 4) of `ccm_derivatives`' H: (x, True), or (rhs, False) if singular."""
    matrix, low, definite = hess
    if not p.dense:
        out = np.empty_like(rhs)
        try:
            for i in range(rhs.shape[0]):
                out[i] = np.linalg.solve(matrix[i], rhs[i])
        except Exception:
            return rhs.copy(), False
        return out, True
    if definite:
        out = np.empty(rhs.size)
        _cholesky_substitute(low, rhs.ravel(), out)
        return out.reshape(rhs.shape), True
    try:
        return np.linalg.solve(matrix[0], rhs.ravel()).reshape(rhs.shape), True
    except Exception:
        return rhs.copy(), False


@_jit
def ccm_node_jacobian(p, q, node):
    """Position (2,) of a chain node [m] and its derivatives (2, N, 4)."""
    return node_jacobian_kernel(q, p.lengths, node)


# -- the outputs of a state ---------------------------------------------------------------
@_jit
def _ccm_samples(q, lengths, per_segment, nodes, theta):
    """
    CCM midplane samples at x = L_i j/m, j = 0..m-1 of every segment, then the tip.

    Returns points (N m + 1, 2), global (X, Z) [m], and their tangent angles from +X
    towards +Z (N m + 1,) [rad], from the chain's `nodes` and node angles `theta`.

    References
    ----------
    Zhou, Headings, Dapino (2022), eq. (15); SPEC "Derived outputs".
    """
    n = q.shape[0]
    m = per_segment
    points = np.empty((n * m + 1, 2))
    tangent = np.empty(n * m + 1)
    for i in range(n):
        c, s = math.cos(theta[i]), math.sin(theta[i])
        b1, b3, d = 1.0 + q[i, 0], q[i, 1], q[i, 3]
        for j in range(m):
            xi = j / m
            u = lengths[i] * (b1 * xi + b3 * xi ** 3)
            w = lengths[i] * (d * xi ** 2)
            k = i * m + j
            points[k, 0] = nodes[i, 0] + (c * u - s * w)
            points[k, 1] = nodes[i, 1] + (s * u + c * w)
            tangent[k] = theta[i] + math.atan2(2.0 * d * xi, b1 + 3.0 * b3 * xi ** 2)
    points[n * m, 0], points[n * m, 1] = nodes[n, 0], nodes[n, 1]
    tangent[n * m] = theta[n - 1] + math.atan2(2.0 * q[n - 1, 3],
                                               1.0 + q[n - 1, 0] + 3.0 * q[n - 1, 1])
    return points, tangent


@_jit
def ccm_outputs(p, q, pressure, nodes, forces, samples):
    """
    Return `engine.newton.OUTPUT_FIELDS` of a CCM state q (N, 4) (scaled unknowns).

    It has no strains: (0, 3).

    References
    ----------
    Zhou, Headings, Dapino (2022), eqs. (15)-(16); SPEC "Kinematics", "Derived outputs".
    """
    chain_nodes, theta, beta = node_positions_kernel(q, p.lengths)
    n = q.shape[0]
    coefficients = q.copy()
    valid = True
    for i in range(n):
        length = p.lengths[i]
        coefficients[i, 1] = q[i, 1] / (length * length)
        coefficients[i, 3] = q[i, 3] / length
        if not abs(2.0 * q[i, 3]) < 1.0:
            valid = False
    if not samples:
        return (chain_nodes, beta, theta, coefficients, valid, np.nan, np.empty((0, 2)),
                np.empty(0), np.empty((0, 3)))
    points, tangent = _ccm_samples(q, p.lengths, p.per_segment, chain_nodes, theta)
    return (chain_nodes, beta, theta, coefficients, valid,
            ccm_energy(p, q, pressure, nodes, forces), points, tangent, np.empty((0, 3)))


#: The CCM's hooks, by the engine's names (`engine.register` takes them).
CCM_HOOKS = {'derivatives': ccm_derivatives, 'energy': ccm_energy, 'step': ccm_step,
             'solve_linear': ccm_solve_linear, 'node_jacobian': ccm_node_jacobian,
             'outputs': ccm_outputs}
