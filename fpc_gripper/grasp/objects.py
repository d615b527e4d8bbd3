"""Rigid objects in the palm frame and their sections in each finger's plane."""

from dataclasses import dataclass
import math

from fpc_gripper.model.contact import Circle, ConvexPolygon, Ellipse
from fpc_gripper.model.validation import real_number

__all__ = ['CoaxialCylinder', 'Sphere', 'CrossCylinder', 'Box', 'make_object', 'OBJECTS']

#: Radius of the rounded edges of cylinder ends and boxes [m]: larger than the spacing of
#: the finger's contact points (1.4 mm on the default contact model), so that the finger
#: slides over an edge instead of hopping from point to point.
EDGE_RADIUS = 2.5e-3
#: |sin| of the angle between a cylinder's axis and a finger's plane below which the plane
#: holds the axis: the section is a strip, not an ellipse.
_PARALLEL = 1e-9


def _positive(name, value):
    value = real_number(name, value, '[m]')
    if value <= 0.0:
        raise ValueError(f'`{name}` must be > 0 [m], got {value}')
    return value


def _above_palm(name, lowest):
    if lowest < 0.0:
        raise ValueError(f'the object intersects the palm: `{name}` puts its lowest point at '
                         f'{lowest:.4g} m along the palm axis, below the palm (0 m)')


def _centre(diameter, center):
    """Check a diameter and a centre height (default: resting on the palm) [m]."""
    diameter = _positive('diameter', diameter)
    center = 0.5 * diameter if center is None else real_number('center', center, '[m]')
    _above_palm('center', center - 0.5 * diameter)
    return diameter, center


def _rectangle(x_low, x_high, half_width, palm_radius):
    """Section X in [x_low, x_high], |rho| <= half_width, as a polygon in the finger frame."""
    z_low, z_high = -palm_radius - half_width, -palm_radius + half_width
    # Small sections get proportionally rounder edges: a tenth of the shorter side at most.
    radius = min(EDGE_RADIUS, 0.1 * min(x_high - x_low, 2.0 * half_width))
    return ConvexPolygon([(x_low, z_low), (x_high, z_low), (x_high, z_high), (x_low, z_high)],
                         radius)


@dataclass(frozen=True)
class CoaxialCylinder:
    """
    A cylinder on the palm axis: the fingers close on its side.

    Parameters
    ----------
    diameter : float
        [m].
    length : float
        Along the palm axis [m].
    base : float
        Height of its bottom face above the palm along the axis [m], >= 0.

    """

    diameter: float
    length: float = 0.120
    base: float = 0.0

    def __post_init__(self):
        """Check the sizes and that it clears the palm."""
        object.__setattr__(self, 'diameter', _positive('diameter', self.diameter))
        object.__setattr__(self, 'length', _positive('length', self.length))
        base = real_number('base', self.base, '[m]')
        _above_palm('base', base)
        object.__setattr__(self, 'base', base)

    def section(self, mount_angle, palm_radius):
        """Return the rectangle X in [base, base + length], |rho| <= D/2 (finger frame)."""
        return (_rectangle(self.base, self.base + self.length, 0.5 * self.diameter,
                           palm_radius),)


@dataclass(frozen=True)
class Sphere:
    """
    A sphere centred on the palm axis.

    Parameters
    ----------
    diameter : float
        [m].
    center : float
        Height of its centre above the palm along the axis [m], >= D/2.

    """

    diameter: float
    center: float = None

    def __post_init__(self):
        """Check the size; the centre defaults to resting on the palm."""
        diameter, center = _centre(self.diameter, self.center)
        object.__setattr__(self, 'diameter', diameter)
        object.__setattr__(self, 'center', center)

    def section(self, mount_angle, palm_radius):
        """Return the great circle: centre (X, Z) = (center, -palm_radius), radius D/2."""
        return (Circle((self.center, -palm_radius), 0.5 * self.diameter),)


def _across(azimuth, mount_angle):
    """(|cos|, |sin|) of the angle between a horizontal axis and a finger's plane."""
    delta = mount_angle - azimuth
    return abs(math.cos(delta)), abs(math.sin(delta))


@dataclass(frozen=True)
class CrossCylinder:
    """
    A cylinder lying across the palm, its axis horizontal at an azimuth.

    In a finger plane at angle delta to its axis the section is the ellipse
    (X - h)^2 + rho^2 sin^2 delta <= R^2 (semi-axes R along the palm axis, R / |sin delta|
    radially), or the strip |X - h| <= R when the plane holds the axis. The section's
    in-plane normal carries the contact; the out-of-plane part of the real normal, which
    would twist the finger, is not modelled.

    Parameters
    ----------
    diameter : float
        [m].
    length : float
        [m]; its ends must not cut any finger's section within the reach of the fingers.
    center : float
        Height of its axis above the palm [m], >= D/2.
    azimuth : float
        Direction of its axis in the palm plane [rad].

    """

    diameter: float
    length: float = 0.300
    center: float = None
    azimuth: float = math.pi / 2

    def __post_init__(self):
        """Check the sizes and that it clears the palm."""
        diameter, center = _centre(self.diameter, self.center)
        object.__setattr__(self, 'diameter', diameter)
        object.__setattr__(self, 'length', _positive('length', self.length))
        object.__setattr__(self, 'center', center)
        object.__setattr__(self, 'azimuth', real_number('azimuth', self.azimuth, '[rad]'))

    def section(self, mount_angle, palm_radius, reach=0.2):
        """Return the ellipse (or strip) in the finger frame; `reach` [m]: radius to cover."""
        radius = 0.5 * self.diameter
        cos_d, sin_d = _across(self.azimuth, mount_angle)
        if sin_d <= _PARALLEL:
            return (_rectangle(self.center - radius, self.center + radius, 0.5 * self.length,
                               palm_radius),)
        if cos_d > _PARALLEL and 0.5 * self.length / cos_d < min(radius / sin_d, reach):
            raise ValueError(f'`length` {self.length} m is too short: the end of the cylinder '
                             f'cuts its section in the finger plane at {mount_angle:.4g} rad')
        return (Ellipse((self.center, -palm_radius), (radius, radius / sin_d), 0.0),)


@dataclass(frozen=True)
class Box:
    """
    A box lying across the palm: a square-ish bar with a horizontal long axis.

    Its section in a finger plane at angle delta to the long axis is the rectangle
    X in [base, base + height], |rho| <= min(length / (2 |cos|), width / (2 |sin|)).

    Parameters
    ----------
    width : float
        Across its long axis, in the palm plane [m].
    height : float
        Along the palm axis [m] (default: the width).
    length : float
        Along its long axis [m].
    base : float
        Height of its bottom face above the palm [m], >= 0.
    azimuth : float
        Direction of the long axis in the palm plane [rad].

    """

    width: float
    height: float = None
    length: float = 0.200
    base: float = 0.0
    azimuth: float = math.pi / 2

    def __post_init__(self):
        """Check the sizes and that it clears the palm."""
        width = _positive('width', self.width)
        height = width if self.height is None else _positive('height', self.height)
        base = real_number('base', self.base, '[m]')
        _above_palm('base', base)
        object.__setattr__(self, 'width', width)
        object.__setattr__(self, 'height', height)
        object.__setattr__(self, 'length', _positive('length', self.length))
        object.__setattr__(self, 'base', base)
        object.__setattr__(self, 'azimuth', real_number('azimuth', self.azimuth, '[rad]'))

    def section(self, mount_angle, palm_radius):
        """Return the rectangle in the finger frame."""
        cos_d, sin_d = _across(self.azimuth, mount_angle)
        half = math.inf
        if cos_d > _PARALLEL:
            half = 0.5 * self.length / cos_d
        if sin_d > _PARALLEL:
            half = min(half, 0.5 * self.width / sin_d)
        return (_rectangle(self.base, self.base + self.height, half, palm_radius),)


#: Names of `fpc-grasp --object`.
OBJECTS = ('cylinder', 'sphere', 'box')


def make_object(kind, diameter, height=0.0):
    """
    Return the object `fpc-grasp --object` names, of a size D.

    Parameters
    ----------
    kind : {'cylinder', 'sphere', 'box'}
        A cylinder coaxial with the palm axis, a sphere centred on it, or a box of D x D
        section lying across the palm (across finger 0's plane).
    diameter : float
        D [m].
    height : float
        Height of the object's lowest point above the palm [m] (0: resting on it).

    """
    height = real_number('height', height, '[m]')
    if kind == 'cylinder':
        return CoaxialCylinder(diameter, base=height)
    if kind == 'sphere':
        diameter = _positive('diameter', diameter)
        return Sphere(diameter, center=height + 0.5 * diameter)
    if kind == 'box':
        return Box(diameter, base=height)
    raise ValueError(f'`kind` must be one of {OBJECTS}, got {kind!r}')
