"""Total potential of the CCM and its exact gradient and Hessian: the compiled kernels."""

import numpy as np

from .kernels import beta_derivatives, load_derivatives, load_energy, node_positions, \
    segment_derivatives, segment_energy

__all__ = ['segment_energy', 'segment_derivatives', 'load_energy', 'load_derivatives',
           'node_jacobian']


def _rotated_chords(lengths, theta):
    """R(theta_j) dp_j/dq_j, shape (N, 2, 4): p_j = L_j (1 + q0 + q1, q3) is linear in q_j."""
    c, s = np.cos(theta), np.sin(theta)
    rp = np.zeros((lengths.size, 2, 4))
    rp[:, 0, 0] = rp[:, 0, 1] = lengths * c
    rp[:, 1, 0] = rp[:, 1, 1] = lengths * s
    rp[:, 0, 3] = -lengths * s
    rp[:, 1, 3] = lengths * c
    return rp


def node_jacobian(q, lengths, node):
    """
    Position of a chain node and its derivatives in the scaled unknowns.

    dO_n/dq_j = R(theta_j) dp_j/dq_j + S (O_n - O_{j+1}) dbeta_j/dq_j for j < n (S the
    90-degree rotation), 0 for j >= n.

    Parameters
    ----------
    q : ndarray, shape (N, 4)
        Scaled unknowns.
    lengths : ndarray, shape (N,)
        Segment lengths [m].
    node : int
        Node index in 0..N (N is the tip).

    Returns
    -------
    position : ndarray, shape (2,)
        (X, Z) [m].
    jacobian : ndarray, shape (2, N, 4)
        d(X, Z)/dq [m].

    References
    ----------
    Zhou, Headings, Dapino (2022), eqs. (15)-(16); docs/physics.md, section 7.

    """
    nodes, theta, _ = node_positions(q, lengths)
    dbeta = beta_derivatives(q)[0]
    rp = _rotated_chords(lengths, theta)
    jac = np.zeros((2, q.shape[0], 4))
    m = int(node)
    r = nodes[m] - nodes[1:m + 1]
    arm = np.stack([-r[:, 1], r[:, 0]])                 # S r_j, (2, m)
    jac[:, :m, :] = rp[:m].transpose(1, 0, 2) + arm[:, :, None] * dbeta[None, :m, :]
    return nodes[m].copy(), jac
