"""Palm geometry of the gripper: finger frames, fingertip radii and the aperture."""

from dataclasses import dataclass
import math

import numpy as np

from fpc_gripper.model.validation import real_number

__all__ = ['PalmGeometry', 'aperture_from_points', 'tip_radius', 'tips_in_palm_frame']


def tip_radius(z_tip, palm_radius):
    """
    Signed radial position of a fingertip, rho = palm_radius + Z_tip.

    Parameters
    ----------
    z_tip : float or array_like
        Tip Z in the finger frame [m] (Z points radially outwards, away from the axis).
    palm_radius : float
        Palm centre to the clamp edge [m].

    Returns
    -------
    float or ndarray
        rho [m]; negative once the tip has crossed the palm axis.

    """
    rho = palm_radius + np.asarray(z_tip, dtype=float)
    return float(rho) if rho.ndim == 0 else rho


def tips_in_palm_frame(tips, palm_radius, mount_angles):
    """
    Fingertip positions in the palm frame.

    The palm frame has its origin at the palm centre, x and y in the palm plane
    (azimuth 0 along x) and z along the palm normal towards the object. Finger i
    is clamped at radius `palm_radius`, azimuth `mount_angles[i]`; its X axis is
    the palm normal and its Z axis points radially outwards, so its tip at
    (X, Z) lies at (rho cos(phi), rho sin(phi), X) with rho = palm_radius + Z.

    Parameters
    ----------
    tips : array_like, shape (n, 2)
        Tip (X, Z) of each finger in its own frame [m].
    palm_radius : float
        [m].
    mount_angles : array_like, shape (n,)
        Azimuths [rad].

    Returns
    -------
    ndarray, shape (n, 3)
        (x, y, z) in the palm frame [m].

    """
    tips = np.asarray(tips, dtype=float).reshape(-1, 2)
    phi = np.asarray(mount_angles, dtype=float).reshape(-1)
    if phi.shape[0] != tips.shape[0]:
        raise ValueError(f'`mount_angles` must have one angle per tip ({tips.shape[0]}), '
                         f'got {phi.shape[0]}')
    rho = palm_radius + tips[:, 1]
    return np.column_stack([rho * np.cos(phi), rho * np.sin(phi), tips[:, 0]])


def aperture_from_points(points):
    """
    Diameter of the circle through fingertip points projected on the palm plane.

    Parameters
    ----------
    points : array_like, shape (n, 2) or (n, 3)
        Palm-frame points [m]; only (x, y) are used.

    Returns
    -------
    float
        Aperture [m]. One point: twice its distance from the axis (the circle is
        centred on the axis). Two points: their distance (the smallest circle
        through both). Three points: the circumscribed circle, ``inf`` when they are
        collinear. More points: the algebraic (Kasa) least-squares circle.

    References
    ----------
    Circumradius R = abc / (4 area) of a triangle with sides a, b, c.

    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[0] < 1 or pts.shape[1] < 2:
        raise ValueError(f'`points` must have shape (n, 2) or (n, 3) [m], got {pts.shape}')
    xy = pts[:, :2]
    n = xy.shape[0]
    if n == 1:
        return 2.0 * float(np.hypot(*xy[0]))
    if n == 2:
        return float(np.hypot(*(xy[1] - xy[0])))
    if n == 3:
        a = np.hypot(*(xy[1] - xy[2]))
        b = np.hypot(*(xy[2] - xy[0]))
        c = np.hypot(*(xy[0] - xy[1]))
        u, v = xy[1] - xy[0], xy[2] - xy[0]
        area2 = abs(u[0] * v[1] - u[1] * v[0])  # twice the triangle's area
        if area2 <= 1e-15 * max(a * b, 1e-300):
            return math.inf
        return float(a * b * c / area2)      # 2 R = abc / (2 area)
    design = np.column_stack([2.0 * xy, np.ones(n)])
    rhs = (xy ** 2).sum(axis=1)
    (cx, cy, k), *_ = np.linalg.lstsq(design, rhs, rcond=None)
    return 2.0 * math.sqrt(max(k + cx * cx + cy * cy, 0.0))


@dataclass(frozen=True)
class PalmGeometry:
    """
    Fingers clamped on a circle around the palm axis.

    Attributes
    ----------
    palm_radius : float
        Palm centre to every clamp edge [m].
    mount_angles : tuple of float
        Azimuth of each finger [rad].

    Notes
    -----
    Finger i's X axis is the palm normal (away from the palm, towards the object)
    and its -Z axis points radially inwards (the closing direction). Its tip is at
    signed radius rho = palm_radius + Z_tip and axial position X_tip.

    Region of use. The controller works where rho is a strictly increasing function
    of the gauge pressure. For the paper's finger (prestrain 0.25, CCM8, adiabatic)
    Z_tip rises monotonically from -59.6 mm at 0 kPa, through 0 near 313 kPa, to
    about +26.9 mm at 400 kPa and keeps rising up to about 675 kPa, where the tip
    curls back past the palm normal; tip loads along Z within +-0.3 N keep it
    monotone on [0, 400 kPa]. With palm_radius = 62 mm the closed finger (0 kPa)
    puts the tips 2.4 mm from the axis (rho > 0, no crossing) and 400 kPa opens
    them to rho = 88.9 mm. `fpc_gripper.control.inverse.InverseModel` checks
    monotonicity on its pressure grid when it is built.

    """

    palm_radius: float
    mount_angles: tuple

    def __post_init__(self):
        """Validate the radius and the angles."""
        radius = real_number('palm_radius', self.palm_radius, '[m]')
        if radius <= 0.0:
            raise ValueError(f'`palm_radius` must be > 0 [m], got {radius}')
        angles = tuple(real_number('mount_angles', a, '[rad]') for a in self.mount_angles)
        if not angles:
            raise ValueError('`mount_angles` must hold at least one angle [rad], got ()')
        object.__setattr__(self, 'palm_radius', radius)
        object.__setattr__(self, 'mount_angles', angles)

    @classmethod
    def from_config(cls, config):
        """Build from a `fpc_gripper.io.config.GripperConfig`."""
        return cls(palm_radius=config.palm_radius,
                   mount_angles=tuple(f.mount_angle for f in config.fingers))

    @property
    def n_fingers(self):
        """Number of fingers."""
        return len(self.mount_angles)

    def rho(self, z_tip):
        """Signed tip radius palm_radius + Z_tip [m] of a tip Z [m] (scalar or array)."""
        return tip_radius(z_tip, self.palm_radius)

    def z_for_rho(self, rho):
        """Tip Z [m] in the finger frame that puts the tip at radius `rho` [m]."""
        return rho - self.palm_radius

    def tip_points(self, tips):
        """Palm-frame (x, y, z) [m] of the finger-frame tips (n, 2) [m]."""
        return tips_in_palm_frame(tips, self.palm_radius, self.mount_angles)

    def aperture(self, tips):
        """Aperture [m]: diameter of the circle through the tips (n, 2) [m] in the palm plane."""
        return aperture_from_points(self.tip_points(tips))

    def aperture_from_rho(self, rhos):
        """Aperture [m] from the signed tip radii (n,) [m] of every finger."""
        rhos = np.asarray(rhos, dtype=float).reshape(-1)
        tips = np.column_stack([np.zeros_like(rhos), rhos - self.palm_radius])
        return self.aperture(tips)

    @staticmethod
    def rho_for_aperture(aperture):
        """
        Tip radius [m] that gives every finger the aperture `aperture` [m].

        Tips on a circle of diameter A centred on the palm axis all sit at rho = A/2,
        whatever their azimuths.
        """
        return 0.5 * real_number('aperture', aperture, '[m]')
