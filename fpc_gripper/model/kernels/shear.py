"""Compiled (numba) shear move of the corrected rung: a tip force's Timoshenko term on PCC arcs."""

import math

import numpy as np

from .circle import circle_fit
from ..compiled import jit

__all__ = ['shear_moves', 'shear_outputs']

# Built at install (`compiled`), once per argument types; nogil lets a caller thread them.
_jit = jit


@_jit
def _part_moments(a, b, length):
    """
    Return int n n^T ds as (xx, xz, zz) over an arc part from angle a to b [m].

    On a part of reference length l whose tangent turns linearly from a to b,
    int n n^T ds = (l / 2) (I - [[C, S], [S, -C]]), (C, S) = (cos, sin)(a + b) sinc(b - a).
    """
    d = b - a
    half = 0.5 * length
    # sin(d) / d loses no digits as d -> 0; only d = 0 itself needs its limit, 1.
    sinc = half if d == 0.0 else math.sin(d) / d * half
    p = a + b
    c = math.cos(p) * sinc
    return half - c, -math.sin(p) * sinc, half + c


@_jit
def shear_moves(x, lengths, segment, offset, f0, p0, compliance):
    """
    Move of the nodes and of material points by the shear strain of a tip force [m].

    A point at arc length s moves by c int_0^s n n^T ds F (`_part_moments` on every
    segment before it, then on its own part): the nodes' integrals are running sums over
    the segments, and a point's is its segment's start node's plus its part's.

    Parameters
    ----------
    x : ndarray, shape (3 N,)
        Engine unknowns (eps_i, c1_i, theta_i) per segment: theta_i is segment i's end
        angle (the first starts at 0) [rad].
    lengths : ndarray, shape (N,)
        Reference lengths [m].
    segment : ndarray of int64, shape (M,)
        Segment of every point.
    offset : ndarray, shape (M,)
        Its reference arc length into that segment, in [0, L_i] [m].
    f0, p0 : float
        Tip force along X and Z [N].
    compliance : float
        1 / (k G A) [1/N].

    Returns
    -------
    nodes : ndarray, shape (N + 1, 2)
        Moves of the segment ends, the clamp's (zero) first and the tip's last [m].
    points : ndarray, shape (M, 2)
        Moves of the points [m].

    References
    ----------
    docs/physics.md, section 18.1.
    """
    n = lengths.size
    fx, fz = compliance * f0, compliance * p0
    # Running (xx, xz, zz) at every node: a point's integral starts from its segment's.
    whole = np.empty((n + 1, 3))
    nodes = np.empty((n + 1, 2))
    xx = xz = zz = 0.0
    start = 0.0
    for i in range(n + 1):
        whole[i, 0], whole[i, 1], whole[i, 2] = xx, xz, zz
        nodes[i, 0] = xx * fx + xz * fz
        nodes[i, 1] = xz * fx + zz * fz
        if i < n:
            end = x[3 * i + 2]
            dxx, dxz, dzz = _part_moments(start, end, lengths[i])
            xx += dxx
            xz += dxz
            zz += dzz
            start = end
    points = np.empty((segment.size, 2))
    for k in range(segment.size):
        i = segment[k]
        a = 0.0 if i == 0 else x[3 * i - 1]
        dxx, dxz, dzz = _part_moments(a, a + (x[3 * i + 2] - a) * (offset[k] / lengths[i]),
                                      offset[k])
        pxx, pxz, pzz = whole[i, 0] + dxx, whole[i, 1] + dxz, whole[i, 2] + dzz
        points[k, 0] = pxx * fx + pxz * fz
        points[k, 1] = pxz * fx + pzz * fz
    return nodes, points


@_jit
def shear_outputs(x, lengths, segment, offset, f0, p0, compliance, tip, nodes, points, fit):
    """
    Return a result's tip, nodes and samples moved by `shear_moves`, and their circle fit.

    Parameters
    ----------
    x, lengths, f0, p0, compliance
        As `shear_moves`.
    segment, offset : ndarray, shape (M,)
        The samples' segments and offsets (empty with no samples).
    tip : ndarray, shape (2,)
        The rod's tip [m].
    nodes : ndarray, shape (N + 1, 2) or (0, 2)
        The rod's nodes [m], or none.
    points : ndarray, shape (M, 2)
        The rod's samples at `segment`, `offset` [m].
    fit : bool
        Whether to fit the circle to the moved samples (`circle.circle_fit`).

    Returns
    -------
    tip, nodes, points : ndarray
        New arrays, the inputs moved [m].
    curvature, fit_rmsd : float
        Of the moved samples' circle [1/m, m]; NaN without `fit`.

    """
    node_moves, point_moves = shear_moves(x, lengths, segment, offset, f0, p0, compliance)
    n = lengths.size
    moved_tip = np.empty(2)
    moved_tip[0] = tip[0] + node_moves[n, 0]
    moved_tip[1] = tip[1] + node_moves[n, 1]
    moved_nodes = np.empty(nodes.shape)
    for i in range(nodes.shape[0]):
        moved_nodes[i, 0] = nodes[i, 0] + node_moves[i, 0]
        moved_nodes[i, 1] = nodes[i, 1] + node_moves[i, 1]
    moved_points = np.empty(points.shape)
    for k in range(points.shape[0]):
        moved_points[k, 0] = points[k, 0] + point_moves[k, 0]
        moved_points[k, 1] = points[k, 1] + point_moves[k, 1]
    curvature = rmsd = np.nan
    if fit and points.shape[0] >= 3:
        curvature, rmsd, _, _ = circle_fit(moved_points)
    return moved_tip, moved_nodes, moved_points, curvature, rmsd
