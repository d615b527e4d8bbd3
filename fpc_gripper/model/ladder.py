"""Model ladder beyond the CCM: a uniform arc (rung a) and a geometrically exact rod (rung d)."""

import math

import numpy as np
from scipy.linalg import cho_factor, cho_solve, eigh

from .analysis import CircleFitted
from .design import ActuatorDesign
from .section_law import station_layout
from .solver import PRESSURE_MODELS, RigidityResult, SolverStatus
from .validation import real_number

__all__ = ['ArcSolver', 'RodSolver', 'LadderResult', 'RodResult', 'ArcResult']

_MESSAGES = {
    SolverStatus.SUCCESS: 'converged: last Newton step {step:.1e} <= {tol:.0e}',
    SolverStatus.MAX_ITERATIONS: 'not converged after {iterations} Newton iterations '
                                 '(last step {step:.1e})',
    SolverStatus.LINE_SEARCH_FAILED: 'line search found no decrease (last step {step:.1e}); '
                                     'the equilibrium may not exist nearby',
    SolverStatus.NOT_FINITE: 'energy or gradient became non-finite',
    SolverStatus.UNSTABLE: 'converged to an unstable equilibrium (Hessian not positive '
                           'definite)',
    SolverStatus.CONTINUATION_FAILED: 'continuation in pressure and load stalled at '
                                      '{fraction:.1%} of the requested loading',
}
#: Gauss rule on [0, 1] for the arc integrals int_0^1 (cos, sin)(phi t) t^k dt; exact to
#: round-off for |phi| up to about 40 rad (several full turns).
_ARC_X, _ARC_WX = np.polynomial.legendre.leggauss(48)
_ARC_T, _ARC_W = 0.5 * (_ARC_X + 1.0), 0.5 * _ARC_WX


class LadderResult(CircleFitted):
    """
    Equilibrium of one finger from a ladder rung, with the fields of `CCMResult`.

    Attributes
    ----------
    success : bool
        True only for a converged, stable equilibrium.
    status : SolverStatus
    message : str
    iterations : int
        Newton iterations, continuation steps included.
    coefficients : ndarray, shape (N, 4) or None
        Arc: the CCM coefficients (b1, b3, c1, d) of one segment with the same
        uniform strain (b1 = eps, d = kappa/2, b3 = -2 d^2/3, SI). Rod: None
        (it has no polynomial segments); see `strains`.
    points : ndarray, shape (M, 2)
        Global (X, Z) midplane samples at evenly spaced reference arc length,
        the root first and the tip last [m].
    tangent : ndarray, shape (M,)
        Tangent angle theta of every sample from +X towards +Z [rad].
    strains : ndarray, shape (M, 3)
        (eps [-], kappa [1/m], c1 [-]) at every sample; kappa = d theta/d s per
        reference length, the deformed curvature is kappa / (1 + eps).
    tip : ndarray, shape (2,)
        Global (X, Z) of the tip [m].
    beta : ndarray, shape (N,)
        Rotation of every element (arc: N = 1, the whole arc) [rad].
    valid : bool
        Always True: these rungs are geometrically exact and have no
        small-rotation rule.
    curvature, fit_rmsd : float
        Signed curvature of the least-squares circle [1/m] and its RMSD [m].
    pressure : float
        Gauge pressure [Pa].
    tip_force : tuple of float
        (f0, p0) [N].
    energy : float
        Total potential [J].

    """

    def __init__(self, solver, state, status, iterations, step, pressure, tip_force,
                 fraction=1.0):
        self.solver = solver
        self.state = state
        self.status = SolverStatus(status)
        self.success = self.status is SolverStatus.SUCCESS
        self.iterations = int(iterations)
        self.last_step = float(step)
        self.pressure = float(pressure)
        self.tip_force = tuple(float(f) for f in tip_force)
        self.valid = True
        self.message = _MESSAGES[self.status].format(
            step=step, tol=solver.tol, iterations=iterations, fraction=fraction)
        out = solver._outputs(state, self.pressure, np.array(self.tip_force))
        self.points, self.tangent, self.strains = out['points'], out['tangent'], out['strains']
        self.tip, self.beta, self.coefficients = out['tip'], out['beta'], out['coefficients']
        self.nodes = out['nodes']
        self.energy = out['energy']

    def __repr__(self):
        return (f'{type(self).__name__}(success={self.success}, status={self.status.name}, '
                f'iterations={self.iterations}, tip={self.tip.round(6).tolist()})')


class ArcResult(LadderResult):
    """Result of `ArcSolver`; `state` is (eps, kappa, c1)."""


class RodResult(LadderResult):
    """Result of `RodSolver`; `state` is (theta nodal values, (eps, c1) at quadrature points)."""


def _check_common(design, pressure_model, samples):
    if not isinstance(design, ActuatorDesign):
        raise TypeError(f'`design` must be an ActuatorDesign, got {type(design).__name__}')
    if pressure_model not in PRESSURE_MODELS:
        raise ValueError(f'`pressure_model` must be one of {sorted(PRESSURE_MODELS)}, '
                         f'got {pressure_model!r}')
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 3:
        raise ValueError(f'`samples` must be an integer >= 3, got {samples!r}')


def _check_solve(pressure, tip_force):
    pressure = real_number('pressure', pressure, '[Pa]')
    if pressure < 0.0:
        raise ValueError(f'`pressure` must be >= 0 (gauge) [Pa], got {pressure}')
    if np.shape(tip_force) != (2,):
        raise ValueError(f'`tip_force` must be (f0, p0) [N], got {tip_force!r}')
    force = np.array([real_number('tip_force[0]', tip_force[0], '[N]'),
                      real_number('tip_force[1]', tip_force[1], '[N]')])
    return pressure, force


class _LadderSolver:
    """Shared solve/continuation/rigidity logic of the non-CCM rungs."""

    _result_type = LadderResult

    def solve(self, pressure=0.0, tip_force=(0.0, 0.0), initial=None):
        """
        Find the equilibrium at a gauge pressure and tip load.

        Parameters
        ----------
        pressure : float
            Gauge pressure P >= 0 [Pa].
        tip_force : (float, float)
            (f0, p0), tip force along global X and Z [N].
        initial : result of this solver, optional
            Warm start: Newton starts there, and if that does not reach a stable
            equilibrium the solve starts again from the flat, unstrained state as
            with None. It changes the iteration count, never the answer.

        Returns
        -------
        LadderResult
            `success` False (with a message) when Newton and continuation both fail.

        """
        pressure, force = _check_solve(pressure, tip_force)
        if initial is not None and not (isinstance(initial, self._result_type)
                                        and initial.solver._compatible(self)):
            raise ValueError(f'`initial` must be None or a {self._result_type.__name__} of a '
                             'solver with the same discretisation')
        its = 0
        if initial is not None:
            # A warm start only saves iterations: if it does not reach a stable equilibrium
            # the solve starts again exactly as a fresh one.
            state, status, its, step = self._newton(initial.state, pressure, force)
            if status is SolverStatus.SUCCESS:
                return self._result_type(self, state, status, its, step, pressure, force)
        flat = self._flat_state()
        state, status, n, step = self._newton(flat, pressure, force)
        its += n
        if status in (SolverStatus.SUCCESS, SolverStatus.UNSTABLE):
            return self._result_type(self, state, status, its, step, pressure, force)
        # Continuation: march pressure and load from the unloaded state to the target.
        state, status, n, step = self._newton(flat, 0.0, np.zeros(2))
        its += n
        if status is not SolverStatus.SUCCESS:
            return self._result_type(self, state, SolverStatus.CONTINUATION_FAILED, its,
                                     step, pressure, force, fraction=0.0)
        lam, dlam = 0.0, 0.25
        while True:
            target = min(1.0, lam + dlam)
            new, status, n, step = self._newton(state, target * pressure, target * force)
            its += n
            if status is SolverStatus.SUCCESS:
                state, lam = new, target
                dlam = min(2.0 * dlam, 1.0)
                if lam >= 1.0:
                    return self._result_type(self, state, status, its, step, pressure, force)
            else:
                dlam *= 0.5
                if dlam < 1.0 / 256:
                    return self._result_type(self, state, SolverStatus.CONTINUATION_FAILED,
                                             its, step, pressure, force, fraction=lam)

    def rigidity(self, pressure=0.0, axis='x', displacement=0.010, initial=None):
        """
        Flexural rigidity at fixed pressure by displacement control, eq. (22).

        The tip force along +X (or +Z) that moves the tip by `displacement`
        along that axis is found by secant iterations on warm-started solves.

        Returns
        -------
        RigidityResult
            K_x = f0 |Z_tip|^3 / (3 delta) or K_z = p0 |X_tip|^3 / (3 delta) [N m^2].

        """
        if axis not in ('x', 'z'):
            raise ValueError(f"`axis` must be 'x' or 'z', got {axis!r}")
        delta = real_number('displacement', displacement, '[m]')
        if delta <= 0.0:
            raise ValueError(f'`displacement` must be > 0 [m], got {delta}')
        unloaded = self.solve(pressure, (0.0, 0.0), initial=initial)
        if not unloaded.success:
            return RigidityResult(axis, delta, math.nan, math.nan, False,
                                  'unloaded solve failed: ' + unloaded.message, unloaded,
                                  None, unloaded.iterations)
        k = 0 if axis == 'x' else 1
        direction = np.eye(2)[k]
        start = unloaded.tip[k]
        iterations = unloaded.iterations
        # Probe the initial stiffness with a small force, then secant steps.
        f_a, d_a = 0.0, 0.0
        f_b = 1e-3
        res_b = self.solve(pressure, tuple(f_b * direction), initial=unloaded)
        iterations += res_b.iterations
        d_b = res_b.tip[k] - start
        for _ in range(60):
            if not res_b.success:
                break
            if abs(d_b - delta) <= 1e-11 * delta:
                lever = abs(res_b.tip[1 - k])
                return RigidityResult(axis, delta, f_b, lever, True, 'converged', unloaded,
                                      res_b, iterations)
            slope = (d_b - d_a) / (f_b - f_a)
            if not (math.isfinite(slope) and slope != 0.0):
                break
            f_new = f_b + (delta - d_b) / slope
            # Keep the steps modest so that warm starts stay in the basin.
            f_new = f_b + max(-1.0, min(1.0, f_new - f_b))
            res_new = self.solve(pressure, tuple(f_new * direction), initial=res_b)
            iterations += res_new.iterations
            f_a, d_a = f_b, d_b
            f_b, d_b, res_b = f_new, res_new.tip[k] - start, res_new
        return RigidityResult(axis, delta, f_b, math.nan, False,
                              'displacement control did not converge', unloaded, res_b,
                              iterations)


class ArcSolver(_LadderSolver):
    """
    Rung a: the finger as one arc of uniform strain (eps, kappa, c1).

    Minimises L W_mean(eps, kappa, c1) - F . tip(eps, kappa) with W_mean the
    length-weighted mean section law (channel with ribs, channel-free tip), and
    tip = (1 + eps) L int_0^1 (cos, sin)(kappa L t) dt. Without a tip load and for
    a uniform section this is exact: the rod's solution is an arc. With loads or
    a non-uniform section it is the one-element constant-strain Ritz solution.

    Parameters
    ----------
    design : ActuatorDesign
        The finger.
    pressure_model : {'adiabatic', 'isobaric'}
        k_p = 1/(gamma - 1) or 1 (SPEC "Pressure work").
    tol : float
        Largest final Newton step in (eps, kappa L, c1) [-].
    samples : int
        Midplane samples M, root to tip.
    max_iterations : int
        Newton iterations per (sub)solve.

    References
    ----------
    docs/physics.md, sections 11.2 and 11.3.

    """

    _result_type = ArcResult

    def __init__(self, design, pressure_model='adiabatic', tol=1e-12, samples=129,
                 max_iterations=60):
        _check_common(design, pressure_model, samples)
        self.design = design
        self.pressure_model = pressure_model
        self.pressure_coefficient = PRESSURE_MODELS[pressure_model]
        self.tol = float(tol)
        self.samples = int(samples)
        self.max_iterations = int(max_iterations)
        self.n_segments = 1
        breaks, types, law = station_layout(design, ribs='average')
        self.law = law.mean(np.bincount(types, np.diff(breaks), minlength=law.n_types))
        self.length = design.free_length
        self._scale = np.array([1.0, self.length, 1.0])

    def _compatible(self, other):
        return isinstance(other, ArcSolver)

    def _flat_state(self):
        return np.zeros(3)

    def _arc_integrals(self, phi, orders=3):
        """Return I[k] = int_0^1 t^k (cos, sin)(phi t) dt, shape (orders, 2, ...)."""
        phi = np.asarray(phi, dtype=float)
        arg = np.multiply.outer(phi, _ARC_T)
        c, s = np.cos(arg), np.sin(arg)
        out = []
        for k in range(orders):
            w = _ARC_W * _ARC_T ** k
            out.append(np.stack([c @ w, s @ w]))
        return np.array(out)

    def _derivatives(self, y, pressure, force):
        length = self.length
        energy, grad, hess = self.law.derivatives(y, self.pressure_coefficient * pressure, 0)
        energy, grad, hess = length * energy, length * grad, length * hess
        i0, i1, i2 = self._arc_integrals(y[1] * length)
        # S = int cos, C = int sin; S' = -int t sin, C' = int t cos; S'' = -int t^2 cos, ...
        base = np.array([i0[0], i0[1]])
        d1 = np.array([-i1[1], i1[0]])
        d2 = np.array([-i2[0], -i2[1]])
        stretch = 1.0 + y[0]
        tip = stretch * length * base
        energy -= force @ tip
        grad[0] -= force @ (length * base)
        grad[1] -= force @ (stretch * length ** 2 * d1)
        hess[0, 1] -= force @ (length ** 2 * d1)
        hess[1, 0] -= force @ (length ** 2 * d1)
        hess[1, 1] -= force @ (stretch * length ** 3 * d2)
        return energy, grad, hess

    def _newton(self, y, pressure, force):
        sc = self._scale
        y = np.array(y, dtype=float)
        energy, grad, hess = self._derivatives(y, pressure, force)
        step_norm = math.inf
        for it in range(1, self.max_iterations + 1):
            if not (np.isfinite(energy) and np.all(np.isfinite(grad))):
                return y, SolverStatus.NOT_FINITE, it, step_norm
            hs = hess / sc[:, None] / sc[None, :]
            gs = grad / sc
            lam, vec = np.linalg.eigh(hs)
            pd = lam.min() > 0.0
            lam = np.maximum(np.abs(lam), 1e-10 * np.abs(lam).max())
            step_s = -vec @ ((vec.T @ gs) / lam)
            step_norm = float(np.abs(step_s).max())
            if step_norm <= self.tol:
                y = y + step_s / sc
                return y, SolverStatus.SUCCESS if pd else SolverStatus.UNSTABLE, it, step_norm
            if step_norm > 0.5:
                step_s *= 0.5 / step_norm
            step = step_s / sc
            slope = float(grad @ step)
            alpha = 1.0
            while True:
                trial = y + alpha * step
                e_trial = self._derivatives(trial, pressure, force)[0]
                if e_trial <= energy + 1e-4 * alpha * slope or \
                        -alpha * slope <= 1e-14 * (abs(energy) + 1e-6):
                    break
                alpha *= 0.5
                if alpha < 1e-10:
                    return y, SolverStatus.LINE_SEARCH_FAILED, it, step_norm
            y = trial
            energy, grad, hess = self._derivatives(y, pressure, force)
        return y, SolverStatus.MAX_ITERATIONS, self.max_iterations, step_norm

    def _outputs(self, y, pressure, force):
        length = self.length
        s = np.linspace(0.0, length, self.samples)
        i0 = self._arc_integrals(y[1] * s, orders=1)[0]
        stretch = 1.0 + y[0]
        points = (stretch * s * i0).T
        tip = points[-1].copy()
        d = 0.5 * y[1]
        return {
            'points': points, 'tangent': y[1] * s,
            'strains': np.tile(y, (self.samples, 1)), 'tip': tip,
            'beta': np.array([y[1] * length]),
            'coefficients': np.array([[y[0], -2.0 * d * d / 3.0, y[2], d]]),
            'nodes': np.array([[0.0, 0.0], tip]),
            'energy': float(self._derivatives(y, pressure, force)[0]),
        }


def _gll_nodes(degree):
    """Gauss-Lobatto-Legendre nodes on [-1, 1], degree + 1 of them."""
    inner = np.polynomial.legendre.Legendre.basis(degree).deriv().roots()
    return np.concatenate([[-1.0], np.sort(inner.real), [1.0]])


def _lagrange(nodes, points):
    """Values and derivatives of the Lagrange basis on `nodes` at `points`, (P, n) each."""
    n = nodes.size
    vander = np.polynomial.legendre.legvander(nodes, n - 1)
    coef = np.linalg.inv(vander)          # column j: Legendre coefficients of basis j
    values = np.polynomial.legendre.legvander(points, n - 1) @ coef
    dcoef = np.stack([np.polynomial.legendre.legder(coef[:, j]) for j in range(n)], axis=1)
    derivs = np.polynomial.legendre.legvander(points, n - 2) @ dcoef
    return values, derivs


class RodSolver(_LadderSolver):
    """
    Rung d: geometrically exact, extensible, shear-rigid planar rod with the section law.

    Kinematics (reference arc length s in [0, L], theta from +X towards +Z):
    r' = (1 + eps)(cos theta, sin theta), and a fibre at height z has length
    (1 + eps - z theta') per unit reference length, so its strain is
    e = eps - z kappa with kappa = theta' -- the CCM's strain with kappa = 2 d.
    The deformed curvature is d theta / d(deformed length) = kappa / (1 + eps).
    The potential

        Pi = int_0^L W(eps, theta', c1; P) ds - F . r(L)

    (the pressure work is in W) is stationary at the BVP
    theta' = kappa, M' = -(1 + eps) F . (-sin theta, cos theta), with
    M = dW/dkappa, dW/deps = F . (cos theta, sin theta), dW/dc1 = 0,
    theta(0) = 0, M(L) = 0. It is solved as a Ritz/spectral-element problem:
    theta is continuous and piecewise polynomial of `degree` on elements whose
    edges include every section change (rib edges, channel end), eps and c1
    are free at the Gauss points (they carry no derivative, so their pointwise
    minimisation is exact), and Newton with the exact Hessian (eps, c1
    condensed point by point) converges quadratically. Within an element the
    solution is analytic, so the error falls exponentially with the degree.

    Parameters
    ----------
    design : ActuatorDesign
        The finger.
    pressure_model : {'adiabatic', 'isobaric'}
        k_p = 1/(gamma - 1) or 1 (SPEC "Pressure work").
    tol : float
        Largest final Newton step in theta [rad] and (eps, c1) [-].
    ribs : {'exact', 'average'}
        Resolve every transverse rib station by station, or smear them.
    degree : int
        Polynomial degree of theta on each element.
    max_element_length : float
        Elements are no longer than this [m].
    samples : int
        Midplane samples M at evenly spaced reference arc length, root to tip.
    max_iterations : int
        Newton iterations per (sub)solve.

    References
    ----------
    docs/physics.md, section 11.4; docs/model_notes.md, "Rod kinematics".

    """

    _result_type = RodResult

    def __init__(self, design, pressure_model='adiabatic', tol=1e-10, ribs='exact', degree=8,
                 max_element_length=0.010, samples=129, max_iterations=60):
        _check_common(design, pressure_model, samples)
        if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)) \
                or degree < 2:
            raise ValueError(f'`degree` must be an integer >= 2, got {degree!r}')
        max_element_length = real_number('max_element_length', max_element_length, '[m]')
        if max_element_length <= 0.0:
            raise ValueError(f'`max_element_length` must be > 0 [m], got {max_element_length}')
        self.design = design
        self.pressure_model = pressure_model
        self.pressure_coefficient = PRESSURE_MODELS[pressure_model]
        self.tol = float(tol)
        self.ribs = ribs
        self.degree = int(degree)
        self.samples = int(samples)
        self.max_iterations = int(max_iterations)
        self.length = design.free_length
        breaks, types, self.law = station_layout(design, ribs=ribs)
        edges, etypes = [0.0], []
        for lo, hi, kind in zip(breaks, breaks[1:], types):
            count = max(1, int(math.ceil((hi - lo) / max_element_length - 1e-9)))
            edges.extend(np.linspace(lo, hi, count + 1)[1:])
            etypes.extend([kind] * count)
        self.edges = np.array(edges)
        self.element_types = np.array(etypes, dtype=int)
        self.n_elements = self.element_types.size
        self.n_segments = self.n_elements
        p = self.degree
        self._nodes_ref = _gll_nodes(p)
        xq, wq = np.polynomial.legendre.leggauss(p + 2)
        self._xq = xq
        self._basis, dbasis = _lagrange(self._nodes_ref, xq)
        half = 0.5 * np.diff(self.edges)
        self._half = half
        self._dbasis = dbasis[None, :, :] / half[:, None, None]          # (E, Q, p+1)
        self._weights = wq[None, :] * half[:, None]                     # (E, Q) [m]
        self._dofs = np.arange(self.n_elements)[:, None] * p + np.arange(p + 1)[None, :]
        self.n_theta = self.n_elements * p + 1
        self._qtypes = np.repeat(self.element_types[:, None], xq.size, axis=1)
        # Scale of the tip-rotation Hessian: EI of the stiffest section over L [J].
        self._theta_scale = float(self.law.stiffness[:, 1, 1].max()) / self.length

    def _compatible(self, other):
        return (isinstance(other, RodSolver) and other.degree == self.degree
                and np.array_equal(other.edges, self.edges))

    def _flat_state(self):
        return (np.zeros(self.n_theta), np.zeros((self.n_elements, self._xq.size, 2)))

    # -- energy -------------------------------------------------------------
    def _point_fields(self, theta):
        te = theta[self._dofs]                                          # (E, p+1)
        th = te @ self._basis.T                                         # (E, Q)
        kap = np.einsum('eqa,ea->eq', self._dbasis, te)
        return th, kap

    def _local(self, th, kap, b, pressure, force, types):
        """Energy density and derivatives in (theta, kappa, eps, c1) at every point."""
        y = np.stack([b[..., 0], kap, b[..., 1]], axis=-1)
        w, g, h = self.law.derivatives(y, self.pressure_coefficient * pressure, types)
        c, s = np.cos(th), np.sin(th)
        gf = force[0] * c + force[1] * s                                # F . t
        gfp = -force[0] * s + force[1] * c                              # F . n
        stretch = 1.0 + b[..., 0]
        return w - stretch * gf, g, h, gf, gfp, stretch

    def _energy(self, state, pressure, force):
        theta, b = state
        th, kap = self._point_fields(theta)
        w = self._local(th, kap, b, pressure, force, self._qtypes)[0]
        return float((self._weights * w).sum())

    def _newton_step(self, state, pressure, force):
        """Return (energy, step, positive_definite, slope) of the condensed Newton system."""
        theta, b = state
        th, kap = self._point_fields(theta)
        w, g, h, gf, gfp, stretch = self._local(th, kap, b, pressure, force, self._qtypes)
        energy = float((self._weights * w).sum())
        wt = self._weights
        # Local blocks: a = (theta, kappa), b = (eps, c1).
        ga = np.stack([-stretch * gfp, g[..., 1]], axis=-1)
        gb = np.stack([g[..., 0] - gf, g[..., 2]], axis=-1)
        haa = np.zeros(th.shape + (2, 2))
        haa[..., 0, 0] = stretch * gf
        haa[..., 1, 1] = h[..., 1, 1]
        hab = np.zeros(th.shape + (2, 2))
        hab[..., 0, 0] = -gfp
        hab[..., 1, 0] = h[..., 1, 0]
        hab[..., 1, 1] = h[..., 1, 2]
        hbb = h[..., [[0], [2]], [0, 2]]
        det = hbb[..., 0, 0] * hbb[..., 1, 1] - hbb[..., 0, 1] * hbb[..., 1, 0]
        if not (np.all(np.isfinite(h)) and np.isfinite(energy)):
            return energy, None, False, 0.0
        local_pd = bool(np.all(det > 0.0) and np.all(hbb[..., 0, 0] > 0.0))
        if local_pd:
            inv = np.empty_like(hbb)
            inv[..., 0, 0] = hbb[..., 1, 1] / det
            inv[..., 1, 1] = hbb[..., 0, 0] / det
            inv[..., 0, 1] = -hbb[..., 0, 1] / det
            inv[..., 1, 0] = -hbb[..., 1, 0] / det
            hab_inv = np.einsum('...ij,...jk->...ik', hab, inv)
            schur = haa - np.einsum('...ij,...kj->...ik', hab_inv, hab)
            ra = ga - np.einsum('...ij,...j->...i', hab_inv, gb)
            nb, db = self._basis, self._dbasis                          # (Q, a), (E, Q, a)
            kmat = (np.einsum('eq,qa,qb->eab', wt * schur[..., 0, 0], nb, nb)
                    + np.einsum('eq,qa,eqb->eab', wt * schur[..., 0, 1], nb, db)
                    + np.einsum('eq,eqa,qb->eab', wt * schur[..., 1, 0], db, nb)
                    + np.einsum('eq,eqa,eqb->eab', wt * schur[..., 1, 1], db, db))
            rvec = (np.einsum('eq,qa->ea', wt * ra[..., 0], nb)
                    + np.einsum('eq,eqa->ea', wt * ra[..., 1], db))
            n = self.n_theta
            big = np.zeros((n, n))
            rhs = np.zeros(n)
            dofs = self._dofs
            np.add.at(big, (dofs[:, :, None], dofs[:, None, :]), kmat)
            np.add.at(rhs, dofs, rvec)
            dtheta = np.zeros(n)
            kred = big[1:, 1:] / self._theta_scale
            try:
                factor = cho_factor(kred, check_finite=False)
                dtheta[1:] = -cho_solve(factor, rhs[1:] / self._theta_scale,
                                        check_finite=False)
                pd = True
            except np.linalg.LinAlgError:
                # Indefinite Schur complement: mirror its eigenvalues. With the local
                # blocks positive definite the condensed step still descends.
                lam, vec = eigh(kred, check_finite=False)
                lam = np.maximum(np.abs(lam), 1e-10 * np.abs(lam).max())
                dtheta[1:] = -vec @ ((vec.T @ rhs[1:] / self._theta_scale) / lam)
                pd = False
            dth, dkap = self._point_fields(dtheta)
            da = np.stack([dth, dkap], axis=-1)
            dbv = -np.einsum('...ij,...j->...i', inv,
                             gb + np.einsum('...ji,...j->...i', hab, da))
            slope = float((wt[..., None] * (ga * da + gb * dbv)).sum())
            return energy, (dtheta, dbv), pd, slope
        return (energy, *self._full_step(th, ga, gb, haa, hab, hbb), False)

    def _full_step(self, th, ga, gb, haa, hab, hbb):
        """Newton step on the full system with mirrored eigenvalues (indefinite case)."""
        n = self.n_theta
        npts = th.size
        size = n + 2 * npts
        wt = self._weights
        nb = np.broadcast_to(self._basis, self._dbasis.shape)
        bmat = np.stack([nb, self._dbasis], axis=2)                     # (E, Q, 2, a)
        big = np.zeros((size, size))
        grad = np.zeros(size)
        dofs = self._dofs
        kaa = np.einsum('eq,eqia,eqij,eqjb->eab', wt, bmat, haa, bmat)
        np.add.at(big, (dofs[:, :, None], dofs[:, None, :]), kaa)
        np.add.at(grad, dofs, np.einsum('eq,eqia,eqi->ea', wt, bmat, ga))
        bidx = n + np.arange(2 * npts).reshape(th.shape + (2,))
        kab = np.einsum('eq,eqia,eqij->eqaj', wt, bmat, hab)
        rows = np.broadcast_to(dofs[:, None, :, None], kab.shape)
        cols = np.broadcast_to(bidx[:, :, None, :], kab.shape)
        np.add.at(big, (rows, cols), kab)
        np.add.at(big, (cols, rows), kab)
        kbb = wt[..., None, None] * hbb
        r2 = np.broadcast_to(bidx[..., :, None], kbb.shape)
        c2 = np.broadcast_to(bidx[..., None, :], kbb.shape)
        np.add.at(big, (r2, c2), kbb)
        grad[n:] = (wt[..., None] * gb).ravel()
        keep = np.arange(1, size)
        hh = big[np.ix_(keep, keep)]
        d = np.sqrt(np.maximum(np.abs(np.diag(hh)), 1e-300))
        lam, vec = eigh(hh / d[:, None] / d[None, :], check_finite=False)
        lam = np.maximum(np.abs(lam), 1e-10 * np.abs(lam).max())
        step = np.zeros(size)
        step[1:] = -(vec @ ((vec.T @ (grad[1:] / d)) / lam)) / d
        return (step[:n], step[n:].reshape(th.shape + (2,))), False, float(grad @ step)

    def _newton(self, state, pressure, force):
        theta, b = state[0].copy(), state[1].copy()
        step_norm = math.inf
        for it in range(1, self.max_iterations + 1):
            energy, step, pd, slope = self._newton_step((theta, b), pressure, force)
            if step is None or not np.isfinite(energy):
                return (theta, b), SolverStatus.NOT_FINITE, it, step_norm
            dtheta, db = step
            step_norm = float(max(np.abs(dtheta).max(), np.abs(db).max()))
            if not math.isfinite(step_norm):
                return (theta, b), SolverStatus.NOT_FINITE, it, step_norm
            if step_norm <= self.tol:
                status = SolverStatus.SUCCESS if pd else SolverStatus.UNSTABLE
                return (theta + dtheta, b + db), status, it, step_norm
            cap = max(np.abs(dtheta).max() / 0.5, np.abs(db).max() / 0.1, 1.0)
            dtheta, db, slope = dtheta / cap, db / cap, slope / cap
            if not slope < 0.0:
                return (theta, b), SolverStatus.LINE_SEARCH_FAILED, it, step_norm
            alpha = 1.0
            while True:
                trial = (theta + alpha * dtheta, b + alpha * db)
                e_trial = self._energy(trial, pressure, force)
                # Armijo; near the solution the energy change is below round-off.
                if e_trial <= energy + 1e-4 * alpha * slope or \
                        -slope <= 1e-13 * (abs(energy) + self._theta_scale):
                    break
                alpha *= 0.5
                if alpha < 1e-10:
                    return (theta, b), SolverStatus.LINE_SEARCH_FAILED, it, step_norm
            theta, b = trial
        return (theta, b), SolverStatus.MAX_ITERATIONS, self.max_iterations, step_norm

    # -- outputs ------------------------------------------------------------
    def _solve_local(self, th, kap, b0, force, types, pressure):
        """Pointwise (eps, c1) minimising W - (1 + eps) F . t at given theta, kappa."""
        b = np.array(b0, dtype=float, copy=True)
        for _ in range(30):
            _, g, h, gf, _, _ = self._local(th, kap, b, pressure, force, types)
            gb = np.stack([g[..., 0] - gf, g[..., 2]], axis=-1)
            hbb = h[..., [[0], [2]], [0, 2]]
            db = -np.linalg.solve(hbb, gb[..., None])[..., 0]
            b += db
            if np.abs(db).max() < 1e-15:
                break
        return b

    def _outputs(self, state, pressure, force):
        theta, b = state
        th, kap = self._point_fields(theta)
        stretch = 1.0 + b[..., 0]
        seg = np.stack([(self._weights * stretch * np.cos(th)).sum(axis=1),
                        (self._weights * stretch * np.sin(th)).sum(axis=1)], axis=1)
        nodes = np.zeros((self.n_elements + 1, 2))
        np.cumsum(seg, axis=0, out=nodes[1:])
        tip = nodes[-1].copy()
        # Samples: theta and kappa from the polynomial; eps, c1 by the local equilibrium; the
        # position by a Gauss rule from the element start.
        s = np.linspace(0.0, self.length, self.samples)
        elem = np.clip(np.searchsorted(self.edges, s, side='right') - 1, 0, self.n_elements - 1)
        lo = self.edges[elem]
        xq = self._xq
        sub = lo[:, None] + (s - lo)[:, None] * 0.5 * (xq + 1.0)[None, :]   # (M, Q)
        allp = np.concatenate([s[:, None], sub], axis=1)                     # (M, Q+1)
        el = np.repeat(elem[:, None], allp.shape[1], axis=1)
        xi = 2.0 * (allp - self.edges[el]) / (2.0 * self._half[el]) - 1.0
        values, derivs = _lagrange(self._nodes_ref, xi.ravel())
        te = theta[self._dofs[el.ravel()]]
        th_s = (values * te).sum(axis=1).reshape(allp.shape)
        kap_s = ((derivs * te).sum(axis=1) / self._half[el.ravel()]).reshape(allp.shape)
        types = self.element_types[el]
        b0 = np.broadcast_to(b[elem].mean(axis=1)[:, None, :], allp.shape + (2,))
        bs = self._solve_local(th_s, kap_s, b0, force, types, pressure)
        st = 1.0 + bs[..., 0]
        wsub = 0.5 * (s - lo)[:, None] * np.polynomial.legendre.leggauss(xq.size)[1][None, :]
        dx = (wsub * st[:, 1:] * np.cos(th_s[:, 1:])).sum(axis=1)
        dz = (wsub * st[:, 1:] * np.sin(th_s[:, 1:])).sum(axis=1)
        points = nodes[elem] + np.stack([dx, dz], axis=1)
        points[-1] = tip
        strains = np.stack([bs[:, 0, 0], kap_s[:, 0], bs[:, 0, 1]], axis=1)
        return {
            'points': points, 'tangent': th_s[:, 0], 'strains': strains, 'tip': tip,
            'beta': theta[self._dofs[:, -1]] - theta[self._dofs[:, 0]],
            'coefficients': None, 'nodes': nodes,
            'energy': self._energy(state, pressure, force),
        }
