"""Reference circle fit with scipy (generalised eigenproblem, MINPACK LM), as before numba."""

import numpy as np
from scipy.linalg import eig
from scipy.optimize import least_squares

from fpc_gripper.model.analysis import CircleFit

__all__ = ['CircleFit', 'fit_circle']

# Pratt's normalisation B^2 + C^2 - 4 A D = 1 as a quadratic form in (A, B, C, D).
_PRATT = np.array([[0.0, 0.0, 0.0, -2.0],
                   [0.0, 1.0, 0.0, 0.0],
                   [0.0, 0.0, 1.0, 0.0],
                   [-2.0, 0.0, 0.0, 0.0]])


def _signed_distances(params, x, z, r2):
    a, d, phi = params
    u = np.sqrt(max(1.0 + 4.0 * a * d, 0.0))
    p = a * r2 + u * np.cos(phi) * x + u * np.sin(phi) * z + d
    return 2.0 * p / (1.0 + np.sqrt(np.maximum(1.0 + 4.0 * a * p, 0.0)))


def _distance_jacobian(params, x, z, r2):
    """Exact d(distance)/d(A, D, phi) of `_signed_distances`, shape (M, 3)."""
    a, d, phi = params
    u = np.sqrt(max(1.0 + 4.0 * a * d, 1e-300))
    c, s = np.cos(phi), np.sin(phi)
    along = c * x + s * z
    p = a * r2 + u * along + d
    q = np.sqrt(np.maximum(1.0 + 4.0 * a * p, 1e-300))
    one_q = 1.0 + q
    # d = 2 P / (1 + Q) with Q = sqrt(1 + 4 A P): partials in P and, explicitly, in A.
    dd_dp = 2.0 / one_q - 2.0 * p / one_q ** 2 * (2.0 * a / q)
    dd_da = -2.0 * p / one_q ** 2 * (2.0 * p / q)
    jac = np.empty((x.size, 3))
    jac[:, 0] = dd_dp * (r2 + 2.0 * d / u * along) + dd_da
    jac[:, 1] = dd_dp * (1.0 + 2.0 * a / u * along)
    jac[:, 2] = dd_dp * u * (-s * x + c * z)
    return jac


def fit_circle(points):
    """
    Fit a circle to points by orthogonal distance, regular at zero curvature.

    The circle is A (x^2 + z^2) + B x + C z + D = 0 with B^2 + C^2 - 4 A D = 1,
    parameterised by (A, D, phi) with (B, C) = sqrt(1 + 4 A D)(cos phi, sin phi),
    so that a straight line (A = 0) is an ordinary point. The exact orthogonal
    distance is 2 P / (1 + sqrt(1 + 4 A P)) with P the implicit function.
    Pratt's algebraic fit starts the Levenberg-Marquardt refinement.

    Parameters
    ----------
    points : array_like, shape (M, 2)
        Ordered (X, Z) samples [m], M >= 3; their order fixes the sign.

    Returns
    -------
    CircleFit

    References
    ----------
    Chernov, "Circular and Linear Regression" (2010), Sections 5.3 and 8.2;
    docs/physics.md, section 9.

    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 3:
        raise ValueError(f'`points` must have shape (M >= 3, 2), got {pts.shape}')
    centroid = pts.mean(axis=0)
    scale = float(np.abs(pts - centroid).max()) or 1.0
    x, z = ((pts - centroid) / scale).T
    r2 = x * x + z * z
    design = np.column_stack([r2, x, z, np.ones_like(x)])
    values, vectors = eig(design.T @ design, _PRATT)
    best = None
    for value, vec in zip(values, vectors.T):
        vec = vec.real
        norm = vec @ _PRATT @ vec
        if np.isfinite(value) and norm > 0 and (best is None or abs(value) < best[0]):
            best = (abs(value), vec / np.sqrt(norm))
    a, b, c, d = best[1]
    fit = least_squares(_signed_distances, (a, d, np.arctan2(c, b)), jac=_distance_jacobian,
                        args=(x, z, r2), method='lm', xtol=1e-15, ftol=1e-15, gtol=1e-15)
    a, d, phi = fit.x
    u = np.sqrt(max(1.0 + 4.0 * a * d, 0.0))
    b, c = u * np.cos(phi), u * np.sin(phi)
    dist = _signed_distances(fit.x, x, z, r2)
    # Orient the implicit function so its gradient at the first point is on the
    # left of the direction of travel; then A > 0 exactly for clockwise turning.
    tx, tz = x[1] - x[0], z[1] - z[0]
    if (2 * a * x[0] + b) * (-tz) + (2 * a * z[0] + c) * tx < 0.0:
        a, b, c, d = -a, -b, -c, -d
    if a != 0.0:
        center = centroid + scale * np.array([-b / (2 * a), -c / (2 * a)])
    else:
        center = np.array([np.inf, np.inf])
    return CircleFit(curvature=float(2.0 * a / scale),
                     rmsd=float(scale * np.sqrt(np.mean(dist * dist))), center=center)
