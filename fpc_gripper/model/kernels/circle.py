"""Compiled (numba) circle fit: the orthogonal-distance circle through a finger's samples."""

import math

import numpy as np

from .arc import _cholesky3, _substitute3
from ..compiled import jit

__all__ = ['signed_distances', 'distance_jacobian', 'circle_fit']

# Built at install (`compiled`), once per argument types; nogil lets a caller thread them.
_jit = jit
#: Levenberg-Marquardt: largest iteration count, and the step (in the scaled parameters
#: (A, D, phi), all of order one after centring and scaling) below which it has converged
#: (Gauss-Newton contracts by about the relative residual, 1e-4 for a finger, per step, so
#: the state is then within round-off of the minimum).
_LM_ITERATIONS = 200
_LM_XTOL = 1e-12
_GAUSS_NEWTON = 1e-8


# -- the circle fit -------------------------------------------------------------------------
@_jit
def signed_distances(params, x, z, r2):
    """
    Signed orthogonal distance of every point to the circle (A, D, phi), shape (M,).

    The circle is A r^2 + B x + C z + D = 0 with (B, C) = sqrt(1 + 4 A D)(cos, sin)(phi);
    the distance is 2 P / (1 + sqrt(1 + 4 A P)), P the implicit function (Chernov 2010,
    section 8.2).
    """
    a, d, phi = params[0], params[1], params[2]
    u = math.sqrt(max(1.0 + 4.0 * a * d, 0.0))
    c, s = u * math.cos(phi), u * math.sin(phi)
    out = np.empty(x.size)
    for k in range(x.size):
        p = a * r2[k] + c * x[k] + s * z[k] + d
        out[k] = 2.0 * p / (1.0 + math.sqrt(max(1.0 + 4.0 * a * p, 0.0)))
    return out


@_jit
def distance_jacobian(params, x, z, r2):
    """Exact d(distance)/d(A, D, phi) of `signed_distances`, shape (M, 3)."""
    a, d, phi = params[0], params[1], params[2]
    u = math.sqrt(max(1.0 + 4.0 * a * d, 1e-300))
    c, s = math.cos(phi), math.sin(phi)
    jac = np.empty((x.size, 3))
    for k in range(x.size):
        along = c * x[k] + s * z[k]
        p = a * r2[k] + u * along + d
        q = math.sqrt(max(1.0 + 4.0 * a * p, 1e-300))
        one_q = 1.0 + q
        # d = 2 P / (1 + Q) with Q = sqrt(1 + 4 A P): partials in P and, explicitly, in A.
        dd_dp = 2.0 / one_q - 2.0 * p / one_q ** 2 * (2.0 * a / q)
        dd_da = -2.0 * p / one_q ** 2 * (2.0 * p / q)
        jac[k, 0] = dd_dp * (r2[k] + 2.0 * d / u * along) + dd_da
        jac[k, 1] = dd_dp * (1.0 + 2.0 * a / u * along)
        jac[k, 2] = dd_dp * u * (-s * x[k] + c * z[k])
    return jac


@_jit
def _pratt(x, z, r2):
    """
    Pratt's algebraic circle (A, B, C, D), B^2 + C^2 - 4 A D = 1, of centred, scaled points.

    Its eigenvalue is the smallest non-negative root of det(M - eta N) (M the moment
    matrix of (r^2, x, z, 1), N Pratt's constraint), found by Newton from 0 on that
    quartic (Chernov 2010, section 5.3); the circle is the null vector of M - eta N,
    regular for a straight line (A = 0).
    """
    n = x.size
    mxx = myy = mxy = mxz = myz = mzz = 0.0
    for k in range(n):
        mxx += x[k] * x[k]
        myy += z[k] * z[k]
        mxy += x[k] * z[k]
        mxz += x[k] * r2[k]
        myz += z[k] * r2[k]
        mzz += r2[k] * r2[k]
    mxx, myy, mxy, mxz, myz, mzz = mxx / n, myy / n, mxy / n, mxz / n, myz / n, mzz / n
    mz = mxx + myy
    cov = mxx * myy - mxy * mxy
    a2 = 4.0 * cov - 3.0 * mz * mz - mzz
    a1 = mzz * mz + 4.0 * cov * mz - mxz * mxz - myz * myz - mz * mz * mz
    a0 = mxz * mxz * myy + myz * myz * mxx - mzz * cov - 2.0 * mxz * myz * mxy + mz * mz * cov
    eta = 0.0
    value = 1e300
    for _ in range(100):
        previous = value
        value = a0 + eta * (a1 + eta * (a2 + 4.0 * eta * eta))
        if abs(value) >= abs(previous):
            break
        slope = a1 + eta * (2.0 * a2 + 16.0 * eta * eta)
        if slope == 0.0:
            break
        step = value / slope
        eta = max(eta - step, 0.0)
        if abs(step) <= 1e-15 * max(eta, 1e-300):
            break
    # M (centred: the x and z means vanish) minus eta N, whose null vector is the circle.
    m = np.empty((4, 4))
    m[0, 0], m[0, 1], m[0, 2], m[0, 3] = mzz, mxz, myz, mz + 2.0 * eta
    m[1, 1], m[1, 2], m[1, 3] = mxx - eta, mxy, 0.0
    m[2, 2], m[2, 3] = myy - eta, 0.0
    m[3, 3] = 1.0
    for i in range(4):
        for j in range(i):
            m[i, j] = m[j, i]
    out = _null_vector(m)
    norm = out[1] * out[1] + out[2] * out[2] - 4.0 * out[0] * out[3]
    if not norm > 0.0:
        out = -out
        norm = -norm
    return out / math.sqrt(norm) if norm > 0.0 else out


@_jit
def _minor3(k, row, col):
    """Return the determinant of 4 x 4 k with `row` and `col` struck out (a 3 x 3 minor)."""
    rows = np.empty(3, dtype=np.int64)
    cols = np.empty(3, dtype=np.int64)
    a = b = 0
    for i in range(4):
        if i != row:
            rows[a] = i
            a += 1
        if i != col:
            cols[b] = i
            b += 1
    r0, r1, r2 = rows[0], rows[1], rows[2]
    c0, c1, c2 = cols[0], cols[1], cols[2]
    return (k[r0, c0] * (k[r1, c1] * k[r2, c2] - k[r1, c2] * k[r2, c1])
            - k[r0, c1] * (k[r1, c0] * k[r2, c2] - k[r1, c2] * k[r2, c0])
            + k[r0, c2] * (k[r1, c0] * k[r2, c1] - k[r1, c1] * k[r2, c0]))


@_jit
def _null_vector(k):
    """
    Null vector of a symmetric 4 x 4 k of rank 3 (or its least singular direction).

    adj(k) = det(k) k^-1 is dominated by v v^T of the eigenvalue nearest zero, so its
    column of largest diagonal entry is that eigenvector, up to scale.
    """
    best = 0
    largest = -1.0
    for j in range(4):
        value = abs(_minor3(k, j, j))
        if value > largest:
            best, largest = j, value
    out = np.empty(4)
    for i in range(4):
        out[i] = (-1.0) ** (i + best) * _minor3(k, best, i)
    return out


@_jit
def _solve3(h, g, lam):
    """Solve (h + lam diag(h)) dx = -g for the 3 x 3 normal matrix h (Cholesky)."""
    a = h.copy()
    for i in range(3):
        a[i, i] += lam * max(h[i, i], 1e-300)
    low, definite = _cholesky3(a)
    if not definite:
        return np.full(3, np.nan)
    return _substitute3(low, -g)


@_jit
def _normal_equations(params, x, z, r2, h, g):
    """Sum of squared distances at `params`; fills J^T J into h (3, 3) and J^T r into g."""
    a, d, phi = params[0], params[1], params[2]
    u = math.sqrt(max(1.0 + 4.0 * a * d, 1e-300))
    c, s = math.cos(phi), math.sin(phi)
    d_u, a_u = 2.0 * d / u, 2.0 * a / u
    # Sums in scalars (registers over the loop), written to h and g at the end.
    g0 = g1 = g2 = h00 = h01 = h02 = h11 = h12 = h22 = 0.0
    cost = 0.0
    for k in range(x.size):
        along = c * x[k] + s * z[k]
        p = a * r2[k] + u * along + d
        q = math.sqrt(max(1.0 + 4.0 * a * p, 1e-300))
        # One division for 1 / (1 + Q) and 1 / (Q (1 + Q)).
        both = 1.0 / (q * (1.0 + q))
        inv = q * both
        r = 2.0 * p * inv
        # As `distance_jacobian`: d = 2 P / (1 + Q), Q = sqrt(1 + 4 A P).
        ratio = r * both
        dd_dp = 2.0 * inv - 2.0 * a * ratio
        dd_da = -2.0 * p * ratio
        j0 = dd_dp * (r2[k] + d_u * along) + dd_da
        j1 = dd_dp * (1.0 + a_u * along)
        j2 = dd_dp * u * (-s * x[k] + c * z[k])
        cost += r * r
        g0 += j0 * r
        g1 += j1 * r
        g2 += j2 * r
        h00 += j0 * j0
        h01 += j0 * j1
        h02 += j0 * j2
        h11 += j1 * j1
        h12 += j1 * j2
        h22 += j2 * j2
    g[0], g[1], g[2] = g0, g1, g2
    h[0, 0], h[0, 1], h[0, 2] = h00, h01, h02
    h[1, 0], h[1, 1], h[1, 2] = h01, h11, h12
    h[2, 0], h[2, 1], h[2, 2] = h02, h12, h22
    return cost


@_jit
def _levenberg_marquardt(params, x, z, r2):
    """
    Minimise the sum of squared `signed_distances` over (A, D, phi) from `params`.

    Marquardt's damping (lam diag(J^T J)) where a step does not decrease the cost; a
    step below `_GAUSS_NEWTON` is taken undamped, since there the cost changes by less
    than its own round-off and only Gauss-Newton's quadratic convergence still tells.
    A step below `_LM_XTOL` is the last: taken without evaluating its end, where the cost
    is stationary to far below its round-off. (`signed_distances` and `distance_jacobian`
    are the same formulas, one point at a time.) One evaluation and one solve per pass.

    Returns
    -------
    params : ndarray, shape (3,)
    cost : float
        The sum of squared distances, at the last evaluated parameters.

    """
    h = np.empty((3, 3))
    g = np.empty(3)
    h_trial = np.empty((3, 3))
    g_trial = np.empty(3)
    trial = params.copy()
    cost = np.inf
    size = np.inf
    lam = 1e-3
    for _ in range(_LM_ITERATIONS):
        cost_trial = _normal_equations(trial, x, z, r2, h_trial, g_trial)
        if cost_trial <= cost or size <= _GAUSS_NEWTON:
            # Swap the buffers (a slice copy would cost seconds of compile).
            params, cost = trial, cost_trial
            h, h_trial = h_trial, h
            g, g_trial = g_trial, g
            lam = max(0.1 * lam, 1e-12)
        elif cost == np.inf:
            # Not finite where it starts: nothing to refine.
            break
        else:
            lam *= 10.0
            if not lam < 1e16:
                break
        step = _solve3(h, g, lam)
        size = max(abs(step[0]), abs(step[1]), abs(step[2]))
        if not size < np.inf:
            break
        trial = params + step
        if size <= _LM_XTOL:
            return trial, cost
    return params, cost


@_jit
def circle_fit(points):
    """
    Orthogonal-distance circle through ordered points: (curvature, rmsd, centre X, centre Z).

    The points are centred and scaled by their largest coordinate; Pratt's fit
    (`_pratt`) starts Levenberg-Marquardt on the exact orthogonal distances in Chernov's
    (A, D, phi), regular at zero curvature. The sign is fixed by the direction of travel:
    curvature = 2 A > 0 when the path turns clockwise in (X, Z), i.e. curls towards -Z.
    The centre is infinite for a straight line. Needs M >= 3 points.

    References
    ----------
    Chernov, "Circular and Linear Regression" (2010), Sections 5.3 and 8.2;
    docs/physics.md, section 9.
    """
    n = points.shape[0]
    cx = cz = 0.0
    for k in range(n):
        cx += points[k, 0]
        cz += points[k, 1]
    if not (abs(cx) < np.inf and abs(cz) < np.inf):
        # A non-finite sample (NaN or inf) makes a sum non-finite.
        return np.nan, np.nan, np.nan, np.nan
    cx /= n
    cz /= n
    scale = 0.0
    for k in range(n):
        scale = max(scale, abs(points[k, 0] - cx), abs(points[k, 1] - cz))
    if scale == 0.0:
        scale = 1.0
    x = np.empty(n)
    z = np.empty(n)
    r2 = np.empty(n)
    for k in range(n):
        x[k] = (points[k, 0] - cx) / scale
        z[k] = (points[k, 1] - cz) / scale
        r2[k] = x[k] * x[k] + z[k] * z[k]
    start = _pratt(x, z, r2)
    params = np.array([start[0], start[3], math.atan2(start[2], start[1])])
    params, square = _levenberg_marquardt(params, x, z, r2)
    a, d, phi = params[0], params[1], params[2]
    u = math.sqrt(max(1.0 + 4.0 * a * d, 0.0))
    b, c = u * math.cos(phi), u * math.sin(phi)
    # Orient the implicit function so that its gradient at the first point is on the left
    # of the direction of travel; then A > 0 exactly for clockwise turning.
    tx, tz = x[1] - x[0], z[1] - z[0]
    if (2.0 * a * x[0] + b) * (-tz) + (2.0 * a * z[0] + c) * tx < 0.0:
        a, b, c = -a, -b, -c
    if a != 0.0:
        center_x = cx + scale * (-b / (2.0 * a))
        center_z = cz + scale * (-c / (2.0 * a))
    else:
        center_x = center_z = np.inf
    return 2.0 * a / scale, scale * math.sqrt(square / n), center_x, center_z
