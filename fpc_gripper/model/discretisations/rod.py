"""Rung d: the geometrically exact, extensible rod, the ladder's reference."""

import functools
import math

import numpy as np
from scipy.linalg import eigh, lu_factor, lu_solve

from .rung import check_common, RungSolver, set_common
from .. import engine
from ..engine import linear_step, NewtonOptions
from ..kernels import rod as rod_kernels
from ..kernels.pcc_section import section_arrays
from ..result import finger_constants
from ..section.law import station_layout
from ..section.segments import interval_of
from ..validation import arc_lengths, integer, real_number

__all__ = ['RodSolver']


class _PointwiseLocal:
    """
    The rod's (eps, c1) at given (theta, kappa) points, as a discretisation of the engine.

    Every point decouples, so the Hessian is (K, 2, 2) blocks; energy, derivatives and
    the step are `rod_kernels.local_energy_kernel`, `local_derivatives_kernel` and
    `local_step_kernel` (the engine's `linear_step` where a block is not definite).
    """

    def __init__(self, rod, kap, along, element, pressure):
        self.gradient_scale = rod.gradient_scale
        self._arrays = (kap, along, element, rod._stiffness, rod._gas, rod._pemc,
                        rod.pressure_coefficient * pressure)

    def energy(self, b, pressure, loads):
        return rod_kernels.local_energy_kernel(b, *self._arrays)

    def derivatives(self, b, pressure, loads):
        return rod_kernels.local_derivatives_kernel(b, *self._arrays)

    @staticmethod
    def step(grad, hess):
        step, definite = rod_kernels.local_step_kernel(grad, hess)
        if definite:
            return step, 1.0
        return linear_step(grad, hess)


#: `_RodHessian.factor` of a condensed system that is not positive definite.
_INDEFINITE = False


class _RodHessian:
    """
    Pointwise Hessian blocks of the rod in a = (theta, kappa) and b = (eps, c1).

    `th` (E, Q) and the blocks `haa`, `hab`, `hbb` (E, Q, 2, 2) are read only. The
    condensation (`rod_kernels.condense_kernel`): `local` (every hbb positive definite),
    `inv` = hbb^-1, `hab_inv` = hab hbb^-1, the band `lower` of the condensed theta system
    and its Cholesky `factor` (`_INDEFINITE` where it is not positive definite, then
    `dense_lu` keeps the LU of the dense condensed system once a solve needs it); None
    where not computed. `derivatives` also keeps the Newton step of its own gradient,
    which the first `step` with that gradient hands out.
    """

    __slots__ = ('th', 'haa', 'hab', 'hbb', 'local', 'inv', 'hab_inv', 'lower', 'factor',
                 '_gradient', '_step', 'dense_lu')

    def __init__(self, th, haa, hab, hbb, local=None, inv=None, hab_inv=None, lower=None,
                 factor=None, gradient=None, step=None):
        self.th, self.haa, self.hab, self.hbb = th, haa, hab, hbb
        self.local, self.inv, self.hab_inv = local, inv, hab_inv
        self.lower, self.factor = lower, factor
        self._gradient, self._step = gradient, step
        self.dense_lu = None


def _dense_band(lower):
    """Return the symmetric (n, n) matrix of a lower band lower[d, k] = H[k + d, k]."""
    n = lower.shape[1]
    out = np.zeros((n, n))
    for d in range(lower.shape[0]):
        k = np.arange(n - d)
        out[k + d, k] = lower[d, :n - d]
        out[k, k + d] = lower[d, :n - d]
    return out


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


class RodSolver(RungSolver):
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
    pressure_model : {None, 'design', 'adiabatic', 'isobaric'}
        k_p = 1/(gamma - 1) or 1 (SPEC "Pressure work"); None or 'design' (the
        default): the design's `pressure_work_factor`.
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

    Notes
    -----
    The energy, gradient, pointwise Hessian blocks, the condensation and its banded
    Cholesky (half-bandwidth `degree`), the node Jacobian and the outputs' pointwise
    local equilibrium are compiled kernels (`rod_kernels`); Python only passes them
    the solver's arrays. Where the condensed system is not positive definite its step
    mirrors the eigenvalues of the dense matrix, and where a pointwise (eps, c1) block
    is not, the step is that of the full system with mirrored eigenvalues (both rare,
    both numpy).

    References
    ----------
    docs/physics.md, section 11.4; docs/model_notes.md, "Rod kinematics".

    """

    rung = 'rod'

    def __init__(self, design, pressure_model=None, tol=1e-10, ribs='exact', degree=8,
                 max_element_length=0.010, samples=129, max_iterations=60):
        check_common(design, pressure_model, samples)
        integer('degree', degree, 2)
        max_element_length = real_number('max_element_length', max_element_length, '[m]')
        if max_element_length <= 0.0:
            raise ValueError(f'`max_element_length` must be > 0 [m], got {max_element_length}')
        set_common(self, design, pressure_model, tol, samples, max_iterations)
        self.ribs = ribs
        self.degree = int(degree)
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
        # The section law of every element as kernel arrays, once: no per-call gathering.
        self._stiffness, self._gas, self._pemc = section_arrays(self.law, self.element_types)
        self._basis = np.ascontiguousarray(self._basis)
        self._dbasis = np.ascontiguousarray(self._dbasis)
        self._weights = np.ascontiguousarray(self._weights)
        self._sample_geometry()
        # Scale of the tip-rotation Hessian: EI of the stiffest section over L [J].
        self._theta_scale = float(self.law.stiffness[:, 1, 1].max()) / self.length
        self.gradient_scale = self._theta_scale
        cap = np.full(self.n_theta - 1 + 2 * self._qtypes.size, 0.1)
        cap[:self.n_theta - 1] = 0.5
        self._options = NewtonOptions(max_iterations=self.max_iterations, xtol=self.tol,
                                      max_step=cap, energy_scale=self._theta_scale)
        self._local_options = NewtonOptions(xtol=1e-15, max_step=0.1,
                                            energy_scale=self._theta_scale)
        #: What the engine runs: the rod has no compiled data, so its own methods.
        self.engine_problem = self
        self._constants = finger_constants(self.rung, self.n_segments, self.edges)

    def _sample_geometry(self):
        """Store where the output samples lie; it depends on the edges alone."""
        self._sample_at = self._geometry(np.linspace(0.0, self.length, self.samples))

    def _geometry(self, s):
        """
        Where points at reference arc lengths s (M,) lie, the last one being the tip.

        Returns (element (M,), Lagrange values and derivatives at every point and at Q
        Gauss points from its element's start to it (M (Q + 1), p + 1), their element's
        half length and index, Gauss weights (M, Q) [m]).
        """
        elem = interval_of(self.edges, s)
        lo = self.edges[elem]
        xq = self._xq
        sub = lo[:, None] + (s - lo)[:, None] * 0.5 * (xq + 1.0)[None, :]   # (M, Q)
        allp = np.concatenate([s[:, None], sub], axis=1)                     # (M, Q+1)
        el = np.repeat(elem[:, None], allp.shape[1], axis=1)
        xi = 2.0 * (allp - self.edges[el]) / (2.0 * self._half[el]) - 1.0
        values, derivs = _lagrange(self._nodes_ref, xi.ravel())
        weights = 0.5 * (s - lo)[:, None] * np.polynomial.legendre.leggauss(xq.size)[1][None, :]
        return (elem.astype(np.int64), np.ascontiguousarray(values),
                np.ascontiguousarray(derivs), self._half[el.ravel()],
                el.ravel().astype(np.int64), weights)

    def _flat_state(self):
        return (np.zeros(self.n_theta), np.zeros((self.n_elements, self._xq.size, 2)))

    # -- the discretisation's side of the engine --------------------------------------
    # Unknowns: theta at the nodes but the clamped root (theta_0 = 0), then (eps, c1) at
    # every quadrature point.
    def _pack(self, state):
        theta, b = state
        return np.concatenate([theta[1:], np.ravel(b)])

    def _unpack(self, x):
        theta = np.concatenate([[0.0], x[:self.n_theta - 1]])
        return theta, x[self.n_theta - 1:].reshape(self._qtypes.shape + (2,))

    def energy(self, x, pressure, loads):
        """Total potential [J] at engine unknowns `x`."""
        return rod_kernels.energy_kernel(
            np.ascontiguousarray(x, dtype=float), self._basis, self._dbasis, self._weights,
            self._stiffness, self._gas, self._pemc, self.pressure_coefficient * pressure,
            self._force(loads))

    def derivatives(self, x, pressure, loads):
        """
        Energy [J], gradient and the pointwise Hessian blocks of the rod potential.

        The Hessian is returned as its pointwise blocks in a = (theta, kappa) and
        b = (eps, c1) (a `_RodHessian`): `step` and `solve_linear` condense b point by
        point, which keeps the system the size of the theta dofs (banded, half-bandwidth
        `degree`); the condensation, its Cholesky factor and the Newton step come with it.
        """
        (energy, grad, th, haa, hab, hbb, local, inv, hab_inv, lower, factor, definite,
         step) = rod_kernels.derivatives_kernel(
            np.ascontiguousarray(x, dtype=float), self._basis, self._dbasis, self._weights,
            self._stiffness, self._gas, self._pemc, self.pressure_coefficient * pressure,
            self._force(loads), self._theta_scale)
        if definite:
            return energy, grad, _RodHessian(th, haa, hab, hbb, local, inv, hab_inv, lower,
                                             factor, grad, step)
        return energy, grad, _RodHessian(th, haa, hab, hbb, local, inv, hab_inv, lower,
                                         _INDEFINITE)

    def _condensed(self, hess, rhs, mirror):
        """
        Solve the Newton system for `rhs` with (eps, c1) condensed point by point.

        Returns (solution, positive_definite); raises LinAlgError where the pointwise
        blocks are not positive definite, and, unless `mirror`, where the condensed
        system is singular. With `mirror` an indefinite condensed system has its
        eigenvalues mirrored (the step still descends, the local blocks being definite).
        """
        if not hess.local:
            raise np.linalg.LinAlgError('pointwise (eps, c1) blocks not positive definite')
        rhs = np.ascontiguousarray(rhs, dtype=float)
        if hess.factor is not _INDEFINITE:
            return rod_kernels.condensed_solve_kernel(
                hess.factor, rhs, hess.inv, hess.hab, hess.hab_inv, self._weights,
                self._basis, self._dbasis, self._theta_scale), True
        # Not positive definite (buckling, far from equilibrium): rare, dense numpy.
        kred = _dense_band(hess.lower)
        reduced = rod_kernels.reduced_rhs_kernel(rhs, hess.hab_inv, self._basis,
                                                 self._dbasis, self._theta_scale)
        if not mirror:
            # One LU per Hessian: the bordered solves of contact reuse it for many columns.
            if hess.dense_lu is None:
                hess.dense_lu = lu_factor(kred, check_finite=False)
                if not np.all(np.isfinite(hess.dense_lu[0])) or np.any(
                        np.diag(hess.dense_lu[0]) == 0.0):
                    raise np.linalg.LinAlgError('the condensed rod system is singular')
            dtheta = lu_solve(hess.dense_lu, reduced, check_finite=False)
        else:
            lam, vec = eigh(kred, check_finite=False)
            lam = np.maximum(np.abs(lam), 1e-10 * np.abs(lam).max())
            dtheta = vec @ ((vec.T @ reduced) / lam)
        return rod_kernels.expand_kernel(dtheta, rhs, hess.inv, hess.hab, self._weights,
                                         self._basis, self._dbasis), False

    def step(self, grad, hess):
        """Newton step, condensed; the full system with mirrored eigenvalues otherwise."""
        if grad is hess._gradient and hess._step is not None:
            # The step `derivatives` computed with the factor; handed out once, as each
            # call's answer is the caller's to keep.
            step, hess._step = hess._step, None
            return step, 1.0
        try:
            dx, positive = self._condensed(hess, -grad, mirror=True)
            return dx, 1.0 if positive else -1.0
        except np.linalg.LinAlgError:
            return self._full_step(grad, hess), -1.0

    def solve_linear(self, hess, rhs):
        """Solve the Newton system H x = rhs (condensed); LinAlgError if it cannot."""
        return self._condensed(hess, rhs, mirror=False)[0]

    def _full_step(self, grad, hess):
        """Newton step on the full system with mirrored eigenvalues (indefinite case)."""
        th, haa, hab, hbb = hess.th, hess.haa, hess.hab, hess.hbb
        n = self.n_theta
        npts = th.size
        size = n + 2 * npts
        wt = self._weights
        nb = np.broadcast_to(self._basis, self._dbasis.shape)
        bmat = np.stack([nb, self._dbasis], axis=2)                     # (E, Q, 2, a)
        big = np.zeros((size, size))
        dofs = self._dofs
        kaa = np.einsum('eq,eqia,eqij,eqjb->eab', wt, bmat, haa, bmat)
        np.add.at(big, (dofs[:, :, None], dofs[:, None, :]), kaa)
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
        keep = np.arange(1, size)
        hh = big[np.ix_(keep, keep)]
        d = np.sqrt(np.maximum(np.abs(np.diag(hh)), 1e-300))
        lam, vec = eigh(hh / d[:, None] / d[None, :], check_finite=False)
        lam = np.maximum(np.abs(lam), 1e-10 * np.abs(lam).max())
        return -(vec @ ((vec.T @ (grad / d)) / lam)) / d

    def node_jacobian(self, x, node):
        """Tip position [m] and its derivatives in the engine unknowns, (2, n)."""
        if node != self.tip_node:
            raise ValueError(f'RodSolver takes loads at the tip (node {self.tip_node}), '
                             f'got node {node}')
        return rod_kernels.node_jacobian_kernel(np.ascontiguousarray(x, dtype=float),
                                                self._basis, self._weights)

    # -- face points at element ends (contact: docs/physics.md, section 15.2) -----------
    # The rod's eps lives at its Gauss points, so a point's position is exact (the tip's
    # quadrature) only at an element end: its contact points are the element ends. These
    # hooks are numpy around the compiled kernels: the rod is the accuracy reference, not
    # the production model.
    def _ends(self, pseg, poff):
        """Element-end node index of every face point; ValueError for any other point."""
        pseg = np.asarray(pseg, dtype=np.int64).reshape(-1)
        poff = np.asarray(poff, dtype=float).reshape(-1)
        if pseg.size and (pseg.min() < 0 or pseg.max() >= self.n_elements):
            raise ValueError(f'face point elements must lie in [0, {self.n_elements}), got '
                             f'{pseg.tolist()}')
        lengths = np.diff(self.edges)[pseg]
        if np.any(np.abs(poff - lengths) > 1e-12 * self.length):
            raise ValueError('RodSolver has face points at element ends only: every offset '
                             'must equal its element length [m]')
        return (pseg + 1) * self.degree

    def _fields(self, x):
        """Nodal theta (n_theta,), theta (E, Q) and stretch 1 + eps (E, Q) at the points."""
        theta = np.concatenate([[0.0], x[:self.n_theta - 1]])
        at_points = theta[self._dofs] @ self._basis.T
        stretch = 1.0 + x[self.n_theta - 1:].reshape(self._qtypes.shape + (2,))[..., 0]
        return theta, at_points, stretch

    def point_positions(self, x, pseg, poff, pz):
        """Positions (K, 2) [m] of face points at element ends."""
        x = np.asarray(x, dtype=float)
        node = self._ends(pseg, poff)
        theta, th, stretch = self._fields(x)
        chords = np.stack([(self._weights * stretch * np.cos(th)).sum(axis=1),
                           (self._weights * stretch * np.sin(th)).sum(axis=1)], axis=1)
        ends = np.concatenate([np.zeros((1, 2)), np.cumsum(chords, axis=0)])
        end_theta = theta[node]
        z = np.asarray(pz, dtype=float).reshape(-1)
        return ends[node // self.degree] + z[:, None] * np.stack(
            [-np.sin(end_theta), np.cos(end_theta)], axis=1)

    def point_jacobian(self, x, seg, offset, z):
        """Position of a face point at an element end [m] and its derivatives, (2, n)."""
        x = np.asarray(x, dtype=float)
        node = int(self._ends([seg], [offset])[0])
        theta, th, stretch = self._fields(x)
        inside = slice(0, int(seg) + 1)
        wt = self._weights[inside]
        jac = np.zeros((2, x.size))
        cs, sn = np.cos(th[inside]), np.sin(th[inside])
        position = np.array([(wt * stretch[inside] * cs).sum(),
                             (wt * stretch[inside] * sn).sum()])
        # theta dofs through the basis; eps at the points directly.
        dofs = self._dofs[inside] - 1
        for row, values in ((0, -wt * stretch[inside] * sn), (1, wt * stretch[inside] * cs)):
            contrib = np.einsum('eq,qa->ea', values, self._basis)
            keep = dofs >= 0
            np.add.at(jac[row], dofs[keep], contrib[keep])
        eps_index = self.n_theta - 1 + 2 * np.arange(wt.size)
        jac[0, eps_index] = (wt * cs).ravel()
        jac[1, eps_index] = (wt * sn).ravel()
        end = theta[node]
        position += z * np.array([-math.sin(end), math.cos(end)])
        jac[0, node - 1] += -z * math.cos(end)
        jac[1, node - 1] += -z * math.sin(end)
        return position, jac

    def point_derivatives(self, x, pressure, loads, pseg, poff, pz, pforce):
        """
        Return `derivatives` with dead forces at face points (element ends) and tip loads.

        A force at the end of element e is carried by the elements 0..e: the kernel's
        pointwise load terms with a carried force per element; its offset z n(theta_end)
        adds a term in that end's nodal theta, which enters the condensed band's diagonal.
        """
        x = np.ascontiguousarray(x, dtype=float)
        pforce = np.asarray(pforce, dtype=float).reshape(-1, 2)
        node = self._ends(pseg, poff)
        z = np.asarray(pz, dtype=float).reshape(-1)
        carried = np.tile(self._force(loads), (self.n_elements, 1))
        element = node // self.degree - 1
        for e, force in zip(element, pforce):
            carried[:e + 1] += force
        (energy, grad, th, haa, hab, hbb, *_) = rod_kernels.derivatives_kernel(
            x, self._basis, self._dbasis, self._weights, self._stiffness, self._gas,
            self._pemc, self.pressure_coefficient * pressure, np.zeros(2), self._theta_scale)
        _, _, stretch = self._fields(x)
        cs, sn = np.cos(th), np.sin(th)
        along = carried[:, :1] * cs + carried[:, 1:] * sn
        normal = -carried[:, :1] * sn + carried[:, 1:] * cs
        energy -= float((self._weights * stretch * along).sum())
        values = self._weights * -stretch * normal
        contrib = np.einsum('eq,qa->ea', values, self._basis)
        dofs = self._dofs - 1
        keep = dofs >= 0
        np.add.at(grad, dofs[keep], contrib[keep])
        eps_index = self.n_theta - 1 + 2 * np.arange(self._weights.size)
        grad[eps_index] -= (self._weights * along).ravel()
        haa[..., 0, 0] += stretch * along
        hab[..., 0, 0] -= normal
        diagonal = np.zeros(self.n_theta - 1)
        theta = np.concatenate([[0.0], x[:self.n_theta - 1]])
        for k, force in enumerate(pforce):
            end = theta[node[k]]
            t = force[0] * math.cos(end) + force[1] * math.sin(end)
            n = -force[0] * math.sin(end) + force[1] * math.cos(end)
            energy -= z[k] * n
            grad[node[k] - 1] += z[k] * t
            diagonal[node[k] - 1] += z[k] * n
        local, inv, hab_inv, lower = rod_kernels.condense_kernel(
            haa, hab, hbb, self._weights, self._basis, self._dbasis, self._theta_scale)
        lower[0] += diagonal / self._theta_scale
        factor, definite = rod_kernels.banded_cholesky(lower)
        if local and definite:
            step = rod_kernels.condensed_solve_kernel(
                factor, -grad, inv, hab, hab_inv, self._weights, self._basis, self._dbasis,
                self._theta_scale)
            return energy, grad, _RodHessian(th, haa, hab, hbb, local, inv, hab_inv, lower,
                                             factor, grad, step)
        return energy, grad, _RodHessian(th, haa, hab, hbb, local, inv, hab_inv, lower,
                                         _INDEFINITE)

    # -- outputs ------------------------------------------------------------
    def _points(self, x, geometry, pressure, force):
        """
        Fields and positions of a state at the points of `geometry` (`_geometry`).

        theta and kappa come from the polynomial; eps and c1 from the local equilibrium
        (started from the element's mean); the position from the element start by the
        Gauss rule of (1 + eps)(cos, sin) theta. Returns (theta (M, Q + 1), kappa, local
        (eps, c1) (M, Q + 1, 2), element ends (E + 1, 2), points (M, 2), the last the tip).
        """
        element, values, derivs, half, point_element, weights = geometry
        shape = (element.size, self._xq.size + 1)
        th_s, kap_s, along, start = rod_kernels.sample_fields_kernel(
            x, self._xq.size, values, derivs, half, point_element, force)
        problem = _PointwiseLocal(self, kap_s, along, point_element, pressure)
        bs = engine.newton(problem, start, pressure, [], self._local_options).x.reshape(
            shape + (2,))
        th_s, kap_s = th_s.reshape(shape), kap_s.reshape(shape)
        nodes, points = rod_kernels.sample_points_kernel(x, bs, th_s, self._basis,
                                                         self._weights, element, weights)
        return th_s, kap_s, bs, nodes, points

    def positions_at(self, x, pressure, force, s):
        """
        (X, Z) [m] of the material points at reference arc lengths s of a state.

        The start of s's element plus the integral of (1 + eps)(cos, sin) theta from there
        to s by the elements' Gauss rule (Q points), eps from the local equilibrium at
        those points: the rod's own kinematics, equal to its nodes at element ends. A
        result's `position_at` is this function of its own state and loads.

        Parameters
        ----------
        x : ndarray
            Engine unknowns.
        pressure : float
            [Pa].
        force : (float, float)
            Tip force [N].
        s : float or array_like
            Reference arc length from the clamp edge, in [0, L] [m].

        Returns
        -------
        ndarray, shape s.shape + (2,)

        """
        values, shape = arc_lengths('s', s, self.length)
        # The kernel ends every point set at the tip: the tip closes the query.
        geometry = self._geometry(np.append(values, self.length))
        points = self._points(x, geometry, pressure, np.asarray(force, dtype=float))[4]
        return points[:-1].reshape(shape + (2,))

    def _positions(self, x, pressure, force):
        """Return the `position_at` of a result at engine unknowns `x`."""
        return functools.partial(self.positions_at, x, pressure, force)

    def _outputs(self, state, pressure, force):
        """Return the output fields of a state, by name (`RungSolver._python_fields`)."""
        theta, _ = state
        x = self._pack(state)
        force = np.ascontiguousarray(force, dtype=float)
        th_s, kap_s, bs, nodes, points = self._points(x, self._sample_at, pressure, force)
        strains = np.stack([bs[:, 0, 0], kap_s[:, 0], bs[:, 0, 1]], axis=1)
        return {
            'points': points, 'tangent': th_s[:, 0], 'strains': strains,
            'tip': nodes[-1].copy(), 'beta': theta[self._dofs[:, -1]] - theta[self._dofs[:, 0]],
            'coefficients': None, 'nodes': nodes,
            'energy': rod_kernels.energy_kernel(
                x, self._basis, self._dbasis, self._weights, self._stiffness, self._gas,
                self._pemc, self.pressure_coefficient * pressure, force),
        }
