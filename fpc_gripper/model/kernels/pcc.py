"""Compiled (numba) PCC rod: banded derivatives of its potential, kinematics, face points."""

import collections
import math

import numpy as np

from .linear import _dense_from_band, banded_step, cholesky_solve, shifted_step
from .pcc_section import _section_energy, _section_slopes, _sinc, _sinc0
from ..compiled import jit

__all__ = ['energy_kernel', 'derivatives_kernel', 'nodes_kernel', 'node_jacobian_kernel',
           'BANDWIDTH', 'PCCData', 'pcc_derivatives', 'pcc_energy', 'pcc_step',
           'pcc_solve_linear', 'pcc_node_jacobian', 'point_positions_kernel',
           'point_jacobian_kernel', 'point_derivatives_kernel', 'PCC_HOOKS']

# Built at install (`compiled`), once per argument types; nogil lets a caller thread them.
_jit = jit

#: Half-bandwidth of the PCC Hessian in the engine's ordering (eps_i, c1_i, theta_i).
BANDWIDTH = 3


@_jit
def _carried_loads(n, load_nodes, load_forces):
    """Load G_i carried by every segment, the sum of node forces at n > i [N], and any != 0."""
    at = np.zeros((n + 1, 2))
    for k in range(load_nodes.size):
        at[load_nodes[k], 0] += load_forces[k, 0]
        at[load_nodes[k], 1] += load_forces[k, 1]
    carried = np.empty((n, 2))
    carried[n - 1, 0], carried[n - 1, 1] = at[n, 0], at[n, 1]
    for i in range(n - 2, -1, -1):
        carried[i, 0] = carried[i + 1, 0] + at[i + 1, 0]
        carried[i, 1] = carried[i + 1, 1] + at[i + 1, 1]
    loaded = False
    for i in range(n):
        # != 0 is also true of NaN, which must reach the energy.
        if carried[i, 0] != 0.0 or carried[i, 1] != 0.0:
            loaded = True
            break
    return carried, loaded


# -- total potential ------------------------------------------------------------------------
@_jit
def energy_kernel(x, lengths, stiffness, gas, pemc, work, load_nodes, load_forces):
    """
    Total potential of the PCC rod [J].

    sum_i L_i W(eps_i, Delta_i / L_i, c1_i; k_p P) - G_i . Delta r_i, with the chord
    Delta r_i = (1 + eps_i) L_i S(Delta_i) (cos, sin)((theta_{i-1} + theta_i) / 2).

    Parameters
    ----------
    x : ndarray, shape (3 N,)
        Engine unknowns (eps_i [-], c1_i [-], theta_i [rad]) per segment.
    lengths : ndarray, shape (N,)
        Reference segment lengths L_i [m].
    stiffness, gas, pemc : ndarray
        See `section_arrays`.
    work : float
        k_p P [Pa].
    load_nodes : ndarray of int64, shape (K,)
        Loaded nodes in 0..N (N is the tip).
    load_forces : ndarray, shape (K, 2)
        (F_X, F_Z) of each load [N].

    References
    ----------
    docs/physics.md, sections 11.2 and 11.6.

    """
    n = lengths.size
    carried, loaded = _carried_loads(n, load_nodes, load_forces)
    strain = 0.0
    load = 0.0
    prev = 0.0
    for i in range(n):
        eps, c1, theta = x[3 * i], x[3 * i + 1], x[3 * i + 2]
        length = lengths[i]
        delta = theta - prev
        strain += length * _section_energy(stiffness, gas, pemc, i, eps, delta / length, c1,
                                           work)
        if loaded:
            mid = 0.5 * (theta + prev)
            along = carried[i, 0] * math.cos(mid) + carried[i, 1] * math.sin(mid)
            load += ((1.0 + eps) * length) * (_sinc0(delta) * along)
        prev = theta
    return strain - load


@_jit
def derivatives_kernel(x, lengths, stiffness, gas, pemc, work, load_nodes, load_forces):
    """
    Energy, gradient and lower band of the exact Hessian of the PCC potential.

    The assembly (`_assemble`) and, since the engine's next call is the Newton step with
    this Hessian, the banded Cholesky factor and step, once for the step and the
    bordered solves (`banded_step`).

    Parameters are those of `energy_kernel`.

    Returns
    -------
    energy, gradient, lower
        See `_assemble`.
    factor, step, definite
        `banded_step` of (lower, gradient).

    References
    ----------
    docs/physics.md, section 11.6.

    """
    energy, grad, lower = _assemble(x, lengths, stiffness, gas, pemc, work, load_nodes,
                                    load_forces)
    factor, step, definite = banded_step(lower, grad)
    return energy, grad, lower, factor, step, definite


@_jit
def _assemble(x, lengths, stiffness, gas, pemc, work, load_nodes, load_forces):
    """
    Energy, gradient and lower band of the exact Hessian of the PCC potential.

    Every segment's term depends on its local unknowns (theta_{i-1}, eps_i, c1_i,
    theta_i), the engine unknowns 3i - 1 .. 3i + 2 (theta_0 = 0 is clamped): the
    element gradient is L T^T g and Hessian L T^T h T of the section law's (g, h) in
    y = (eps, (theta_i - theta_{i-1}) / L, c1), minus the load term's, assembled into
    the band directly.

    Parameters are those of `energy_kernel`.

    Returns
    -------
    energy : float
        [J], equal to `energy_kernel`'s.
    gradient : ndarray, shape (3 N,)
        [J].
    lower : ndarray, shape (4, 3 N)
        lower[d, k] = H[k + d, k] [J].

    """
    n = lengths.size
    carried, loaded = _carried_loads(n, load_nodes, load_forces)
    grad = np.empty(3 * n)
    lower = np.zeros((4, 3 * n))
    g = np.empty(3)
    h = np.empty((3, 3))
    strain = 0.0
    load = 0.0
    prev = 0.0
    for i in range(n):
        eps, c1, theta = x[3 * i], x[3 * i + 1], x[3 * i + 2]
        length = lengths[i]
        delta = theta - prev
        kappa = delta / length
        strain += length * _section_energy(stiffness, gas, pemc, i, eps, kappa, c1, work)
        _section_slopes(stiffness, gas, pemc, i, eps, kappa, c1, work, g, h)
        # Local unknowns (a, e, c, b) = (theta_{i-1}, eps_i, c1_i, theta_i).
        g_a, g_e, g_c, g_b = -g[1], length * g[0], length * g[2], g[1]
        bend = h[1, 1] / length
        h_aa = h_bb = bend
        h_ab = -bend
        h_ee, h_cc, h_ec = length * h[0, 0], length * h[2, 2], length * h[0, 2]
        h_ea, h_eb = -h[0, 1], h[0, 1]
        h_ca, h_cb = -h[2, 1], h[2, 1]
        if loaded:
            # -G . Delta r = -(1 + eps) L phi(a, b), phi = S(Delta) G . u(m), Delta = b - a,
            # m = (a + b)/2, u = (cos, sin)(m), n = u' = (-sin, cos)(m).
            mid = 0.5 * (theta + prev)
            s0, s1, s2 = _sinc(delta)
            cm, sm = math.cos(mid), math.sin(mid)
            gu = carried[i, 0] * cm + carried[i, 1] * sm
            gn = -carried[i, 0] * sm + carried[i, 1] * cm
            phi = s0 * gu
            p_d, p_m = s1 * gu, s0 * gn
            p_dd, p_dm, p_mm = s2 * gu, s1 * gn, -s0 * gu
            p_a, p_b = -p_d + 0.5 * p_m, p_d + 0.5 * p_m
            stretch = (1.0 + eps) * length
            load += stretch * phi
            g_a -= stretch * p_a
            g_e -= length * phi
            g_b -= stretch * p_b
            h_aa -= stretch * (p_dd - p_dm + 0.25 * p_mm)
            h_bb -= stretch * (p_dd + p_dm + 0.25 * p_mm)
            h_ab -= stretch * (-p_dd + 0.25 * p_mm)
            h_ea -= length * p_a
            h_eb -= length * p_b
        e, c, b = 3 * i, 3 * i + 1, 3 * i + 2
        grad[e] = g_e
        grad[c] = g_c
        grad[b] = g_b
        if i > 0:
            a = e - 1
            grad[a] += g_a
            lower[0, a] += h_aa
            lower[1, a] = h_ea
            lower[2, a] = h_ca
            lower[3, a] = h_ab
        lower[0, e] = h_ee
        lower[1, e] = h_ec
        lower[2, e] = h_eb
        lower[0, c] = h_cc
        lower[1, c] = h_cb
        lower[0, b] = h_bb
        prev = theta
    return strain - load, grad, lower


# -- kinematics ------------------------------------------------------------------------------
@_jit
def nodes_kernel(x, lengths):
    """Segment ends O_0 = 0 .. O_N = tip [m], shape (N + 1, 2): the sum of the chords."""
    n = lengths.size
    out = np.zeros((n + 1, 2))
    prev = 0.0
    for i in range(n):
        eps, theta = x[3 * i], x[3 * i + 2]
        reach = ((1.0 + eps) * lengths[i]) * _sinc0(theta - prev)
        mid = 0.5 * (theta + prev)
        if i == 0:
            out[1, 0], out[1, 1] = reach * math.cos(mid), reach * math.sin(mid)
        else:
            out[i + 1, 0] = out[i, 0] + reach * math.cos(mid)
            out[i + 1, 1] = out[i, 1] + reach * math.sin(mid)
        prev = theta
    return out


@_jit
def node_jacobian_kernel(x, lengths, node):
    """
    Position of node `node` [m] and its derivatives in the engine unknowns.

    O_n = sum_{i < n} Delta r_i; chord i depends on (theta_{i-1}, eps_i, theta_i).

    Returns
    -------
    position : ndarray, shape (2,)
        [m].
    jacobian : ndarray, shape (2, 3 N)
        [m], per unit strain or radian.

    """
    n = lengths.size
    position = np.zeros(2)
    jac = np.zeros((2, 3 * n))
    prev = 0.0
    for i in range(node):
        eps, theta = x[3 * i], x[3 * i + 2]
        length = lengths[i]
        delta = theta - prev
        mid = 0.5 * (theta + prev)
        s0, s1, _ = _sinc(delta)
        ux, uz = math.cos(mid), math.sin(mid)
        stretch = (1.0 + eps) * length
        reach = stretch * s0
        position[0] += reach * ux
        position[1] += reach * uz
        # d/d delta along u, d/d mid along the normal (-uz, ux): a = prev, b = theta.
        dx_d, dz_d = s1 * ux, s1 * uz
        dx_m, dz_m = s0 * -uz, s0 * ux
        jac[0, 3 * i] = (length * s0) * ux
        jac[1, 3 * i] = (length * s0) * uz
        jac[0, 3 * i + 2] = stretch * (dx_d + 0.5 * dx_m)
        jac[1, 3 * i + 2] = stretch * (dz_d + 0.5 * dz_m)
        if i > 0:
            jac[0, 3 * i - 1] += stretch * (-dx_d + 0.5 * dx_m)
            jac[1, 3 * i - 1] += stretch * (-dz_d + 0.5 * dz_m)
        prev = theta
    return position, jac


# -- face points: a material point at reference arc length sigma into segment i, at height z
# from the midplane along its normal (docs/physics.md, section 15.2) ----------------------------
@_jit
def _face_angles(a, b, length, offset):
    """Return f = sigma / L, phi = f (b - a), S(phi), S', S'' and the angles a + phi/2, a + phi."""
    f = offset / length
    phi = f * (b - a)
    s0, s1, s2 = _sinc(phi)
    return f, phi, s0, s1, s2, a + 0.5 * phi, a + phi


@_jit
def _face_offset(a, eps, b, length, offset, z):
    """
    Offset q of a face point from its segment's start node, and dq/d(a, eps, b).

    With f = sigma / L_i, phi = f (b - a) the turning up to the point, the partial chord
    (1 + eps) sigma S(phi) (cos, sin)(a + phi / 2) and the normal n = (-sin, cos)(a + phi),
    q = chord + z n.

    Returns
    -------
    q : (float, float)
        [m].
    dq : ndarray, shape (2, 3)
        Columns d/da, d/deps, d/db [m].

    """
    f, phi, s0, s1, s2, mid, end = _face_angles(a, b, length, offset)
    cm, sm = math.cos(mid), math.sin(mid)
    ce, se = math.cos(end), math.sin(end)
    reach = (1.0 + eps) * offset
    qx = reach * s0 * cm - z * se
    qz = reach * s0 * sm + z * ce
    dq = np.empty((2, 3))
    # d/dphi of the chord along u(mid), d/dmid along n(mid); n(end)' = -u(end).
    for r in range(2):
        u = cm if r == 0 else sm
        nn = -sm if r == 0 else cm
        ue = ce if r == 0 else se
        d_phi = reach * s1 * u
        d_mid = reach * s0 * nn
        dq[r, 0] = -f * d_phi + (1.0 - 0.5 * f) * d_mid - z * (1.0 - f) * ue
        dq[r, 1] = offset * s0 * u
        dq[r, 2] = f * d_phi + 0.5 * f * d_mid - z * f * ue
    return qx, qz, dq


@_jit
def _face_load(a, eps, b, length, offset, z, fx, fz, grad_h):
    """
    Potential -F . q of a dead force at a face point, its gradient and Hessian in (a, eps, b).

    grad_h (4, 3) receives the gradient (row 0) and the Hessian (rows 1..3) [J]; returns
    the potential [J].
    """
    f, phi, s0, s1, s2, mid, end = _face_angles(a, b, length, offset)
    cm, sm = math.cos(mid), math.sin(mid)
    gu = fx * cm + fz * sm                     # F . u(mid)
    gn = -fx * sm + fz * cm                    # F . n(mid) = d(F . u)/d mid
    ce, se = math.cos(end), math.sin(end)
    gu2 = fx * ce + fz * se
    gn2 = -fx * se + fz * ce                   # F . n(end)
    reach = (1.0 + eps) * offset
    # F . q = reach h(phi, mid) + z k(end), h = S(phi) F . u(mid), k = F . n(end).
    h = s0 * gu
    h_p, h_m = s1 * gu, s0 * gn
    h_pp, h_pm, h_mm = s2 * gu, s1 * gn, -s0 * gu
    k_1, k_2 = -gu2, -gn2
    # d(phi, mid, end)/d(a, b) = (-f, 1 - f/2, 1 - f) and (f, f/2, f).
    jp = (-f, f)
    jm = (1.0 - 0.5 * f, 0.5 * f)
    je = (1.0 - f, f)
    da = (reach * (h_p * jp[0] + h_m * jm[0]) + z * k_1 * je[0],
          reach * (h_p * jp[1] + h_m * jm[1]) + z * k_1 * je[1])
    de = (offset * (h_p * jp[0] + h_m * jm[0]), offset * (h_p * jp[1] + h_m * jm[1]))
    # Columns of grad_h: (a, eps, b); the potential is -F . q.
    grad_h[0, 0] = -da[0]
    grad_h[0, 1] = -offset * h
    grad_h[0, 2] = -da[1]
    for r in range(2):
        for c in range(2):
            hess = reach * (jp[r] * jp[c] * h_pp + (jp[r] * jm[c] + jm[r] * jp[c]) * h_pm
                            + jm[r] * jm[c] * h_mm) + z * k_2 * je[r] * je[c]
            grad_h[1 + 2 * r, 2 * c] = -hess
        grad_h[1 + 2 * r, 1] = -de[r]
        grad_h[2, 2 * r] = -de[r]
    grad_h[2, 1] = 0.0
    return -(reach * h + z * (fx * (-se) + fz * ce))


@_jit
def point_positions_kernel(x, lengths, pseg, poff, pz):
    """
    Positions of face points [m], shape (K, 2).

    Point k lies sigma_k = poff[k] into segment pseg[k], at height pz[k] along the normal.
    """
    nodes = nodes_kernel(x, lengths)
    out = np.empty((pseg.size, 2))
    for k in range(pseg.size):
        i = pseg[k]
        a = 0.0 if i == 0 else x[3 * i - 1]
        qx, qz, _ = _face_offset(a, x[3 * i], x[3 * i + 2], lengths[i], poff[k], pz[k])
        out[k, 0] = nodes[i, 0] + qx
        out[k, 1] = nodes[i, 1] + qz
    return out


@_jit
def point_jacobian_kernel(x, lengths, seg, offset, z):
    """Position (2,) of a face point [m] and its derivatives (2, 3 N) in the engine unknowns."""
    position, jac = node_jacobian_kernel(x, lengths, seg)
    a = 0.0 if seg == 0 else x[3 * seg - 1]
    qx, qz, dq = _face_offset(a, x[3 * seg], x[3 * seg + 2], lengths[seg], offset, z)
    position[0] += qx
    position[1] += qz
    for r in range(2):
        if seg > 0:
            jac[r, 3 * seg - 1] += dq[r, 0]
        jac[r, 3 * seg] += dq[r, 1]
        jac[r, 3 * seg + 2] += dq[r, 2]
    return position, jac


@_jit
def point_derivatives_kernel(x, lengths, stiffness, gas, pemc, work, load_nodes, load_forces,
                             pseg, poff, pz, pforce):
    """
    `derivatives_kernel` with dead forces at face points as well as at nodes.

    A force F at point k of segment i has the potential -F . (O_i + q_k): a node load at
    node i (the segment's start), which the carried loads take, and -F . q_k, a function
    of segment i's (theta_{i-1}, eps_i, theta_i) alone, so the Hessian stays banded.

    Parameters
    ----------
    x, lengths, stiffness, gas, pemc, work, load_nodes, load_forces
        As `energy_kernel`.
    pseg, poff, pz : ndarray, shape (K,)
        Segment, arc length into it [m] and height [m] of every point.
    pforce : ndarray, shape (K, 2)
        (F_X, F_Z) at every point [N]; points with no force cost nothing.

    Returns
    -------
    The tuple of `derivatives_kernel`.

    References
    ----------
    docs/physics.md, section 15.2.

    """
    count = 0
    for k in range(pseg.size):
        if pforce[k, 0] != 0.0 or pforce[k, 1] != 0.0:
            count += 1
    nodes = np.empty(load_nodes.size + count, dtype=np.int64)
    forces = np.empty((load_nodes.size + count, 2))
    nodes[:load_nodes.size] = load_nodes
    forces[:load_nodes.size] = load_forces
    j = load_nodes.size
    for k in range(pseg.size):
        if pforce[k, 0] != 0.0 or pforce[k, 1] != 0.0:
            nodes[j] = pseg[k]
            forces[j, 0], forces[j, 1] = pforce[k, 0], pforce[k, 1]
            j += 1
    energy, grad, lower = _assemble(x, lengths, stiffness, gas, pemc, work, nodes, forces)
    local = np.empty((4, 3))
    for k in range(pseg.size):
        if pforce[k, 0] == 0.0 and pforce[k, 1] == 0.0:
            continue
        i = pseg[k]
        a = 0.0 if i == 0 else x[3 * i - 1]
        energy += _face_load(a, x[3 * i], x[3 * i + 2], lengths[i], poff[k], pz[k],
                             pforce[k, 0], pforce[k, 1], local)
        # Local (a, e, b) = engine unknowns 3i - 1, 3i, 3i + 2 (a clamped for i = 0).
        e, b = 3 * i, 3 * i + 2
        grad[e] += local[0, 1]
        grad[b] += local[0, 2]
        lower[0, e] += local[2, 1]
        lower[2, e] += local[3, 1]
        lower[0, b] += local[3, 2]
        if i > 0:
            grad[e - 1] += local[0, 0]
            lower[0, e - 1] += local[1, 0]
            lower[1, e - 1] += local[2, 0]
            lower[3, e - 1] += local[3, 0]
    factor, step, definite = banded_step(lower, grad)
    return energy, grad, lower, factor, step, definite


# -- the engine's discretisation: the PCC rod as a namedtuple of arrays -----------------------
#: The PCC rod as `engine` runs it compiled: `section_arrays`, the segment lengths [m], k_p,
#: the gradient scale [J], and the segment (int64) and offset into it [m] of every output
#: sample. Its Hessian is (lower, factor, step, definite) of `derivatives_kernel`.
PCCData = collections.namedtuple('PCCData', ('lengths', 'stiffness', 'gas', 'pemc',
                                             'pressure_coefficient', 'gradient_scale',
                                             'sample_segment', 'sample_offset'))


@_jit
def pcc_derivatives(p, x, pressure, nodes, forces):
    """Energy [J], gradient (3N,) and banded Hessian (lower, factor, step, definite)."""
    energy, grad, lower, factor, step, definite = derivatives_kernel(
        x, p.lengths, p.stiffness, p.gas, p.pemc, p.pressure_coefficient * pressure, nodes,
        forces)
    return energy, grad, (lower, factor, step, definite)


@_jit
def pcc_energy(p, x, pressure, nodes, forces):
    """Total potential [J] of the PCC rod at engine unknowns x."""
    return energy_kernel(x, p.lengths, p.stiffness, p.gas, p.pemc,
                         p.pressure_coefficient * pressure, nodes, forces)


@_jit
def pcc_step(p, grad, hess):
    """Newton step by banded Cholesky, or `shifted_step`; and lambda_min (1.0 if PD)."""
    lower, factor, step, definite = hess
    if definite:
        return step, 1.0
    return shifted_step(lower, grad, p.gradient_scale)


@_jit
def pcc_solve_linear(p, hess, rhs):
    """Solve H x = rhs (banded Cholesky, else dense LU): (x, True), or (rhs, False)."""
    lower, factor, _, definite = hess
    if definite:
        return cholesky_solve(factor, rhs), True
    try:
        return np.linalg.solve(_dense_from_band(lower), rhs), True
    except Exception:
        return rhs.copy(), False


@_jit
def pcc_node_jacobian(p, x, node):
    """Position (2,) of node `node` [m] and its derivatives (2, 3N)."""
    return node_jacobian_kernel(x, p.lengths, node)


@_jit
def pcc_point_derivatives(p, x, pressure, nodes, forces, pseg, poff, pz, pforce):
    """Energy, gradient and banded Hessian with node and face-point loads."""
    energy, grad, lower, factor, step, definite = point_derivatives_kernel(
        x, p.lengths, p.stiffness, p.gas, p.pemc, p.pressure_coefficient * pressure, nodes,
        forces, pseg, poff, pz, pforce)
    return energy, grad, (lower, factor, step, definite)


@_jit
def pcc_point_positions(p, x, pseg, poff, pz):
    """Positions (K, 2) of face points [m]."""
    return point_positions_kernel(x, p.lengths, pseg, poff, pz)


@_jit
def pcc_point_jacobian(p, x, seg, offset, z):
    """Position (2,) of a face point [m] and its derivatives (2, 3N)."""
    return point_jacobian_kernel(x, p.lengths, seg, offset, z)


# -- the outputs of a state ---------------------------------------------------------------
@_jit
def pcc_outputs(p, x, pressure, nodes, forces, samples):
    """
    Return `engine.newton.OUTPUT_FIELDS` of a PCC state x (3 N,), the engine unknowns.

    A sample at sigma into segment i has turned by kappa_i sigma, and its partial chord is
    (1 + eps_i) sigma S(kappa_i sigma) along the mean tangent: exactly on the arc; the last
    sample is the tip. coefficients are (eps, -kappa^2/6, c1, kappa/2) [-, 1/m^2, -, 1/m],
    the CCM's of a segment with the same uniform strain.

    References
    ----------
    docs/physics.md, sections 11.4 and 11.6.
    """
    lengths = p.lengths
    n = lengths.size
    chain_nodes = nodes_kernel(x, lengths)
    prev = np.empty(n)
    beta = np.empty(n)
    kappa = np.empty(n)
    coefficients = np.empty((n, 4))
    before = 0.0
    for i in range(n):
        eps, c1, theta = x[3 * i], x[3 * i + 1], x[3 * i + 2]
        prev[i] = before
        beta[i] = theta - before
        kappa[i] = beta[i] / lengths[i]
        coefficients[i, 0] = eps
        coefficients[i, 1] = -(kappa[i] * kappa[i]) / 6.0
        coefficients[i, 2] = c1
        coefficients[i, 3] = 0.5 * kappa[i]
        before = theta
    if not samples:
        return (chain_nodes, beta, prev, coefficients, True, np.nan, np.empty((0, 2)),
                np.empty(0), np.empty((0, 3)))
    energy = energy_kernel(x, lengths, p.stiffness, p.gas, p.pemc,
                           p.pressure_coefficient * pressure, nodes, forces)
    m = p.sample_segment.size
    points = np.empty((m, 2))
    tangent = np.empty(m)
    strains = np.empty((m, 3))
    for k in range(m):
        i = p.sample_segment[k]
        sigma = p.sample_offset[k]
        eps = x[3 * i]
        turn = kappa[i] * sigma
        half = prev[i] + 0.5 * turn
        reach = ((1.0 + eps) * sigma) * _sinc0(turn)
        points[k, 0] = chain_nodes[i, 0] + reach * math.cos(half)
        points[k, 1] = chain_nodes[i, 1] + reach * math.sin(half)
        tangent[k] = prev[i] + turn
        strains[k, 0] = eps
        strains[k, 1] = kappa[i]
        strains[k, 2] = x[3 * i + 1]
    points[m - 1, 0], points[m - 1, 1] = chain_nodes[n, 0], chain_nodes[n, 1]
    return chain_nodes, beta, prev, coefficients, True, energy, points, tangent, strains


#: The PCC's hooks, by the engine's names (`engine.register` takes them).
PCC_HOOKS = {'derivatives': pcc_derivatives, 'energy': pcc_energy, 'step': pcc_step,
             'solve_linear': pcc_solve_linear, 'node_jacobian': pcc_node_jacobian,
             'point_derivatives': pcc_point_derivatives, 'point_positions': pcc_point_positions,
             'point_jacobian': pcc_point_jacobian, 'outputs': pcc_outputs}
