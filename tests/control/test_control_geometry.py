"""Palm geometry: tip radii, palm-frame points and the aperture circle."""

import math

from control_sim import circumdiameter
import numpy as np
from numpy.testing import assert_allclose
import pytest

from fpc_gripper.control.geometry import aperture_from_points, PalmGeometry, tip_radius
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.model import CCMSolver

THIRDS = (0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0)


def test_tip_radius_is_palm_radius_plus_z():
    assert tip_radius(-0.05, 0.062) == pytest.approx(0.012)
    assert_allclose(tip_radius([-0.07, 0.01], 0.062), [-0.008, 0.072])


def test_palm_frame_points_follow_the_finger_axes():
    geometry = PalmGeometry(0.062, (0.0, math.pi / 2.0))
    points = geometry.tip_points([[0.03, -0.05], [0.04, 0.01]])
    # Finger X is the palm normal (z), finger Z points radially outwards.
    assert_allclose(points, [[0.012, 0.0, 0.03], [0.0, 0.072, 0.04]], atol=1e-15)


@pytest.mark.parametrize('rho', [0.0025, 0.02, 0.0889, -0.004])
def test_symmetric_aperture_is_twice_the_tip_radius(rho):
    geometry = PalmGeometry(0.062, THIRDS)
    tips = [[0.05, rho - 0.062]] * 3
    assert geometry.aperture(tips) == pytest.approx(2.0 * abs(rho), rel=1e-12)
    assert geometry.aperture_from_rho([rho] * 3) == pytest.approx(2.0 * abs(rho), rel=1e-12)
    assert PalmGeometry.rho_for_aperture(2.0 * abs(rho)) == pytest.approx(abs(rho))


@pytest.mark.parametrize('rhos', [(0.02, 0.03, 0.025), (0.05, 0.01, 0.04), (0.001, 0.06, 0.06)])
@pytest.mark.parametrize('offset', [0.0, 0.3])
def test_general_aperture_is_the_circumscribed_circle(rhos, offset):
    angles = tuple(a + offset for a in THIRDS)
    geometry = PalmGeometry(0.062, angles)
    points = [(r * math.cos(a), r * math.sin(a)) for r, a in zip(rhos, angles)]
    assert geometry.aperture_from_rho(rhos) == pytest.approx(circumdiameter(points), rel=1e-10)


def test_degenerate_and_other_finger_counts():
    # Exact: collinear points return the sentinel math.inf itself.
    assert aperture_from_points([[0.01, 0.0], [0.0, 0.0], [-0.01, 0.0]]) == math.inf
    assert aperture_from_points([[0.03, 0.0], [-0.02, 0.0]]) == pytest.approx(0.05)
    assert aperture_from_points([[0.0, -0.02]]) == pytest.approx(0.04)
    square = [[0.03 * math.cos(a), 0.03 * math.sin(a)] for a in np.arange(4) * math.pi / 2]
    assert aperture_from_points(square) == pytest.approx(0.06, rel=1e-12)


@pytest.mark.parametrize('kwargs, word', [
    ({'palm_radius': 0.0, 'mount_angles': (0.0,)}, 'palm_radius'),
    ({'palm_radius': 0.06, 'mount_angles': ()}, 'mount_angles'),
    ({'palm_radius': math.nan, 'mount_angles': (0.0,)}, 'palm_radius'),
])
def test_invalid_geometry_is_refused(kwargs, word):
    with pytest.raises(ValueError, match=word):
        PalmGeometry(**kwargs)


def test_shipped_palm_radius_closes_near_the_axis_and_opens_at_max_pressure():
    config = load_gripper_config()
    geometry = PalmGeometry.from_config(config)
    solver = CCMSolver(config.fingers[0].design)
    closed = geometry.rho(solver.solve(0.0).tip[1])
    opened = geometry.rho(solver.solve(config.max_pressure).tip[1])
    assert 0.0 < closed < 0.005           # tips a few mm from the axis, not crossing it
    assert opened > 0.08                  # 400 kPa opens to an aperture above 160 mm
    zs = [solver.solve(p).tip[1] for p in np.linspace(0.0, config.max_pressure, 21)]
    assert np.all(np.diff(zs) > 0.0)      # the controlled region: rho monotone in pressure
