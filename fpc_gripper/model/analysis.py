"""Derived outputs: the geometric circle fit of a midplane and the flexural rigidity formula."""

from dataclasses import dataclass

import numpy as np

from .kernels import circle as circle_kernels

__all__ = ['CircleFit', 'fit_circle', 'flexural_rigidity']


@dataclass(frozen=True)
class CircleFit:
    """
    Result of an orthogonal-distance circle fit.

    Attributes
    ----------
    curvature : float
        Signed curvature [1/m], > 0 when the path turns clockwise in (X, Z),
        that is when a finger leaving along +X curls towards -Z.
    rmsd : float
        Root-mean-square orthogonal distance of the points to the circle [m].
    center : ndarray, shape (2,)
        Circle centre [m]; infinite for a straight line.

    """

    curvature: float
    rmsd: float
    center: np.ndarray


def _signed_distances(params, x, z, r2):
    """Signed orthogonal distances to the circle (A, D, phi) (`circle_kernels`), shape (M,)."""
    return circle_kernels.signed_distances(np.asarray(params, dtype=float), x, z, r2)


def _distance_jacobian(params, x, z, r2):
    """Exact d(distance)/d(A, D, phi) of `_signed_distances`, shape (M, 3)."""
    return circle_kernels.distance_jacobian(np.asarray(params, dtype=float), x, z, r2)


def fit_circle(points):
    """
    Fit a circle to points by orthogonal distance, regular at zero curvature.

    The circle is A (x^2 + z^2) + B x + C z + D = 0 with B^2 + C^2 - 4 A D = 1,
    parameterised by (A, D, phi) with (B, C) = sqrt(1 + 4 A D)(cos phi, sin phi),
    so that a straight line (A = 0) is an ordinary point. The exact orthogonal
    distance is 2 P / (1 + sqrt(1 + 4 A P)) with P the implicit function.
    Pratt's algebraic fit starts the Levenberg-Marquardt refinement. Compiled
    (`circle_kernels.circle_fit`): the batched sweeps fit their scenes with the same code.

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
    if not np.all(np.isfinite(pts)):
        raise ValueError('`points` must be finite [m]')
    curvature, rmsd, cx, cz = circle_kernels.circle_fit(np.ascontiguousarray(pts))
    return CircleFit(curvature=float(curvature), rmsd=float(rmsd), center=np.array([cx, cz]))


def flexural_rigidity(force, lever, displacement):
    """
    Cantilever-like flexural rigidity K = f l^3 / (3 delta), eq. (22) [N m^2].

    Parameters
    ----------
    force : float
        End load along the displacement [N].
    lever : float
        Lever arm in the loaded state [m].
    displacement : float
        Imposed tip displacement [m].

    References
    ----------
    Zhou, Headings, Dapino (2022), eq. (22); docs/physics.md, section 10.

    """
    return force * abs(lever) ** 3 / (3.0 * displacement)
