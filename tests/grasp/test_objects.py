"""Objects in the palm: their sections in the finger planes against their 3-D surfaces."""

import math

import numpy as np
import pytest

from fpc_gripper.grasp import Box, CoaxialCylinder, CrossCylinder, make_object, Sphere
from fpc_gripper.model import contact as C

PALM = 0.062
ANGLES = (0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0, 0.3)


def to_palm(points, angle):
    """Finger-frame (X, Z) [m] to palm-frame (x, y, z): rho = PALM + Z at the azimuth."""
    points = np.asarray(points, dtype=float)
    rho = PALM + points[:, 1]
    return np.stack([rho * np.cos(angle), rho * np.sin(angle), points[:, 0]], axis=1)


def boundary(section, count=400):
    """Points on the boundary of a planar obstacle (a polygon's sharp outline)."""
    t = np.linspace(0.0, 2.0 * np.pi, count, endpoint=False)
    if isinstance(section, C.Circle):
        return np.array(section.center) + section.radius * np.stack([np.cos(t), np.sin(t)], 1)
    if isinstance(section, C.Ellipse):
        a, b = section.semi_axes
        c, s = math.cos(section.angle), math.sin(section.angle)
        local = np.stack([a * np.cos(t), b * np.sin(t)], 1)
        return np.array(section.center) + local @ np.array([[c, s], [-s, c]])
    corners = np.array(section.vertices)
    edges = [corners[k] + np.outer(np.linspace(0, 1, 50), corners[(k + 1) % len(corners)]
                                   - corners[k]) for k in range(len(corners))]
    return np.concatenate(edges)


@pytest.mark.parametrize('angle', ANGLES)
def test_sphere_section_lies_on_the_sphere(angle):
    sphere = Sphere(0.050, center=0.040)
    (section,) = sphere.section(angle, PALM)
    points = to_palm(boundary(section), angle)
    np.testing.assert_allclose(np.hypot(np.hypot(points[:, 0], points[:, 1]),
                                        points[:, 2] - 0.040), 0.025, atol=1e-15)


@pytest.mark.parametrize('angle', ANGLES)
def test_coaxial_cylinder_section_is_its_axial_section(angle):
    cylinder = CoaxialCylinder(0.040, length=0.1, base=0.002)
    (section,) = cylinder.section(angle, PALM)
    points = to_palm(boundary(section), angle)
    radius = np.hypot(points[:, 0], points[:, 1])
    on_side = np.isclose(radius, 0.020, atol=1e-12)
    height = points[:, 2]
    on_ends = np.isclose(height, 0.002, atol=1e-15) | np.isclose(height, 0.102, atol=1e-15)
    assert np.all(on_side | on_ends) and on_side.any() and on_ends.any()


@pytest.mark.parametrize('angle', ANGLES)
def test_cross_cylinder_section_lies_on_the_cylinder(angle):
    cylinder = CrossCylinder(0.030, center=0.030, azimuth=math.pi / 2 + 0.1)
    (section,) = cylinder.section(angle, PALM)
    points = to_palm(boundary(section), angle)
    axis = np.array([math.cos(cylinder.azimuth), math.sin(cylinder.azimuth), 0.0])
    relative = points - [0.0, 0.0, 0.030]
    across = relative - np.outer(relative @ axis, axis)
    np.testing.assert_allclose(np.linalg.norm(across, axis=1), 0.015, atol=1e-12)


@pytest.mark.parametrize('angle', ANGLES)
def test_box_section_lies_on_the_box(angle):
    box = Box(0.040, height=0.030, length=0.2, base=0.001, azimuth=math.pi / 2 + 0.2)
    (section,) = box.section(angle, PALM)
    points = to_palm(boundary(section), angle)
    axis = np.array([math.cos(box.azimuth), math.sin(box.azimuth)])
    across = np.array([-axis[1], axis[0]])
    along, side = points[:, :2] @ axis, points[:, :2] @ across
    inside = (np.abs(along) <= 0.1 + 1e-12) & (np.abs(side) <= 0.02 + 1e-12) \
        & (points[:, 2] >= 0.001 - 1e-15) & (points[:, 2] <= 0.031 + 1e-15)
    height = points[:, 2]
    on_face = (np.isclose(np.abs(along), 0.1, atol=1e-12)
               | np.isclose(np.abs(side), 0.02, atol=1e-12)
               | np.isclose(height, 0.001, atol=1e-15) | np.isclose(height, 0.031, atol=1e-15))
    assert np.all(inside & on_face)


def test_make_object_rests_on_the_palm():
    assert make_object('cylinder', 0.04).base == 0.0
    assert make_object('sphere', 0.05).center == pytest.approx(0.025)
    assert make_object('sphere', 0.05, height=0.01).center == pytest.approx(0.035)
    assert make_object('box', 0.04).width == 0.04


@pytest.mark.parametrize('make, word', [
    (lambda: Sphere(-0.05), 'diameter'),
    (lambda: Sphere(float('nan')), 'diameter'),
    (lambda: Sphere(0.05, center=0.02), 'palm'),
    (lambda: CoaxialCylinder(0.04, base=-0.001), 'palm'),
    (lambda: CoaxialCylinder(0.04, length=0.0), 'length'),
    (lambda: Box(0.04, base=float('nan')), 'base'),
    (lambda: CrossCylinder(0.04, center=0.01), 'palm'),
    (lambda: CrossCylinder(0.04, length=0.05, azimuth=0.3).section(0.0, PALM), 'length'),
    (lambda: make_object('cone', 0.04), 'kind'),
])
def test_bad_objects_are_refused_naming_the_argument(make, word):
    with pytest.raises(ValueError, match=word):
        make()
