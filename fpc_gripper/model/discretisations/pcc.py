"""Piecewise-constant-strain rod (PCC): the finger as N exact arcs, solved with a banded Newton."""

import functools

import numpy as np

from .rung import check_common, RungSolver, set_common
from ..engine import CompiledProblem, NewtonOptions, register
from ..kernels import linear, pcc as kernels
from ..kernels.pcc_section import half_angle_sinc_kernel, section_arrays
from ..result import finger_constants
from ..section.law import station_layout
from ..section.segments import interval_of, share_segments
from ..validation import arc_lengths, integer

__all__ = ['PCCSolver', 'pcc_edges', 'half_angle_sinc', 'material_jacobian', 'positions_at']

# The engine runs this discretisation compiled through these hooks (`engine.register`).
register(kernels.PCCData, kernels.PCC_HOOKS)

#: Step caps: 0.1 on (eps, c1) as the rod, 0.5 rad on the angles.
_CAP = np.array([0.1, 0.1, 0.5])
#: Columns of a state (theta, eps, c1) in the engine's order (eps, c1, theta), and back.
_PACK = np.array([1, 2, 0])
_UNPACK = np.array([2, 0, 1])
#: No loads, as the kernels take them.
_NO_NODES = np.zeros(0, dtype=np.int64)
_NO_FORCES = np.zeros((0, 2))


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
    delta = np.asarray(delta, dtype=float)
    rows = half_angle_sinc_kernel(delta.ravel(), int(order))
    return tuple(row.reshape(delta.shape) for row in rows)


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
    spans = np.diff(breaks)
    counts = share_segments(spans, max(int(n_segments), types.size))
    # Every interval's np.linspace(a, b, c + 1)[:-1], a + k (b - a) / c, all at once: the
    # same operations, so the same edges, without a call per interval.
    first = np.repeat(np.cumsum(counts) - counts, counts)
    k = np.arange(counts.sum(), dtype=float) - first
    edges = np.concatenate([k * np.repeat(spans / counts, counts)
                            + np.repeat(breaks[:-1], counts), breaks[-1:]])
    return edges, np.repeat(types, counts), law


def _point_arrays(pseg, poff, pz):
    """Face points as the kernels take them: (segment int64, offset, height) arrays."""
    return (np.ascontiguousarray(pseg, dtype=np.int64), np.ascontiguousarray(poff, dtype=float),
            np.ascontiguousarray(pz, dtype=float))


class _Banded:
    """
    Symmetric banded Hessian: lower form ab[d, k] = H[k + d, k], d = 0..3 [J].

    `hook` is the Hessian as the compiled kernels take it: (lower, Cholesky factor,
    Newton step of the gradient it was computed with, positive definite).
    """

    __slots__ = ('hook',)

    def __init__(self, hook):
        self.hook = hook

    @property
    def lower(self):
        """The lower band, shape (4, n) [J]."""
        return self.hook[0]

    @property
    def definite(self):
        """Whether H is positive definite."""
        return bool(self.hook[3])

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
        return linear._dense_from_band(self.lower)


class PCCSolver(RungSolver):
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
    pressure_model : {None, 'design', 'adiabatic', 'isobaric'}
        k_p = 1/(gamma - 1) or 1 (SPEC "Pressure work"); None or 'design' (the
        default): the design's `pressure_work_factor`.
    tol : float
        Largest final Newton step in theta [rad] and (eps, c1) [-].
    samples : int
        Midplane samples M at evenly spaced reference arc length, root to tip.
    max_iterations : int
        Newton iterations per (sub)solve.

    Notes
    -----
    The energy, gradient, banded Hessian, chords, node Jacobian and outputs are
    compiled kernels (`pcc_kernels`), and `engine_problem` hands them to the engine, whose
    loops then run compiled too; Python only builds the result.
    Newton steps solve the banded system by Cholesky (compiled, LAPACK's dpbtf2
    algorithm). Where the Hessian H is not positive definite the step solves
    (H + tau D) dx = -g with D = |diag H| and tau = 2 |lambda_min| of the Jacobi-scaled
    Hessian D^(-1/2) H D^(-1/2) (`pcc_kernels.shifted_step`; a dense eigenvalue solve,
    rare), which is positive definite (its smallest eigenvalue is |lambda_min|), so the
    step descends; that lambda_min < 0 is reported for the stability verdict. The engine
    then backtracks as for every rung.

    References
    ----------
    docs/physics.md, sections 11.2, 11.4 and 11.6.

    """

    rung = 'pcc'

    def __init__(self, design, n_segments=64, pressure_model=None, tol=1e-12,
                 samples=129, max_iterations=60):
        check_common(design, pressure_model, samples)
        integer('n_segments', n_segments, 1)
        set_common(self, design, pressure_model, tol, samples, max_iterations)
        self.edges, self.segment_types, self.law = self._layout(design, n_segments)
        self.lengths = np.diff(self.edges)
        self.n_segments = self.lengths.size
        n = self.n_segments
        # The section law of every segment as kernel arrays, once: no per-call gathering.
        self._stiffness, self._gas, self._pemc = section_arrays(self.law, self.segment_types)
        # Samples at evenly spaced reference arc length: their segment and the arc length
        # into it depend on the edges alone.
        s = np.linspace(0.0, self.length, self.samples)
        seg = interval_of(self.edges, s)
        self._sample_segment = seg.astype(np.int64)
        self._sample_offset = s - self.edges[seg]
        # Scale of the angle gradients and Hessian: EI of the stiffest section over L [J].
        self.gradient_scale = float(self.law.stiffness[:, 1, 1].max()) / self.length
        self._options = NewtonOptions(max_iterations=self.max_iterations, xtol=self.tol,
                                      max_step=np.tile(_CAP, n),
                                      energy_scale=self.gradient_scale)
        self._data = kernels.PCCData(self.lengths, self._stiffness, self._gas, self._pemc,
                                     float(self.pressure_coefficient), self.gradient_scale,
                                     self._sample_segment, self._sample_offset)
        #: What the engine runs: the compiled data, never this object.
        self.engine_problem = CompiledProblem(self._data, self._data, self.flat(),
                                              self.gradient_scale)
        self._constants = finger_constants(self.rung, self.n_segments, self.edges)

    def _layout(self, design, n_segments):
        """Return the segment edges [m], their section types and the section law."""
        return pcc_edges(design, n_segments)

    def _flat_state(self):
        return np.zeros((self.n_segments, 3))

    # -- the discretisation's side of the engine: per segment (eps_i, c1_i, theta_i) --
    def _pack(self, state):
        return np.asarray(state, dtype=float)[:, _PACK].ravel()

    def _unpack(self, x):
        return np.asarray(x, dtype=float).reshape(-1, 3)[:, _UNPACK]

    def _load_arrays(self, loads):
        """Return the loaded nodes (K,) in 0..N (N: the tip) and forces (K, 2) [N] for kernels."""
        if not loads:
            return _NO_NODES, _NO_FORCES
        n = self.n_segments
        nodes = np.empty(len(loads), dtype=np.int64)
        forces = np.empty((len(loads), 2))
        for k, (node, force) in enumerate(loads):
            if isinstance(node, bool) or not isinstance(node, (int, np.integer)) \
                    or not 0 <= node <= n:
                raise ValueError(f'load node must be an integer in [0, {n}], got {node!r}')
            nodes[k] = node
            forces[k] = force
        return nodes, forces

    def energy(self, x, pressure, loads):
        """Total potential [J] at engine unknowns `x`."""
        return kernels.pcc_energy(self._data, np.ascontiguousarray(x, dtype=float),
                                  float(pressure), *self._load_arrays(loads))

    def derivatives(self, x, pressure, loads):
        """
        Energy [J], gradient and banded Hessian of the PCC potential in the engine unknowns.

        Returns
        -------
        energy : float
            [J], equal to `energy`'s.
        gradient : ndarray, shape (3 N,)
            In (eps_i, c1_i, theta_i) per segment [J].
        hessian : _Banded
            Lower band (4, 3 N) of the exact Hessian [J], with its Cholesky factor.

        """
        energy, grad, hook = kernels.pcc_derivatives(
            self._data, np.ascontiguousarray(x, dtype=float), float(pressure),
            *self._load_arrays(loads))
        return energy, grad, _Banded(hook)

    def step(self, grad, hess):
        """
        Newton step by banded Cholesky; a shifted, descending step where H is indefinite.

        Returns
        -------
        step : ndarray, shape (3 N,)
        min_eig : float
            1.0 when H is positive definite, else the smallest eigenvalue of the
            Jacobi-scaled Hessian (< 0); see `pcc_kernels.shifted_step`.

        """
        grad = np.ascontiguousarray(grad, dtype=float)
        lower, factor, _, definite = hess.hook
        if definite:
            return linear.cholesky_solve(factor, -grad), 1.0
        return linear.shifted_step(lower, grad, self.gradient_scale)

    def solve_linear(self, hess, rhs):
        """Solve H x = rhs (banded Cholesky, else LU); LinAlgError if singular."""
        rhs = np.asarray(rhs, dtype=float)
        columns = rhs.reshape(rhs.shape[0], -1).T
        out = []
        for column in columns:
            solution, ok = kernels.pcc_solve_linear(self._data, hess.hook,
                                                    np.ascontiguousarray(column))
            if not ok:
                raise np.linalg.LinAlgError('the PCC Hessian is singular')
            out.append(solution)
        return np.stack(out, axis=1).reshape(rhs.shape)

    def parameter_gradient(self, x, pressure, loads):
        """
        Differentiate the gradient in the engine unknowns by the section law's parameters.

        The parameters are `section_law.SECTION_PARAMETERS`; the derivatives are exact.
        The loads do not depend on them: only the segments' L_i W(eps_i, Delta_i / L_i,
        c1_i) terms do, whose gradient is L_i g_eps, L_i g_c1 on (eps_i, c1_i) and
        +g_kappa, -g_kappa on (theta_i, theta_{i-1}).

        Returns
        -------
        ndarray, shape (8, 3 N)
            [J per unit of each parameter].

        """
        rates = self.law.parameter_gradients(self._section_strains(x), pressure,
                                             self.segment_types)   # (N, 8, 3)
        return self._to_unknowns(rates.transpose(1, 0, 2))

    def _section_strains(self, x):
        """Return each segment's section strains (eps, kappa, c1), (N, 3), of a state."""
        state = self._unpack(x)
        kappa = np.diff(state[:, 0], prepend=0.0) / self.lengths
        return np.stack([state[:, 1], kappa, state[:, 2]], axis=1)

    def _to_unknowns(self, rates):
        """
        Map rates of the section energy's gradient to the unknowns, (P, N, 3) -> (P, 3 N).

        `rates` [p, i] = d(g_eps, g_kappa, g_c1)/d(parameter p) of segment i: L_i g_eps,
        L_i g_c1 on (eps_i, c1_i) and +g_kappa, -g_kappa on (theta_i, theta_{i-1}).
        """
        out = np.empty((rates.shape[0], self.n_segments, 3))
        out[:, :, 0] = self.lengths * rates[:, :, 0]
        out[:, :, 1] = self.lengths * rates[:, :, 2]
        out[:, :, 2] = rates[:, :, 1]
        out[:, :-1, 2] -= rates[:, 1:, 1]
        return out.reshape(rates.shape[0], -1)

    # -- face points (contact: docs/physics.md, section 15.2) -------------------
    def point_derivatives(self, x, pressure, loads, pseg, poff, pz, pforce):
        """
        Return `derivatives` with dead forces at face points as well as node loads.

        Parameters
        ----------
        pseg, poff, pz : ndarray, shape (K,)
            Segment, reference arc length into it [m] and height from the midplane [m]
            of every point.
        pforce : ndarray, shape (K, 2)
            (F_X, F_Z) at every point [N].

        """
        energy, grad, *hook = kernels.point_derivatives_kernel(
            np.ascontiguousarray(x, dtype=float), self.lengths, self._stiffness, self._gas,
            self._pemc, self.pressure_coefficient * float(pressure), *self._load_arrays(loads),
            *_point_arrays(pseg, poff, pz), np.ascontiguousarray(pforce, dtype=float))
        return energy, grad, _Banded(tuple(hook))

    def point_positions(self, x, pseg, poff, pz):
        """Positions (K, 2) [m] of face points at engine unknowns `x`."""
        return kernels.point_positions_kernel(np.ascontiguousarray(x, dtype=float),
                                              self.lengths, *_point_arrays(pseg, poff, pz))

    def point_jacobian(self, x, seg, offset, z):
        """Position of a face point [m] and its derivatives in the engine unknowns, (2, 3 N)."""
        return kernels.point_jacobian_kernel(np.ascontiguousarray(x, dtype=float),
                                             self.lengths, int(seg), float(offset), float(z))

    def nodes(self, x):
        """Segment ends O_0 = 0 .. O_N = tip [m], (N + 1, 2), at engine unknowns `x`."""
        return kernels.nodes_kernel(np.ascontiguousarray(x, dtype=float), self.lengths)

    def node_jacobian(self, x, node):
        """Position of node `node` [m] and its derivatives in the engine unknowns, (2, 3 N)."""
        n = self.n_segments
        if isinstance(node, bool) or not isinstance(node, (int, np.integer)) \
                or not 0 <= node <= n:
            raise ValueError(f'`node` must be an integer in [0, {n}], got {node!r}')
        return kernels.node_jacobian_kernel(np.ascontiguousarray(x, dtype=float),
                                            self.lengths, int(node))

    def material_jacobian(self, x, s):
        """Positions of material points at arc lengths s, and their derivatives in x."""
        return material_jacobian(x, self.edges, s)

    def _positions(self, x, pressure, force):
        """Return the `position_at` of a result at engine unknowns `x`."""
        return functools.partial(positions_at, x, self.edges)


def material_jacobian(x, edges, s):
    """
    Positions of the material points at reference arc lengths s and their derivatives.

    The point at s in segment i, sigma = s - edge_i into it, is
    O_i + (1 + eps_i) sigma S(rho Delta_i) (cos, sin)(theta_{i-1} + rho Delta_i / 2),
    rho = sigma / L_i: exactly on the arc (rho = 1 gives the chord, so the node).
    Written as the sum over every segment k of that partial chord with sigma_k =
    clip(s - edge_k, 0, L_k), it is differentiated segment by segment.

    Parameters
    ----------
    x : ndarray, shape (3 N,)
        Engine unknowns (eps_i, c1_i, theta_i) per segment.
    edges : ndarray, shape (N + 1,)
        Segment edges [m].
    s : ndarray, shape (K,)
        Arc lengths in [0, L] [m].

    Returns
    -------
    positions : ndarray, shape (K, 2)
        [m].
    jacobian : ndarray, shape (K, 2, 3 N)
        d position / d x [m per unit strain or radian].

    """
    lengths = np.diff(edges)
    n = lengths.size
    state = np.asarray(x, dtype=float).reshape(-1, 3)
    theta, eps = state[:, 2], state[:, 0]
    before = np.concatenate([[0.0], theta[:-1]])
    sigma = np.clip(s[:, None] - edges[None, :-1], 0.0, lengths[None, :])
    rho = sigma / lengths
    turn = rho * (theta - before)                                    # (K, N)
    sinc, dsinc = half_angle_sinc(turn, order=1)
    angle = before + 0.5 * turn
    along = np.stack([np.cos(angle), np.sin(angle)], axis=1)         # (K, 2, N)
    normal = np.stack([-along[:, 1], along[:, 0]], axis=1)
    reach = (1.0 + eps) * sigma                                      # (K, N)
    chords = (reach * sinc)[:, None, :] * along
    positions = chords.sum(axis=2)
    jac = np.zeros((s.size, 2, n, 3))
    jac[..., 0] = (sigma * sinc)[:, None, :] * along
    arc = (reach * rho * dsinc)[:, None, :] * along
    bend = (reach * sinc)[:, None, :] * normal
    jac[..., 2] = arc + (0.5 * rho)[:, None, :] * bend
    # theta_{i-1} is theta of the segment before (theta_0 = 0 is clamped).
    jac[..., :-1, 2] += (-arc + (1.0 - 0.5 * rho)[:, None, :] * bend)[..., 1:]
    return positions, jac.reshape(s.size, 2, -1)


def positions_at(x, edges, s):
    """
    Midplane position of the PCC's material points at reference arc lengths `s` [m].

    Exactly on its arcs (`material_jacobian`); a result's `position_at` is this function
    of its own state and edges.

    Parameters
    ----------
    x : ndarray, shape (3 N,)
        Engine unknowns.
    edges : ndarray, shape (N + 1,)
        Segment edges [m].
    s : float or array_like
        Reference arc length from the clamp edge, in [0, L] [m].

    Returns
    -------
    ndarray, shape s.shape + (2,)
        Global (X, Z) [m].

    References
    ----------
    docs/physics.md, section 13.

    """
    values, shape = arc_lengths('s', s, edges[-1])
    return material_jacobian(x, edges, values)[0].reshape(shape + (2,))
