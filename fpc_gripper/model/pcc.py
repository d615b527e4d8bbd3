"""Piecewise-constant-strain rod (PCC): the finger as N exact arcs, solved with a banded Newton."""

import math

import numpy as np
from scipy.linalg import cho_solve_banded, cholesky_banded, eig_banded, LinAlgError, solve_banded

from .engine import NewtonOptions
from .ladder import _check_common, _LadderSolver, LadderResult
from .section import share_segments
from .section_law import station_layout
from .solver import PRESSURE_MODELS

__all__ = ['PCCSolver', 'PCCResult', 'pcc_edges', 'half_angle_sinc']

#: Taylor coefficients (-1)^k / (2k + 1)! of sin(h)/h in h^2, k = 0..9: for |h| < 1 the
#: first omitted terms (of S and its derivatives) are below 1e-17 of S, S' / h and S''.
_SINC = np.array([(-1.0) ** k / math.factorial(2 * k + 1) for k in range(10)])
_K = np.arange(10)
#: The same series differentiated once (divided by h) and twice in h.
_SINC_D1 = (2 * _K * _SINC)[1:]
_SINC_D2 = (2 * _K * (2 * _K - 1) * _SINC)[1:]
#: |h| below which the series replaces the closed forms (which cancel as h -> 0).
_SERIES_BELOW = 1.0
#: Lower band of an element's 4 x 4 Hessian in the local unknowns (theta_prev, eps, c1,
#: theta): (row p, column q) with p >= q, i.e. band row d = p - q.
_BAND_PAIRS = tuple((q + d, q) for q in range(4) for d in range(4 - q))
#: Step caps: 0.1 on (eps, c1) as the rod, 0.5 rad on the angles.
_CAP = np.array([0.1, 0.1, 0.5])


def half_angle_sinc(delta, order=2):
    """
    S(delta) = sin(delta/2) / (delta/2) and its derivatives in delta, exact and smooth at 0.

    The chord of an arc that turns by delta over a deformed length l is
    l S(delta) along the mean tangent (docs/physics.md, section 11.6).

    Parameters
    ----------
    delta : array_like
        Turning angle [rad].
    order : {0, 1, 2}
        Highest derivative returned.

    Returns
    -------
    tuple of ndarray
        (S, dS/ddelta, d2S/ddelta2)[:order + 1] [-, 1/rad, 1/rad^2]; a Taylor series in
        h = delta/2 for |h| < 1, the closed forms elsewhere.

    """
    h = 0.5 * np.asarray(delta, dtype=float)
    h2 = h * h
    small = np.abs(h) < _SERIES_BELOW
    hs = np.where(small, 1.0, h)                     # closed forms only where |h| >= 1
    sn, cs = np.sin(hs), np.cos(hs)
    out = [np.where(small, _horner(h2, _SINC), sn / hs)]
    if order >= 1:
        d1 = np.where(small, h * _horner(h2, _SINC_D1), (hs * cs - sn) / hs ** 2)
        out.append(0.5 * d1)
    if order >= 2:
        d2 = np.where(small, _horner(h2, _SINC_D2),
                      -sn / hs - 2.0 * cs / hs ** 2 + 2.0 * sn / hs ** 3)
        out.append(0.25 * d2)
    return tuple(out)


def _horner(x, coefficients):
    """Return sum_k coefficients[k] x^k by Horner's rule (x an ndarray)."""
    out = np.full_like(x, coefficients[-1])
    for c in coefficients[-2::-1]:
        out *= x
        out += c
    return out


def pcc_edges(design, n_segments):
    """
    Segment edges of the PCC rod: every section change, then about N segments in all.

    The K constant-section intervals of `station_layout(design, ribs='exact')` (rib
    edges, channel end) are cut evenly, at least one segment each and max(N, K) in all,
    the counts chosen so that the segment lengths are as even as possible (the
    longest as short as possible), so that every segment has one section type.

    Parameters
    ----------
    design : ActuatorDesign
    n_segments : int
        Requested N; raised to K if smaller (K = 22 for the paper's finger, 1 for a
        rib-free finger whose channel spans the free length).

    Returns
    -------
    edges : ndarray, shape (max(N, K) + 1,)
        [m].
    types : ndarray of int, shape (max(N, K),)
        Section type of every segment (see `station_layout`).
    law : SectionLaw

    """
    breaks, types, law = station_layout(design, ribs='exact')
    counts = share_segments(np.diff(breaks), max(int(n_segments), types.size))
    edges = np.concatenate([*(np.linspace(a, b, c + 1)[:-1]
                              for a, b, c in zip(breaks, breaks[1:], counts)), breaks[-1:]])
    return edges, np.repeat(types, counts), law


class PCCResult(LadderResult):
    """
    Result of `PCCSolver`.

    `state` is an (N, 3) array of (theta_i [rad], eps_i [-], c1_i [-]): the end angle
    and the uniform axial and transverse strains of every segment; kappa_i =
    (theta_i - theta_{i-1}) / L_i. `beta` holds theta_i - theta_{i-1} [rad],
    `coefficients` the CCM coefficients (b1, b3, c1, d) = (eps, -kappa^2/6, c1,
    kappa/2) [-, 1/m^2, -, 1/m] of a segment with the same uniform strain, `nodes` the
    (N + 1, 2) segment ends [m]; `points` lie exactly on the arcs.
    """


class _Banded:
    """Symmetric banded Hessian: lower form ab[d, k] = H[k + d, k], d = 0..3 [J]."""

    __slots__ = ('lower',)

    def __init__(self, lower):
        self.lower = lower

    def full_band(self):
        """Return the (7, n) general band form of `solve_banded` with (l, u) = (3, 3)."""
        lower = self.lower
        n = lower.shape[1]
        band = np.zeros((7, n))
        band[3:] = lower
        for d in range(1, 4):
            band[3 - d, d:] = lower[d, :n - d]
        return band

    def dense(self):
        """Return the full (n, n) matrix (tests and diagnostics)."""
        lower = self.lower
        n = lower.shape[1]
        out = np.zeros((n, n))
        for d in range(4):
            k = np.arange(n - d)
            out[k + d, k] = lower[d, :n - d]
            out[k, k + d] = lower[d, :n - d]
        return out


class PCCSolver(_LadderSolver):
    """
    Piecewise-constant-strain rod: N segments, each an exact arc of uniform strain.

    Each segment i (reference length L_i, ONE section type: its edges include every
    rib edge and the channel end) has the uniform strain (eps_i, kappa_i, c1_i) of
    the rod's kinematics r' = (1 + eps)(cos theta, sin theta), theta' = kappa
    (docs/physics.md, section 11.4), so its energy L_i W(eps_i, kappa_i, c1_i; k_p P)
    is exact for that strain (section 11.2). The unknowns are the absolute end angles
    theta_i (theta_0 = 0 at the clamp) with eps_i and c1_i; kappa_i = (theta_i -
    theta_{i-1}) / L_i, and the chord of a segment is

        Delta r_i = (1 + eps_i) L_i S(Delta_i) (cos, sin)((theta_{i-1} + theta_i) / 2),

    Delta_i = theta_i - theta_{i-1}, S(Delta) = sin(Delta/2) / (Delta/2). A node load
    F_n has the potential -F_n . O_n = -sum_{i <= n} F_n . Delta r_i, so the total
    potential is a sum of segment terms in (theta_{i-1}, eps_i, c1_i, theta_i), and its
    exact Hessian is banded (half-bandwidth 3 in the engine's ordering (eps_i, c1_i,
    theta_i) per segment). It converges to the rod at second order in the segment
    length (section 11.6).

    Parameters
    ----------
    design : ActuatorDesign
        The finger.
    n_segments : int
        Number of segments N, raised to the number of constant-section intervals if
        smaller (22 for the paper's finger; see `pcc_edges`).
    pressure_model : {'adiabatic', 'isobaric'}
        k_p = 1/(gamma - 1) or 1 (SPEC "Pressure work").
    tol : float
        Largest final Newton step in theta [rad] and (eps, c1) [-].
    samples : int
        Midplane samples M at evenly spaced reference arc length, root to tip.
    max_iterations : int
        Newton iterations per (sub)solve.

    Notes
    -----
    Newton steps solve the banded system by Cholesky (`scipy.linalg.cholesky_banded`).
    Where the Hessian H is not positive definite the step solves (H + tau D) dx = -g
    with D = |diag H| and tau = 2 |lambda_min| of the Jacobi-scaled Hessian
    D^(-1/2) H D^(-1/2) (a banded eigenvalue solve), which is positive definite (its
    smallest eigenvalue is |lambda_min|), so the step descends; that lambda_min < 0 is
    reported for the stability verdict. The engine then backtracks as for every rung.

    References
    ----------
    docs/physics.md, sections 11.2, 11.4 and 11.6.

    """

    _result_type = PCCResult

    def __init__(self, design, n_segments=64, pressure_model='adiabatic', tol=1e-12,
                 samples=129, max_iterations=60):
        _check_common(design, pressure_model, samples)
        if isinstance(n_segments, bool) or not isinstance(n_segments, (int, np.integer)) \
                or n_segments < 1:
            raise ValueError(f'`n_segments` must be an integer >= 1, got {n_segments!r}')
        self.design = design
        self.pressure_model = pressure_model
        self.pressure_coefficient = PRESSURE_MODELS[pressure_model]
        self.tol = float(tol)
        self.samples = int(samples)
        self.max_iterations = int(max_iterations)
        self.length = design.free_length
        self.edges, self.segment_types, self.law = pcc_edges(design, n_segments)
        self.lengths = np.diff(self.edges)
        self.n_segments = self.lengths.size
        n = self.n_segments
        self._stiffness = self.law.stiffness[self.segment_types]
        self._gas = self.law.gas[self.segment_types]
        # Band assembly: element i's local unknowns (theta_{i-1}, eps_i, c1_i, theta_i) are
        # the engine unknowns 3i - 1 .. 3i + 2; theta_0 (index -1) is clamped.
        first = 3 * np.arange(n) - 1
        index, take = [], []
        for p, q in _BAND_PAIRS:
            keep = np.arange(n) if q > 0 else np.arange(1, n)
            index.append((p - q) * 3 * n + first[keep] + q)
            take.append(keep * 16 + 4 * p + q)
        self._band_index = np.concatenate(index)
        self._band_take = np.concatenate(take)
        # Scale of the angle gradients and Hessian: EI of the stiffest section over L [J].
        self.gradient_scale = float(self.law.stiffness[:, 1, 1].max()) / self.length
        self._options = NewtonOptions(max_iterations=self.max_iterations, xtol=self.tol,
                                      max_step=np.tile(_CAP, n),
                                      energy_scale=self.gradient_scale)

    def _compatible(self, other):
        return isinstance(other, PCCSolver) and np.array_equal(other.edges, self.edges)

    def _flat_state(self):
        return np.zeros((self.n_segments, 3))

    # -- the discretisation's side of the engine: per segment (eps_i, c1_i, theta_i) --
    def _pack(self, state):
        return np.asarray(state, dtype=float)[:, [1, 2, 0]].ravel()

    def _unpack(self, x):
        return np.asarray(x, dtype=float).reshape(-1, 3)[:, [2, 0, 1]]

    def _fields(self, x):
        v = x.reshape(-1, 3)
        eps, c1, theta = v[:, 0], v[:, 1], v[:, 2]
        prev = np.concatenate([[0.0], theta[:-1]])
        return eps, c1, theta, prev

    def _segment_loads(self, loads):
        """
        Load carried by every segment, G_i = sum of the node forces at n >= i [N], (N, 2).

        Node n is the end of segment n (node 0 the clamp, node N the tip).
        """
        n = self.n_segments
        at = np.zeros((n + 1, 2))
        for node, force in loads:
            if isinstance(node, bool) or not isinstance(node, (int, np.integer)) \
                    or not 0 <= node <= n:
                raise ValueError(f'load node must be an integer in [0, {n}], got {node!r}')
            at[node] += np.asarray(force, dtype=float)
        return np.cumsum(at[::-1], axis=0)[::-1][1:]

    def energy(self, x, pressure, loads):
        """Total potential [J] at engine unknowns `x`."""
        eps, c1, theta, prev = self._fields(x)
        lengths = self.lengths
        delta = theta - prev
        y = np.stack([eps, delta / lengths, c1], axis=1)
        total = float(lengths @ self.law.energy(y, self.pressure_coefficient * pressure,
                                                self.segment_types))
        carried = self._segment_loads(loads)
        if carried.any():
            mid = 0.5 * (theta + prev)
            (sinc,) = half_angle_sinc(delta, order=0)
            along = carried[:, 0] * np.cos(mid) + carried[:, 1] * np.sin(mid)
            total -= float(((1.0 + eps) * lengths * sinc) @ along)
        return total

    def _element_derivatives(self, x, pressure, loads):
        """Energy [J], element gradients (N, 4) and Hessians (N, 4, 4) in (a, eps, c1, b)."""
        eps, c1, theta, prev = self._fields(x)
        lengths = self.lengths
        delta = theta - prev
        y = np.stack([eps, delta / lengths, c1], axis=1)
        w, g, h = self.law.derivatives(y, self.pressure_coefficient * pressure,
                                       self.segment_types)
        energy = float(lengths @ w)
        ge = np.zeros((lengths.size, 4))
        he = np.zeros((lengths.size, 4, 4))
        # y = (eps, (b - a) / L, c1): gradient L T^T g and Hessian L T^T h T.
        ge[:, 0] = -g[:, 1]
        ge[:, 1] = lengths * g[:, 0]
        ge[:, 2] = lengths * g[:, 2]
        ge[:, 3] = g[:, 1]
        bend = h[:, 1, 1] / lengths
        he[:, 0, 0] = he[:, 3, 3] = bend
        he[:, 0, 3] = he[:, 3, 0] = -bend
        he[:, 1, 1] = lengths * h[:, 0, 0]
        he[:, 2, 2] = lengths * h[:, 2, 2]
        he[:, 1, 2] = he[:, 2, 1] = lengths * h[:, 0, 2]
        for k, col in ((1, 0), (2, 2)):
            he[:, k, 0] = he[:, 0, k] = -h[:, col, 1]
            he[:, k, 3] = he[:, 3, k] = h[:, col, 1]
        carried = self._segment_loads(loads)
        if carried.any():
            # -G . Delta r = -(1 + eps) L phi(a, b), phi = S(Delta) G . u(m), Delta = b - a,
            # m = (a + b)/2, u = (cos, sin)(m), n = u' = (-sin, cos)(m).
            mid = 0.5 * (theta + prev)
            s0, s1, s2 = half_angle_sinc(delta)
            cm, sm = np.cos(mid), np.sin(mid)
            gu = carried[:, 0] * cm + carried[:, 1] * sm
            gn = -carried[:, 0] * sm + carried[:, 1] * cm
            phi = s0 * gu
            p_d, p_m = s1 * gu, s0 * gn
            p_dd, p_dm, p_mm = s2 * gu, s1 * gn, -s0 * gu
            p_a, p_b = -p_d + 0.5 * p_m, p_d + 0.5 * p_m
            p_aa = p_dd - p_dm + 0.25 * p_mm
            p_bb = p_dd + p_dm + 0.25 * p_mm
            p_ab = -p_dd + 0.25 * p_mm
            stretch = (1.0 + eps) * lengths
            energy -= float(stretch @ phi)
            ge[:, 0] -= stretch * p_a
            ge[:, 1] -= lengths * phi
            ge[:, 3] -= stretch * p_b
            he[:, 0, 0] -= stretch * p_aa
            he[:, 3, 3] -= stretch * p_bb
            he[:, 0, 3] -= stretch * p_ab
            he[:, 3, 0] -= stretch * p_ab
            he[:, 1, 0] -= lengths * p_a
            he[:, 0, 1] -= lengths * p_a
            he[:, 1, 3] -= lengths * p_b
            he[:, 3, 1] -= lengths * p_b
        return energy, ge, he

    def derivatives(self, x, pressure, loads):
        """
        Energy [J], gradient and banded Hessian of the PCC potential in the engine unknowns.

        Returns
        -------
        energy : float
            [J].
        gradient : ndarray, shape (3 N,)
            In (eps_i, c1_i, theta_i) per segment [J].
        hessian : _Banded
            Lower band (4, 3 N) of the exact Hessian [J].

        """
        energy, ge, he = self._element_derivatives(x, pressure, loads)
        grad = ge[:, 1:].copy()
        grad[:-1, 2] += ge[1:, 0]
        lower = np.bincount(self._band_index, he.ravel()[self._band_take],
                            minlength=4 * x.size).reshape(4, x.size)
        return energy, grad.ravel(), _Banded(lower)

    def step(self, grad, hess):
        """
        Newton step by banded Cholesky; a shifted, descending step where H is indefinite.

        Returns
        -------
        step : ndarray, shape (3 N,)
        min_eig : float
            1.0 when H is positive definite, else the smallest eigenvalue of the
            Jacobi-scaled Hessian (< 0).

        """
        lower = hess.lower
        try:
            factor = cholesky_banded(lower, lower=True, check_finite=False)
            return cho_solve_banded((factor, True), -grad, check_finite=False), 1.0
        except LinAlgError:
            pass
        diag = np.maximum(np.abs(lower[0]), 1e-300)
        root = np.sqrt(diag)
        n = diag.size
        scaled = lower.copy()
        for d in range(4):
            scaled[d, :n - d] /= root[d:] * root[:n - d]
        if not np.all(np.isfinite(scaled)):
            return np.full(n, math.nan), -1.0
        min_eig = float(eig_banded(scaled, lower=True, eigvals_only=True, select='i',
                                   select_range=(0, 0), check_finite=False)[0])
        shift = 2.0 * abs(min_eig) + 1e-10
        for _ in range(60):
            try:
                trial = scaled.copy()
                trial[0] += shift
                factor = cholesky_banded(trial, lower=True, check_finite=False)
                break
            except LinAlgError:
                shift *= 2.0
        else:
            return -grad / self.gradient_scale, min(min_eig, -1e-300)
        dx = cho_solve_banded((factor, True), -grad / root, check_finite=False) / root
        return dx, min(min_eig, -1e-300)

    def solve_linear(self, hess, rhs):
        """Solve H x = rhs (banded Cholesky, else banded LU); LinAlgError if singular."""
        try:
            factor = cholesky_banded(hess.lower, lower=True, check_finite=False)
            return cho_solve_banded((factor, True), rhs, check_finite=False)
        except LinAlgError:
            return solve_banded((3, 3), hess.full_band(), rhs, check_finite=False)

    def _chords(self, eps, theta, prev, order=0):
        """Chords Delta r_i [m] (N, 2) and, with order 1, their derivatives in (a, eps, b)."""
        lengths = self.lengths
        delta = theta - prev
        mid = 0.5 * (theta + prev)
        sincs = half_angle_sinc(delta, order=order)
        u = np.stack([np.cos(mid), np.sin(mid)], axis=1)
        chord = ((1.0 + eps) * lengths * sincs[0])[:, None] * u
        if order == 0:
            return chord
        normal = np.stack([-u[:, 1], u[:, 0]], axis=1)
        stretch = ((1.0 + eps) * lengths)[:, None]
        d_delta = sincs[1][:, None] * u
        d_mid = sincs[0][:, None] * normal
        d_a = stretch * (-d_delta + 0.5 * d_mid)
        d_b = stretch * (d_delta + 0.5 * d_mid)
        d_eps = (lengths * sincs[0])[:, None] * u
        return chord, d_a, d_eps, d_b

    def nodes(self, x):
        """Segment ends O_0 = 0 .. O_N = tip [m], (N + 1, 2), at engine unknowns `x`."""
        eps, _, theta, prev = self._fields(x)
        out = np.zeros((self.n_segments + 1, 2))
        np.cumsum(self._chords(eps, theta, prev), axis=0, out=out[1:])
        return out

    def node_jacobian(self, x, node):
        """Position of node `node` [m] and its derivatives in the engine unknowns, (2, 3 N)."""
        n = self.n_segments
        if isinstance(node, bool) or not isinstance(node, (int, np.integer)) \
                or not 0 <= node <= n:
            raise ValueError(f'`node` must be an integer in [0, {n}], got {node!r}')
        eps, _, theta, prev = self._fields(x)
        chord, d_a, d_eps, d_b = self._chords(eps, theta, prev, order=1)
        jac = np.zeros((2, n, 3))
        jac[:, :node, 0] = d_eps[:node].T
        jac[:, :node, 2] = d_b[:node].T
        jac[:, :node - 1, 2] += d_a[1:node].T
        return chord[:node].sum(axis=0), jac.reshape(2, 3 * n)

    # -- outputs ------------------------------------------------------------
    def _outputs(self, state, pressure, force):
        x = self._pack(state)
        theta, eps, c1 = state[:, 0], state[:, 1], state[:, 2]
        prev = np.concatenate([[0.0], theta[:-1]])
        beta = theta - prev
        kappa = beta / self.lengths
        nodes = self.nodes(x)
        tip = nodes[-1].copy()
        # Samples on the exact arcs: at sigma into segment i the tangent has turned by
        # kappa_i sigma, and the partial chord is (1 + eps_i) sigma S(kappa_i sigma) along
        # the mean tangent.
        s = np.linspace(0.0, self.length, self.samples)
        seg = np.clip(np.searchsorted(self.edges, s, side='right') - 1, 0, self.n_segments - 1)
        sigma = s - self.edges[seg]
        turn = kappa[seg] * sigma
        (sinc,) = half_angle_sinc(turn, order=0)
        half = prev[seg] + 0.5 * turn
        reach = (1.0 + eps[seg]) * sigma * sinc
        points = nodes[seg] + reach[:, None] * np.stack([np.cos(half), np.sin(half)], axis=1)
        points[-1] = tip
        strains = np.stack([eps[seg], kappa[seg], c1[seg]], axis=1)
        loads = [(self.tip_node, force)] if np.any(force) else []
        return {
            'points': points, 'tangent': prev[seg] + turn, 'strains': strains, 'tip': tip,
            'beta': beta,
            'coefficients': np.stack([eps, -kappa ** 2 / 6.0, c1, 0.5 * kappa], axis=1),
            'nodes': nodes, 'energy': self.energy(x, pressure, loads),
        }
