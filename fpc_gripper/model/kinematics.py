"""Chain kinematics of the CCM: end rotations, node positions and midplane samples."""

import numpy as np

__all__ = ['to_scaled', 'from_scaled', 'end_rotation', 'node_positions', 'midplane_samples',
           'rotation_sum']

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
    Zhou, Headings, Dapino (2022), eq. (16), with SPEC's erratum (no stray L_i).

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
