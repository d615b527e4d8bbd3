"""Compiled (numba) outputs of a state: each discretisation's `outputs` hook, one shape."""

import math

import numpy as np

from . import chain
from .arc import arc_energy, arc_node_jacobian
from .ccm import ccm_energy
from .pcc import energy_kernel, nodes_kernel
from .pcc_section import _sinc0
from ..compiled import jit

__all__ = ['ccm_outputs', 'pcc_outputs', 'arc_outputs', 'OUTPUT_FIELDS']

# Built at install (`compiled`), once per argument types; nogil lets a caller thread them.
_jit = jit
#: What every `outputs` hook returns, in order. nodes (N + 1, 2) [m], the tip last; beta (N,)
#: and theta (N,), every segment's rotation and its angle at its start [rad]; coefficients
#: (N, 4) (b1 [-], b3 [1/m^2], c1 [-], d [1/m]), or (0, 4) where the discretisation has
#: none; valid (the CCM's small-rotation rule, else True); and with `samples`: the energy
#: [J] (else NaN), points (M, 2) [m], tangent (M,) [rad] and strains (M, 3) (eps [-],
#: kappa [1/m], c1 [-]), or (0, 3) where the discretisation has none; without, (0, ...).
OUTPUT_FIELDS = ('nodes', 'beta', 'theta', 'coefficients', 'valid', 'energy', 'points',
                 'tangent', 'strains')


# -- the CCM -----------------------------------------------------------------------------------
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
    `OUTPUT_FIELDS` of a CCM state q (N, 4) (scaled unknowns); strains (0, 3): it has none.

    References
    ----------
    Zhou, Headings, Dapino (2022), eqs. (15)-(16); SPEC "Kinematics", "Derived outputs".
    """
    chain_nodes, theta, beta = chain.node_positions_kernel(q, p.lengths)
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


# -- the PCC rod ---------------------------------------------------------------------------------
@_jit
def pcc_outputs(p, x, pressure, nodes, forces, samples):
    """
    `OUTPUT_FIELDS` of a PCC state x (3 N,) (engine unknowns (eps_i, c1_i, theta_i)).

    A sample at sigma into segment i has turned by kappa_i sigma, and its partial chord is
    (1 + eps_i) sigma S(kappa_i sigma) along the mean tangent: exactly on the arc; the last
    sample is the tip. coefficients are (eps, -kappa^2/6, c1, kappa/2) [-, 1/m^2, -, 1/m],
    the CCM's of a segment with the same uniform strain.

    References
    ----------
    docs/physics.md, sections 11.4 and 11.6.
    """
    lengths = p.lengths
    n = lengths.size
    chain_nodes = nodes_kernel(x, lengths)
    prev = np.empty(n)
    beta = np.empty(n)
    kappa = np.empty(n)
    coefficients = np.empty((n, 4))
    before = 0.0
    for i in range(n):
        eps, c1, theta = x[3 * i], x[3 * i + 1], x[3 * i + 2]
        prev[i] = before
        beta[i] = theta - before
        kappa[i] = beta[i] / lengths[i]
        coefficients[i, 0] = eps
        coefficients[i, 1] = -(kappa[i] * kappa[i]) / 6.0
        coefficients[i, 2] = c1
        coefficients[i, 3] = 0.5 * kappa[i]
        before = theta
    if not samples:
        return (chain_nodes, beta, prev, coefficients, True, np.nan, np.empty((0, 2)),
                np.empty(0), np.empty((0, 3)))
    energy = energy_kernel(x, lengths, p.stiffness, p.gas, p.pemc,
                           p.pressure_coefficient * pressure, nodes, forces)
    m = p.sample_segment.size
    points = np.empty((m, 2))
    tangent = np.empty(m)
    strains = np.empty((m, 3))
    for k in range(m):
        i = p.sample_segment[k]
        sigma = p.sample_offset[k]
        eps = x[3 * i]
        turn = kappa[i] * sigma
        half = prev[i] + 0.5 * turn
        reach = ((1.0 + eps) * sigma) * _sinc0(turn)
        points[k, 0] = chain_nodes[i, 0] + reach * math.cos(half)
        points[k, 1] = chain_nodes[i, 1] + reach * math.sin(half)
        tangent[k] = prev[i] + turn
        strains[k, 0] = eps
        strains[k, 1] = kappa[i]
        strains[k, 2] = x[3 * i + 1]
    points[m - 1, 0], points[m - 1, 1] = chain_nodes[n, 0], chain_nodes[n, 1]
    return chain_nodes, beta, prev, coefficients, True, energy, points, tangent, strains


# -- the arc -------------------------------------------------------------------------------------
@_jit
def arc_outputs(p, x, pressure, nodes, forces, samples):
    """
    `OUTPUT_FIELDS` of an arc state x = (eps, kappa L, c1) at `p.samples` evenly spaced s.

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
