"""The PCC rod's numpy formulas as they were before compilation: the tests' slow reference."""

import math

import numpy as np
from scipy.linalg import cho_solve_banded, cholesky_banded, eig_banded, LinAlgError, solve_banded

from fpc_gripper.model.discretisations.pcc import _Banded, PCCSolver

#: Taylor coefficients (-1)^k / (2k + 1)! of sin(h)/h in h^2, k = 0..9.
_SINC = np.array([(-1.0) ** k / math.factorial(2 * k + 1) for k in range(10)])
_K = np.arange(10)
_SINC_D1 = (2 * _K * _SINC)[1:]
_SINC_D2 = (2 * _K * (2 * _K - 1) * _SINC)[1:]
_SERIES_BELOW = 1.0
#: Lower band of an element's 4 x 4 Hessian in (theta_prev, eps, c1, theta): (p, q), p >= q.
_BAND_PAIRS = tuple((q + d, q) for q in range(4) for d in range(4 - q))


def half_angle_sinc(delta, order=2):
    """S(delta) = sin(delta/2) / (delta/2) and its derivatives, numpy (see pcc)."""
    h = 0.5 * np.asarray(delta, dtype=float)
    h2 = h * h
    small = np.abs(h) < _SERIES_BELOW
    hs = np.where(small, 1.0, h)
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
    out = np.full_like(x, coefficients[-1])
    for c in coefficients[-2::-1]:
        out *= x
        out += c
    return out


class Banded(_Banded):
    """A symmetric band in lower form, ab[d, k] = H[k + d, k], for scipy's solvers."""

    def __init__(self, lower):
        super().__init__((lower, None, None, False))

    def dense(self):
        lower = self.lower
        n = lower.shape[1]
        out = np.zeros((n, n))
        for d in range(4):
            k = np.arange(n - d)
            out[k + d, k] = lower[d, :n - d]
            out[k, k + d] = lower[d, :n - d]
        return out


def random_state(solver, seed, turning=3.0):
    """Return a state turning by about `turning` rad, eps and c1 near equilibrium."""
    rng = np.random.default_rng(seed)
    n = solver.n_segments
    kappa = -turning / solver.length * (1.0 + 0.3 * rng.normal(size=n))
    theta = np.cumsum(kappa * solver.lengths)
    eps = -0.08 + 0.02 * rng.normal(size=n)
    c1 = 1e-3 * rng.normal(size=n)
    return solver._pack(np.stack([theta, eps, c1], axis=1))


class ReferencePCCSolver(PCCSolver):
    """
    `PCCSolver` with every hot path in numpy, as before the kernels (tests and benchmarks).

    The constructor, the engine and the results are PCCSolver's; energy, derivatives,
    the banded Hessian assembly (np.bincount), the Newton step and linear solves
    (scipy's banded Cholesky), the node Jacobian and the outputs are the numpy originals.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        n = self.n_segments
        first = 3 * np.arange(n) - 1
        index, take = [], []
        for p, q in _BAND_PAIRS:
            keep = np.arange(n) if q > 0 else np.arange(1, n)
            index.append((p - q) * 3 * n + first[keep] + q)
            take.append(keep * 16 + 4 * p + q)
        self._band_index = np.concatenate(index)
        self._band_take = np.concatenate(take)

    def _compatible(self, other):
        return isinstance(other, PCCSolver) and np.array_equal(other.edges, self.edges)

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
        n = self.n_segments
        at = np.zeros((n + 1, 2))
        for node, force in loads:
            if isinstance(node, bool) or not isinstance(node, (int, np.integer)) \
                    or not 0 <= node <= n:
                raise ValueError(f'load node must be an integer in [0, {n}], got {node!r}')
            at[node] += np.asarray(force, dtype=float)
        return np.cumsum(at[::-1], axis=0)[::-1][1:]

    def energy(self, x, pressure, loads):
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
        eps, c1, theta, prev = self._fields(x)
        lengths = self.lengths
        delta = theta - prev
        y = np.stack([eps, delta / lengths, c1], axis=1)
        w, g, h = self.law.derivatives(y, self.pressure_coefficient * pressure,
                                       self.segment_types)
        energy = float(lengths @ w)
        ge = np.zeros((lengths.size, 4))
        he = np.zeros((lengths.size, 4, 4))
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
        energy, ge, he = self._element_derivatives(x, pressure, loads)
        grad = ge[:, 1:].copy()
        grad[:-1, 2] += ge[1:, 0]
        lower = np.bincount(self._band_index, he.ravel()[self._band_take],
                            minlength=4 * x.size).reshape(4, x.size)
        return energy, grad.ravel(), Banded(lower)

    def step(self, grad, hess):
        lower = hess.lower
        try:
            factor = cholesky_banded(lower, lower=True, check_finite=False)
            return cho_solve_banded((factor, True), -grad, check_finite=False), 1.0
        except LinAlgError:
            pass
        return self._shifted_step(np.asarray(grad, dtype=float), lower)

    def _shifted_step(self, grad, lower):
        """(H + tau D) dx = -g by scipy's banded eigenvalue solver and Cholesky."""
        diag = np.maximum(np.abs(lower[0]), 1e-300)
        root = np.sqrt(diag)
        n = diag.size
        scaled = lower.copy()
        for d in range(4):
            scaled[d, :n - d] /= root[d:] * root[:n - d]
        if not np.all(np.isfinite(scaled)):
            return np.full(n, np.nan), -1.0
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
        try:
            factor = cholesky_banded(hess.lower, lower=True, check_finite=False)
            return cho_solve_banded((factor, True), rhs, check_finite=False)
        except LinAlgError:
            return solve_banded((3, 3), hess.full_band(), rhs, check_finite=False)

    def _chords(self, eps, theta, prev, order=0):
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
        eps, _, theta, prev = self._fields(x)
        out = np.zeros((self.n_segments + 1, 2))
        np.cumsum(self._chords(eps, theta, prev), axis=0, out=out[1:])
        return out

    def node_jacobian(self, x, node):
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

    def _outputs(self, state, pressure, force):
        x = self._pack(state)
        theta, eps, c1 = state[:, 0], state[:, 1], state[:, 2]
        prev = np.concatenate([[0.0], theta[:-1]])
        beta = theta - prev
        kappa = beta / self.lengths
        nodes = self.nodes(x)
        tip = nodes[-1].copy()
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
