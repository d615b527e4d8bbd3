"""Rigid planar obstacles as the engine sees them: signed distance, normal and curvature."""

import math

from numba.extending import register_jitable
import numpy as np

from ..compiled import jit

__all__ = ['HALF_PLANE', 'CIRCLE', 'POLYGON', 'ELLIPSE', 'KIND_NAMES', 'signed_distance',
           'closest_point', 'FREE', 'NORMAL', 'STICK', 'SLIP_POS', 'SLIP_NEG', 'STATUS_NAMES',
           'shifted_params', 'pair_geometry', 'pair_forces']

# Obstacle kinds and the layout of their parameter row (padded with zeros):
#   HALF_PLANE  (nu_x, nu_z, c): the obstacle is {nu . p <= c}, nu its outward unit normal.
#   CIRCLE      (c_x, c_z, R).
#   POLYGON     (V, k, x_0, z_0, ..., x_{V-1}, z_{V-1}): a convex polygon, counter-clockwise
#               in (X, Z), its corners rounded by blending the two edges' distances over a
#               width k (a C2 smooth maximum), so its boundary's curvature is continuous.
#   ELLIPSE     (c_x, c_z, a, b, phi): semi-axes a along (cos, sin) phi and b across.
HALF_PLANE = 0
CIRCLE = 1
POLYGON = 2
ELLIPSE = 3
KIND_NAMES = ('half-plane', 'circle', 'polygon', 'ellipse')

# Status of a (finger point, obstacle) pair.
FREE = 0        # not in contact
NORMAL = 1      # in contact, frictionless: one row, g = 0
STICK = 2       # in contact, sticking: two rows, p = anchor
SLIP_POS = 3    # in contact, slipping: one row, force lambda (nu + mu tau)
SLIP_NEG = 4    # in contact, slipping: one row, force lambda (nu - mu tau)
STATUS_NAMES = ('free', 'frictionless', 'stick', 'slip', 'slip')

#: Bisection steps of the ellipse's closest point: the root is bracketed in a range of
#: size about 2 |p| a, and 80 halvings resolve it to round-off.
_ELLIPSE_STEPS = 80


@register_jitable
def _half_plane(params, px, pz):
    nx, nz = params[0], params[1]
    return nx * px + nz * pz - params[2], nx, nz, 0.0, -nz, nx


@register_jitable
def _circle(params, px, pz):
    dx, dz = px - params[0], pz - params[1]
    rho = math.hypot(dx, dz)
    if rho == 0.0:
        # The centre: every direction is a normal; take +X (only deep inside, never at
        # a converged contact).
        return -params[2], 1.0, 0.0, 0.0, 0.0, 1.0
    nx, nz = dx / rho, dz / rho
    return rho - params[2], nx, nz, 1.0 / rho, -nz, nx


@register_jitable
def _polygon(params, px, pz):
    """
    Smooth maximum of the edge-line distances of a convex CCW polygon.

    g = max_j s_j, s_j = n_j . (p - v_j), except where the two largest are within k of
    each other (at a corner): there g = max + k h^3 / 6, h = 1 - |s_a - s_b| / k (C2), and
    its Hessian is (h / k) (n_a - n_b)(n_a - n_b)^T.
    """
    count = int(params[0])
    width = params[1]
    first = second = -np.inf
    ax = az = bx = bz = 0.0
    for k in range(count):
        x0, z0 = params[2 + 2 * k], params[3 + 2 * k]
        j = (k + 1) % count
        ex, ez = params[2 + 2 * j] - x0, params[3 + 2 * j] - z0
        length = math.hypot(ex, ez)
        # Outward normal of a counter-clockwise polygon: the edge direction turned right.
        nx, nz = ez / length, -ex / length
        side = nx * (px - x0) + nz * (pz - z0)
        if side > first:
            second, bx, bz = first, ax, az
            first, ax, az = side, nx, nz
        elif side > second:
            second, bx, bz = side, nx, nz
    gap = first - second
    if gap >= width:
        return first, ax, az, 0.0, -az, ax
    h = 1.0 - gap / width
    # d/ds_a = 1/2 + (1/2)(1 - h^2) ... written as the weights of the two normals.
    wa = 1.0 - 0.5 * h * h
    gx, gz = wa * ax + (1.0 - wa) * bx, wa * az + (1.0 - wa) * bz
    dx, dz = ax - bx, az - bz
    size = math.hypot(dx, dz)
    return (first + width * h * h * h / 6.0, gx, gz, h / width * size * size, dx / size,
            dz / size)


@register_jitable
def _ellipse_root(a, b, u, v):
    """Closest point (x, y) on x^2/a^2 + y^2/b^2 = 1 to (u, v), u, v >= 0 (Eberly)."""
    if v == 0.0 and u < (a * a - b * b) / a:
        # On the major axis inside the evolute: the closest point is off the axis.
        x = a * a * u / (a * a - b * b)
        return x, b * math.sqrt(max(1.0 - (x / a) ** 2, 0.0))
    if u == 0.0 and v == 0.0:
        return 0.0, b
    # f(t) = (a u / (t + a^2))^2 + (b v / (t + b^2))^2 - 1 decreases for t > -b^2 (b <= a).
    low = -b * b + b * v
    high = -b * b + math.hypot(a * u, b * v)
    for _ in range(_ELLIPSE_STEPS):
        t = 0.5 * (low + high)
        f = (a * u / (t + a * a)) ** 2 + (b * v / (t + b * b)) ** 2 - 1.0
        if f > 0.0:
            low = t
        else:
            high = t
    t = 0.5 * (low + high)
    return a * a * u / (t + a * a), b * b * v / (t + b * b)


@register_jitable
def _ellipse(params, px, pz):
    cx, cz, a, b, phi = params[0], params[1], params[2], params[3], params[4]
    cs, sn = math.cos(phi), math.sin(phi)
    # Local frame with the major axis first (the root finder wants a >= b).
    du, dv = px - cx, pz - cz
    u, v = cs * du + sn * dv, -sn * du + cs * dv
    swap = b > a
    if swap:
        a, b, u, v = b, a, v, -u
    x, y = _ellipse_root(a, b, abs(u), abs(v))
    x, y = math.copysign(x, u), math.copysign(y, v)
    # Outward normal and curvature of the ellipse at (x, y).
    gx, gy = x / (a * a), y / (b * b)
    size = math.hypot(gx, gy)
    nx, ny = gx / size, gy / size
    curvature = 1.0 / (a * a * b * b * size ** 3)
    g = (u - x) * nx + (v - y) * ny
    if swap:
        nx, ny = -ny, nx
    # d2g/dp2 = k / (1 + k g) tau tau^T for a point at signed distance g along the normal.
    gx, gz = cs * nx - sn * ny, sn * nx + cs * ny
    return g, gx, gz, curvature / max(1.0 + curvature * g, 1e-12), -gz, gx


@register_jitable
def signed_distance(kind, params, px, pz):
    """
    Gap function of an obstacle at (px, pz): value, gradient and Hessian.

    Parameters
    ----------
    kind : int
        HALF_PLANE, CIRCLE, POLYGON or ELLIPSE.
    params : ndarray
        The obstacle's parameter row (see the module's layout) [m, rad].
    px, pz : float
        Point in the finger frame [m].

    Returns
    -------
    g : float
        > 0 outside, 0 on the boundary [m]: the signed distance for a half-plane, circle
        and ellipse; for a polygon the largest edge-line distance, smoothed at corners
        (the distance itself on the faces and inside).
    g_x, g_z : float
        Its gradient: the outward unit normal nu, except in a polygon's corner blend
        (there shorter than 1, along the normal of the rounded boundary).
    curvature : float
    v_x, v_z : float
        The Hessian of g is curvature v v^T, v a unit vector [1/m]: tau = (-nu_z, nu_x)
        with 1/|p - c| for a circle, k_b / (1 + k_b g) for an ellipse of boundary
        curvature k_b; 0 on flat faces.

    """
    if kind == HALF_PLANE:
        return _half_plane(params, px, pz)
    if kind == CIRCLE:
        return _circle(params, px, pz)
    if kind == POLYGON:
        return _polygon(params, px, pz)
    return _ellipse(params, px, pz)


@register_jitable
def closest_point(kind, params, px, pz):
    """Return the obstacle's boundary point nearest to (px, pz) [m] (one projection step)."""
    g, gx, gz, _, _, _ = signed_distance(kind, params, px, pz)
    size2 = gx * gx + gz * gz
    return px - g * gx / size2, pz - g * gz / size2


@jit
def pair_geometry(kind, params, positions, pair_point, pair_object):
    """
    `signed_distance` of every (point, obstacle) pair and the nearest boundary point.

    Parameters
    ----------
    kind : ndarray of int, shape (B,)
    params : ndarray, shape (B, P)
    positions : ndarray, shape (K, 2)
        Finger points [m].
    pair_point, pair_object : ndarray of int, shape (C,)

    Returns
    -------
    ndarray, shape (C, 6)
        g [m], the unit normal (nu_x, nu_z), |grad g| [-] and the nearest boundary point
        (X, Z) [m].

    """
    out = np.empty((pair_point.size, 6))
    for j in range(pair_point.size):
        k = pair_point[j]
        b = pair_object[j]
        px, pz = positions[k, 0], positions[k, 1]
        g, gx, gz, curvature, _, _ = signed_distance(kind[b], params[b], px, pz)
        size = math.hypot(gx, gz)
        out[j, 0], out[j, 1], out[j, 2], out[j, 3] = g, gx / size, gz / size, size
        out[j, 4], out[j, 5] = closest_point(kind[b], params[b], px, pz)
    return out


@jit
def pair_forces(kind, params, positions, pair_point, pair_object, status, lam, mu):
    """
    Gap, unit normal and contact force of every (point, obstacle) pair.

    Parameters
    ----------
    kind, params, positions, pair_point, pair_object
        As `pair_geometry`.
    status : ndarray of int, shape (C,)
    lam : ndarray, shape (C, 2)
        Pair multipliers: (lambda, 0) touching (the force is lambda (I + sigma mu R)
        grad g, sigma = +-1 slipping, 0 frictionless), the force itself when sticking.
    mu : float

    Returns
    -------
    gap : ndarray, shape (C,)
        [m].
    normal : ndarray, shape (C, 2)
        grad g / |grad g|.
    force : ndarray, shape (C, 2)
        On the finger [N]; zero for free pairs.
    normal_force, tangential_force : ndarray, shape (C,)
        force . normal and force . (-normal_z, normal_x) [N].

    """
    count = pair_point.size
    gap = np.empty(count)
    normal = np.empty((count, 2))
    force = np.zeros((count, 2))
    along = np.zeros(count)
    across = np.zeros(count)
    for j in range(count):
        k = pair_point[j]
        b = pair_object[j]
        g, gx, gz, _, _, _ = signed_distance(kind[b], params[b], positions[k, 0],
                                             positions[k, 1])
        size = math.hypot(gx, gz)
        nx, nz = gx / size, gz / size
        gap[j] = g
        normal[j, 0], normal[j, 1] = nx, nz
        s = status[j]
        if s == FREE:
            continue
        if s == STICK:
            fx, fz = lam[j, 0], lam[j, 1]
        else:
            sense = mu if s == SLIP_POS else (-mu if s == SLIP_NEG else 0.0)
            fx = lam[j, 0] * (gx - sense * gz)
            fz = lam[j, 0] * (gz + sense * gx)
        force[j, 0], force[j, 1] = fx, fz
        along[j] = fx * nx + fz * nz
        across[j] = -fx * nz + fz * nx
    return gap, normal, force, along, across


def shifted_params(kind, params, shifts):
    """
    Parameter rows of obstacles translated by `shifts` (B, 2) [m] (numpy, not compiled).

    Parameters
    ----------
    kind : ndarray of int, shape (B,)
    params : ndarray, shape (B, P)
    shifts : array_like, shape (B, 2)

    Returns
    -------
    ndarray, shape (B, P)

    """
    out = np.array(params, dtype=float)
    shifts = np.asarray(shifts, dtype=float).reshape(-1, 2)
    for b, (dx, dz) in enumerate(shifts):
        if kind[b] == HALF_PLANE:
            out[b, 2] += out[b, 0] * dx + out[b, 1] * dz
        elif kind[b] == POLYGON:
            count = int(out[b, 0])
            out[b, 2:2 + 2 * count:2] += dx
            out[b, 3:3 + 2 * count:2] += dz
        else:
            out[b, 0] += dx
            out[b, 1] += dz
    return out
