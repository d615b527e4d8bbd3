"""The one equilibrium engine: damped Newton, continuation, the bordered Newton of constraints."""

import collections
from dataclasses import dataclass
import enum
import math
import typing

import numba
from numba import types
from numba.extending import overload, register_jitable
import numpy as np

from . import contact_kernels as ck
from . import kernels
from .compiled import jit, over_cores

__all__ = ['SolverStatus', 'NewtonOptions', 'NewtonOutcome', 'newton', 'solve', 'rigidity',
           'linear_step', 'linear_solve', 'BorderedOutcome', 'solve_batch', 'rigidity_batch',
           'BatchOutcome', 'sensitivity', 'ContactSet', 'NodeLine', 'ContactOutcome',
           'contact_solve', 'contact_step', 'contact_path', 'next_anchors']


class SolverStatus(enum.IntEnum):
    """Outcome of a solve; only SUCCESS has success=True."""

    SUCCESS = 0
    MAX_ITERATIONS = 1
    LINE_SEARCH_FAILED = 2
    NOT_FINITE = 3
    UNSTABLE = 4
    CONTINUATION_FAILED = 5


# The loops below compare plain ints: numba compiles them as constants.
_SUCCESS = int(SolverStatus.SUCCESS)
_MAX_ITERATIONS = int(SolverStatus.MAX_ITERATIONS)
_LINE_SEARCH_FAILED = int(SolverStatus.LINE_SEARCH_FAILED)
_NOT_FINITE = int(SolverStatus.NOT_FINITE)
_UNSTABLE = int(SolverStatus.UNSTABLE)
_CONTINUATION_FAILED = int(SolverStatus.CONTINUATION_FAILED)


@dataclass(frozen=True)
class NewtonOptions:
    """
    Tolerances and safeguards of the damped Newton, in a discretisation's scaled unknowns.

    Attributes
    ----------
    max_iterations : int
        Newton iterations per (sub)solve.
    gtol : float
        Largest max|gradient| / gradient_scale at convergence (inf: not checked).
    xtol : float
        Largest final Newton step, max|dx| [scaled units].
    max_step : float or ndarray
        Cap on each component of a step (broadcast to the unknowns): Newton stays local,
        where the quintic PEMC energy (unbounded below at large tension) is meaningful.
    flat_slope : float
        Near the solution the energy change is below round-off: a full step is taken
        when -slope <= flat_slope * (|E| + energy_scale).
    energy_scale : float
        Energy scale of that test [J].
    armijo : float
        Sufficient-decrease constant of the backtracking line search.

    """

    max_iterations: int = 60
    gtol: float = math.inf
    xtol: float = 1e-9
    max_step: object = 0.5
    flat_slope: float = 1e-13
    energy_scale: float = 1.0
    armijo: float = 1e-4

    def packed(self, gradient_scale, shape):
        """Return the options as the loops take them: a tuple and the step cap of `shape`."""
        cap = np.ascontiguousarray(np.broadcast_to(np.asarray(self.max_step, dtype=float),
                                                   shape))
        return (int(self.max_iterations), float(self.gtol), float(self.xtol),
                float(self.flat_slope), float(self.energy_scale), float(self.armijo),
                float(gradient_scale)), cap


class NewtonOutcome(typing.NamedTuple):
    """State and figures of one Newton run (internal: solvers build their results from it)."""

    x: np.ndarray
    status: SolverStatus
    iterations: int
    gradient: float
    step: float
    min_eig: float = math.nan
    fraction: float = 1.0


#: SolverStatus by code, without the enum's own lookup on every solve.
_STATUS = tuple(SolverStatus)


@dataclass(frozen=True)
class BorderedOutcome:
    """Loaded state of a displacement-controlled solve (internal)."""

    x: np.ndarray
    force: float
    success: bool
    iterations: int
    fraction: float
    stable: bool
    gradient: float


def linear_step(grad, hess, floor=kernels.EIGEN_FLOOR):
    """
    Newton step -H^-1 g, and the smallest eigenvalue's sign (1.0 when positive definite).

    Where H is not positive definite its eigenvalues are mirrored (|lambda|, floored at
    `floor` times the largest) so that the step still descends; the smallest eigenvalue
    is returned. H is dense (n, n), or (N, m, m) blocks for g of shape (N, m). Compiled
    (`kernels.newton_step`).
    """
    return kernels.newton_step(grad, hess, floor)


def linear_solve(hess, rhs):
    """Solve H x = rhs for a dense (n, n) or block (N, m, m) H; LinAlgError if singular."""
    if hess.ndim == 3:
        return np.linalg.solve(hess, rhs[:, :, None])[:, :, 0]
    return np.linalg.solve(hess, rhs.ravel()).reshape(rhs.shape)


# -- the discretisation interface ----------------------------------------------------------
# A discretisation is either a Python object with methods (the loops then run interpreted)
# or a namedtuple of arrays whose class carries `_kernels`, a dict of compiled functions of
# the same names taking the namedtuple first (the loops then run compiled, for that
# namedtuple type). These functions are that interface; the loops call nothing else. The
# first five serve every solve; the three `_point_*` (face points: the PCC and the rod)
# serve contact only.
def _loads(nodes, forces):
    return [(int(node), forces[k]) for k, node in enumerate(nodes)]


def _derivatives(problem, x, pressure, nodes, forces):
    """Energy [J], gradient (shape of x) and Hessian (opaque to the engine) at x."""
    return problem.derivatives(x, pressure, _loads(nodes, forces))


def _energy(problem, x, pressure, nodes, forces):
    """Total potential [J] at x."""
    return problem.energy(x, pressure, _loads(nodes, forces))


def _step(problem, grad, hess):
    """Newton step (shape of grad) and the smallest eigenvalue (1.0 when H is PD)."""
    return problem.step(grad, hess)


def _solve_linear(problem, hess, rhs):
    """Solve H x = rhs: (x, True), or (anything, False) where H is singular."""
    try:
        return problem.solve_linear(hess, rhs), True
    except np.linalg.LinAlgError:
        return rhs, False


def _node_jacobian(problem, x, node):
    """Position (2,) of a node [m] and its derivatives, shape (2,) + x.shape."""
    return problem.node_jacobian(x, node)


def _point_derivatives(problem, x, pressure, nodes, forces, pseg, poff, pz, pforce):
    """Return `_derivatives` with dead forces pforce (K, 2) at face points too."""
    return problem.point_derivatives(x, pressure, _loads(nodes, forces), pseg, poff, pz,
                                     pforce)


def _point_positions(problem, x, pseg, poff, pz):
    """Positions (K, 2) [m] of face points: segment, arc length into it [m], height [m]."""
    return problem.point_positions(x, pseg, poff, pz)


def _point_jacobian(problem, x, seg, offset, z):
    """Position (2,) of a face point [m] and its derivatives, shape (2,) + x.shape."""
    return problem.point_jacobian(x, seg, offset, z)


def _kernel(problem, name):
    """Return the compiled `name` of a namedtuple discretisation type, None for others."""
    if isinstance(problem, types.BaseNamedTuple):
        return getattr(problem.instance_class, '_kernels', {}).get(name)
    return None


@overload(_derivatives, jit_options={'nogil': True})
def _derivatives_compiled(problem, x, pressure, nodes, forces):
    kernel = _kernel(problem, 'derivatives')
    if kernel is not None:
        return lambda problem, x, pressure, nodes, forces: kernel(problem, x, pressure, nodes,
                                                                  forces)
    return None


@overload(_energy, jit_options={'nogil': True})
def _energy_compiled(problem, x, pressure, nodes, forces):
    kernel = _kernel(problem, 'energy')
    if kernel is not None:
        return lambda problem, x, pressure, nodes, forces: kernel(problem, x, pressure, nodes,
                                                                  forces)
    return None


@overload(_step, jit_options={'nogil': True})
def _step_compiled(problem, grad, hess):
    kernel = _kernel(problem, 'step')
    if kernel is not None:
        return lambda problem, grad, hess: kernel(problem, grad, hess)
    return None


@overload(_solve_linear, jit_options={'nogil': True})
def _solve_linear_compiled(problem, hess, rhs):
    kernel = _kernel(problem, 'solve_linear')
    if kernel is not None:
        return lambda problem, hess, rhs: kernel(problem, hess, rhs)
    return None


@overload(_node_jacobian, jit_options={'nogil': True})
def _node_jacobian_compiled(problem, x, node):
    kernel = _kernel(problem, 'node_jacobian')
    if kernel is not None:
        return lambda problem, x, node: kernel(problem, x, node)
    return None


@overload(_point_derivatives, jit_options={'nogil': True})
def _point_derivatives_compiled(problem, x, pressure, nodes, forces, pseg, poff, pz, pforce):
    kernel = _kernel(problem, 'point_derivatives')
    if kernel is not None:
        return lambda problem, x, pressure, nodes, forces, pseg, poff, pz, pforce: kernel(
            problem, x, pressure, nodes, forces, pseg, poff, pz, pforce)
    return None


@overload(_point_positions, jit_options={'nogil': True})
def _point_positions_compiled(problem, x, pseg, poff, pz):
    kernel = _kernel(problem, 'point_positions')
    if kernel is not None:
        return lambda problem, x, pseg, poff, pz: kernel(problem, x, pseg, poff, pz)
    return None


@overload(_point_jacobian, jit_options={'nogil': True})
def _point_jacobian_compiled(problem, x, seg, offset, z):
    kernel = _kernel(problem, 'point_jacobian')
    if kernel is not None:
        return lambda problem, x, seg, offset, z: kernel(problem, x, seg, offset, z)
    return None


# Reductions of the loops: numpy when interpreted, allocation-free loops when compiled.
def _max_abs(a):
    """Return max |a|, 0 for an empty array."""
    return float(np.abs(a).max()) if a.size else 0.0


def _max_ratio(a, cap):
    """Return max |a| / cap, cap elementwise of a's shape; 0 for an empty array."""
    return float((np.abs(a) / cap).max()) if a.size else 0.0


def _dot(a, b):
    """Return the sum of a * b over all elements."""
    return float(np.vdot(a, b))


@overload(_max_abs, jit_options={'nogil': True})
def _max_abs_compiled(a):
    def impl(a):
        out = 0.0
        for value in a.flat:
            if value != value:
                # max() would drop a NaN: the loops test this figure for finiteness.
                return np.nan
            out = max(out, abs(value))
        return out
    return impl


@overload(_max_ratio, jit_options={'nogil': True})
def _max_ratio_compiled(a, cap):
    def impl(a, cap):
        out = 0.0
        flat_cap = cap.ravel()
        k = 0
        for value in a.flat:
            out = max(out, abs(value) / flat_cap[k])
            k += 1
        return out
    return impl


@overload(_dot, jit_options={'nogil': True})
def _dot_compiled(a, b):
    def impl(a, b):
        out = 0.0
        flat_b = b.ravel()
        k = 0
        for value in a.flat:
            out += value * flat_b[k]
            k += 1
        return out
    return impl


# -- the loops: each written once, run compiled or interpreted -----------------------------
@register_jitable
def _newton(problem, x, pressure, nodes, forces, options, cap):
    """Damped Newton: (x, status, iterations, gradient, step, min_eig); see `newton`."""
    max_iterations, gtol, xtol, flat_slope, energy_scale, armijo, scale = options
    step_norm = np.inf
    grad_rel = np.inf
    energy, grad, hess = _derivatives(problem, x, pressure, nodes, forces)
    for iteration in range(1, max_iterations + 1):
        grad_rel = _max_abs(grad) / scale
        if not (np.isfinite(energy) and np.isfinite(grad_rel)):
            return x, _NOT_FINITE, iteration, grad_rel, step_norm, np.nan
        step, min_eig = _step(problem, grad, hess)
        step_norm = _max_abs(step)
        if not np.isfinite(step_norm):
            return x, _NOT_FINITE, iteration, grad_rel, step_norm, np.nan
        if grad_rel <= gtol and step_norm <= xtol:
            status = _SUCCESS if min_eig > 0.0 else _UNSTABLE
            return x + step, status, iteration, grad_rel, step_norm, min_eig
        ratio = _max_ratio(step, cap)
        if ratio > 1.0:
            step = step / ratio
        slope = _dot(grad, step)
        if not slope < 0.0:
            step = -grad / scale
            slope = -_dot(grad, grad) / scale
        trial = x + step
        e_trial, g_trial, h_trial = _derivatives(problem, trial, pressure, nodes, forces)
        flat = -slope <= flat_slope * (abs(energy) + energy_scale)
        if e_trial <= energy + armijo * slope or flat:
            x, energy, grad, hess = trial, e_trial, g_trial, h_trial
            step_norm = _max_abs(step)
            continue
        alpha = 0.5
        while True:
            trial = x + alpha * step
            if _energy(problem, trial, pressure, nodes, forces) <= energy + armijo * alpha * slope:
                break
            alpha *= 0.5
            if alpha < 1e-10:
                return x, _LINE_SEARCH_FAILED, iteration, grad_rel, step_norm, min_eig
        x = trial
        step_norm = alpha * _max_abs(step)
        energy, grad, hess = _derivatives(problem, x, pressure, nodes, forces)
    return x, _MAX_ITERATIONS, max_iterations, grad_rel, step_norm, np.nan


@register_jitable
def _solve(problem, initial, warm, flat, pressure, nodes, forces, options, cap):
    """Warm, cold, then continuation: `_newton`'s tuple and the fraction; see `solve`."""
    spent = 0
    if warm:
        x, status, its, grad, step, eig = _newton(problem, initial, pressure, nodes, forces,
                                                  options, cap)
        if status == _SUCCESS:
            return x, status, its, grad, step, eig, 1.0
        spent = its
    x, status, its, grad, step, eig = _newton(problem, flat, pressure, nodes, forces, options,
                                              cap)
    spent += its
    if status == _SUCCESS or status == _UNSTABLE:
        return x, status, spent, grad, step, eig, 1.0
    x, status, its, grad, step, eig = _newton(problem, flat, 0.0, nodes[:0], forces[:0],
                                              options, cap)
    spent += its
    if status != _SUCCESS:
        return x, _CONTINUATION_FAILED, spent, np.inf, np.inf, np.nan, 0.0
    lam = 0.0
    dlam = 0.25
    while True:
        target = min(1.0, lam + dlam)
        sub, status, its, grad, step, eig = _newton(problem, x, target * pressure, nodes,
                                                    target * forces, options, cap)
        spent += its
        if status == _SUCCESS:
            x, lam = sub, target
            dlam = min(2.0 * dlam, 1.0)
            if lam >= 1.0:
                return x, status, spent, grad, step, eig, 1.0
        else:
            dlam *= 0.5
            if dlam < 1.0 / 256:
                return x, _CONTINUATION_FAILED, spent, grad, step, np.nan, lam


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
    Obstacle kinds (`contact_kernels`).
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


# -- contact: active set, stability, cold solves by obstacle growth ---------------------------
#: Outer (active-set) iterations of one contact solve.
_MAX_ACTIVE_SET = 50
#: Gap below which a free pair is penetrating, relative to the set's length scale [-].
_GAP_TOL = 1e-10
#: Multiplier below which a pair pulls (and is released), relative to the force scale [-].
_FORCE_TOL = 1e-10
#: Penetration, relative to the length scale, that a pair released during a solve may keep
#: before it is regained (anti-cycling; 9 nm on the paper's finger) [-].
_REGAIN_TOL = 1e-7


@register_jitable
def _gather(lam_pairs, status):
    """Row multipliers of a status layout from the (C, 2) pair multipliers."""
    lam = np.empty(_row_count(status))
    r = 0
    for j in range(status.size):
        s = status[j]
        if s == ck.STICK:
            lam[r] = lam_pairs[j, 0]
            lam[r + 1] = lam_pairs[j, 1]
            r += 2
        elif s != ck.FREE:
            lam[r] = lam_pairs[j, 0]
            r += 1
    return lam


@register_jitable
def _scatter(lam, status):
    """(C, 2) pair multipliers of row multipliers: (lambda_N, 0), or (F_x, F_z) when sticking."""
    out = np.zeros((status.size, 2))
    r = 0
    for j in range(status.size):
        s = status[j]
        if s == ck.STICK:
            out[j, 0] = lam[r]
            out[j, 1] = lam[r + 1]
            r += 2
        elif s != ck.FREE:
            out[j, 0] = lam[r]
            r += 1
    return out


@register_jitable
def _pair_gaps(problem, x, con, offset):
    """Point positions (K, 2) and the shifted gap g + offset (C,) of every pair [m]."""
    positions = _point_positions(problem, x, con.pseg, con.poff, con.pz)
    gaps = np.empty(con.status.size)
    for j in range(con.status.size):
        k = con.pair_point[j]
        b = con.pair_object[j]
        gaps[j] = ck.signed_distance(con.kind[b], con.params[b], positions[k, 0],
                                     positions[k, 1])[0] + offset
    return positions, gaps


@register_jitable
def _update_status(problem, x, lam_pairs, con, offset, force_scale, released):
    """
    One active-set update after an inner solve: 1 if a status changed, else 0 (or -1).

    Penetrating free pairs are added (sliding against their motion, or frictionless); if
    none was added, pairs that pull are released; a sticking pair whose tangential force
    passes mu times its normal force slips in that force's sense; a slipping pair whose
    point moved against its friction force sticks again. With friction the incremental
    problem is not monotone: a pair may pull when it touches and penetrate when it is
    free. A pair released earlier in the same solve (`released` counts the releases)
    comes back only below -_REGAIN_TOL scale, and after its second release touching
    frictionless, after its third sticking; a fourth ends the solve (returns -1: the
    caller takes a smaller step).
    """
    positions, gaps = _pair_gaps(problem, x, con, offset)
    gap_tol = _GAP_TOL * con.scale
    force_tol = _FORCE_TOL * force_scale
    added = False
    for j in range(con.status.size):
        limit = _REGAIN_TOL * con.scale if released[j] else gap_tol
        if con.status[j] == ck.FREE and gaps[j] < -limit:
            if released[j] >= 4:
                return -1
            # A pair that closes during a step has no point to stick to yet (where its
            # path crossed the surface is unknown): it slides, against its motion along
            # the surface since the step's start (from the obstacle point nearest to where
            # it started, its anchor), and sticks from the next step on; without friction
            # or motion it touches frictionless.
            con.status[j] = ck.NORMAL
            if con.mu > 0.0:
                k = con.pair_point[j]
                b = con.pair_object[j]
                _, gx, gz, _, _, _ = ck.signed_distance(con.kind[b], con.params[b],
                                                        positions[k, 0], positions[k, 1])
                moved = (-gz * (positions[k, 0] - con.anchor[j, 0])
                         + gx * (positions[k, 1] - con.anchor[j, 1]))
                if moved > gap_tol:
                    con.status[j] = ck.SLIP_NEG
                elif moved < -gap_tol:
                    con.status[j] = ck.SLIP_POS
                if released[j] == 2:
                    con.status[j] = ck.NORMAL
                elif released[j] == 3:
                    con.status[j] = ck.STICK
            lam_pairs[j, 0] = 0.0
            lam_pairs[j, 1] = 0.0
            added = True
    if added:
        return 1
    changed = False
    for j in range(con.status.size):
        s = con.status[j]
        if s == ck.FREE:
            continue
        k = con.pair_point[j]
        b = con.pair_object[j]
        _, gx, gz, _, _, _ = ck.signed_distance(con.kind[b], con.params[b], positions[k, 0],
                                                positions[k, 1])
        size = math.hypot(gx, gz)
        nx, nz = gx / size, gz / size
        tx, tz = -nz, nx
        if s == ck.NORMAL:
            if lam_pairs[j, 0] < -force_tol:
                con.status[j] = ck.FREE
                lam_pairs[j, 0] = 0.0
                released[j] += 1
                changed = True
        elif s == ck.STICK:
            normal = lam_pairs[j, 0] * nx + lam_pairs[j, 1] * nz
            tangent = lam_pairs[j, 0] * tx + lam_pairs[j, 1] * tz
            if abs(tangent) > con.mu * normal + force_tol:
                # Outside the cone (a tie that pulls is outside too): slip first, the
                # slipping solve tells whether the pair then lifts off.
                con.status[j] = ck.SLIP_POS if tangent > 0.0 else ck.SLIP_NEG
                lam_pairs[j, 0] = max(normal, 0.0) / size
                lam_pairs[j, 1] = 0.0
                changed = True
            elif normal < -force_tol:
                con.status[j] = ck.FREE
                lam_pairs[j, 0] = 0.0
                lam_pairs[j, 1] = 0.0
                released[j] += 1
                changed = True
        else:
            sense = 1.0 if s == ck.SLIP_POS else -1.0
            normal = lam_pairs[j, 0] * size
            moved = tx * (positions[k, 0] - con.anchor[j, 0]) \
                + tz * (positions[k, 1] - con.anchor[j, 1])
            if normal < -force_tol:
                con.status[j] = ck.FREE
                lam_pairs[j, 0] = 0.0
                released[j] += 1
                changed = True
            elif sense * moved > gap_tol:
                # Friction on the finger along +sense tau means slip along -sense tau.
                con.status[j] = ck.STICK
                lam_pairs[j, 0] = normal * (nx + sense * con.mu * tx)
                lam_pairs[j, 1] = normal * (nz + sense * con.mu * tz)
                changed = True
    return 1 if changed else 0


@register_jitable
def _contact_settle(problem, x, lam_pairs, pressure, nodes, forces, con, offset, options, cap):
    """Inner bordered Newton and active-set updates until no status changes."""
    force_scale = options[6] / con.scale
    released = np.zeros(con.status.size, dtype=np.int64)
    spent = 0
    for _ in range(_MAX_ACTIVE_SET):
        lam = _gather(lam_pairs, con.status)
        x_new, lam_new, ok, its = _constrained_newton(problem, x, lam, pressure, nodes,
                                                      forces, con, offset, options, cap)
        spent += its
        if not ok:
            return x, lam_pairs, False, spent
        x = x_new
        lam_pairs = _scatter(lam_new, con.status)
        changed = _update_status(problem, x, lam_pairs, con, offset, force_scale, released)
        if changed < 0:
            return x, lam_pairs, False, spent
        if changed == 0:
            return x, lam_pairs, True, spent
    return x, lam_pairs, False, spent


@register_jitable
def _contact_stable(problem, x, lam_pairs, pressure, nodes, forces, con, offset):
    """
    Stability of a converged contact state: 1.0 stable, -1.0 not, 0.0 not certified.

    Stable when the Hessian of the Lagrangian is positive definite on the tangent space
    of the active rows (taken frictionless: d = w). With H, the Hessian under the contact
    forces as dead loads, positive definite that holds exactly when
    S = [[I - A^1/2 V H^-1 V^T A^1/2, -A^1/2 V H^-1 G^T], [., -E - G H^-1 G^T]] has as many
    negative eigenvalues as rows and no zero one (Haynsworth inertia additivity): when its
    last block is negative definite (independent rows) and the Schur complement of that
    block positive definite (two Cholesky factorisations). 0.0 where H is not positive
    definite.
    """
    lam = _gather(lam_pairs, con.status)
    c, comp, brow, grow, urow, vrow, coef, point, direction = _rows(con, problem, x, lam,
                                                                    offset)
    _, residual, hess = _constraint_derivatives(con, problem, x, pressure, nodes, forces, lam,
                                                point, direction)
    if _step(problem, residual, hess)[1] <= 0.0:
        return 0.0
    m = c.size
    q = coef.size
    yg, ok_g = _columns(problem, hess, grow, residual.shape)
    yv, ok_v = _columns(problem, hess, vrow, residual.shape)
    if not (ok_g and ok_v):
        return 0.0
    root = np.empty(q)
    for i in range(q):
        root[i] = np.sqrt(max(coef[i], 0.0))
    # -S22 = E + G H^-1 G^T, positive definite for independent rows.
    neg = _times(grow, yg)
    for i in range(m):
        neg[i, i] += comp[i]
    if not _positive_definite(neg):
        return -1.0
    # S11 - S12 S22^-1 S21 = S11 + S12 (-S22)^-1 S21, S12 = -A^1/2 V H^-1 G^T.
    vv = _times(vrow, yv)
    vg = _times(vrow, yg)
    schur = np.zeros((q, q))
    for i in range(q):
        for k in range(q):
            schur[i, k] = (1.0 if i == k else 0.0) - root[i] * vv[i, k] * root[k]
    for k in range(q):
        column, ok = _dense_solve(neg, root[k] * vg[k])
        if not ok:
            return -1.0
        for i in range(q):
            total = 0.0
            for r in range(m):
                total += root[i] * vg[i, r] * column[r]
            schur[i, k] += total
    return 1.0 if _positive_definite(schur) else -1.0


@register_jitable
def _contact_grow(problem, x, depth, pressure, nodes, forces, con, options, cap):
    """
    Grow the obstacles from their shapes offset by `depth` to their true shapes.

    `depth` is the free finger's deepest penetration, so that it touches them at first;
    the growth step doubles or halves (1/4 first, 1/256 smallest). Returns the tuple of
    `_contact`.
    """
    con.status[:] = ck.FREE
    lam = np.zeros((con.status.size, 2))
    spent = 0
    done = 0.0
    step = 0.25
    while True:
        goal = min(1.0, done + step)
        saved = con.status.copy()
        x_new, lam_new, ok, its = _contact_settle(problem, x, lam, pressure, nodes, forces,
                                                  con, (1.0 - goal) * depth, options, cap)
        spent += its
        if ok:
            x, lam, done = x_new, lam_new, goal
            step = min(2.0 * step, 1.0)
            if done >= 1.0:
                break
        else:
            con.status[:] = saved
            step *= 0.5
            if step < 1.0 / 256:
                return x, _CONTINUATION_FAILED, spent, lam, done, np.nan
    stable = _contact_stable(problem, x, lam, pressure, nodes, forces, con, 0.0)
    return x, _SUCCESS if stable > 0.0 else _UNSTABLE, spent, lam, 1.0, stable


@register_jitable
def _contact_step(problem, x, lam_pairs, status0, pressure, nodes, forces, con, options, cap):
    """Settle from a state and its statuses (a warm start or a path step); see `_contact`."""
    con.status[:] = status0
    x, lam, ok, its = _contact_settle(problem, x, lam_pairs.copy(), pressure, nodes, forces,
                                      con, 0.0, options, cap)
    if not ok:
        return x, _MAX_ITERATIONS, its, lam, 0.0, np.nan
    stable = _contact_stable(problem, x, lam, pressure, nodes, forces, con, 0.0)
    return x, _SUCCESS if stable > 0.0 else _UNSTABLE, its, lam, 1.0, stable


@register_jitable
def _contact(problem, x, lam, status, depth, pressure, nodes, forces, con, options, cap,
             grow):
    """
    Run `_contact_grow` (from the free finger x) or `_contact_step` (from x, lam, status).

    Returns (x, status code, iterations, lam_pairs (C, 2), fraction, stability);
    `con.status` holds the final statuses.
    """
    if grow:
        return _contact_grow(problem, x, depth, pressure, nodes, forces, con, options, cap)
    return _contact_step(problem, x, lam, status, pressure, nodes, forces, con, options, cap)


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


@jit
def _newton_entry(problem, x, pressure, nodes, forces, options, cap):
    return _newton(problem, x, pressure, nodes, forces, options, cap)


@jit
def _solve_entry(problem, initial, warm, flat, pressure, nodes, forces, options, cap):
    return _solve(problem, initial, warm, flat, pressure, nodes, forces, options, cap)


@jit
def _rigidity_entry(problem, x, pressure, node, direction, displacement, options, cap):
    return _rigidity(problem, x, pressure, node, direction, displacement, options, cap)


# numpy's error model (a division by zero gives inf or nan, which the loops test for) keeps
# the many divisions of the contact code free of exception paths: it compiles in less time.
@jit(error_model='numpy')
def _contact_entry(problem, x, lam, status, depth, pressure, nodes, forces, con, options, cap,
                   grow):
    return _contact(problem, x, lam, status, depth, pressure, nodes, forces, con, options, cap,
                    grow)


@jit
def _solve_batch_entry(problems, design, pressures, nodes, forces, initial, flat, options, cap,
                       tip):
    count = pressures.size
    warm = initial.shape[0] > 0
    states = np.empty((count,) + flat.shape)
    status = np.empty(count, dtype=np.int64)
    iterations = np.empty(count, dtype=np.int64)
    figures = np.empty((count, 6))
    for i in range(count):
        problem = problems[design[i]]
        start = initial[i] if warm else flat
        x, code, its, grad, step, eig, fraction = _solve(
            problem, start, warm, flat, pressures[i], nodes, forces[i], options, cap)
        states[i] = x
        status[i] = code
        iterations[i] = its
        position = _node_jacobian(problem, x, tip)[0]
        figures[i, 0] = grad
        figures[i, 1] = step
        figures[i, 2] = eig
        figures[i, 3] = fraction
        figures[i, 4] = position[0]
        figures[i, 5] = position[1]
    return states, status, iterations, figures


@jit
def _rigidity_batch_entry(unloaded, loaded, design, pressures, node, direction, displacement,
                          flat, options, cap):
    count = pressures.size
    free = np.empty((count,) + flat.shape)
    states = np.empty((count,) + flat.shape)
    status = np.empty(count, dtype=np.int64)
    iterations = np.empty((count, 2), dtype=np.int64)
    figures = np.empty((count, 10))
    nodes = np.zeros(0, dtype=np.int64)
    forces = np.zeros((0, 2))
    for i in range(count):
        d = design[i]
        x, code, its, grad, step, eig, fraction = _solve(
            unloaded[d], flat, False, flat, pressures[i], nodes, forces, options, cap)
        free[i] = x
        status[i] = code
        iterations[i, 0] = its
        figures[i, 0] = grad
        figures[i, 1] = step
        figures[i, 2] = eig
        figures[i, 3] = fraction
        figures[i, 4:] = np.nan
        iterations[i, 1] = 0
        states[i] = x
        if code != _SUCCESS:
            continue
        y, force, ok, its, done, stable, gradient = _rigidity(
            loaded[d], x, pressures[i], node, direction, displacement, options, cap)
        position = _node_jacobian(loaded[d], y, node)[0]
        states[i] = y
        iterations[i, 1] = its
        figures[i, 4] = force if ok else np.nan
        figures[i, 5] = done
        figures[i, 6] = 1.0 if stable else 0.0
        figures[i, 7] = gradient
        figures[i, 8] = position[0]
        figures[i, 9] = position[1]
    return free, status, states, iterations, figures


# -- the engine's Python entry points -------------------------------------------------------
def _compiled(problem, loaded):
    """Return the namedtuple a discretisation runs compiled as (`kernel_data`), or None."""
    make = getattr(problem, 'kernel_data', None)
    return None if make is None else make(loaded)


def _packed(problem, options, shape):
    """Return the loops' options and step cap for `shape` (once per solver and options)."""
    key = (id(options), shape)
    memo = problem.__dict__.setdefault('_engine_packed', {})
    hit = memo.get(key)
    if hit is None or hit[0] is not options:
        hit = memo[key] = (options, *options.packed(problem.gradient_scale, shape))
    return hit[1], hit[2]


def _flat(problem):
    """``problem.flat()``, once per solver: the loops never write to their start (`_own`)."""
    flat = problem.__dict__.get('_engine_flat')
    if flat is None:
        flat = np.ascontiguousarray(problem.flat(), dtype=float)
        problem.__dict__['_engine_flat'] = flat
    return flat


def _own(x, problem):
    """`x`, copied if it is the solver's shared flat state (a failed first step returns it)."""
    return x.copy() if x is problem.__dict__.get('_engine_flat') else x


def _outcome(out, problem, fraction=1.0):
    x, status, iterations, grad, step, eig = out[:6]
    return NewtonOutcome(_own(x, problem), _STATUS[status], iterations, grad, step, eig,
                         out[6] if len(out) > 6 else fraction)


def newton(problem, x, pressure, loads, options):
    """
    Damped Newton on the total potential of a discretisation.

    The loop (`_newton`) is written once: compiled for a discretisation that has
    ``kernel_data(loaded)`` (a namedtuple whose class carries its compiled kernels),
    interpreted with the discretisation's methods otherwise.

    Parameters
    ----------
    problem : discretisation
        Has ``derivatives(x, pressure, loads) -> (energy, gradient, hessian)``,
        ``energy(x, pressure, loads)``, ``step(gradient, hessian) -> (dx, min_eig)`` and
        ``gradient_scale``; `x` and the gradient share a shape, the Hessian is opaque to
        the engine.
    x : ndarray
        Start [scaled units].
    pressure : float
        Gauge pressure [Pa].
    loads : sequence of (int, ndarray (2,))
        Node index and force (F_X, F_Z) [N].
    options : NewtonOptions

    Returns
    -------
    NewtonOutcome
        SUCCESS when max|g|/scale <= gtol and the last step <= xtol with a positive-definite
        Hessian (the returned state includes that last step); UNSTABLE for a converged
        saddle; otherwise why it stopped.

    References
    ----------
    docs/physics.md, section 8.

    """
    x = np.ascontiguousarray(x, dtype=float)
    nodes, forces = kernels.load_arrays(loads)
    opts, cap = _packed(problem, options, x.shape)
    data = _compiled(problem, bool(loads))
    if data is None:
        return _outcome(_newton(problem, x, pressure, nodes, forces, opts, cap), problem)
    return _outcome(_newton_entry(data, x, float(pressure), nodes, forces, opts, cap), problem)


def solve(problem, pressure, loads, options, initial=None):
    """
    Equilibrium at a pressure and loads: warm start, else Newton from flat, else continuation.

    A warm start only saves iterations: if Newton from it does not reach a stable
    equilibrium, the solve starts again exactly as a fresh one, so the answer never
    depends on what was solved before. A fresh solve is Newton from ``problem.flat()``;
    if that fails (neither SUCCESS nor UNSTABLE), pressure and loads are marched from
    the unloaded state to the target, doubling or halving the load fraction step (1/4
    first, 1/256 smallest).

    Parameters
    ----------
    problem : discretisation
        See `newton`; also ``flat()`` (the unstrained state).
    pressure : float
        Gauge pressure [Pa].
    loads : sequence of (int, ndarray (2,))
        Node index and force [N].
    options : NewtonOptions
    initial : ndarray, optional
        Warm start [scaled units].

    Returns
    -------
    NewtonOutcome
        `iterations` counts every Newton iteration spent; CONTINUATION_FAILED carries the
        fraction of the loading reached.

    """
    flat = _flat(problem)
    warm = initial is not None
    start = np.ascontiguousarray(initial, dtype=float) if warm else flat
    nodes, forces = kernels.load_arrays(loads)
    opts, cap = _packed(problem, options, flat.shape)
    data = _compiled(problem, bool(loads))
    if data is None:
        out = _solve(problem, start, warm, flat, pressure, nodes, forces, opts, cap)
    else:
        out = _solve_entry(data, start, warm, flat, float(pressure), nodes, forces, opts, cap)
    return _outcome(out, problem)


def rigidity(problem, unloaded_x, pressure, node, direction, displacement, options):
    """
    Displacement control: the force along `direction` that moves node `node` by `displacement`.

    A bordered Newton system in (x, f), the force magnitude being the Lagrange
    multiplier of e . O_node = e . O_node(unloaded) + delta, marched in fractions of the
    displacement (whole first, halved on failure down to 1/64).

    Parameters
    ----------
    problem : discretisation
        See `newton`; also ``node_jacobian(x, node) -> (position (2,), d position/dx)``
        and ``solve_linear(hessian, rhs)`` (raises LinAlgError when singular).
    unloaded_x : ndarray
        Converged unloaded state.
    pressure : float
        [Pa].
    node : int
        Loaded node (the tip).
    direction : ndarray (2,)
        Unit load and displacement direction e.
    displacement : float
        delta [m].
    options : NewtonOptions

    Returns
    -------
    BorderedOutcome

    References
    ----------
    Zhou, Headings, Dapino (2022), eq. (22); docs/physics.md, section 10.

    """
    x = np.ascontiguousarray(unloaded_x, dtype=float)
    direction = np.ascontiguousarray(direction, dtype=float)
    opts, cap = _packed(problem, options, x.shape)
    data = _compiled(problem, True)
    if data is None:
        out = _rigidity(problem, x, pressure, int(node), direction, float(displacement), opts,
                        cap)
    else:
        out = _rigidity_entry(data, x, float(pressure), int(node), direction,
                              float(displacement), opts, cap)
    x, force, success, iterations, fraction, stable, gradient = out
    return BorderedOutcome(x, float(force), bool(success), int(iterations), float(fraction),
                           bool(stable), float(gradient))


def sensitivity(problem, x, pressure, loads, control=None):
    """
    Parameter sensitivities of an equilibrium by the implicit function theorem.

    At an equilibrium g(x; theta) = 0 with a non-singular Hessian H, the state moves
    with the parameters as dx/dtheta = -H^-1 dg/dtheta; dg/dtheta is the
    discretisation's ``parameter_gradient(x, pressure, loads)`` (the loads do not depend
    on theta). Under displacement control (`rigidity`'s bordered system: the gradient
    g - f grad c with c = e . O_node, and c(x) = target), the force f moves too:

        H dx - f' grad c = -dg/dtheta,    grad c . dx = d target / d theta,

    so with u = H^-1 dg/dtheta and v = H^-1 grad c, f' = (target' + grad c . u) /
    (grad c . v) and dx = f' v - u. H is the Hessian of the loaded potential there, as
    the bordered Newton uses it.

    Parameters
    ----------
    problem : discretisation
        As for `rigidity`, with ``parameter_gradient(x, pressure, loads) -> (P,) + x.shape``.
    x : ndarray
        The equilibrium [scaled units].
    pressure : float
        [Pa].
    loads : sequence of (int, ndarray (2,))
        The loads of that equilibrium (under displacement control: the found force at
        the node, ``[(node, f e)]``).
    control : (int, ndarray (2,), ndarray (P,)), optional
        Displacement control: the node, the unit direction e, and d target / d theta
        (the rate of e . O_node of the unloaded state plus delta) [m per unit].

    Returns
    -------
    dx : ndarray, shape (P,) + x.shape
        d x / d theta [scaled units per unit of each parameter].
    dforce : ndarray, shape (P,) or None
        d f / d theta under displacement control [N per unit], None without.

    Raises
    ------
    numpy.linalg.LinAlgError
        Where H (or the bordered system) is singular: the equilibrium does not move
        smoothly with the parameters.

    References
    ----------
    docs/physics.md, section 14.

    """
    x = np.ascontiguousarray(x, dtype=float)
    nodes, forces = kernels.load_arrays(loads)
    _, _, hess = _derivatives(problem, x, pressure, nodes, forces)
    rates = np.asarray(problem.parameter_gradient(x, pressure, loads), dtype=float)
    solved = np.empty_like(rates)
    for k, rate in enumerate(rates):
        solved[k], ok = _solve_linear(problem, hess, np.ascontiguousarray(rate))
        if not ok:
            raise np.linalg.LinAlgError('the Hessian is singular at this equilibrium')
    if control is None:
        return -solved, None
    node, direction, target_rate = control
    jacobian = _node_jacobian(problem, x, node)[1]
    grad_c = direction[0] * jacobian[0] + direction[1] * jacobian[1]
    along, ok = _solve_linear(problem, hess, np.ascontiguousarray(grad_c))
    denominator = float(np.sum(grad_c * along))
    if not (ok and np.isfinite(denominator) and denominator != 0.0):
        raise np.linalg.LinAlgError('the bordered system is singular at this equilibrium')
    axes = tuple(range(1, solved.ndim))
    dforce = (np.asarray(target_rate, dtype=float) + np.tensordot(solved, grad_c, axes=(
        axes, tuple(range(grad_c.ndim))))) / denominator
    dx = dforce.reshape((-1,) + (1,) * grad_c.ndim) * along - solved
    return dx, dforce


# -- contact ---------------------------------------------------------------------------------
class ContactOutcome(typing.NamedTuple):
    """
    State of a contact solve or path step (internal: `contact` builds its results from it).

    Attributes
    ----------
    x : ndarray
        Finger state [scaled units].
    status : SolverStatus
    iterations : int
        Bordered Newton iterations (free solve and continuation included).
    multipliers : ndarray, shape (C, 2)
        Per pair: (lambda_N [N], 0) in contact without sticking; the force (F_X, F_Z) on the
        finger [N] when sticking; zeros when free.
    pair_status : ndarray of int, shape (C,)
        `contact_kernels` status of every pair.
    anchors : ndarray, shape (C, 2)
        The anchors the step used [m].
    fraction : float
        Of the obstacle growth (cold solve) or of the step reached.
    stability : float
        > 0 stable; < 0 not; 0 not certified (the Hessian under the contact forces as dead
        loads is not positive definite); NaN not computed.

    """

    x: np.ndarray
    status: SolverStatus
    iterations: int
    multipliers: np.ndarray
    pair_status: np.ndarray
    anchors: np.ndarray
    fraction: float
    stability: float


def _contact_inputs(problem, loads, contact, options):
    """Compiled data (or None), flat state, loads, options and a private copy of `contact`."""
    if not all(hasattr(problem, name) for name in ('point_positions', 'point_jacobian',
                                                   'point_derivatives')):
        raise TypeError(f'contact needs a discretisation with face points (the PCC or the '
                        f'rod), got {type(problem).__name__}')
    flat = _flat(problem)
    nodes, forces = kernels.load_arrays(loads)
    opts, cap = _packed(problem, options, flat.shape)
    con = contact._replace(status=np.array(contact.status, dtype=np.int64),
                           anchor=np.array(contact.anchor, dtype=float))
    return _compiled(problem, True), flat, nodes, forces, opts, cap, con


def _contact_outcome(out, problem, con):
    x, code, iterations, lam, fraction, stability = out
    return ContactOutcome(_own(x, problem), _STATUS[code], int(iterations), lam,
                          con.status.copy(), con.anchor.copy(), float(fraction),
                          float(stability))


def _free_depth(problem, x, con):
    """Deepest penetration of a finger state into the obstacles [m] (<= 0: clear)."""
    positions = problem.point_positions(x, con.pseg, con.poff, con.pz)
    return -ck.pair_geometry(con.kind, con.params, positions, con.pair_point,
                             con.pair_object)[:, 0].min()


def contact_solve(problem, pressure, loads, contact, options, initial=None, top=None):
    """
    Frictionless contact equilibrium: the constrained minimum of the total potential.

    min Pi(x) subject to g_j(x) >= 0 for every candidate (finger point, obstacle) pair,
    g the signed distance of the point from the obstacle. An active-set method: the
    equality-constrained problem of the active pairs is solved by the bordered Newton
    (`_constrained_newton`, exact derivatives, H^-1 through the discretisation's own
    solves), then pairs that penetrate are added and pairs that pull released, until
    nothing changes. A warm start (`initial`) is tried first and kept only if it converges
    to a stable state. Otherwise the finger is solved free (`solve`), and if it
    penetrates, the gripper's own path is taken: from the pressure at which the free
    finger touches the obstacles (bisection between `pressure` and `top`) the pressure is
    released to `pressure` in steps of at most 10 kPa (halved on failure, down to 1/64),
    each a solve from the last. Where the finger touches at every pressure up to `top`
    (or the release fails), the obstacles are grown instead from their shapes offset by
    the deepest penetration (touching) to their true shapes in doubling or halving steps
    (1/4 first, 1/256 smallest). So the answer is a function of the inputs alone, and the
    one the finger reaches by closing on the obstacles.

    Parameters
    ----------
    problem : discretisation
        With face points (`point_positions`, `point_jacobian`, `point_derivatives`).
    pressure : float
        [Pa].
    loads : sequence of (int, ndarray (2,))
        Node loads besides the contact [N].
    contact : ContactSet
        Its `mu` is ignored (frictionless); its status and anchor arrays are not written.
    options : NewtonOptions
    initial : (x, multipliers, pair_status), optional
        A previous outcome's, of the same discretisation and pairs.
    top : float, optional
        Highest pressure of the release path [Pa] (the design's limit); None: growth only.

    Returns
    -------
    ContactOutcome
        SUCCESS for a stable constrained equilibrium, UNSTABLE when its stability fails or
        cannot be certified, CONTINUATION_FAILED with the fraction of the release (or
        growth) reached.

    References
    ----------
    docs/physics.md, section 15.

    """
    data, flat, nodes, forces, opts, cap, con = _contact_inputs(problem, loads, contact,
                                                                options)
    con = con._replace(mu=0.0)
    count = con.status.size
    spent = 0
    if initial is not None:
        status0 = np.where(np.asarray(initial[2]) == ck.FREE, ck.FREE, ck.NORMAL).astype(
            np.int64)
        warm = _run_contact(problem, data, np.ascontiguousarray(initial[0], dtype=float),
                            np.ascontiguousarray(initial[1], dtype=float), status0, 0.0,
                            pressure, nodes, forces, con, opts, cap, False)
        if warm.status is SolverStatus.SUCCESS:
            return warm
        spent = warm.iterations
        con = con._replace(status=np.zeros(count, dtype=np.int64))
    # The free finger (the engine's own solve, compiled once for every use), then growth.
    free = solve(problem, pressure, loads, options)
    spent += free.iterations
    lam = np.zeros((count, 2))
    if free.status not in (SolverStatus.SUCCESS, SolverStatus.UNSTABLE):
        return ContactOutcome(free.x, free.status, spent, lam, con.status.copy(),
                              con.anchor.copy(), 0.0, math.nan)
    depth = _free_depth(problem, free.x, con)
    if depth <= _GAP_TOL * con.scale:
        return ContactOutcome(free.x, free.status, spent, lam, con.status.copy(),
                              con.anchor.copy(), 1.0, free.min_eig)
    if top is not None and float(top) > float(pressure):
        out = _release(problem, data, float(pressure), float(top), loads, nodes, forces, con,
                       opts, cap, options)
        if out is not None:
            return out._replace(iterations=out.iterations + spent)
    out = _run_contact(problem, data, free.x, lam, con.status, depth, pressure, nodes, forces,
                       con, opts, cap, True)
    return out._replace(iterations=out.iterations + spent)


#: Largest pressure step of a cold contact solve's release path [Pa], and its smallest
#: fraction after halvings.
_RELEASE_STEP = 10.0e3
_RELEASE_SMALLEST = 1.0 / 64


def _release(problem, data, pressure, top, loads, nodes, forces, con, opts, cap, options):
    """
    Close the finger on the obstacles: from the pressure where it touches down to `pressure`.

    Returns the outcome at `pressure`, or None when the free finger touches at `top` too
    or a step fails even at its smallest (then the caller grows the obstacles).
    """
    def depth(p):
        out = solve(problem, p, loads, options)
        if out.status not in (SolverStatus.SUCCESS, SolverStatus.UNSTABLE):
            return math.inf, out
        return _free_depth(problem, out.x, con), out

    high, state = depth(top)
    if high > _GAP_TOL * con.scale:
        return None
    low = pressure
    spent = state.iterations
    # Bisection on the free finger's penetration to 1e-6 of the span: where it touches.
    while top - low > 1e-6 * max(top, 1.0):
        middle = 0.5 * (low + top)
        d, out = depth(middle)
        spent += out.iterations
        if d > _GAP_TOL * con.scale:
            low = middle
        else:
            top, state = middle, out
    x, lam = state.x, np.zeros((con.status.size, 2))
    status = np.zeros(con.status.size, dtype=np.int64)
    current, size = top, _RELEASE_STEP
    while current > pressure:
        goal = max(pressure, current - size)
        out = _run_contact(problem, data, x, lam, status, 0.0, goal, nodes, forces, con, opts,
                           cap, False)
        spent += out.iterations
        if out.status in (SolverStatus.SUCCESS, SolverStatus.UNSTABLE):
            x, lam, status, current = out.x, out.multipliers, out.pair_status, goal
            size = min(2.0 * size, _RELEASE_STEP)
            continue
        size *= 0.5
        if size < _RELEASE_SMALLEST * _RELEASE_STEP:
            return None
    return out._replace(iterations=spent)


def _run_contact(problem, data, x, lam, status, depth, pressure, nodes, forces, con, opts, cap,
                 grow):
    """Run `_contact` compiled (on `data`) or interpreted, and wrap its outcome."""
    args = (x, lam, status, float(depth), float(pressure), nodes, forces, con, opts, cap,
            bool(grow))
    if data is None:
        out = _contact(problem, *args)
    else:
        out = _contact_entry(data, *args)
    return _contact_outcome(out, problem, con)


def contact_step(problem, pressure, loads, contact, state, options):
    """
    One step of a contact path with Coulomb friction, from a converged state.

    Every pair in contact starts the step sticking to its anchor (a return map); a
    sticking pair whose tangential force passes mu times its normal force slips, with
    the friction force mu lambda_N against its motion, a slipping pair that would move
    against its friction force sticks again, a penetrating pair touches (sticking to its
    anchor), a pulling one is released: the active-set loop of `contact_solve`.

    Parameters
    ----------
    problem, pressure, loads, options
        As `contact_solve`.
    contact : ContactSet
        Obstacles at the step's pose and the anchors of every pair (see `contact_path`).
    state : (x, multipliers, pair_status)
        The converged state the step starts from.

    Returns
    -------
    ContactOutcome
        MAX_ITERATIONS when the step does not converge (the caller takes a smaller one).

    """
    data, flat, nodes, forces, opts, cap, con = _contact_inputs(problem, loads, contact,
                                                                options)
    x = np.ascontiguousarray(state[0], dtype=float)
    lam0 = np.array(state[1], dtype=float)
    status0 = np.array(state[2], dtype=np.int64)
    if con.mu > 0.0:
        _start_sticking(problem, x, con, lam0, status0)
    return _run_contact(problem, data, x, lam0, status0, 0.0, pressure, nodes, forces, con,
                        opts, cap, False)


def _start_sticking(problem, x, con, lam, status):
    """Turn touching pairs that do not stick into sticking ones (the return map's trial)."""
    slipping = np.nonzero((status == ck.SLIP_POS) | (status == ck.SLIP_NEG)
                          | (status == ck.NORMAL))[0]
    if not slipping.size:
        return
    positions = problem.point_positions(x, con.pseg, con.poff, con.pz)
    for j in slipping:
        b = con.pair_object[j]
        p = positions[con.pair_point[j]]
        _, gx, gz, _, _, _ = ck.signed_distance(int(con.kind[b]), con.params[b], p[0], p[1])
        sense = {ck.SLIP_POS: con.mu, ck.SLIP_NEG: -con.mu}.get(int(status[j]), 0.0)
        multiplier = lam[j, 0]
        lam[j] = multiplier * (gx - sense * gz), multiplier * (gz + sense * gx)
        status[j] = ck.STICK


def next_anchors(problem, x, contact, pair_status):
    """
    Return the anchors of the next path step [m], shape (C, 2).

    Sticking pairs keep theirs; every other pair takes the obstacle point nearest to its
    finger point now.
    """
    positions = problem.point_positions(np.ascontiguousarray(x, dtype=float), contact.pseg,
                                        contact.poff, contact.pz)
    nearest = ck.pair_geometry(contact.kind, contact.params, positions, contact.pair_point,
                               contact.pair_object)[:, 4:]
    return np.where((np.asarray(pair_status) == ck.STICK)[:, None], contact.anchor, nearest)


def contact_path(problem, pressures, shifts, loads, contact, options, state, halvings=6):
    """
    March a contact path with friction: the answer depends on the path, which is the input.

    Step k takes the finger to pressure `pressures[k]` and every obstacle to its base pose
    (`contact.params`) moved by `shifts[k]`, from the converged state of step k - 1 (or
    `state`). Anchors ride with their obstacle; after each step sticking pairs keep theirs
    and the others take the obstacle point nearest their finger point (`next_anchors`). A
    step that fails is split in two (linearly in pressure and pose), down to
    2^-`halvings` of it, else the path stops there.

    Parameters
    ----------
    problem, loads, options
        As `contact_solve`.
    pressures : sequence of float, length S
        [Pa].
    shifts : array_like, shape (S, B, 2)
        Translation of every obstacle from its base pose [m].
    contact : ContactSet
        Base obstacles, pairs and the anchors at the start (at the pose of `shifts` of
        the start state: `state[3]`).
    state : (x, multipliers, pair_status, shift (B, 2), pressure)
        Converged start.
    halvings : int

    Returns
    -------
    list of (ContactOutcome, params (B, P))
        One per step reached (the obstacles' parameter rows of that step); shorter than S
        when a step cannot be completed, its last entry then the failed outcome.

    """
    x, lam, status, shift, pressure = state
    shift = np.array(shift, dtype=float).reshape(contact.kind.size, 2)
    anchors = np.array(contact.anchor, dtype=float)
    out = []
    for k in range(len(pressures)):
        goal_p = float(pressures[k])
        goal_s = np.asarray(shifts[k], dtype=float).reshape(shift.shape)
        done, size = 0.0, 1.0
        start_p, start_s = pressure, shift.copy()
        while done < 1.0:
            frac = min(1.0, done + size)
            p_k = start_p + frac * (goal_p - start_p)
            s_k = start_s + frac * (goal_s - start_s)
            params = ck.shifted_params(contact.kind, contact.params, s_k)
            moved = anchors + (s_k - shift)[contact.pair_object]
            step = contact._replace(params=params, anchor=moved)
            outcome = contact_step(problem, p_k, loads, step, (x, lam, status), options)
            if outcome.status in (SolverStatus.SUCCESS, SolverStatus.UNSTABLE):
                x, lam, status = outcome.x, outcome.multipliers, outcome.pair_status
                anchors = next_anchors(problem, x, step._replace(anchor=moved), status)
                shift, pressure, done = s_k, p_k, frac
                size = min(1.0, 2.0 * size)
                if done >= 1.0:
                    out.append((outcome, params))
            else:
                size *= 0.5
                if size < 2.0 ** -halvings:
                    out.append((outcome._replace(fraction=done), params))
                    return out
    return out


# -- batches -------------------------------------------------------------------------------
@dataclass(frozen=True)
class BatchOutcome:
    """
    Equilibria of S independent scenes (internal: `batch` builds its results from it).

    Attributes
    ----------
    states : ndarray, shape (S,) + unknowns
    status : ndarray of int, shape (S,)
        `SolverStatus` codes.
    iterations : ndarray of int, shape (S,)
    gradient, step, min_eig, fraction : ndarray, shape (S,)
        As in `NewtonOutcome`.
    tips : ndarray, shape (S, 2)
        Position of the tip node [m].

    """

    states: np.ndarray
    status: np.ndarray
    iterations: np.ndarray
    gradient: np.ndarray
    step: np.ndarray
    min_eig: np.ndarray
    fraction: np.ndarray
    tips: np.ndarray


@dataclass(frozen=True)
class BatchRigidity:
    """
    Displacement-controlled solves of S scenes (internal; see `rigidity_batch`).

    Attributes
    ----------
    unloaded : BatchOutcome
        The unloaded solves (`tips` of the unloaded states).
    states : ndarray, shape (S,) + unknowns
        Loaded states (the unloaded one where that failed).
    force : ndarray, shape (S,)
        End load magnitude along the direction [N]; NaN where not found.
    iterations : ndarray of int, shape (S,)
        Bordered Newton iterations.
    fraction : ndarray, shape (S,)
        Fraction of the displacement reached.
    stable : ndarray of bool, shape (S,)
        Loaded state stable under force control.
    gradient : ndarray, shape (S,)
        Relative gradient of the loaded state.
    tips : ndarray, shape (S, 2)
        Loaded tip [m]; NaN where not found.

    """

    unloaded: BatchOutcome
    states: np.ndarray
    force: np.ndarray
    iterations: np.ndarray
    fraction: np.ndarray
    stable: np.ndarray
    gradient: np.ndarray
    tips: np.ndarray


def _batch_inputs(problems, loaded, options):
    """Typed list of compiled discretisations, flat state, options and cap; checks them."""
    datas = [_compiled(problem, loaded) for problem in problems]
    if not datas or any(data is None for data in datas):
        raise TypeError('`problems` must be a non-empty sequence of discretisations that run '
                        'compiled (with `kernel_data`)')
    flat = _flat(problems[0])
    opts, cap = _packed(problems[0], options, flat.shape)
    for problem, data in zip(problems, datas):
        other = _flat(problem)
        if type(data) is not type(datas[0]) or other.shape != flat.shape \
                or _packed(problem, options, flat.shape)[0] != opts \
                or not np.array_equal(_packed(problem, options, flat.shape)[1], cap):
            raise ValueError('`problems` must share one discretisation type, number of '
                             'unknowns and options')
    return numba.typed.List(datas), flat, opts, cap


def _index(design, pressures, count):
    design = np.ascontiguousarray(design, dtype=np.int64)
    pressures = np.ascontiguousarray(pressures, dtype=float)
    if design.shape != pressures.shape or design.ndim != 1:
        raise ValueError('`design` and `pressures` must be 1-d of one length, got shapes '
                         f'{design.shape} and {pressures.shape}')
    if design.size and not (0 <= design.min() and design.max() < count):
        raise ValueError(f'`design` indices must lie in [0, {count})')
    return design, pressures


def solve_batch(problems, design, pressures, nodes, forces, options, tip, initial=None):
    """
    Solves of S independent scenes in compiled loops over both cores (`over_cores`).

    Scene i is `solve(problems[design[i]], pressures[i], loads_i, options, initial[i])`,
    loads_i being `forces[i]` at `nodes`: the same arithmetic, so the same answer.

    Parameters
    ----------
    problems : sequence of discretisation
        Each with ``kernel_data``; one type, unknowns' shape and options.
    design : array_like of int, shape (S,)
        Index into `problems` of every scene.
    pressures : array_like, shape (S,)
        [Pa].
    nodes : array_like of int, shape (K,)
        Loaded nodes, shared by all scenes (K = 0: unloaded).
    forces : array_like, shape (S, K, 2)
        [N].
    options : NewtonOptions
    tip : int
        Node whose position is returned.
    initial : array_like, shape (S,) + unknowns, optional
        Warm starts [scaled units]; None: every scene from the flat state.

    Returns
    -------
    BatchOutcome

    """
    design, pressures = _index(design, pressures, len(problems))
    nodes = np.ascontiguousarray(nodes, dtype=np.int64).reshape(-1)
    forces = np.ascontiguousarray(forces, dtype=float).reshape(pressures.size, nodes.size, 2)
    datas, flat, opts, cap = _batch_inputs(problems, nodes.size > 0, options)
    if initial is None:
        initial = np.zeros((0,) + flat.shape)
    else:
        initial = np.ascontiguousarray(initial, dtype=float)
        if initial.shape != (pressures.size,) + flat.shape:
            raise ValueError(f'`initial` must have shape {(pressures.size,) + flat.shape}, '
                             f'got {initial.shape}')
    warm = initial.shape[0] > 0

    def run(lo, hi):
        return _solve_batch_entry(datas, design[lo:hi], pressures[lo:hi], nodes, forces[lo:hi],
                                  initial[lo:hi] if warm else initial, flat, opts, cap,
                                  int(tip))
    states, status, iterations, figures = over_cores(run, pressures.size)
    return BatchOutcome(states, status, iterations, *figures[:, :4].T, figures[:, 4:])


def rigidity_batch(problems, design, pressures, node, direction, displacement, options):
    """
    `rigidity` of S scenes after their cold unloaded solves, compiled over both cores.

    Parameters
    ----------
    problems : sequence of discretisation
        As for `solve_batch`.
    design : array_like of int, shape (S,)
    pressures : array_like, shape (S,)
        [Pa].
    node : int
        Loaded node (the tip).
    direction : array_like (2,)
        Unit load and displacement direction.
    displacement : float
        [m].
    options : NewtonOptions

    Returns
    -------
    BatchRigidity

    """
    design, pressures = _index(design, pressures, len(problems))
    free, flat, opts, cap = _batch_inputs(problems, False, options)
    loaded = _batch_inputs(problems, True, options)[0]
    direction = np.ascontiguousarray(direction, dtype=float)

    def run(lo, hi):
        return _rigidity_batch_entry(free, loaded, design[lo:hi], pressures[lo:hi], int(node),
                                     direction, float(displacement), flat, opts, cap)
    out = over_cores(run, pressures.size)
    unloaded_x, status, states, iterations, figures = out
    unloaded = BatchOutcome(unloaded_x, status, iterations[:, 0], *figures[:, :4].T,
                            np.full((pressures.size, 2), np.nan))
    return BatchRigidity(unloaded, states, figures[:, 4], iterations[:, 1], figures[:, 5],
                         figures[:, 6] == 1.0, figures[:, 7], figures[:, 8:10])
