"""Exact integration data of every segment: signed layer boxes reduced to moment matrices."""

from dataclasses import dataclass
import functools

import numpy as np

__all__ = ['SegmentData', 'build_segments', 'interval_of', 'share_segments', 'uniform_edges']

# Gauss-Legendre rules exact for the PEMC integrand: degree 10 in x, 5 in z (SPEC "Energy").
_GL_X = np.polynomial.legendre.leggauss(6)
_GL_Z = np.polynomial.legendre.leggauss(3)

# Basis of the axial strain e = A + B' xi^2 + D' z' with xi = x/L_i and z' = -2 z/L_i:
# exponents (p of xi, q of z') of the A, B', D' terms.
_EXPONENTS = ((0, 0), (2, 0), (0, 1))


@dataclass(frozen=True)
class SegmentData:
    """
    Integration data of N segments, built once per design and segmentation.

    All energies are written in the scaled unknowns q = (b1, b3 L^2, c1, d L) of
    each segment; the strain is e = A + B' xi^2 + D' z' with (A, B', D') =
    (q0, 3 q1 + 2 q3^2, q3), xi = x/L_i in [0, 1] and z' = -2 z/L_i.

    Attributes
    ----------
    edges : ndarray, shape (N + 1,)
        Segment edges along the free length [m].
    lengths : ndarray, shape (N,)
        Reference lengths L_i [m].
    stiffness : ndarray, shape (N, 4, 4)
        Linear-layer energy 1/2 y K y in y = (A, B', D', C=c1) [J].
    gas_volume : ndarray, shape (N,)
        Undeformed gas volume (channel minus ribs) [m^3].
    gas_moments : ndarray, shape (N, 3)
        Integrals of (1, xi^2, z') over the gas region [m^3].
    pemc_basis : ndarray, shape (N, P, 3)
        (1, xi^2, z') at the PEMC quadrature points.
    pemc_weights : ndarray, shape (N, P)
        Quadrature weights times the PEMC width [m^3].
    pemc_products : ndarray, shape (N, P, 10)
        Weights times (1, phi_a, phi_a phi_b for a <= b), the integrands of the
        PEMC energy, gradient and Hessian at each point [m^3].

    """

    edges: np.ndarray
    lengths: np.ndarray
    stiffness: np.ndarray
    gas_volume: np.ndarray
    gas_moments: np.ndarray
    pemc_basis: np.ndarray
    pemc_weights: np.ndarray
    pemc_products: np.ndarray

    @property
    def pemc_basis_t(self):
        """The PEMC basis transposed, shape (N, 3, P)."""
        return self.pemc_basis.transpose(0, 2, 1)

    @functools.cached_property
    def chain_jacobian(self):
        """d(A, B', D', C)/dq at q3 = 0, shape (N, 4, 4); dB'/dq3 = 4 q3 is set per call."""
        jac = np.zeros((self.n, 4, 4))
        jac[:, 0, 0] = 1.0
        jac[:, 1, 1] = 3.0
        jac[:, 2, 3] = 1.0
        jac[:, 3, 2] = 1.0
        return jac

    @property
    def n(self):
        """Number of segments."""
        return self.lengths.size


def share_segments(spans, n):
    """
    Segments per span, at least one each and `n` in all, as even in length as possible.

    Parameters
    ----------
    spans : ndarray, shape (K,)
        Span lengths [m].
    n : int
        Total segments, >= K.

    Returns
    -------
    ndarray of int, shape (K,)

    """
    spans = np.asarray(spans, dtype=float)
    counts = np.maximum(1, np.round(spans * (n / spans.sum()))).astype(int)
    while counts.sum() > n:
        # Take a segment where the lengths grow least, so that they stay the shortest.
        counts[np.argmin(np.where(counts > 1, spans / np.maximum(counts - 1, 1), np.inf))] -= 1
    while counts.sum() < n:
        counts[np.argmax(spans / counts)] += 1
    return counts


def interval_of(breaks, values):
    """
    Return the interval of increasing `breaks` holding each value: breaks[i] <= v < breaks[i + 1].

    A value at the last break, or beyond either end, belongs to the end interval (the
    segment of an arc length: the tip is in the last one).

    Parameters
    ----------
    breaks : ndarray, shape (K + 1,)
        Increasing.
    values : ndarray

    Returns
    -------
    ndarray of int, shape of `values`
        In [0, K - 1].

    """
    return np.clip(np.searchsorted(breaks, values, side='right') - 1, 0, breaks.size - 2)


def uniform_edges(length, n_segments, load_points=()):
    """
    Segment edges: n_segments equal parts, split so that every load point is an edge.

    Parameters
    ----------
    length : float
        Free length L [m].
    n_segments : int
        Total number of segments, at least 1 + number of interior load points.
    load_points : sequence of float
        Arc lengths in (0, L] where point loads act [m].

    Returns
    -------
    ndarray, shape (N + 1,)

    """
    points = sorted({float(s) for s in load_points if 0.0 < float(s) < length})
    breaks = np.array([0.0, *points, float(length)])
    spans = np.diff(breaks)
    if n_segments < spans.size:
        raise ValueError(f'`n_segments` must be >= {spans.size} to put an edge at every load '
                         f'point, got {n_segments}')
    # Segmentize before and after each load point separately (paper, Section III-D),
    # sharing the segments in proportion to the spans.
    counts = share_segments(spans, n_segments)
    edges = [np.linspace(a, b, c + 1)[:-1] for a, b, c in zip(breaks, breaks[1:], counts)]
    return np.concatenate([*edges, [float(length)]])


def _x_moments(lo, hi, length):
    """Integrals of xi^p dx over [lo, hi] (segment-local [m]) for p = 0..4, shape (..., 5)."""
    p = np.arange(5)
    a = np.clip(lo / length, 0.0, 1.0)[..., None]
    b = np.clip(hi / length, 0.0, 1.0)[..., None]
    return length[..., None] * (b ** (p + 1) - a ** (p + 1)) / (p + 1)


def _z_moments(z0, z1, length):
    """Integrals of z'^q dz over [z0, z1] for q = 0..2, z' = -2 z/L_i, shape (N, 3)."""
    q = np.arange(3)
    s = (-2.0 / length)[:, None]
    return s ** q * (z1 ** (q + 1) - z0 ** (q + 1)) / (q + 1)


def _box_matrices(xm, zm):
    """Return M[a, b] = int phi_a phi_b and v[a] = int phi_a over boxes, shapes (N,3,3), (N,3)."""
    n = xm.shape[0]
    mat = np.empty((n, 3, 3))
    vec = np.empty((n, 3))
    for a, (pa, qa) in enumerate(_EXPONENTS):
        vec[:, a] = xm[:, pa] * zm[:, qa]
        for b, (pb, qb) in enumerate(_EXPONENTS):
            mat[:, a, b] = xm[:, pa + pb] * zm[:, qa + qb]
    return mat, vec


def build_segments(design, edges):
    """
    Build the exact integration data for a design and segment edges.

    Parameters
    ----------
    design : ActuatorDesign
        The finger.
    edges : array_like, shape (N + 1,)
        Increasing segment edges from 0 to the free length [m].

    Returns
    -------
    SegmentData

    References
    ----------
    Zhou, Headings, Dapino (2022), eqs. (5)-(12) and (19); SPEC "Geometry", "Energy";
    docs/physics.md, sections 2, 5 and 6.

    """
    edges = np.asarray(edges, dtype=float)
    length = design.free_length
    if edges.ndim != 1 or edges.size < 2:
        raise ValueError(f'`segment_edges` must be a 1-D array of >= 2 edges [m], got shape '
                         f'{edges.shape}')
    if not np.all(np.isfinite(edges)) or np.any(np.diff(edges) <= 0.0):
        raise ValueError('`segment_edges` must be finite and strictly increasing [m]')
    if abs(edges[0]) > 1e-12 or abs(edges[-1] - length) > 1e-12 * max(length, 1.0):
        raise ValueError(f'`segment_edges` must run from 0 to the free length {length} [m], '
                         f'got [{edges[0]}, {edges[-1]}]')
    starts, ends = edges[:-1], edges[1:]
    lens = ends - starts
    n = lens.size
    full = _x_moments(np.zeros(n), lens, lens)

    cl, fl, emc = design.constraining_layer, design.fluidic_layer, design.emc
    width = design.Ly
    # (x moments, z-range, width, material, sign) of every linear box.
    boxes = [
        (full, (design.h1, design.H / 2), width, cl, 1.0),
        (full, (design.h2, design.h1), width, emc, 1.0),
        (full, (-design.h3, design.h2), width, fl, 1.0),
    ]
    channel = (-design.h3b, design.h3a)
    # Segments past the channel end get an empty interval: _x_moments clips to [0, L_i].
    chan_x = _x_moments(np.zeros(n), np.minimum(design.channel_end, ends) - starts, lens)
    gas = [(chan_x, design.Cy, 1.0)]
    if design.ribs:
        gas.append((chan_x, design.t, -1.0))
        ribs = design.transverse_ribs()
        rib_x = np.zeros((n, 5))
        for lo, hi in ribs:
            cut_lo = np.maximum(lo, starts) - starts
            cut_hi = np.minimum(hi, ends) - starts
            inside = cut_hi > cut_lo
            rib_x[inside] += _x_moments(cut_lo[inside], cut_hi[inside], lens[inside])
        gas.append((rib_x, 2.0 * design.w1, -1.0))
    # FL energy = whole - channel + ribs (eq. 8): the gas boxes with the opposite sign.
    boxes.extend((xm, channel, w, fl, -sign) for xm, w, sign in gas)

    stiffness = np.zeros((n, 4, 4))
    for xm, (z0, z1), w, mat_, sign in boxes:
        mat, vec = _box_matrices(xm, _z_moments(z0, z1, lens))
        stiffness[:, :3, :3] += sign * w * mat_.Q11 * mat
        stiffness[:, :3, 3] += sign * w * mat_.Q12 * vec
        stiffness[:, 3, 3] += sign * w * mat_.Q22 * vec[:, 0]
    stiffness[:, 3, :3] = stiffness[:, :3, 3]

    gas_moments = np.zeros((n, 3))
    for xm, w, sign in gas:
        gas_moments += sign * w * _box_matrices(xm, _z_moments(*channel, lens))[1]

    # PEMC: nonlinear along X by quadrature; its transverse term Q22 c1^2/2 is linear.
    zp0, zp1 = -design.H / 2, -design.h3
    stiffness[:, 3, 3] += width * emc.Q22 * lens * (zp1 - zp0)
    xi = 0.5 * (_GL_X[0] + 1.0)
    zq = zp0 + 0.5 * (_GL_Z[0] + 1.0) * (zp1 - zp0)
    wx = 0.5 * _GL_X[1]
    wz = 0.5 * (zp1 - zp0) * _GL_Z[1]
    xi_pts = np.repeat(xi, zq.size)
    z_pts = np.tile(zq, xi.size)
    w_pts = np.repeat(wx, zq.size) * np.tile(wz, xi.size)
    basis = np.empty((n, xi_pts.size, 3))
    basis[:, :, 0] = 1.0
    basis[:, :, 1] = xi_pts ** 2
    basis[:, :, 2] = -2.0 * z_pts[None, :] / lens[:, None]
    weights = width * lens[:, None] * w_pts[None, :]

    pairs = [(a, b) for a in range(3) for b in range(a, 3)]
    products = np.concatenate(
        [np.ones_like(weights)[:, :, None], basis,
         np.stack([basis[:, :, a] * basis[:, :, b] for a, b in pairs], axis=2)], axis=2)
    products *= weights[:, :, None]

    return SegmentData(edges=edges, lengths=lens, stiffness=stiffness,
                       gas_volume=gas_moments[:, 0].copy(), gas_moments=gas_moments,
                       pemc_basis=basis, pemc_weights=weights, pemc_products=products)
