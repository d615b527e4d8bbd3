"""Compiled (numba) kernels of the spectral-element rod: energy, derivatives, condensed steps."""

import math

import numpy as np

from .linear import banded_cholesky, cholesky_solve
from .pcc_section import _section_energy, _section_slopes
from ..compiled import jit

__all__ = ['energy_kernel', 'derivatives_kernel', 'newton_step_kernel', 'condense_kernel',
           'reduced_rhs_kernel', 'expand_kernel', 'condensed_solve_kernel',
           'node_jacobian_kernel', 'local_energy_kernel', 'local_derivatives_kernel',
           'local_step_kernel', 'sample_fields_kernel', 'sample_points_kernel']

# Built at install (`compiled`), once per argument types; nogil lets a caller thread them.
_jit = jit

# Array convention of every kernel (E elements, Q Gauss points each, degree p):
#   basis (Q, p + 1)        N_a at the Gauss points of the reference element [-]
#   dbasis (E, Q, p + 1)    N_a' = dN_a/ds on every element [1/m]
#   weights (E, Q)          Gauss weights times the half element length [m]
#   stiffness, gas, pemc    pcc_kernels.section_arrays of the element types
#   x (n_theta - 1 + 2 E Q) engine unknowns: theta at nodes 1 .. E p (theta_0 = 0 is
#                           clamped), then (eps, c1) at point (e, q) at n_theta - 1 + 2 (e Q + q)
# Element e holds the nodes e p .. e p + p.


@_jit
def _element_theta(x, e, degree, te):
    """Fill te (p + 1,) with the nodal theta of element e (theta_0 = 0) [rad]."""
    first = e * degree
    for a in range(degree + 1):
        dof = first + a
        te[a] = 0.0 if dof == 0 else x[dof - 1]


@_jit
def _point_fields(te, basis, dbasis, e, q):
    """Return (theta [rad], kappa [1/m]) at point (e, q) from the element's nodal theta."""
    th = 0.0
    kap = 0.0
    for a in range(te.size):
        th += basis[q, a] * te[a]
        kap += dbasis[e, q, a] * te[a]
    return th, kap


@_jit
def _point_energy(stiffness, gas, pemc, e, th, kap, eps, c1, work, force):
    """W(eps, kappa, c1) - (1 + eps) F . t(theta) at one point [J/m]."""
    along = force[0] * math.cos(th) + force[1] * math.sin(th)
    return _section_energy(stiffness, gas, pemc, e, eps, kap, c1, work) - (1.0 + eps) * along


# -- total potential ------------------------------------------------------------------------
@_jit
def energy_kernel(x, basis, dbasis, weights, stiffness, gas, pemc, work, force):
    """
    Total potential of the rod [J].

    Pi = sum_e sum_q w_eq (W(eps, theta', c1; k_p P) - (1 + eps) F . (cos, sin) theta)
    at the Gauss points, theta = sum_a N_a theta_a on every element.

    Parameters
    ----------
    x : ndarray, shape (n_theta - 1 + 2 E Q,)
        Engine unknowns (see the module's array convention) [rad, -].
    basis, dbasis, weights, stiffness, gas, pemc : ndarray
        See the module's array convention.
    work : float
        k_p P [Pa].
    force : ndarray, shape (2,)
        Tip force (F_X, F_Z) [N].

    References
    ----------
    docs/physics.md, section 11.4.

    """
    n_el, n_q = weights.shape
    degree = basis.shape[1] - 1
    offset = n_el * degree
    te = np.empty(degree + 1)
    total = 0.0
    for e in range(n_el):
        _element_theta(x, e, degree, te)
        for q in range(n_q):
            th, kap = _point_fields(te, basis, dbasis, e, q)
            k = offset + 2 * (e * n_q + q)
            total += weights[e, q] * _point_energy(stiffness, gas, pemc, e, th, kap, x[k],
                                                   x[k + 1], work, force)
    return total


@_jit
def derivatives_kernel(x, basis, dbasis, weights, stiffness, gas, pemc, work, force,
                       theta_scale):
    """
    Energy, gradient and pointwise Hessian blocks of the rod, and the condensed Newton step.

    At every point the density depends on a = (theta, kappa) and b = (eps, c1); its
    Hessian is the blocks haa, hab, hbb (haa[0, 1] = hab[0, 1] = 0). The gradient in the
    theta dofs is sum_q w (g_theta N_a + g_kappa N_a'), in b it is w g_b.

    Parameters
    ----------
    x, basis, dbasis, weights, stiffness, gas, pemc, work, force
        As `energy_kernel`.
    theta_scale : float
        Scale of the condensed system [J] (see `condense_kernel`).

    Returns
    -------
    energy : float
        [J], equal to `energy_kernel`'s.
    gradient : ndarray, shape like x
        [J].
    theta : ndarray, shape (E, Q)
        theta at the points [rad].
    haa, hab, hbb : ndarray, shape (E, Q, 2, 2)
        Hessian blocks of the density per unit length.
    local, inv, hab_inv, lower, factor, definite, step
        `newton_step_kernel` of these blocks and the gradient.

    References
    ----------
    docs/physics.md, section 11.4.

    """
    n_el, n_q = weights.shape
    degree = basis.shape[1] - 1
    offset = n_el * degree
    grad = np.zeros(x.size)
    theta = np.empty((n_el, n_q))
    haa = np.zeros((n_el, n_q, 2, 2))
    hab = np.zeros((n_el, n_q, 2, 2))
    hbb = np.empty((n_el, n_q, 2, 2))
    te = np.empty(degree + 1)
    g = np.empty(3)
    h = np.empty((3, 3))
    total = 0.0
    for e in range(n_el):
        _element_theta(x, e, degree, te)
        first = e * degree
        for q in range(n_q):
            th, kap = _point_fields(te, basis, dbasis, e, q)
            k = offset + 2 * (e * n_q + q)
            eps, c1 = x[k], x[k + 1]
            wt = weights[e, q]
            total += wt * _point_energy(stiffness, gas, pemc, e, th, kap, eps, c1, work, force)
            _section_slopes(stiffness, gas, pemc, e, eps, kap, c1, work, g, h)
            cs, sn = math.cos(th), math.sin(th)
            along = force[0] * cs + force[1] * sn              # F . t
            normal = -force[0] * sn + force[1] * cs            # F . n = d(F . t)/d theta
            stretch = 1.0 + eps
            g_th, g_kap = -stretch * normal, g[1]
            for a in range(degree + 1):
                dof = first + a
                if dof > 0:
                    grad[dof - 1] += wt * (g_th * basis[q, a] + g_kap * dbasis[e, q, a])
            grad[k] = wt * (g[0] - along)
            grad[k + 1] = wt * g[2]
            theta[e, q] = th
            haa[e, q, 0, 0] = stretch * along
            haa[e, q, 1, 1] = h[1, 1]
            hab[e, q, 0, 0] = -normal
            hab[e, q, 1, 0] = h[1, 0]
            hab[e, q, 1, 1] = h[1, 2]
            hbb[e, q, 0, 0] = h[0, 0]
            hbb[e, q, 0, 1] = h[0, 2]
            hbb[e, q, 1, 0] = h[2, 0]
            hbb[e, q, 1, 1] = h[2, 2]
    # The engine's next call is the Newton step with this Hessian: condense and factorise it
    # here, once for the step and the bordered solves.
    local, inv, hab_inv, lower, factor, definite, step = newton_step_kernel(
        grad, haa, hab, hbb, weights, basis, dbasis, theta_scale)
    return (total, grad, theta, haa, hab, hbb, local, inv, hab_inv, lower, factor, definite,
            step)


# -- the Newton system, (eps, c1) condensed point by point -------------------------------------
@_jit
def condense_kernel(haa, hab, hbb, weights, basis, dbasis, theta_scale):
    """
    Condense (eps, c1) point by point: the banded theta system K of the Schur complement.

    With B mapping the theta dofs to (theta, kappa) at a point, the full Newton system
    [[sum w B^T haa B, sum w B^T hab], [w hab^T B, w hbb]] reduces to
    K = sum_q w B^T (haa - hab hbb^-1 hab^T) B in the theta dofs, banded with
    half-bandwidth p (neighbouring elements share one node).

    Parameters
    ----------
    haa, hab, hbb : ndarray, shape (E, Q, 2, 2)
        Pointwise Hessian blocks (`derivatives_kernel`).
    weights, basis, dbasis : ndarray
        See the module's array convention.
    theta_scale : float
        K is returned divided by it [J].

    Returns
    -------
    local : bool
        Every hbb is finite and positive definite; nothing else is meaningful otherwise.
    inv, hab_inv : ndarray, shape (E, Q, 2, 2)
        hbb^-1 and hab hbb^-1.
    lower : ndarray, shape (p + 1, n_theta - 1)
        lower[d, k] = K[k + d + 1, k + 1] / theta_scale, theta_0 (clamped) left out.

    """
    n_el, n_q = weights.shape
    degree = basis.shape[1] - 1
    inv = np.empty((n_el, n_q, 2, 2))
    hab_inv = np.empty((n_el, n_q, 2, 2))
    lower = np.zeros((degree + 1, n_el * degree))
    for e in range(n_el):
        for q in range(n_q):
            h00, h01, h10, h11 = hbb[e, q, 0, 0], hbb[e, q, 0, 1], hbb[e, q, 1, 0], \
                hbb[e, q, 1, 1]
            det = h00 * h11 - h01 * h10
            if not (math.isfinite(h00) and math.isfinite(h01) and math.isfinite(h10)
                    and math.isfinite(h11) and det > 0.0 and h00 > 0.0):
                return False, inv, hab_inv, lower
            inv[e, q, 0, 0] = h11 / det
            inv[e, q, 1, 1] = h00 / det
            inv[e, q, 0, 1] = -h01 / det
            inv[e, q, 1, 0] = -h10 / det
            for i in range(2):
                for j in range(2):
                    hab_inv[e, q, i, j] = (hab[e, q, i, 0] * inv[e, q, 0, j]
                                           + hab[e, q, i, 1] * inv[e, q, 1, j])
    element = np.empty((degree + 1, degree + 1))
    schur = np.empty((2, 2))
    u = np.empty(degree + 1)
    v = np.empty(degree + 1)
    for e in range(n_el):
        element[:] = 0.0
        for q in range(n_q):
            wt = weights[e, q]
            for i in range(2):
                for k in range(2):
                    coupled = (hab_inv[e, q, i, 0] * hab[e, q, k, 0]
                               + hab_inv[e, q, i, 1] * hab[e, q, k, 1])
                    schur[i, k] = wt * (haa[e, q, i, k] - coupled)
            # B_a^T S B_b = u_a N_b + v_a N_b' with (u_a, v_a) = (N_a, N_a') S.
            for a in range(degree + 1):
                u[a] = schur[0, 0] * basis[q, a] + schur[1, 0] * dbasis[e, q, a]
                v[a] = schur[0, 1] * basis[q, a] + schur[1, 1] * dbasis[e, q, a]
            for a in range(degree + 1):
                ua, va = u[a], v[a]
                for b in range(a + 1):
                    element[a, b] += ua * basis[q, b] + va * dbasis[e, q, b]
        first = e * degree
        for a in range(degree + 1):
            for b in range(a + 1):
                if first + b > 0:
                    lower[a - b, first + b - 1] += element[a, b]
    for d in range(degree + 1):
        for k in range(lower.shape[1]):
            lower[d, k] /= theta_scale
    return True, inv, hab_inv, lower


@_jit
def reduced_rhs_kernel(rhs, hab_inv, basis, dbasis, theta_scale):
    """
    Right-hand side of the condensed system: (r_theta - sum_q B^T hab hbb^-1 r_b) / scale.

    Parameters
    ----------
    rhs : ndarray, shape like the engine unknowns
        Full right-hand side [J].
    hab_inv : ndarray, shape (E, Q, 2, 2)
        hab hbb^-1 (`condense_kernel`).
    basis, dbasis : ndarray
        See the module's array convention.
    theta_scale : float
        [J].

    Returns
    -------
    ndarray, shape (n_theta - 1,)

    """
    n_el, n_q = hab_inv.shape[0], hab_inv.shape[1]
    degree = basis.shape[1] - 1
    offset = n_el * degree
    out = rhs[:offset].copy()
    for e in range(n_el):
        first = e * degree
        for q in range(n_q):
            k = offset + 2 * (e * n_q + q)
            v0 = hab_inv[e, q, 0, 0] * rhs[k] + hab_inv[e, q, 0, 1] * rhs[k + 1]
            v1 = hab_inv[e, q, 1, 0] * rhs[k] + hab_inv[e, q, 1, 1] * rhs[k + 1]
            for a in range(degree + 1):
                dof = first + a
                if dof > 0:
                    out[dof - 1] -= v0 * basis[q, a] + v1 * dbasis[e, q, a]
    for j in range(offset):
        out[j] /= theta_scale
    return out


@_jit
def expand_kernel(dtheta, rhs, inv, hab, weights, basis, dbasis):
    """
    Full solution from the condensed one: db = hbb^-1 (r_b / w - hab^T (dtheta, dkappa)).

    Parameters
    ----------
    dtheta : ndarray, shape (n_theta - 1,)
        Solution in the theta dofs 1 .. E p.
    rhs : ndarray, shape like the engine unknowns
        The full right-hand side.
    inv, hab : ndarray, shape (E, Q, 2, 2)
        hbb^-1 and hab.
    weights, basis, dbasis : ndarray
        See the module's array convention.

    Returns
    -------
    ndarray, shape like rhs

    """
    n_el, n_q = weights.shape
    degree = basis.shape[1] - 1
    offset = n_el * degree
    out = np.empty(rhs.size)
    out[:offset] = dtheta
    te = np.empty(degree + 1)
    for e in range(n_el):
        _element_theta(dtheta, e, degree, te)
        for q in range(n_q):
            dth, dkap = _point_fields(te, basis, dbasis, e, q)
            k = offset + 2 * (e * n_q + q)
            wt = weights[e, q]
            r0 = rhs[k] / wt - (hab[e, q, 0, 0] * dth + hab[e, q, 1, 0] * dkap)
            r1 = rhs[k + 1] / wt - (hab[e, q, 0, 1] * dth + hab[e, q, 1, 1] * dkap)
            out[k] = inv[e, q, 0, 0] * r0 + inv[e, q, 0, 1] * r1
            out[k + 1] = inv[e, q, 1, 0] * r0 + inv[e, q, 1, 1] * r1
    return out


@_jit
def condensed_solve_kernel(factor, rhs, inv, hab, hab_inv, weights, basis, dbasis,
                           theta_scale):
    """Solve the full Newton system H x = rhs given the Cholesky factor of the condensed K."""
    reduced = reduced_rhs_kernel(rhs, hab_inv, basis, dbasis, theta_scale)
    return expand_kernel(cholesky_solve(factor, reduced), rhs, inv, hab, weights, basis,
                         dbasis)


@_jit
def newton_step_kernel(grad, haa, hab, hbb, weights, basis, dbasis, theta_scale):
    """
    Condensed Newton step -H^-1 g by banded Cholesky of K (half-bandwidth p).

    Returns
    -------
    local, inv, hab_inv, lower
        `condense_kernel`.
    factor : ndarray, shape (p + 1, n_theta - 1)
        Cholesky factor of K / theta_scale (reused by linear solves with the same H).
    definite : bool
        `local` and K positive definite: H is positive definite.
    step : ndarray, shape like grad
        -H^-1 g; meaningless unless `definite`.

    """
    local, inv, hab_inv, lower = condense_kernel(haa, hab, hbb, weights, basis, dbasis,
                                                 theta_scale)
    if not local:
        return local, inv, hab_inv, lower, lower, False, -grad
    factor, definite = banded_cholesky(lower)
    if not definite:
        return local, inv, hab_inv, lower, factor, False, -grad
    step = condensed_solve_kernel(factor, -grad, inv, hab, hab_inv, weights, basis, dbasis,
                                  theta_scale)
    return local, inv, hab_inv, lower, factor, True, step


# -- kinematics ------------------------------------------------------------------------------
@_jit
def node_jacobian_kernel(x, basis, weights):
    """
    Tip position r(L) = sum_eq w (1 + eps) (cos, sin) theta [m] and its derivatives in x.

    Returns
    -------
    tip : ndarray, shape (2,)
        [m].
    jacobian : ndarray, shape (2, x.size)
        [m] per radian or unit strain.

    """
    n_el, n_q = weights.shape
    degree = basis.shape[1] - 1
    offset = n_el * degree
    tip = np.zeros(2)
    jac = np.zeros((2, x.size))
    te = np.empty(degree + 1)
    for e in range(n_el):
        _element_theta(x, e, degree, te)
        first = e * degree
        for q in range(n_q):
            th = 0.0
            for a in range(degree + 1):
                th += basis[q, a] * te[a]
            k = offset + 2 * (e * n_q + q)
            wt = weights[e, q]
            stretch = 1.0 + x[k]
            cs, sn = math.cos(th), math.sin(th)
            tip[0] += wt * stretch * cs
            tip[1] += wt * stretch * sn
            for a in range(degree + 1):
                dof = first + a
                if dof > 0:
                    jac[0, dof - 1] += wt * stretch * -sn * basis[q, a]
                    jac[1, dof - 1] += wt * stretch * cs * basis[q, a]
            jac[0, k] = wt * cs
            jac[1, k] = wt * sn
    return tip, jac


# -- outputs: (eps, c1) in local equilibrium at given (theta, kappa) ---------------------------
@_jit
def sample_fields_kernel(x, n_q, values, derivs, half, element, force):
    """
    Fields at K sample points, and the start of their local equilibrium.

    Parameters
    ----------
    x : ndarray
        Engine unknowns (see the module's array convention).
    n_q : int
        Gauss points Q per element.
    values, derivs : ndarray, shape (K, p + 1)
        N_a and dN_a/dxi at the points.
    half : ndarray, shape (K,)
        Half length of every point's element [m].
    element : ndarray of int64, shape (K,)
        Element of every point.
    force : ndarray, shape (2,)
        Tip load (F_X, F_Z) [N].

    Returns
    -------
    theta, kappa, along : ndarray, shape (K,)
        theta [rad], kappa [1/m] and F . t [N].
    start : ndarray, shape (K, 2)
        (eps, c1) averaged over the Gauss points of the point's element.

    """
    m = element.size
    degree = values.shape[1] - 1
    offset = x.size // (degree + 2 * n_q) * degree
    th = np.empty(m)
    kap = np.empty(m)
    along = np.empty(m)
    start = np.empty((m, 2))
    te = np.empty(degree + 1)
    for k in range(m):
        e = element[k]
        _element_theta(x, e, degree, te)
        t = 0.0
        d = 0.0
        for a in range(degree + 1):
            t += values[k, a] * te[a]
            d += derivs[k, a] * te[a]
        th[k] = t
        kap[k] = d / half[k]
        along[k] = force[0] * math.cos(t) + force[1] * math.sin(t)
        eps = 0.0
        c1 = 0.0
        for q in range(n_q):
            j = offset + 2 * (e * n_q + q)
            eps += x[j]
            c1 += x[j + 1]
        start[k, 0] = eps / n_q
        start[k, 1] = c1 / n_q
    return th, kap, along, start


@_jit
def sample_points_kernel(x, local, th, basis, weights, sample_element, sample_weights):
    """
    Element ends and sample positions of a solved rod [m].

    Parameters
    ----------
    x, basis, weights : ndarray
        See the module's array convention.
    local : ndarray, shape (M, Q + 1, 2)
        (eps, c1) at every sample and at Q Gauss points from its element's start to it.
    th : ndarray, shape (M, Q + 1)
        theta at the same points [rad].
    sample_element : ndarray of int64, shape (M,)
        Element of every sample.
    sample_weights : ndarray, shape (M, Q)
        Gauss weights of that rule [m].

    Returns
    -------
    nodes : ndarray, shape (E + 1, 2)
        r at the element ends, the clamp first [m].
    points : ndarray, shape (M, 2)
        r at the samples: the element start plus the rule's sum of (1 + eps) t; the last
        is the tip [m].

    """
    n_el, n_q = weights.shape
    degree = basis.shape[1] - 1
    offset = n_el * degree
    nodes = np.zeros((n_el + 1, 2))
    te = np.empty(degree + 1)
    for e in range(n_el):
        _element_theta(x, e, degree, te)
        cx = 0.0
        cz = 0.0
        for q in range(n_q):
            t = 0.0
            for a in range(degree + 1):
                t += basis[q, a] * te[a]
            reach = weights[e, q] * (1.0 + x[offset + 2 * (e * n_q + q)])
            cx += reach * math.cos(t)
            cz += reach * math.sin(t)
        nodes[e + 1, 0] = nodes[e, 0] + cx
        nodes[e + 1, 1] = nodes[e, 1] + cz
    m = sample_element.size
    points = np.empty((m, 2))
    for k in range(m):
        px = nodes[sample_element[k], 0]
        pz = nodes[sample_element[k], 1]
        for j in range(sample_weights.shape[1]):
            reach = sample_weights[k, j] * (1.0 + local[k, j + 1, 0])
            px += reach * math.cos(th[k, j + 1])
            pz += reach * math.sin(th[k, j + 1])
        points[k, 0] = px
        points[k, 1] = pz
    points[m - 1, 0], points[m - 1, 1] = nodes[n_el, 0], nodes[n_el, 1]
    return nodes, points


@_jit
def local_energy_kernel(b, kap, along, element, stiffness, gas, pemc, work):
    """
    Sum over K points of W(eps, kappa, c1) - (1 + eps) F . t at b = (eps, c1), (K, 2).

    kap (K,) is kappa [1/m], along (K,) the load along the tangent F . t [N] (fixed while
    b changes), element (K,) the element of every point.
    """
    total = 0.0
    for k in range(element.size):
        eps = b[k, 0]
        total += (_section_energy(stiffness, gas, pemc, element[k], eps, kap[k], b[k, 1], work)
                  - (1.0 + eps) * along[k])
    return total


@_jit
def local_derivatives_kernel(b, kap, along, element, stiffness, gas, pemc, work):
    """
    `local_energy_kernel`, its gradient in b (K, 2) and Hessian blocks (K, 2, 2).

    Every point is a problem of its own in (eps, c1): d/deps = N - F . t, d/dc1 = T.
    """
    m = element.size
    grad = np.empty((m, 2))
    hess = np.empty((m, 2, 2))
    g = np.empty(3)
    h = np.empty((3, 3))
    total = 0.0
    for k in range(m):
        e = element[k]
        eps, c1 = b[k, 0], b[k, 1]
        total += (_section_energy(stiffness, gas, pemc, e, eps, kap[k], c1, work)
                  - (1.0 + eps) * along[k])
        _section_slopes(stiffness, gas, pemc, e, eps, kap[k], c1, work, g, h)
        grad[k, 0] = g[0] - along[k]
        grad[k, 1] = g[2]
        hess[k, 0, 0] = h[0, 0]
        hess[k, 0, 1] = h[0, 2]
        hess[k, 1, 0] = h[2, 0]
        hess[k, 1, 1] = h[2, 2]
    return total, grad, hess


@_jit
def local_step_kernel(grad, hess):
    """
    Newton step -h^-1 g of (K, 2, 2) blocks by 2 x 2 Cholesky, and whether all are definite.

    The arithmetic of `kernels.newton_step_blocks` on its positive-definite path; the
    step is meaningless where a block is not positive definite (False).
    """
    m = grad.shape[0]
    step = np.empty((m, 2))
    for k in range(m):
        a00 = hess[k, 0, 0]
        if not a00 > 0.0:
            return step, False
        l00 = math.sqrt(a00)
        l10 = hess[k, 1, 0] / l00
        a11 = hess[k, 1, 1] - l10 * l10
        if not a11 > 0.0:
            return step, False
        l11 = math.sqrt(a11)
        y0 = -grad[k, 0] / l00
        y1 = (-grad[k, 1] - l10 * y0) / l11
        x1 = y1 / l11
        step[k, 0] = (y0 - l10 * x1) / l00
        step[k, 1] = x1
    return step, True
