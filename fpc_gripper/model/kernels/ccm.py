"""Compiled (numba) drop-in equivalents of the CCM energy, kinematics and Newton step."""

import collections
import functools
import math

import numpy as np

from ..compiled import jit

__all__ = ['segment_energy', 'segment_derivatives', 'load_energy', 'load_derivatives',
           'node_jacobian', 'load_arrays', 'consistent_strain_map', 'node_positions',
           'end_rotation',
           'newton_step', 'segment_energy_kernel', 'segment_derivatives_kernel',
           'load_energy_kernel', 'load_derivatives_kernel', 'consistent_strain_map_kernel',
           'node_positions_kernel', 'end_rotation_kernel', 'newton_step_blocks',
           'newton_step_dense']

# Built at install (`compiled`), once per argument types; nogil lets a caller thread them.
_jit = jit
#: Eigenvalues of an indefinite Hessian are mirrored and floored at this times max |lambda|.
EIGEN_FLOOR = 1e-8
# Columns of the PEMC products (1, phi_a, phi_a phi_b) take F, sigma and sigma' in turn
# (as energy._PRODUCT_LAW), and the (a, b) of phi_a phi_b at products[..., 4 + k].
_PRODUCT_LAW = (0, 1, 1, 1, 2, 2, 2, 2, 2, 2)
_PAIR_A = (0, 0, 0, 1, 1, 2)
_PAIR_B = (0, 1, 2, 1, 2, 2)


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
def _horner5(law, column, s):
    """Column `column` of the PEMC law at strain s: sum_k law[k, column] s^k, k = 0..5."""
    acc = law[5, column]
    for k in range(4, -1, -1):
        acc = acc * s + law[k, column]
    return acc


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
            pemc += pemc_weights[i, p] * _horner5(law, 0, s)
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
    grad = np.zeros((n, 4))
    hess = np.zeros((n, 4, 4))
    y = np.empty(4)
    g_y = np.empty(4)
    h_y = np.empty((4, 4))
    pemc = np.empty(10)
    # d(A, B', D', C)/dq: constant but for dB'/dq3 = 4 q3.
    jac = np.zeros((4, 4))
    jac[0, 0] = 1.0
    jac[1, 1] = 3.0
    jac[2, 3] = 1.0
    jac[3, 2] = 1.0
    m = np.empty((4, 4))
    for i in range(n):
        _strain_unknowns(q, i, y)
        pemc[:] = 0.0
        for p in range(points):
            s = _pemc_strain(pemc_basis, i, p, y, prestrain)
            density = _horner5(law, 0, s)
            stress = _horner5(law, 1, s)
            tangent = _horner5(law, 2, s)
            # The (1, phi_a, phi_a phi_b) products take F, sigma and sigma' (_PRODUCT_LAW).
            pemc[0] += density * pemc_products[i, p, 0]
            for c in range(1, 4):
                pemc[c] += stress * pemc_products[i, p, c]
            for c in range(4, 10):
                pemc[c] += tangent * pemc_products[i, p, c]
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
        energy[i] = 0.5 * quadratic + pemc[0] - work * lin_gas
        for a in range(3):
            g_y[a] += pemc[1 + a] - work * gas_moments[i, a]
        g_y[3] -= pressure_work * lin_gas
        for a in range(4):
            for b in range(4):
                h_y[a, b] = stiffness[i, a, b]
        for k in range(6):
            a, b = _PAIR_A[k], _PAIR_B[k]
            h_y[a, b] += pemc[4 + k]
            if a != b:
                h_y[b, a] += pemc[4 + k]
        for a in range(3):
            h_y[a, 3] -= pressure_work * gas_moments[i, a]
            h_y[3, a] -= pressure_work * gas_moments[i, a]
        # Chain rule y(q): A = q0, B' = 3 q1 + 2 q3^2, D' = q3, C = q2.
        jac[1, 3] = 4.0 * q[i, 3]
        _chain_rule(g_y, h_y, jac, m, grad[i], hess[i])
        hess[i, 3, 3] += 4.0 * g_y[1]
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


# -- kinematics ---------------------------------------------------------------------------
@_jit
def end_rotation_kernel(q):
    """
    End rotation of each segment, beta_i = atan2(2 d L_i, 1 + b1 + 3 b3 L_i^2) [rad].

    References
    ----------
    Zhou, Headings, Dapino (2022), eq. (16), with SPEC's erratum (no stray L_i).

    """
    n = q.shape[0]
    beta = np.empty(n)
    for i in range(n):
        beta[i] = math.atan2(2.0 * q[i, 3], 1.0 + q[i, 0] + 3.0 * q[i, 1])
    return beta


@_jit
def node_positions_kernel(q, lengths):
    """
    Global (X, Z) of every node by eq. (15), with node angles (eq. 1) and end rotations.

    Returns
    -------
    nodes : ndarray, shape (N + 1, 2)
        Node positions [m]; nodes[-1] is the tip.
    theta : ndarray, shape (N,)
        Node angles [rad].
    beta : ndarray, shape (N,)
        End rotations [rad].

    """
    n = q.shape[0]
    beta = end_rotation_kernel(q)
    theta = np.empty(n)
    nodes = np.zeros((n + 1, 2))
    angle = 0.0
    for i in range(n):
        theta[i] = angle
        angle += beta[i]
        u = lengths[i] * (1.0 + q[i, 0] + q[i, 1])
        w = lengths[i] * q[i, 3]
        c, s = math.cos(theta[i]), math.sin(theta[i])
        nodes[i + 1, 0] = nodes[i, 0] + (c * u - s * w)
        nodes[i + 1, 1] = nodes[i, 1] + (s * u + c * w)
    return nodes, theta, beta


@_jit
def consistent_strain_map_kernel(q):
    """
    Strain unknowns of the 'consistent' reconstruction, with first and second derivatives.

    b1 = bt1 + 3 bt3 L^2, b3 L^2 = -2 bt3 L^2, d L = dt L / (1 + b1); see
    `ccm_geometry.consistent_strain_map`.

    Returns
    -------
    qs : ndarray, shape (N, 4)
        Scaled strain unknowns (b1, b3 L^2, c1, d L).
    jac : ndarray, shape (N, 4, 4)
        d qs / d qt.
    hess3 : ndarray, shape (N, 4, 4)
        d^2 qs[3] / d qt^2.

    """
    n = q.shape[0]
    qs = np.empty((n, 4))
    jac = np.zeros((n, 4, 4))
    hess3 = np.zeros((n, 4, 4))
    for i in range(n):
        inv = 1.0 / (1.0 + q[i, 0] + 3.0 * q[i, 1])
        d = q[i, 3]
        qs[i, 0] = q[i, 0] + 3.0 * q[i, 1]
        qs[i, 1] = -2.0 * q[i, 1]
        qs[i, 2] = q[i, 2]
        qs[i, 3] = d * inv
        jac[i, 0, 0] = jac[i, 2, 2] = 1.0
        jac[i, 0, 1] = 3.0
        jac[i, 1, 1] = -2.0
        jac[i, 3, 0] = -d * inv * inv
        jac[i, 3, 1] = -3.0 * d * inv * inv
        jac[i, 3, 3] = inv
        # (2 d inv^3) a a^T - inv^2 (a e3^T + e3 a^T), a = (1, 3, 0, 0).
        curve = 2.0 * d * inv ** 3
        mixed = inv * inv
        hess3[i, 0, 0] = curve
        hess3[i, 0, 1] = hess3[i, 1, 0] = 3.0 * curve
        hess3[i, 1, 1] = 9.0 * curve
        hess3[i, 0, 3] = hess3[i, 3, 0] = -mixed
        hess3[i, 1, 3] = hess3[i, 3, 1] = -3.0 * mixed
    return qs, jac, hess3


def end_rotation(q):
    """Compiled `ccm_geometry.end_rotation`, shape (N,) [rad]."""
    return end_rotation_kernel(q)


def node_positions(q, lengths):
    """Compiled `ccm_geometry.node_positions`: (nodes (N + 1, 2), theta (N,), beta (N,))."""
    return node_positions_kernel(q, lengths)


def consistent_strain_map(q):
    """Compiled `ccm_geometry.consistent_strain_map`: (qs (N, 4), jac, hess3 (N, 4, 4))."""
    return consistent_strain_map_kernel(q)


# -- point loads --------------------------------------------------------------------------
_NO_NODES = np.zeros(0, dtype=np.int64)
_NO_FORCES = np.zeros((0, 2))


def load_arrays(loads):
    """
    Point loads as the kernels take them.

    Parameters
    ----------
    loads : sequence of (int, array_like (2,))
        Node index n in 1..N and force (F_X, F_Z) [N].

    Returns
    -------
    nodes : ndarray of int64, shape (K,)
    forces : ndarray, shape (K, 2)
        [N].

    """
    if not loads:
        return _NO_NODES, _NO_FORCES
    nodes = np.array([node for node, _ in loads], dtype=np.int64)
    forces = np.array([force for _, force in loads], dtype=float).reshape(len(loads), 2)
    return nodes, forces


@_jit
def load_energy_kernel(q, lengths, nodes, forces):
    """Potential of point loads, -sum F . O_n [J]; see `load_arrays` for nodes, forces."""
    if nodes.size == 0:
        return 0.0
    positions = node_positions_kernel(q, lengths)[0]
    total = 0.0
    for k in range(nodes.size):
        node = nodes[k]
        total += forces[k, 0] * positions[node, 0] + forces[k, 1] * positions[node, 1]
    return -total


@_jit
def _chain_terms(q, lengths):
    """
    Node positions, dbeta/dq, d2beta/dq2 and R(theta_j) dp_j/dq_j of every segment, compiled.

    p_j = L_j (1 + q0 + q1, q3) is the chord of segment j in its own frame, linear in q_j.
    """
    n = q.shape[0]
    positions, theta, _ = node_positions_kernel(q, lengths)
    # beta = atan2(b, a), a = 1 + q0 + 3 q1, b = 2 q3: da/dq = (1, 3, 0, 0), db/dq = 2 e3.
    dbeta = np.zeros((n, 4))
    d2beta = np.zeros((n, 4, 4))
    # R(theta_j) dp_j/dq_j: p_j depends on (q0, q1) along X_j and q3 along Z_j.
    rp = np.zeros((n, 2, 4))
    for j in range(n):
        a = 1.0 + q[j, 0] + 3.0 * q[j, 1]
        b = 2.0 * q[j, 3]
        r2 = a * a + b * b
        dbeta[j, 0] = -b / r2
        dbeta[j, 1] = 3.0 * (-b / r2)
        dbeta[j, 3] = 2.0 * (a / r2)
        r4 = r2 * r2
        # (2 a b / r^4)(da da^T - db db^T) + ((b^2 - a^2) / r^4)(da db^T + db da^T).
        diff = 2.0 * a * b / r4
        mix = (b * b - a * a) / r4
        d2beta[j, 0, 0] = diff
        d2beta[j, 0, 1] = d2beta[j, 1, 0] = 3.0 * diff
        d2beta[j, 1, 1] = 9.0 * diff
        d2beta[j, 3, 3] = -4.0 * diff
        d2beta[j, 0, 3] = d2beta[j, 3, 0] = 2.0 * mix
        d2beta[j, 1, 3] = d2beta[j, 3, 1] = 6.0 * mix
        c, s = math.cos(theta[j]), math.sin(theta[j])
        rp[j, 0, 0] = rp[j, 0, 1] = lengths[j] * c
        rp[j, 1, 0] = rp[j, 1, 1] = lengths[j] * s
        rp[j, 0, 3] = -lengths[j] * s
        rp[j, 1, 3] = lengths[j] * c
    return positions, dbeta, d2beta, rp


@_jit
def node_jacobian_kernel(q, lengths, node):
    """
    Position of a chain node and its derivatives in the scaled unknowns, compiled.

    dO_n/dq_j = R(theta_j) dp_j/dq_j + S (O_n - O_{j+1}) dbeta_j/dq_j for j < n (S the
    90-degree rotation), 0 for j >= n.

    Returns
    -------
    position : ndarray, shape (2,)
        (X, Z) [m].
    jacobian : ndarray, shape (2, N, 4)
        d(X, Z)/dq [m].

    """
    positions, dbeta, _, rp = _chain_terms(q, lengths)
    jac = np.zeros((2, q.shape[0], 4))
    tx, tz = positions[node, 0], positions[node, 1]
    for j in range(node):
        # S r_j with r_j = O_n - O_{j+1}.
        ax = -(tz - positions[j + 1, 1])
        az = tx - positions[j + 1, 0]
        for a in range(4):
            jac[0, j, a] = rp[j, 0, a] + ax * dbeta[j, a]
            jac[1, j, a] = rp[j, 1, a] + az * dbeta[j, a]
    return positions[node].copy(), jac


@_jit
def load_derivatives_kernel(q, lengths, nodes, forces):
    """
    Energy, gradient and dense Hessian of point loads acting on chain nodes, compiled.

    The derivative of a node position O_n with respect to segment j < n is
    R(theta_j) dp_j/dq_j + S (O_n - O_{j+1}) dbeta_j/dq_j, with S the
    90-degree rotation; p_j = L_j (1 + q0 + q1, q3) is linear in q_j.

    Parameters
    ----------
    q : ndarray, shape (N, 4)
        Scaled unknowns.
    lengths : ndarray, shape (N,)
        Segment lengths [m].
    nodes : ndarray of int64, shape (K,)
        Loaded node indices in 1..N (N is the tip).
    forces : ndarray, shape (K, 2)
        (F_X, F_Z) of each load [N].

    Returns
    -------
    energy : float
    gradient : ndarray, shape (N, 4)
    hessian : ndarray, shape (4 N, 4 N)

    References
    ----------
    Zhou, Headings, Dapino (2022), eqs. (1), (15)-(18).

    """
    n = q.shape[0]
    grad = np.zeros((n, 4))
    hess = np.zeros((4 * n, 4 * n))
    energy = 0.0
    if nodes.size == 0:
        return energy, grad, hess
    positions, dbeta, d2beta, rp = _chain_terms(q, lengths)
    arm = np.empty((n, 4))
    for k in range(nodes.size):
        fx, fz = forces[k, 0], forces[k, 1]
        if fx == 0.0 and fz == 0.0:
            continue
        m = nodes[k]
        tx, tz = positions[m, 0], positions[m, 1]
        energy -= fx * tx + fz * tz
        for j in range(m):
            # r_j = O_n - O_{j+1}: the arm from node j+1 to the loaded node.
            rx = tx - positions[j + 1, 0]
            rz = tz - positions[j + 1, 1]
            moment = -fx * rz + fz * rx          # F^T S r_j
            f_dot_r = fx * rx + fz * rz
            for a in range(4):
                f_rp = fx * rp[j, 0, a] + fz * rp[j, 1, a]          # F^T R_j P_j
                fs_rp = -fx * rp[j, 1, a] + fz * rp[j, 0, a]        # F^T S R_j P_j
                grad[j, a] -= f_rp + moment * dbeta[j, a]
                # a_j = F^T S dO_n/dq_j couples segment j to every earlier rotation.
                arm[j, a] = fs_rp - f_dot_r * dbeta[j, a]
            for a in range(4):
                for b in range(4):
                    hess[4 * j + a, 4 * j + b] -= (moment * d2beta[j, a, b]
                                                   - f_dot_r * dbeta[j, a] * dbeta[j, b])
        for j in range(m):
            for la in range(j + 1, m):
                for a in range(4):
                    for b in range(4):
                        value = -(dbeta[j, a] * arm[la, b])
                        hess[4 * j + a, 4 * la + b] += value
                        hess[4 * la + b, 4 * j + a] += value
    return energy, grad, hess


def node_jacobian(q, lengths, node):
    """
    Position of a chain node [m] and its derivatives in the scaled unknowns, (2, N, 4).

    References
    ----------
    Zhou, Headings, Dapino (2022), eqs. (15)-(16); docs/physics.md, section 7.

    """
    return node_jacobian_kernel(np.ascontiguousarray(q, dtype=float), lengths, int(node))


def load_energy(q, lengths, loads):
    """
    Compiled `energy.load_energy`: potential of point loads, -sum F . O_n [J].

    Parameters
    ----------
    q : ndarray, shape (N, 4)
        Scaled unknowns.
    lengths : ndarray, shape (N,)
        Segment lengths [m].
    loads : sequence of (int, ndarray (2,))
        Node index n in 1..N (N is the tip) and force (F_X, F_Z) [N].

    """
    if not loads:
        return 0.0
    return load_energy_kernel(q, lengths, *load_arrays(loads))


def load_derivatives(q, lengths, loads):
    """
    Compiled `energy.load_derivatives`: energy, gradient (N, 4), dense Hessian (4N, 4N).

    References
    ----------
    Zhou, Headings, Dapino (2022), eqs. (1), (15)-(18).

    """
    if not loads:
        # Unloaded the answer is zeros: numpy allocates them faster than a kernel call.
        n = q.shape[0]
        return 0.0, np.zeros((n, 4)), np.zeros((4 * n, 4 * n))
    return load_derivatives_kernel(q, lengths, *load_arrays(loads))


# -- Newton step --------------------------------------------------------------------------
@_jit
def _cholesky_factor(a, low):
    """
    Cholesky factor of the lower triangle of a into low; False if a is not PD.

    As LAPACK potrf (OpenBLAS) it fails on a pivot <= 0 only: NaN propagates.
    """
    n = a.shape[0]
    for i in range(n):
        for j in range(i + 1):
            acc = a[i, j]
            for k in range(j):
                acc -= low[i, k] * low[j, k]
            if i == j:
                if acc <= 0.0:
                    return False
                low[i, i] = math.sqrt(acc)
            else:
                low[i, j] = acc / low[j, j]
    return True


@_jit
def _cholesky_substitute(low, rhs, out):
    """Solve L L^T x = rhs into out by forward and back substitution."""
    n = rhs.size
    for i in range(n):
        acc = rhs[i]
        for k in range(i):
            acc -= low[i, k] * out[k]
        out[i] = acc / low[i, i]
    for i in range(n - 1, -1, -1):
        acc = out[i]
        for k in range(i + 1, n):
            acc -= low[k, i] * out[k]
        out[i] = acc / low[i, i]


@_jit
def _dense_cholesky(a):
    """LAPACK Cholesky factor of a (lower), and whether a is positive definite."""
    # In nopython mode only `except Exception` is supported; LinAlgError is the only raise.
    try:
        return np.linalg.cholesky(a), True
    except Exception:
        return np.empty((0, 0)), False


@_jit
def _mirrored_solve(lam, vec, rhs, floor, out):
    """Solve V |Lambda| V^T x = rhs into out, |lambda| floored at floor."""
    n = lam.size
    out[:] = 0.0
    for k in range(n):
        coef = 0.0
        for i in range(n):
            coef += rhs[i] * vec[i, k]
        coef /= max(abs(lam[k]), floor)
        for i in range(n):
            out[i] += vec[i, k] * coef


@_jit
def newton_step_blocks(grad, hess, floor):
    """
    Newton step for a block-diagonal Hessian, compiled.

    Where every block is positive definite, the step solves each block by
    Cholesky. Otherwise the eigenvalues of every block are mirrored (|lambda|,
    floored at `floor` times the block's largest) so that the step still descends.

    Parameters
    ----------
    grad : ndarray, shape (N, m)
    hess : ndarray, shape (N, m, m)
    floor : float

    Returns
    -------
    step : ndarray, shape (N, m)
    min_eig : float
        1.0 when every block is positive definite, else the smallest eigenvalue.

    """
    n, m = grad.shape
    step = np.empty((n, m))
    low = np.empty((m, m))
    rhs = np.empty(m)
    out = np.empty(m)
    definite = True
    for i in range(n):
        for a in range(m):
            rhs[a] = -grad[i, a]
        if not _cholesky_factor(hess[i], low):
            definite = False
            break
        _cholesky_substitute(low, rhs, out)
        step[i] = out
    if definite:
        return step, 1.0
    min_eig = np.inf
    for i in range(n):
        lam, vec = np.linalg.eigh(hess[i])
        min_eig = min(min_eig, lam.min())
        for a in range(m):
            rhs[a] = -grad[i, a]
        _mirrored_solve(lam, vec, rhs, floor * np.abs(lam).max(), out)
        step[i] = out
    return step, min_eig


@_jit
def newton_step_dense(grad, hess, floor):
    """
    Newton step for a dense Hessian, compiled: Cholesky, else mirrored eigenvalues.

    Parameters
    ----------
    grad : ndarray, shape (n,)
    hess : ndarray, shape (n, n)
    floor : float
        Mirrored eigenvalues are floored at this times the largest |lambda|.

    Returns
    -------
    step : ndarray, shape (n,)
    min_eig : float
        1.0 when the Hessian is positive definite, else its smallest eigenvalue.

    """
    # A 4 N system is large enough that LAPACK's blocked factorisation beats loops.
    low, definite = _dense_cholesky(hess)
    return _factored_step(grad, hess, low, definite, floor)


@_jit
def _factored_step(grad, hess, low, definite, floor):
    """`newton_step_dense` given the Cholesky factor of hess (when `definite`)."""
    n = hess.shape[0]
    rhs = -grad
    out = np.empty(n)
    if definite:
        _cholesky_substitute(low, rhs, out)
        return out, 1.0
    lam, vec = np.linalg.eigh(hess)
    _mirrored_solve(lam, vec, rhs, floor * np.abs(lam).max(), out)
    return out, lam.min()


def newton_step(grad, hess, floor=EIGEN_FLOOR):
    """
    Newton step -H^-1 g, and the smallest eigenvalue (1.0 when H is positive definite).

    Where H is not positive definite its eigenvalues are mirrored (|lambda|, floored at
    `floor` times the largest) so that the step still descends.

    Parameters
    ----------
    grad : ndarray
        (N, m) for a block Hessian; any shape for a dense one.
    hess : ndarray, shape (N, m, m) or (n, n)
        Block-diagonal or dense Hessian.
    floor : float

    Returns
    -------
    step : ndarray, shape of `grad`
    min_eig : float

    """
    grad = np.ascontiguousarray(grad, dtype=float)
    hess = np.ascontiguousarray(hess, dtype=float)
    if hess.ndim == 3:
        return newton_step_blocks(grad, hess, float(floor))
    step, min_eig = newton_step_dense(grad.ravel(), hess, float(floor))
    return step.reshape(grad.shape), min_eig


# -- the engine's discretisation: CCM-N as a namedtuple of arrays ----------------------------
#: CCM-N as `engine` runs it compiled. `dense` (the scene has point loads) picks the Hessian:
#: unloaded, the segments decouple into (N, 4, 4) blocks; loaded, the chained frames couple
#: every segment into one dense (4N, 4N) matrix. One type for both, so that each engine loop
#: compiles once for the CCM. The Hessian is (blocks or (1, 4N, 4N), factor, definite).
CCMData = collections.namedtuple('CCMData', (
    'stiffness', 'gas_volume', 'gas_moments', 'pemc_basis', 'pemc_weights', 'pemc_products',
    'prestrain', 'law', 'pressure_coefficient', 'lengths', 'consistent', 'dense'))
#: The factor slot of a block Hessian, which has none.
_NO_FACTOR = np.zeros((0, 0))


def ccm_data(seg, prestrain, emc, pressure_coefficient, consistent, loaded):
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

    """
    return CCMData(seg.stiffness, seg.gas_volume, seg.gas_moments, seg.pemc_basis,
                   seg.pemc_weights, seg.pemc_products, float(prestrain), _law_matrix(emc),
                   float(pressure_coefficient), seg.lengths, bool(consistent), bool(loaded))


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


#: The CCM's hooks, by the engine's names (`engine.register` takes them).
CCM_HOOKS = {'derivatives': ccm_derivatives, 'energy': ccm_energy, 'step': ccm_step,
             'solve_linear': ccm_solve_linear, 'node_jacobian': ccm_node_jacobian}
