"""The bordered Newton of constraints: displacement control, contact rows, rigidity."""

import collections

from numba.extending import overload, register_jitable
import numpy as np

from .newton import (_derivatives, _max_abs, _max_ratio, _node_jacobian, _point_derivatives,
                     _point_jacobian, _solve_linear, _step)
from ..kernels import contact as ck


# -- constraints: the rows of a bordered Newton system -----------------------------------------
# A constraint set is a namedtuple: `NodeLine` (displacement control: one node moved along a
# direction) or `ContactSet` (finger points against rigid obstacles). Each active row k has a
# value c_k (zero at the solution, c_k + E_k lambda_k with a compliance E_k), the gradient
# G_k = w_k^T J_k of c_k, and a force lambda_k d_k on the finger at its point (J_k the point's
# Jacobian), whose work borders the system with B_k = d_k^T J_k. Where d_k turns with the
# point (a curved obstacle) it adds lambda_k J_k^T (dd_k/dp) J_k = coef U_k^T V_k to the
# Hessian (rank one per row). docs/physics.md, section 15.3.
NodeLine = collections.namedtuple('NodeLine', ('node', 'direction', 'target', 'scale'))
NodeLine.__doc__ = """
Displacement control of one node: e . O_node(x) = target, the force along e its multiplier.

Attributes
----------
node : int
direction : ndarray (2,)
    Unit direction e.
target : float
    [m].
scale : float
    Length of the gap tolerance 1e-12 scale [m].
"""

ContactSet = collections.namedtuple('ContactSet', (
    'pseg', 'poff', 'pz', 'kind', 'params', 'pair_point', 'pair_object', 'status', 'anchor',
    'mu', 'compliance', 'scale'))
ContactSet.__doc__ = """
Finger points against rigid obstacles, as the engine's loops take them (internal).

Attributes
----------
pseg, poff, pz : ndarray, shape (K,)
    Candidate finger points: segment (int), reference arc length into it [m], height from
    the midplane along its normal [m] (-H/2: the PEMC face, +H/2: the CL face).
kind : ndarray of int, shape (B,)
    Obstacle kinds (`kernels.contact`).
params : ndarray, shape (B, P)
    Obstacle parameter rows, in the finger frame at the obstacle's current pose.
pair_point, pair_object : ndarray of int, shape (C,)
    Candidate (point, obstacle) pairs.
status : ndarray of int, shape (C,)
    FREE, NORMAL, STICK, SLIP_POS or SLIP_NEG of every pair; the loops update it.
anchor : ndarray, shape (C, 2)
    Where a sticking pair's point is tied [m]; for the other pairs, the obstacle point it
    would stick to if it touched during this step.
mu : float
    Coulomb coefficient (0: frictionless).
compliance : float
    1/k of a penalty surface of stiffness k [m/N]; 0 for the rigid constraint.
scale : float
    Length scale of the gap tolerances [m].
"""


def _is_line(con):
    return isinstance(con, NodeLine)


@overload(_is_line, jit_options={'nogil': True})
def _is_line_compiled(con):
    line = con.instance_class is NodeLine
    return lambda con: line


@register_jitable
def _line_rows(con, problem, x, lam, offset):
    """Row of `NodeLine`: c = e . O_node - target, w = d = e."""
    position, jacobian = _node_jacobian(problem, x, con.node)
    e0, e1 = con.direction[0], con.direction[1]
    grow = (e0 * jacobian[0] + e1 * jacobian[1]).ravel()
    n = grow.size
    c = np.full(1, e0 * position[0] + e1 * position[1] - con.target)
    rows = np.empty((1, n))
    rows[0] = grow
    point = np.zeros(1, dtype=np.int64)
    direction = np.empty((1, 2))
    direction[0, 0], direction[0, 1] = e0, e1
    return (c, np.zeros(1), rows, rows, np.empty((0, n)), np.empty((0, n)), np.empty(0),
            point, direction)


@register_jitable
def _row_count(status):
    """Rows of a status layout: one per NORMAL or SLIP pair, two per STICK pair."""
    m = 0
    for s in status:
        if s == ck.STICK:
            m += 2
        elif s != ck.FREE:
            m += 1
    return m


@register_jitable
def _contact_rows(con, problem, x, lam, offset):
    """Rows of `ContactSet` at x for its current statuses (lam: the row multipliers)."""
    n = x.size
    m = _row_count(con.status)
    curved = 0
    for j in range(con.status.size):
        s = con.status[j]
        if s == ck.NORMAL or s == ck.SLIP_POS or s == ck.SLIP_NEG:
            curved += 1
    c = np.empty(m)
    comp = np.zeros(m)
    brow = np.empty((m, n))
    grow = np.empty((m, n))
    urow = np.zeros((curved, n))
    vrow = np.zeros((curved, n))
    coef = np.zeros(curved)
    point = np.empty(m, dtype=np.int64)
    direction = np.empty((m, 2))
    r = 0
    u = 0
    for j in range(con.status.size):
        s = con.status[j]
        if s == ck.FREE:
            continue
        k = con.pair_point[j]
        b = con.pair_object[j]
        p, jac = _point_jacobian(problem, x, con.pseg[k], con.poff[k], con.pz[k])
        j0 = jac[0].ravel()
        j1 = jac[1].ravel()
        if s == ck.STICK:
            for axis in range(2):
                c[r] = p[axis] - con.anchor[j, axis]
                row = j0 if axis == 0 else j1
                brow[r] = row
                grow[r] = row
                point[r] = k
                direction[r, 0] = 1.0 if axis == 0 else 0.0
                direction[r, 1] = 1.0 - direction[r, 0]
                r += 1
            continue
        g, gx, gz, kappa, vx, vz = ck.signed_distance(con.kind[b], con.params[b], p[0],
                                                      p[1])
        sigma = 0.0
        if s == ck.SLIP_POS:
            sigma = con.mu
        elif s == ck.SLIP_NEG:
            sigma = -con.mu
        # Force on the finger lambda d, d = (I + sigma R) grad g with R the quarter turn
        # (friction mu times the normal force, along tau); the Hessian of g is kappa v v^T,
        # so dd/dp = kappa ((I + sigma R) v) v^T.
        dx, dz = gx - sigma * gz, gz + sigma * gx
        ux, uz = vx - sigma * vz, vz + sigma * vx
        c[r] = g + offset
        comp[r] = con.compliance
        # One loop for the four rows (plain loops compile faster than array expressions).
        for i in range(n):
            grow[r, i] = gx * j0[i] + gz * j1[i]
            brow[r, i] = dx * j0[i] + dz * j1[i]
            urow[u, i] = ux * j0[i] + uz * j1[i]
            vrow[u, i] = vx * j0[i] + vz * j1[i]
        coef[u] = lam[r] * kappa
        point[r] = k
        direction[r, 0], direction[r, 1] = dx, dz
        r += 1
        u += 1
    return c, comp, brow, grow, urow, vrow, coef, point, direction


def _rows(con, problem, x, lam, offset):
    """(c, E, B, G, U, V, coef, point, direction) of the active rows; see `_line_rows`."""
    if _is_line(con):
        return _line_rows(con, problem, x, lam, offset)
    return _contact_rows(con, problem, x, lam, offset)


@overload(_rows, jit_options={'nogil': True})
def _rows_compiled(con, problem, x, lam, offset):
    if con.instance_class is NodeLine:
        return lambda con, problem, x, lam, offset: _line_rows(con, problem, x, lam, offset)
    return lambda con, problem, x, lam, offset: _contact_rows(con, problem, x, lam, offset)


@register_jitable
def _line_derivatives(con, problem, x, pressure, nodes, forces, lam, point, direction):
    """Return the derivatives with the line's force lam e at its node as a node load."""
    count = nodes.size
    all_nodes = np.empty(count + 1, dtype=np.int64)
    all_forces = np.empty((count + 1, 2))
    all_nodes[:count] = nodes
    all_forces[:count] = forces
    all_nodes[count] = con.node
    all_forces[count] = lam[0] * con.direction
    return _derivatives(problem, x, pressure, all_nodes, all_forces)


@register_jitable
def _contact_derivatives(con, problem, x, pressure, nodes, forces, lam, point, direction):
    """Return the derivatives with the contact forces lam_k d_k as dead point loads."""
    pforce = np.zeros((con.pseg.size, 2))
    for r in range(lam.size):
        pforce[point[r], 0] += lam[r] * direction[r, 0]
        pforce[point[r], 1] += lam[r] * direction[r, 1]
    return _point_derivatives(problem, x, pressure, nodes, forces, con.pseg, con.poff, con.pz,
                              pforce)


def _constraint_derivatives(con, problem, x, pressure, nodes, forces, lam, point, direction):
    """Energy, gradient and Hessian of the potential with the constraint forces as loads."""
    if _is_line(con):
        return _line_derivatives(con, problem, x, pressure, nodes, forces, lam, point,
                                 direction)
    return _contact_derivatives(con, problem, x, pressure, nodes, forces, lam, point,
                                direction)


@overload(_constraint_derivatives, jit_options={'nogil': True})
def _constraint_derivatives_compiled(con, problem, x, pressure, nodes, forces, lam, point,
                                     direction):
    if con.instance_class is NodeLine:
        return lambda con, problem, x, pressure, nodes, forces, lam, point, direction: \
            _line_derivatives(con, problem, x, pressure, nodes, forces, lam, point, direction)
    return lambda con, problem, x, pressure, nodes, forces, lam, point, direction: \
        _contact_derivatives(con, problem, x, pressure, nodes, forces, lam, point, direction)


@register_jitable
def _columns(problem, hess, rows, shape):
    """Solve H y = row^T for every row: (Y (n, m), ok)."""
    m, n = rows.shape
    out = np.empty((n, m))
    for k in range(m):
        column = np.ascontiguousarray(rows[k]).reshape(shape)
        y, ok = _solve_linear(problem, hess, column)
        if not ok:
            return out, False
        out[:, k] = y.ravel()
    return out, True


def _times(rows, right):
    """Return rows @ right, rows (m, n), right (n,) or (n, k)."""
    return rows @ right


@overload(_times, jit_options={'nogil': True})
def _times_compiled(rows, right):
    # Loops, not BLAS: these products are small, and numba's BLAS bindings compile slowly.
    if right.ndim == 1:
        def vector(rows, right):
            out = np.zeros(rows.shape[0])
            for i in range(rows.shape[0]):
                for j in range(rows.shape[1]):
                    out[i] += rows[i, j] * right[j]
            return out
        return vector

    def matrix(rows, right):
        out = np.zeros((rows.shape[0], right.shape[1]))
        for i in range(rows.shape[0]):
            for j in range(rows.shape[1]):
                value = rows[i, j]
                for k in range(right.shape[1]):
                    out[i, k] += value * right[j, k]
        return out
    return matrix


@register_jitable
def _dense_solve(mat, vec):
    """Solve the small dense system mat y = vec: Gaussian elimination with partial pivoting."""
    size = vec.size
    a = mat.copy()
    y = vec.copy()
    scale = 0.0
    for value in a.flat:
        scale = max(scale, abs(value))
    for k in range(size):
        pivot = k
        for i in range(k + 1, size):
            if abs(a[i, k]) > abs(a[pivot, k]):
                pivot = i
        if not abs(a[pivot, k]) > 1e-14 * scale:
            return y, False
        if pivot != k:
            for j in range(size):
                a[k, j], a[pivot, j] = a[pivot, j], a[k, j]
            y[k], y[pivot] = y[pivot], y[k]
        for i in range(k + 1, size):
            factor = a[i, k] / a[k, k]
            for j in range(k, size):
                a[i, j] -= factor * a[k, j]
            y[i] -= factor * y[k]
    for k in range(size - 1, -1, -1):
        total = y[k]
        for j in range(k + 1, size):
            total -= a[k, j] * y[j]
        y[k] = total / a[k, k]
    return y, True


@register_jitable
def _positive_definite(mat):
    """Whether the symmetric part of a small matrix is positive definite (Cholesky)."""
    size = mat.shape[0]
    low = np.zeros((size, size))
    for j in range(size):
        total = mat[j, j]
        for k in range(j):
            total -= low[j, k] * low[j, k]
        if not total > 0.0:
            return False
        low[j, j] = np.sqrt(total)
        for i in range(j + 1, size):
            value = 0.5 * (mat[i, j] + mat[j, i])
            for k in range(j):
                value -= low[i, k] * low[j, k]
            low[i, j] = value / low[j, j]
    return True


@register_jitable
def _bordered_step(con, problem, hess, residual, c, comp, lam, brow, grow, urow, vrow, coef):
    """
    Newton step (dx, dlam) of the bordered system, by H^-1 and a small dense solve.

        (H - U^T diag(coef) V) dx - B^T dlam = -r,    G dx + E dlam = -(c + E lam)

    H is applied through `_solve_linear` only (the discretisation's own factor: banded for
    the PCC): dx = a + Y_B dlam + Y_U y with a = -H^-1 r, Y = H^-1 (rows)^T and
    y = diag(coef) V dx as extra unknowns (so no division by coef), and `_schur` solves
    the small system for (y, dlam). Returns (dx (n,), dlam (m,), ok).
    """
    shape = residual.shape
    a, ok = _solve_linear(problem, hess, -residual)
    a = a.ravel()
    if not ok:
        return a, np.zeros(c.size), False
    yb, ok = _columns(problem, hess, brow, shape)
    if not ok:
        return a, np.zeros(c.size), False
    return _schur(con, problem, hess, shape, a, yb, c, comp, lam, grow, urow, vrow, coef)


@register_jitable
def _schur_line(con, problem, hess, shape, a, yb, c, comp, lam, grow, urow, vrow, coef):
    """`_schur` of one straight row (displacement control): the complement is a number."""
    rhs = -(c[0] + comp[0] * lam[0])
    ga = 0.0
    gy = 0.0
    for i in range(a.size):
        ga += grow[0, i] * a[i]
        gy += grow[0, i] * yb[i, 0]
    denominator = gy + comp[0]
    if not (np.isfinite(denominator) and denominator != 0.0):
        return a, np.zeros(1), False
    dlam = np.full(1, (rhs - ga) / denominator)
    return a + yb[:, 0] * dlam[0], dlam, True


@register_jitable
def _schur_contact(con, problem, hess, shape, a, yb, c, comp, lam, grow, urow, vrow, coef):
    """`_schur` of contact rows: the (q + m) system in (y, dlam), dense elimination."""
    m = c.size
    q = coef.size
    yu, ok = _columns(problem, hess, urow, shape)
    if not ok:
        return a, np.zeros(m), False
    size = q + m
    if size == 0:
        return a, np.zeros(0), True
    mat = np.zeros((size, size))
    vec = np.empty(size)
    ga = _times(grow, a)
    gb = _times(grow, yb)
    va = _times(vrow, a)
    vu = _times(vrow, yu)
    vb = _times(vrow, yb)
    gu = _times(grow, yu)
    for i in range(q):
        vec[i] = coef[i] * va[i]
        for k in range(q):
            mat[i, k] = (1.0 if i == k else 0.0) - coef[i] * vu[i, k]
        for k in range(m):
            mat[i, q + k] = -coef[i] * vb[i, k]
    for i in range(m):
        vec[q + i] = -(c[i] + comp[i] * lam[i]) - ga[i]
        for k in range(q):
            mat[q + i, k] = gu[i, k]
        for k in range(m):
            mat[q + i, q + k] = gb[i, k] + (comp[i] if i == k else 0.0)
    sol, ok = _dense_solve(mat, vec)
    if not ok:
        return a, np.zeros(m), False
    dx = a.copy()
    for i in range(dx.size):
        for k in range(m):
            dx[i] += yb[i, k] * sol[q + k]
        for k in range(q):
            dx[i] += yu[i, k] * sol[k]
    return dx, sol[q:].copy(), np.isfinite(_max_abs(sol))


def _schur(con, problem, hess, shape, a, yb, c, comp, lam, grow, urow, vrow, coef):
    """Solve the bordered system's small part: (dx, dlam, ok); see `_bordered_step`."""
    if _is_line(con):
        return _schur_line(con, problem, hess, shape, a, yb, c, comp, lam, grow, urow, vrow,
                           coef)
    return _schur_contact(con, problem, hess, shape, a, yb, c, comp, lam, grow, urow, vrow,
                          coef)


@overload(_schur, jit_options={'nogil': True})
def _schur_compiled(con, problem, hess, shape, a, yb, c, comp, lam, grow, urow, vrow, coef):
    impl = _schur_line if con.instance_class is NodeLine else _schur_contact
    return lambda con, problem, hess, shape, a, yb, c, comp, lam, grow, urow, vrow, coef: \
        impl(con, problem, hess, shape, a, yb, c, comp, lam, grow, urow, vrow, coef)


@register_jitable
def _kkt(con, problem, x, lam, pressure, nodes, forces, offset):
    """Rows of `con` and the derivatives with their forces, at (x, lam)."""
    c, comp, brow, grow, urow, vrow, coef, point, direction = _rows(con, problem, x, lam,
                                                                    offset)
    _, residual, hess = _constraint_derivatives(con, problem, x, pressure, nodes, forces, lam,
                                                point, direction)
    return c, comp, brow, grow, urow, vrow, coef, residual, hess


def _merit(residual, c, comp, lam, scale, length):
    """Squared norm of the bordered system's residual, made dimensionless."""
    return float(np.sum((residual / scale) ** 2) + np.sum(((c + comp * lam) / length) ** 2))


@overload(_merit, jit_options={'nogil': True})
def _merit_compiled(residual, c, comp, lam, scale, length):
    def impl(residual, c, comp, lam, scale, length):
        out = 0.0
        for value in residual.flat:
            out += (value / scale) ** 2
        for k in range(c.size):
            out += ((c[k] + comp[k] * lam[k]) / length) ** 2
        return out
    return impl


@register_jitable
def _full_step(con, problem, x, lam, dx, dlam, before, pressure, nodes, forces, offset,
               scale):
    """`_advance` of displacement control: the whole Newton step."""
    x = x + dx
    lam = lam + dlam
    return (x, lam, True) + _kkt(con, problem, x, lam, pressure, nodes, forces, offset)


@register_jitable
def _backtracked(con, problem, x, lam, dx, dlam, before, pressure, nodes, forces, offset,
                 scale):
    """`_advance` of contact: the step halved (down to 2^-10) until the merit falls."""
    alpha = 1.0
    while True:
        x_try = x + alpha * dx
        lam_try = lam + alpha * dlam
        out = _kkt(con, problem, x_try, lam_try, pressure, nodes, forces, offset)
        if _merit(out[7], out[0], out[1], lam_try, scale, con.scale) \
                <= (1.0 - 1e-4 * alpha) * before:
            return (x_try, lam_try, True) + out
        alpha *= 0.5
        if alpha < 1.0 / 1024:
            return (x, lam, False) + out


def _advance(con, problem, x, lam, dx, dlam, before, pressure, nodes, forces, offset, scale):
    """Take a Newton step: (x, lam, ok) and `_kkt` at the new point."""
    if _is_line(con):
        return _full_step(con, problem, x, lam, dx, dlam, before, pressure, nodes, forces,
                          offset, scale)
    return _backtracked(con, problem, x, lam, dx, dlam, before, pressure, nodes, forces,
                        offset, scale)


@overload(_advance, jit_options={'nogil': True})
def _advance_compiled(con, problem, x, lam, dx, dlam, before, pressure, nodes, forces, offset,
                      scale):
    impl = _full_step if con.instance_class is NodeLine else _backtracked
    return lambda con, problem, x, lam, dx, dlam, before, pressure, nodes, forces, offset, \
        scale: impl(con, problem, x, lam, dx, dlam, before, pressure, nodes, forces, offset,
                    scale)


@register_jitable
def _constrained_newton(problem, x, lam, pressure, nodes, forces, con, offset, options, cap):
    """
    Newton on the bordered system of the active rows of `con`: (x, lam, ok, iterations).

    The state x and the row multipliers lam solve grad Pi(x; loads, lam_k d_k at the
    points) = 0 and c_k(x) + E_k lam_k = 0 (c shifted by `offset` for obstacles). A step
    above the cap is a failure, which the caller meets by a smaller increment. For
    contact the step is backtracked (halved, down to 2^-10) until the residual's norm
    falls (`_advance`): full steps can cycle where an obstacle's curvature changes fast.
    Displacement control takes full steps. Converged when the last step is <= xtol, the
    relative residual <= gtol and every |c + E lam| <= 1e-12 scale [m].
    """
    max_iterations, gtol, xtol, _, _, _, scale = options
    c, comp, brow, grow, urow, vrow, coef, residual, hess = _kkt(con, problem, x, lam,
                                                                 pressure, nodes, forces,
                                                                 offset)
    for iteration in range(1, max_iterations + 1):
        dx, dlam, ok = _bordered_step(con, problem, hess, residual, c, comp, lam, brow, grow,
                                      urow, vrow, coef)
        if not ok:
            return x, lam, False, iteration
        dx = dx.reshape(x.shape)
        step = _max_abs(dx)
        if not np.isfinite(step):
            return x, lam, False, iteration
        if _max_ratio(dx, cap) > 1.0:
            return x, lam, False, iteration
        gap = 0.0
        for k in range(c.size):
            gap = max(gap, abs(c[k] + comp[k] * lam[k]))
        balanced = not np.isfinite(gtol) or _max_abs(residual) / scale <= gtol
        if balanced and step <= xtol and gap <= 1e-12 * con.scale:
            return x + dx, lam + dlam, True, iteration
        before = _merit(residual, c, comp, lam, scale, con.scale)
        x, lam, ok, c, comp, brow, grow, urow, vrow, coef, residual, hess = _advance(
            con, problem, x, lam, dx, dlam, before, pressure, nodes, forces, offset, scale)
        if not ok:
            return x, lam, False, iteration
    return x, lam, False, max_iterations


@register_jitable
def _bordered_newton(problem, x, force, pressure, node, direction, target, options, cap):
    """Solve grad Pi(x; f e) = 0 and e . O_node(x) = target for (x, f): (x, f, ok, its)."""
    line = NodeLine(node, direction, target, max(abs(target), 1e-3))
    nodes = np.zeros(0, dtype=np.int64)
    forces = np.zeros((0, 2))
    x, lam, ok, iterations = _constrained_newton(problem, x, np.full(1, force), pressure,
                                                 nodes, forces, line, 0.0, options, cap)
    return x, lam[0], ok, iterations


@register_jitable
def _rigidity(problem, x, pressure, node, direction, displacement, options, cap):
    """Displacement control: (x, force, success, its, fraction, stable, gradient)."""
    force = 0.0
    position = _node_jacobian(problem, x, node)[0]
    start = direction[0] * position[0] + direction[1] * position[1]
    done = 0.0
    iterations = 0
    increment = 1.0
    while done < 1.0:
        goal = min(1.0, done + increment)
        x_new, f_new, ok, its = _bordered_newton(problem, x, force, pressure, node, direction,
                                                 start + goal * displacement, options, cap)
        iterations += its
        if ok:
            x, force, done = x_new, f_new, goal
            increment = min(1.0, 2.0 * increment)
        else:
            increment *= 0.5
            if increment < 1.0 / 64:
                return x, force, False, iterations, done, False, np.inf
    nodes = np.full(1, node)
    forces = (force * direction).reshape(1, 2)
    _, grad, hess = _derivatives(problem, x, pressure, nodes, forces)
    min_eig = _step(problem, grad, hess)[1]
    return x, force, True, iterations, 1.0, min_eig > 0.0, np.abs(grad).max() / options[6]
