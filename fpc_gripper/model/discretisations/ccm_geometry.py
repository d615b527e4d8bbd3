"""Chain kinematics of the CCM: end rotations, node positions and midplane samples."""

import numpy as np

from ..kernels import chain
from ..section.segments import interval_of

__all__ = ['to_scaled', 'from_scaled', 'end_rotation', 'node_positions',
           'material_positions', 'consistent_strain_map', 'consistent_from_strain']

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
    End rotation beta_i = atan2(2 q3, 1 + q0 + 3 q1) of every segment [rad] (compiled).

    References
    ----------
    Zhou, Headings, Dapino (2022), eq. (16) without its stray L_i (SPEC erratum).

    """
    return chain.end_rotation(q)


def node_positions(q, lengths):
    """
    Chain nodes O_i (eq. 15), cumulative rotations theta_i and end rotations beta_i (compiled).

    Returns
    -------
    nodes : ndarray, shape (N + 1, 2)
        [m].
    theta : ndarray, shape (N,)
        Rotation of each segment's local frame [rad].
    beta : ndarray, shape (N,)
        End rotations [rad].

    """
    return chain.node_positions(q, lengths)


def _segment_points(q, lengths, nodes, theta, segment, xi):
    """
    Global (X, Z) of the points at xi = x / L_i of segments `segment` (eq. 13, then eq. 15).

    `segment` indexes the segments (an index array, or a slice), and `xi` broadcasts
    against a column per indexed segment; returns X and Z of that broadcast shape [m].
    """
    q = q[segment]
    length = lengths[segment][:, None]
    u = length * ((1.0 + q[:, :1]) * xi + q[:, 1:2] * xi ** 3)
    w = length * q[:, 3:4] * xi ** 2
    c, s = np.cos(theta[segment])[:, None], np.sin(theta[segment])[:, None]
    origin = nodes[:-1][segment]
    return origin[:, :1] + c * u - s * w, origin[:, 1:] + s * u + c * w


def material_positions(q, edges, s):
    """
    Global (X, Z) of the CCM's material points at reference arc lengths s [m].

    The point at s lies in segment i (edges[i] <= s < edges[i + 1], the last segment
    for s = L) at x = s - edges[i], and its position is O_i + R(theta_i) (U(x), W(x)) of
    eqs. (13) and (15): exactly the drawn midplane (a result's `points`).

    Parameters
    ----------
    q : ndarray, shape (N, 4)
        Scaled unknowns.
    edges : ndarray, shape (N + 1,)
        Segment edges [m].
    s : ndarray, shape (K,)
        Arc lengths in [0, L] [m].

    Returns
    -------
    ndarray, shape (K, 2)
        [m].

    """
    lengths = np.diff(edges)
    nodes, theta, _ = node_positions(q, lengths)
    segment = interval_of(edges, s)
    xi = ((s - edges[segment]) / lengths[segment])[:, None]
    x, z = _segment_points(q, lengths, nodes, theta, segment, xi)
    return np.concatenate([x, z], axis=1)


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
    return chain.consistent_strain_map(q)


def consistent_from_strain(qs):
    """Inverse of `consistent_strain_map`: scaled reconstruction unknowns from strain ones."""
    qs = np.asarray(qs, dtype=float)
    q = np.empty_like(qs)
    q[:, 1] = -0.5 * qs[:, 1]
    q[:, 0] = qs[:, 0] - 3.0 * q[:, 1]
    q[:, 2] = qs[:, 2]
    q[:, _D] = (1.0 + qs[:, 0]) * qs[:, _D]
    return q
