"""Chain kinematics of the CCM: end rotations, node positions and midplane samples."""

import numpy as np

__all__ = ['to_scaled', 'from_scaled', 'end_rotation', 'node_positions', 'midplane_samples',
           'rotation_sum', 'consistent_strain_map', 'consistent_from_strain']

# q = (b1, b3 L^2, c1, d L) is dimensionless; these columns take it to SI and back.
_B3, _D = 1, 3


def to_scaled(coefficients, lengths):
    """Map SI coefficients (b1, b3, c1, d), shape (N, 4), to scaled q."""
    q = np.array(coefficients, dtype=float, copy=True)
    q[:, _B3] *= lengths ** 2
    q[:, _D] *= lengths
    return q


def from_scaled(q, lengths):
    """Map scaled q, shape (N, 4), to SI coefficients (b1 [-], b3 [1/m^2], c1 [-], d [1/m])."""
    c = np.array(q, dtype=float, copy=True)
    c[:, _B3] /= lengths ** 2
    c[:, _D] /= lengths
    return c


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


def consistent_strain_map(q):
    """
    Strain unknowns of the 'consistent' reconstruction, with first and second derivatives.

    The paper draws a segment as U = (1 + b1) x + b3 x^3, W = d x^2 and turns the
    chain by beta = atan2(2 d L, 1 + b1 + 3 b3 L^2), while the strain
    e = b1 + (3 b3 + 2 d^2) x^2 - 2 z d bends it by 2 d per reference length.
    Two inconsistencies follow that do not vanish as N grows: the chain turns
    by 2 d / (1 + b1) per reference length (deformed curvature 2 d / (1 + b1)^2
    instead of the rod's kappa / (1 + eps) = 2 d / (1 + b1)), and the axial
    strain variation B = 3 b3 + 2 d^2 rotates the segment end, so that tip
    loads drive B away from zero. The consistent reconstruction keeps the
    paper's kinematics in unknowns qt = (bt1, bt3 L^2, c1, dt L) chosen so that
    U(L) = (1 + b1) L + b3 L^3 (the integral of the axial strain, as the
    paper), W(L) = (1 + b1) d L^2 and beta = atan(2 d L), which are the rod's
    chord and end rotation of a segment to O(L^3):

        b1 = bt1 + 3 bt3 L^2,  b3 L^2 = -2 bt3 L^2,  d L = dt L / (1 + b1).

    Parameters
    ----------
    q : ndarray, shape (N, 4)
        Scaled reconstruction unknowns qt.

    Returns
    -------
    qs : ndarray, shape (N, 4)
        Scaled strain unknowns (b1, b3 L^2, c1, d L) used by the energy.
    jac : ndarray, shape (N, 4, 4)
        d qs / d qt.
    hess3 : ndarray, shape (N, 4, 4)
        d^2 qs[3] / d qt^2 (the only nonlinear component).

    References
    ----------
    docs/physics.md, section 11.1; docs/model_notes.md, "CCM reconstruction vs rod".

    """
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


def consistent_from_strain(qs):
    """Inverse of `consistent_strain_map`: scaled reconstruction unknowns from strain ones."""
    qs = np.asarray(qs, dtype=float)
    q = np.empty_like(qs)
    q[:, 1] = -0.5 * qs[:, 1]
    q[:, 0] = qs[:, 0] - 3.0 * q[:, 1]
    q[:, 2] = qs[:, 2]
    q[:, _D] = (1.0 + qs[:, 0]) * qs[:, _D]
    return q
