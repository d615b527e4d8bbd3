"""Rigid planar obstacles of contact scenes: discs, half-planes, rounded polygons, ellipses."""

from dataclasses import dataclass
import math

import numpy as np

from .kernels import contact as ck
from .validation import real_number, real_pair

__all__ = ['Circle', 'HalfPlane', 'ConvexPolygon', 'Ellipse', 'translated', 'check_obstacles',
           'obstacle_params']


def _point(name, value):
    pair = real_pair(name, value, '[m]')
    return np.array(pair)


def _unit(name, value):
    vector = np.array(real_pair(name, value, '[-]'))
    size = math.hypot(*vector)
    if size == 0.0:
        raise ValueError(f'`{name}` must be a non-zero vector, got {tuple(value)!r}')
    return vector / size


@dataclass(frozen=True)
class Circle:
    """
    A disc in the finger's (X, Z) plane: a cylinder along Y, or a sphere's section.

    Parameters
    ----------
    center : (float, float)
        (X, Z) [m].
    radius : float
        [m], > 0.

    """

    center: tuple
    radius: float

    kind = ck.CIRCLE

    def __post_init__(self):
        """Check the centre and radius."""
        object.__setattr__(self, 'center', tuple(_point('center', self.center)))
        radius = real_number('radius', self.radius, '[m]')
        if radius <= 0.0:
            raise ValueError(f'`radius` must be > 0 [m], got {radius}')
        object.__setattr__(self, 'radius', radius)

    @property
    def reference(self):
        """Point the moment on the obstacle is taken about: the centre [m]."""
        return np.array(self.center)

    def row(self):
        """Parameter row of `kernels.contact`."""
        return np.array([*self.center, self.radius])


@dataclass(frozen=True)
class HalfPlane:
    """
    The half-plane behind a straight boundary: a table, a wall or a box face.

    Parameters
    ----------
    point : (float, float)
        A point of the boundary, (X, Z) [m].
    normal : (float, float)
        Outward normal: from the obstacle into free space (normalised) [-].

    """

    point: tuple
    normal: tuple

    kind = ck.HALF_PLANE

    def __post_init__(self):
        """Check and normalise."""
        object.__setattr__(self, 'point', tuple(_point('point', self.point)))
        object.__setattr__(self, 'normal', tuple(_unit('normal', self.normal)))

    @property
    def reference(self):
        """Point the moment on the obstacle is taken about: `point` [m]."""
        return np.array(self.point)

    def row(self):
        """Parameter row of `kernels.contact`."""
        normal = np.array(self.normal)
        return np.array([*normal, float(normal @ np.array(self.point))])


@dataclass(frozen=True)
class ConvexPolygon:
    """
    A convex polygon with rounded corners: a box section.

    Parameters
    ----------
    vertices : array_like, shape (V, 2)
        (X, Z) [m], V >= 3, in either order; strictly convex.
    corner_radius : float
        Smallest radius of curvature of the rounding at a right-angle corner [m], > 0.
        The corners are rounded by a C2 smooth maximum of the two edges' distances over a
        width 2 sqrt(2) r (docs/physics.md, section 15.1), so the boundary's curvature is
        continuous and Newton keeps its quadratic rate where the finger rests on a
        corner; a sharp corner has no normal there. It must leave every edge at least
        twice that width long.

    """

    vertices: tuple
    corner_radius: float = 0.5e-3

    kind = ck.POLYGON

    def __post_init__(self):
        """Check convexity and the rounding, and orient counter-clockwise."""
        try:
            verts = np.array(self.vertices, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f'`vertices` must be (V, 2) real numbers [m], got '
                             f'{self.vertices!r}') from None
        if verts.ndim != 2 or verts.shape[1] != 2 or verts.shape[0] < 3:
            raise ValueError(f'`vertices` must have shape (V, 2) with V >= 3 [m], got '
                             f'{verts.shape}')
        if not np.all(np.isfinite(verts)):
            raise ValueError(f'`vertices` must be finite [m], got {verts.tolist()}')
        radius = real_number('corner_radius', self.corner_radius, '[m]')
        if radius <= 0.0:
            raise ValueError(f'`corner_radius` must be > 0 [m], got {radius}')
        edges = np.roll(verts, -1, axis=0) - verts
        turns = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1] \
            - edges[:, 1] * np.roll(edges, -1, axis=0)[:, 0]
        if not (np.all(turns > 0.0) or np.all(turns < 0.0)):
            raise ValueError('`vertices` must form a strictly convex polygon [m], got '
                             f'{verts.tolist()}')
        if turns[0] < 0.0:
            verts = verts[::-1].copy()
        shortest = float(np.hypot(edges[:, 0], edges[:, 1]).min())
        if 2.0 * self.blend_width_of(radius) > shortest:
            most = shortest / (4.0 * math.sqrt(2.0))
            raise ValueError(f'`corner_radius` must be at most {most:.3g} [m] for edges as '
                             f'short as {shortest:.3g} m, got {radius}')
        object.__setattr__(self, 'vertices', tuple(map(tuple, verts)))
        object.__setattr__(self, 'corner_radius', radius)

    @staticmethod
    def blend_width_of(radius):
        """Width k of the corner blend for a corner radius [m]: 2 sqrt(2) r."""
        return 2.0 * math.sqrt(2.0) * radius

    @property
    def reference(self):
        """Point the moment on the obstacle is taken about: the vertices' mean [m]."""
        return np.array(self.vertices).mean(axis=0)

    def row(self):
        """Parameter row of `kernels.contact`: count, blend width, vertices."""
        return np.concatenate([[len(self.vertices), self.blend_width_of(self.corner_radius)],
                               np.ravel(self.vertices)])


@dataclass(frozen=True)
class Ellipse:
    """
    An ellipse: the section of a cylinder cut obliquely by the finger's plane.

    Parameters
    ----------
    center : (float, float)
        (X, Z) [m].
    semi_axes : (float, float)
        (a, b) [m], > 0: a along the direction `angle`, b across it.
    angle : float
        Direction of the first axis from +X towards +Z [rad].

    """

    center: tuple
    semi_axes: tuple
    angle: float = 0.0

    kind = ck.ELLIPSE

    def __post_init__(self):
        """Check the centre, axes and angle."""
        object.__setattr__(self, 'center', tuple(_point('center', self.center)))
        axes = real_pair('semi_axes', self.semi_axes, '[m]')
        if min(axes) <= 0.0:
            raise ValueError(f'`semi_axes` must be > 0 [m], got {axes}')
        object.__setattr__(self, 'semi_axes', axes)
        object.__setattr__(self, 'angle', real_number('angle', self.angle, '[rad]'))

    @property
    def reference(self):
        """Point the moment on the obstacle is taken about: the centre [m]."""
        return np.array(self.center)

    def row(self):
        """Parameter row of `kernels.contact`."""
        return np.array([*self.center, *self.semi_axes, self.angle])


_OBSTACLES = (Circle, HalfPlane, ConvexPolygon, Ellipse)


def check_obstacles(obstacles):
    """Return obstacles as a non-empty tuple; raise naming `obstacles` otherwise."""
    if isinstance(obstacles, _OBSTACLES):
        obstacles = (obstacles,)
    try:
        obstacles = tuple(obstacles)
    except TypeError:
        raise TypeError(f'`obstacles` must be an obstacle or a sequence of them, got '
                        f'{obstacles!r}') from None
    if not obstacles or not all(isinstance(o, _OBSTACLES) for o in obstacles):
        raise TypeError('`obstacles` must hold at least one Circle, HalfPlane, '
                        f'ConvexPolygon or Ellipse, got {obstacles!r}')
    return obstacles


def obstacle_params(obstacles):
    """Kinds (B,) and parameter rows (B, W) of obstacles, as `kernels.contact` takes them."""
    rows = [o.row() for o in obstacles]
    width = max(r.size for r in rows)
    out = np.zeros((len(rows), width))
    for b, row in enumerate(rows):
        out[b, :row.size] = row
    return np.array([o.kind for o in obstacles], dtype=np.int64), out


def translated(obstacle, shift):
    """Return the obstacle moved by `shift` (2,) [m]."""
    dx, dz = shift
    if isinstance(obstacle, HalfPlane):
        return HalfPlane((obstacle.point[0] + dx, obstacle.point[1] + dz), obstacle.normal)
    if isinstance(obstacle, ConvexPolygon):
        return ConvexPolygon([(x + dx, z + dz) for x, z in obstacle.vertices],
                             obstacle.corner_radius)
    if isinstance(obstacle, Circle):
        return Circle((obstacle.center[0] + dx, obstacle.center[1] + dz), obstacle.radius)
    return Ellipse((obstacle.center[0] + dx, obstacle.center[1] + dz), obstacle.semi_axes,
                   obstacle.angle)
