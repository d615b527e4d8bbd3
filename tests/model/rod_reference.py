"""The rod's numpy hot paths as they were before compilation: the tests' slow reference."""

import numpy as np
from scipy.linalg import cho_factor, cho_solve, eigh

from fpc_gripper.model import engine
from fpc_gripper.model.discretisations.rod import _lagrange, _RodHessian, RodSolver
from fpc_gripper.model.engine import linear_step, NewtonOptions


class _PointwiseLocal:
    """
    The rod's (eps, c1) at given (theta, kappa) points, as a discretisation of the engine.

    Every point decouples, so the Hessian is (M, 2, 2) blocks.
    """

    def __init__(self, rod, th, kap, force, types, pressure):
        self.rod, self.th, self.kap, self.force, self.types = rod, th, kap, force, types
        self.pressure = pressure
        self.gradient_scale = rod.gradient_scale

    def energy(self, b, pressure, loads):
        b = b.reshape(self.th.shape + (2,))
        return float(self.rod._local(self.th, self.kap, b, self.pressure, self.force,
                                     self.types)[0].sum())

    def derivatives(self, b, pressure, loads):
        b = b.reshape(self.th.shape + (2,))
        w, g, h, gf, _, _ = self.rod._local(self.th, self.kap, b, self.pressure, self.force,
                                            self.types)
        gb = np.stack([g[..., 0] - gf, g[..., 2]], axis=-1)
        return float(w.sum()), gb.reshape(-1, 2), h[..., [[0], [2]], [0, 2]].reshape(-1, 2, 2)

    step = staticmethod(linear_step)


class ReferenceRodSolver(RodSolver):
    """
    `RodSolver` with every hot path in numpy, as before the kernels (tests and benchmarks).

    The constructor, the engine, the results and the indefinite full-system step are
    RodSolver's; the energy, derivatives (einsum, np.add.at, the section law in numpy),
    the condensed Newton step and linear solves (dense Schur complement, scipy's dense
    Cholesky), the node Jacobian and the outputs (Lagrange basis at the samples per
    call, pointwise local Newton in numpy) are the numpy originals.
    """

    def _compatible(self, other):
        return (isinstance(other, RodSolver) and other.degree == self.degree
                and np.array_equal(other.edges, self.edges))

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

    def energy(self, x, pressure, loads):
        return self._energy(self._unpack(x), pressure, self._force(loads))

    def _assemble(self, values_a):
        """Sum sum_q (v_q0 N_a + v_q1 N_a') over each element into the theta dofs, (n_theta,)."""
        rvec = (np.einsum('eq,qa->ea', values_a[..., 0], self._basis)
                + np.einsum('eq,eqa->ea', values_a[..., 1], self._dbasis))
        out = np.zeros(self.n_theta)
        np.add.at(out, self._dofs, rvec)
        return out

    def derivatives(self, x, pressure, loads):
        theta, b = self._unpack(x)
        force = self._force(loads)
        th, kap = self._point_fields(theta)
        w, g, h, gf, gfp, stretch = self._local(th, kap, b, pressure, force, self._qtypes)
        wt = self._weights
        energy = float((wt * w).sum())
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
        grad = np.concatenate([self._assemble(wt[..., None] * ga)[1:],
                               (wt[..., None] * gb).ravel()])
        return energy, grad, _RodHessian(th, haa, hab, hbb)

    def condensed_matrix(self, hess):
        """Return the condensed theta system K[1:, 1:] / theta_scale, dense, and hab hbb^-1."""
        hab, hbb = hess.hab, hess.hbb
        det = hbb[..., 0, 0] * hbb[..., 1, 1] - hbb[..., 0, 1] * hbb[..., 1, 0]
        if not (np.all(np.isfinite(hbb)) and np.all(det > 0.0)
                and np.all(hbb[..., 0, 0] > 0.0)):
            raise np.linalg.LinAlgError('pointwise (eps, c1) blocks not positive definite')
        inv = np.empty_like(hbb)
        inv[..., 0, 0] = hbb[..., 1, 1] / det
        inv[..., 1, 1] = hbb[..., 0, 0] / det
        inv[..., 0, 1] = -hbb[..., 0, 1] / det
        inv[..., 1, 0] = -hbb[..., 1, 0] / det
        wt = self._weights
        hab_inv = np.einsum('...ij,...jk->...ik', hab, inv)
        schur = hess.haa - np.einsum('...ij,...kj->...ik', hab_inv, hab)
        nb, db = self._basis, self._dbasis                              # (Q, a), (E, Q, a)
        kmat = (np.einsum('eq,qa,qb->eab', wt * schur[..., 0, 0], nb, nb)
                + np.einsum('eq,qa,eqb->eab', wt * schur[..., 0, 1], nb, db)
                + np.einsum('eq,eqa,qb->eab', wt * schur[..., 1, 0], db, nb)
                + np.einsum('eq,eqa,eqb->eab', wt * schur[..., 1, 1], db, db))
        n = self.n_theta
        big = np.zeros((n, n))
        dofs = self._dofs
        np.add.at(big, (dofs[:, :, None], dofs[:, None, :]), kmat)
        return big[1:, 1:] / self._theta_scale, inv, hab_inv

    def _condensed(self, hess, rhs, mirror):
        kred, inv, hab_inv = self.condensed_matrix(hess)
        hab, wt, n = hess.hab, self._weights, self.n_theta
        r_theta = np.concatenate([[0.0], rhs[:n - 1]])
        r_b = rhs[n - 1:].reshape(hess.hbb.shape[:-1])
        # K dtheta = r_theta - sum_q B^T hab hbb^-1 r_b,q (B maps theta dofs to (theta, kappa)).
        reduced = r_theta - self._assemble(np.einsum('...ij,...j->...i', hab_inv, r_b))
        dtheta = np.zeros(n)
        positive = True
        try:
            factor = cho_factor(kred, check_finite=False)
            dtheta[1:] = cho_solve(factor, reduced[1:] / self._theta_scale, check_finite=False)
        except np.linalg.LinAlgError:
            positive = False
            if not mirror:
                dtheta[1:] = np.linalg.solve(kred, reduced[1:] / self._theta_scale)
            else:
                lam, vec = eigh(kred, check_finite=False)
                lam = np.maximum(np.abs(lam), 1e-10 * np.abs(lam).max())
                dtheta[1:] = vec @ ((vec.T @ reduced[1:] / self._theta_scale) / lam)
        dth, dkap = self._point_fields(dtheta)
        da = np.stack([dth, dkap], axis=-1)
        dbv = np.einsum('...ij,...j->...i', inv,
                        r_b / wt[..., None] - np.einsum('...ji,...j->...i', hab, da))
        return np.concatenate([dtheta[1:], dbv.ravel()]), positive

    def step(self, grad, hess):
        try:
            dx, positive = self._condensed(hess, -grad, mirror=True)
            return dx, 1.0 if positive else -1.0
        except np.linalg.LinAlgError:
            return self._full_step(grad, hess), -1.0

    def solve_linear(self, hess, rhs):
        return self._condensed(hess, rhs, mirror=False)[0]

    def node_jacobian(self, x, node):
        if node != self.tip_node:
            raise ValueError(f'RodSolver takes loads at the tip (node {self.tip_node}), '
                             f'got node {node}')
        theta, b = self._unpack(x)
        th, _ = self._point_fields(theta)
        wt = self._weights
        stretch = 1.0 + b[..., 0]
        c, s = np.cos(th), np.sin(th)
        tip = np.array([(wt * stretch * c).sum(), (wt * stretch * s).sum()])
        jac = np.zeros((2, x.size))
        for k, (dt, de) in enumerate(((-s, c), (c, s))):
            jac[k, :self.n_theta - 1] = self._assemble(
                np.stack([wt * stretch * dt, np.zeros_like(th)], axis=-1))[1:]
            local = np.zeros(th.shape + (2,))
            local[..., 0] = wt * de
            jac[k, self.n_theta - 1:] = local.ravel()
        return tip, jac

    # -- outputs ------------------------------------------------------------
    def _solve_local(self, th, kap, b0, force, types, pressure):
        """Pointwise (eps, c1) minimising W - (1 + eps) F . t at given theta, kappa."""
        problem = _PointwiseLocal(self, th, kap, force, types, pressure)
        options = NewtonOptions(xtol=1e-15, max_step=0.1, energy_scale=self._theta_scale)
        b = np.array(b0, dtype=float).reshape(-1, 2)
        return engine.newton(problem, b, pressure, [], options).x.reshape(np.shape(b0))

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
