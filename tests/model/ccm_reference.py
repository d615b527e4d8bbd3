"""Numpy reference of the CCM energy and chain kinematics, for the compiled kernels' tests."""

import functools

import numpy as np

# q = (b1, b3 L^2, c1, d L): the column of d L.
_D = 3


def end_rotation(q):
    """
    End rotation of each segment, beta_i = atan2(2 d L_i, 1 + b1 + 3 b3 L_i^2) [rad].

    References
    ----------
    Zhou, Headings, Dapino (2022), eq. (16), with SPEC's erratum (no stray L_i);
    docs/physics.md, section 4.

    """
    return np.arctan2(2.0 * q[:, 3], 1.0 + q[:, 0] + 3.0 * q[:, 1])


def rotation_sum(beta):
    """Node angles theta_i = sum_{k<i} beta_k, theta_1 = 0 (eq. 1) [rad], shape (N,)."""
    theta = np.empty_like(beta)
    theta[0] = 0.0
    np.cumsum(beta[:-1], out=theta[1:])
    return theta


def node_positions(q, lengths):
    """
    Global (X, Z) of every node O_1..O_{N+1} by eq. (15).

    Returns
    -------
    nodes : ndarray, shape (N + 1, 2)
        Node positions [m]; nodes[-1] is the tip.
    theta : ndarray, shape (N,)
        Node angles [rad].
    beta : ndarray, shape (N,)
        End rotations [rad].

    """
    beta = end_rotation(q)
    theta = rotation_sum(beta)
    u = lengths * (1.0 + q[:, 0] + q[:, 1])
    w = lengths * q[:, 3]
    c, s = np.cos(theta), np.sin(theta)
    nodes = np.zeros((q.shape[0] + 1, 2))
    np.cumsum(c * u - s * w, out=nodes[1:, 0])
    np.cumsum(s * u + c * w, out=nodes[1:, 1])
    return nodes, theta, beta


def consistent_strain_map(q):
    """Compute `kinematics.consistent_strain_map` in numpy: the same returns."""
    n = q.shape[0]
    stretch = 1.0 + q[:, 0] + 3.0 * q[:, 1]
    inv = 1.0 / stretch
    qs = np.empty((n, 4))
    qs[:, 0] = q[:, 0] + 3.0 * q[:, 1]
    qs[:, 1] = -2.0 * q[:, 1]
    qs[:, 2] = q[:, 2]
    qs[:, _D] = q[:, _D] * inv
    jac = np.zeros((n, 4, 4))
    jac[:, 0, 0] = jac[:, 2, 2] = 1.0
    jac[:, 0, 1] = 3.0
    jac[:, 1, 1] = -2.0
    jac[:, _D, 0] = -q[:, _D] * inv * inv
    jac[:, _D, 1] = -3.0 * q[:, _D] * inv * inv
    jac[:, _D, _D] = inv
    a = np.array([1.0, 3.0, 0.0, 0.0])
    e3 = np.array([0.0, 0.0, 0.0, 1.0])
    hess3 = ((2.0 * q[:, _D] * inv ** 3)[:, None, None] * np.outer(a, a)
             - (inv * inv)[:, None, None] * (np.outer(a, e3) + np.outer(e3, a)))
    return qs, jac, hess3


def _strain_state(q, seg, prestrain):
    """Return y = (A, B', D', C) (N, 4) and the PEMC strain at the quadrature points (N, P)."""
    y = np.empty((q.shape[0], 4))
    y[:, 0] = q[:, 0]
    y[:, 1] = 3.0 * q[:, 1] + 2.0 * q[:, 3] ** 2
    y[:, 2] = q[:, 3]
    y[:, 3] = q[:, 2]
    strain = np.matmul(seg.pemc_basis, y[:, :3, None])[:, :, 0]
    strain += prestrain
    return y, strain


_POWERS = np.arange(6)
# Columns of the PEMC products (1, phi_a, phi_a phi_b) take F, sigma and sigma' in turn.
_PRODUCT_LAW = np.array([0, 1, 1, 1, 2, 2, 2, 2, 2, 2])
_SYM3 = np.array([[4, 5, 6], [5, 7, 8], [6, 8, 9]])


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


def segment_energy(q, seg, prestrain, emc, pressure_work):
    """
    Strain energy minus pressure work of every segment.

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
        k_p P, the pressure coefficient of Pi_P = -k_p P V [Pa].

    Returns
    -------
    ndarray, shape (N,)
        Phi_i - k_p P V_i [J].

    References
    ----------
    Zhou, Headings, Dapino (2022), eqs. (5)-(12), (19)-(20); SPEC "Energy", "Pressure work";
    docs/physics.md, sections 5 and 6.

    """
    y, strain = _strain_state(q, seg, prestrain)
    ky = np.matmul(seg.stiffness, y[:, :, None])[:, :, 0]
    density = np.matmul(strain[:, :, None] ** _POWERS, _law_matrix(emc)[:, 0])
    pemc = (seg.pemc_weights * density).sum(axis=1)
    # Pi_P = -c (1 + C)(V0 + g . y3): the gas volume is bilinear in (y3, C).
    volume = (1.0 + y[:, 3]) * (seg.gas_volume + (seg.gas_moments * y[:, :3]).sum(axis=1))
    return 0.5 * (y * ky).sum(axis=1) + pemc - pressure_work * volume


def segment_derivatives(q, seg, prestrain, emc, pressure_work):
    """
    Energy, gradient and Hessian of every segment in the scaled unknowns q.

    Without loads the segments decouple, so the Hessian is block diagonal.

    Returns
    -------
    energy : ndarray, shape (N,)
    gradient : ndarray, shape (N, 4)
    hessian : ndarray, shape (N, 4, 4)

    """
    y, strain = _strain_state(q, seg, prestrain)
    k = seg.stiffness
    ky = np.matmul(k, y[:, :, None])[:, :, 0]
    # F, sigma and sigma' at every point at once, then all PEMC integrals in one sum.
    law = np.matmul(strain[:, :, None] ** _POWERS, _law_matrix(emc))
    pemc = (law[:, :, _PRODUCT_LAW] * seg.pemc_products).sum(axis=1)

    gas = seg.gas_moments
    c1 = y[:, 3]
    lin_gas = seg.gas_volume + (gas * y[:, :3]).sum(axis=1)
    energy = 0.5 * (y * ky).sum(axis=1) + pemc[:, 0] - pressure_work * (1.0 + c1) * lin_gas

    g_y = ky
    g_y[:, :3] += pemc[:, 1:4] - pressure_work * (1.0 + c1)[:, None] * gas
    g_y[:, 3] -= pressure_work * lin_gas
    h_y = k.copy()
    h_y[:, :3, :3] += pemc[:, _SYM3]
    h_y[:, :3, 3] -= pressure_work * gas
    h_y[:, 3, :3] -= pressure_work * gas

    # Chain rule y(q): A = q0, B' = 3 q1 + 2 q3^2, D' = q3, C = q2.
    jac = np.array(seg.chain_jacobian)
    jac[:, 1, 3] = 4.0 * q[:, 3]
    grad = np.matmul(g_y[:, None, :], jac)[:, 0, :]
    hess = np.matmul(jac.transpose(0, 2, 1), np.matmul(h_y, jac))
    hess[:, 3, 3] += 4.0 * g_y[:, 1]
    return energy, grad, hess


def load_energy(q, lengths, loads):
    """
    Potential of point loads, -sum F . O_n [J].

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
    nodes = node_positions(q, lengths)[0]
    return -sum(float(force @ nodes[node]) for node, force in loads)


# beta = atan2(b, a) with a = 1 + q0 + 3 q1 and b = 2 q3: the constant da/dq, db/dq.
_DA = np.array([1.0, 3.0, 0.0, 0.0])
_DB = np.array([0.0, 0.0, 0.0, 2.0])
_DADB = np.stack([_DA, _DB])
# Second-derivative patterns: da da^T - db db^T and da db^T + db da^T.
_OUTER_DIFF = np.outer(_DA, _DA) - np.outer(_DB, _DB)
_OUTER_MIX = np.outer(_DA, _DB) + np.outer(_DB, _DA)


def _beta_derivatives(q):
    """First and second derivatives of beta_i in q_i, shapes (N, 4) and (N, 4, 4)."""
    a = 1.0 + q[:, 0] + 3.0 * q[:, 1]
    b = 2.0 * q[:, 3]
    r2 = a * a + b * b
    grad = np.stack([-b / r2, a / r2], axis=1) @ _DADB
    r4 = r2 * r2
    hess = ((2.0 * a * b / r4)[:, None, None] * _OUTER_DIFF
            + ((b * b - a * a) / r4)[:, None, None] * _OUTER_MIX)
    return grad, hess


def _rotated_chords(q, lengths, theta):
    """R(theta_j) dp_j/dq_j, shape (N, 2, 4): p_j = L_j (1 + q0 + q1, q3) is linear in q_j."""
    c, s = np.cos(theta), np.sin(theta)
    rp = np.zeros((q.shape[0], 2, 4))
    rp[:, 0, 0] = rp[:, 0, 1] = lengths * c
    rp[:, 1, 0] = rp[:, 1, 1] = lengths * s
    rp[:, 0, 3] = -lengths * s
    rp[:, 1, 3] = lengths * c
    return rp


def load_derivatives(q, lengths, loads):
    """
    Energy, gradient and full Hessian of point loads acting on chain nodes.

    The derivative of a node position O_n with respect to segment j < n is
    R(theta_j) dp_j/dq_j + S (O_n - O_{j+1}) dbeta_j/dq_j, with S the
    90-degree rotation; p_j = L_j (1 + q0 + q1, q3) is linear in q_j.

    Returns
    -------
    energy : float
    gradient : ndarray, shape (N, 4)
    hessian : ndarray, shape (4 N, 4 N)

    References
    ----------
    Zhou, Headings, Dapino (2022), eqs. (1), (15)-(18); docs/physics.md, section 7.

    """
    n = q.shape[0]
    grad = np.zeros((n, 4))
    hess = np.zeros((n, 4, n, 4))
    energy = 0.0
    if not loads:
        return energy, grad, hess.reshape(4 * n, 4 * n)
    nodes, theta, _ = node_positions(q, lengths)
    dbeta, d2beta = _beta_derivatives(q)
    rp = _rotated_chords(q, lengths, theta)
    for node, force in loads:
        fx, fz = float(force[0]), float(force[1])
        if fx == 0.0 and fz == 0.0:
            continue
        m = node
        tip = nodes[m]
        energy -= fx * tip[0] + fz * tip[1]
        # r_j = O_n - O_{j+1}: the arm from node j+1 to the loaded node.
        r = tip - nodes[1:m + 1]
        moment = -fx * r[:, 1] + fz * r[:, 0]          # F^T S r_j
        f_dot_r = fx * r[:, 0] + fz * r[:, 1]
        f_rp = fx * rp[:m, 0] + fz * rp[:m, 1]          # F^T R_j P_j, (m, 4)
        fs_rp = -fx * rp[:m, 1] + fz * rp[:m, 0]        # F^T S R_j P_j
        grad[:m] -= f_rp + moment[:, None] * dbeta[:m]
        # a_l = F^T S dO_n/dq_l couples segment l to every earlier rotation j < l.
        a = fs_rp - f_dot_r[:, None] * dbeta[:m]
        upper = -np.einsum('ja,lb->jalb', dbeta[:m], a)
        upper *= np.triu(np.ones((m, m)), 1)[:, None, :, None]
        block = hess[:m, :, :m, :]
        block += upper + upper.transpose(2, 3, 0, 1)
        idx = np.arange(m)
        block[idx, :, idx, :] -= (moment[:, None, None] * d2beta[:m]
                                  - f_dot_r[:, None, None]
                                  * dbeta[:m, :, None] * dbeta[:m, None, :])
    return energy, grad, hess.reshape(4 * n, 4 * n)


def newton_step(grad, hess, floor=1e-8):
    """Newton step and smallest eigenvalue (1.0 when positive definite), by numpy/scipy."""
    from scipy.linalg import eigh
    try:
        np.linalg.cholesky(hess)
        if hess.ndim == 3:
            return -np.linalg.solve(hess, grad[:, :, None])[:, :, 0], 1.0
        return -np.linalg.solve(hess, grad.ravel()).reshape(grad.shape), 1.0
    except np.linalg.LinAlgError:
        pass
    if hess.ndim == 3:
        lam, vec = np.linalg.eigh(hess)
        min_eig = float(lam.min())
        lam = np.maximum(np.abs(lam), floor * np.abs(lam).max(axis=1, keepdims=True))
        coef = np.matmul(grad[:, None, :], vec)[:, 0, :] / lam
        return -np.matmul(vec, coef[:, :, None])[:, :, 0], min_eig
    lam, vec = eigh(hess, check_finite=False)
    min_eig = float(lam.min())
    lam = np.maximum(np.abs(lam), floor * np.abs(lam).max())
    return -(vec @ ((vec.T @ grad.ravel()) / lam)).reshape(grad.shape), min_eig


def midplane_samples(q, lengths, per_segment=16):
    """
    Midplane samples at x = L_i j/m, j = 0..m-1 of every segment, then the tip.

    Returns
    -------
    points : ndarray, shape (N m + 1, 2)
        Global (X, Z) [m].
    tangent : ndarray, shape (N m + 1,)
        Angle of the tangent from +X towards +Z [rad].

    """
    nodes, theta, _ = node_positions(q, lengths)
    xi = np.arange(per_segment) / per_segment
    length = lengths[:, None]
    u = length * ((1.0 + q[:, :1]) * xi + q[:, 1:2] * xi ** 3)
    w = length * q[:, 3:4] * xi ** 2
    du = (1.0 + q[:, :1]) + 3.0 * q[:, 1:2] * xi ** 2
    dw = 2.0 * q[:, 3:4] * xi
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    x = nodes[:-1, :1] + c * u - s * w
    z = nodes[:-1, 1:] + s * u + c * w
    ang = theta[:, None] + np.arctan2(dw, du)
    tip_angle = theta[-1] + np.arctan2(2.0 * q[-1, 3], 1.0 + q[-1, 0] + 3.0 * q[-1, 1])
    points = np.concatenate([np.stack([x.ravel(), z.ravel()], axis=1), nodes[-1:]])
    return points, np.concatenate([ang.ravel(), [tip_angle]])
