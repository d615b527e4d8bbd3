"""Compiled (numba) kinematics of the CCM chain and its point loads: positions, Jacobians, work."""

import math

import numpy as np

from ..compiled import jit

__all__ = ['end_rotation', 'node_positions', 'consistent_strain_map', 'load_arrays',
           'node_jacobian', 'load_energy', 'load_derivatives', 'end_rotation_kernel',
           'node_positions_kernel', 'consistent_strain_map_kernel', 'load_energy_kernel',
           'node_jacobian_kernel', 'load_derivatives_kernel']

# Built at install (`compiled`), once per argument types; nogil lets a caller thread them.
_jit = jit


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
