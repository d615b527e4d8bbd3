"""Three-finger grasps: symmetry, friction and holding force, the pressure inverse, fpc-grasp."""

import csv
import math
import re

import numpy as np
import pytest

from fpc_gripper.grasp import (Box, FingerGrasp, GraspSettings, GraspStatus, make_object,
                               simulate_grasp)
from fpc_gripper.grasp.cli import CSV_COLUMNS, main
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.model.contact import solve_contact
from fpc_gripper.model.pipeline import contact_model

CONFIG = load_gripper_config()
CYLINDER = make_object('cylinder', 0.040)
SPHERE = make_object('sphere', 0.050)


@pytest.fixture(scope='module')
def cylinder_sweep():
    return {mu: simulate_grasp(CONFIG, CYLINDER, [100e3, 50e3, 0.0], mu)
            for mu in (0.0, 0.25, 0.5)}


def test_coaxial_object_loads_the_three_fingers_equally(cylinder_sweep):
    """Each finger is solved on its own section, cut at its own mount angle."""
    for point in cylinder_sweep[0.5].points:
        forces = [c.normal_force_total for c in point.contacts]
        assert forces[0] > 0.1
        np.testing.assert_allclose(forces, forces[0], rtol=1e-9)
        assert point.fingers_in_contact == 3
    for point in simulate_grasp(CONFIG, SPHERE, [20e3], 0.3).points:
        forces = [c.normal_force_total for c in point.contacts]
        np.testing.assert_allclose(forces, forces[0], rtol=1e-9)


def test_mirrored_box_gives_mirrored_contact():
    """A box turned by +10 degrees from across finger 0, and its mirror image at -10."""
    box = {'width': 0.030, 'height': 0.040}
    turned = simulate_grasp(CONFIG, Box(**box, azimuth=math.radians(100.0)), [20e3], 0.0)
    mirror = simulate_grasp(CONFIG, Box(**box, azimuth=math.radians(80.0)), [20e3], 0.0)
    assert turned.points[0].fingers_in_contact == 3, turned.points[0].message
    a, b = turned.points[0].contacts, mirror.points[0].contacts
    # Finger 0 is on the mirror plane; fingers 1 and 2 swap.
    for i, j in ((0, 0), (1, 2), (2, 1)):
        assert a[i].normal_force_total == pytest.approx(b[j].normal_force_total, rel=1e-9,
                                                        abs=1e-12)
        assert a[i].contact_arc() == b[j].contact_arc()
    # The turn breaks the symmetry between fingers 1 and 2.
    assert abs(a[1].normal_force_total - a[2].normal_force_total) > 1e-3


def test_without_friction_a_coaxial_cylinder_is_not_held(cylinder_sweep):
    for point in cylinder_sweep[0.0].points:
        assert point.success, point.message
        assert point.grasp_force > 0.5
        assert abs(point.holding_force) < 1e-9


def test_holding_force_rises_with_friction_and_with_release(cylinder_sweep):
    """
    The model's prediction for a coaxial cylinder: the tip slides along it at the Coulomb
    limit, so the holding force is mu times the normal force.
    """
    for mu in (0.25, 0.5):
        points = cylinder_sweep[mu].points              # 100, 50, 0 kPa: released further
        holding = [p.holding_force for p in points]
        assert all(p.success for p in points), [p.message for p in points]
        assert np.all(np.diff(holding) > 0.0)
        for p in points:
            assert p.holding_force == pytest.approx(mu * p.grasp_force, rel=1e-6)
    for low, high in zip(cylinder_sweep[0.25].points, cylinder_sweep[0.5].points):
        assert high.holding_force > low.holding_force
    best = cylinder_sweep[0.5].best
    assert best.pressure == 0.0 and best.holding_force == max(
        p.holding_force for p in cylinder_sweep[0.5].points)


def test_a_caging_sphere_is_held_without_friction_and_more_with_it():
    """The fingertips reach past the sphere's far pole: pulling it out bends them open."""
    held = {mu: simulate_grasp(CONFIG, SPHERE, [0.0], mu).points[0] for mu in (0.0, 0.5)}
    assert held[0.0].success and held[0.5].success
    assert held[0.0].holding_force > 0.5
    assert held[0.5].holding_force > held[0.0].holding_force


def test_object_that_does_not_fit_the_open_gripper_is_reported():
    sweep = simulate_grasp(CONFIG, make_object('cylinder', 0.190), [100e3], 0.5)
    point = sweep.points[0]
    assert not point.success and point.status is GraspStatus.DOES_NOT_FIT
    assert 'cannot be placed' in point.message


def test_finger_grasp_inverse_presses_with_the_force_asked():
    finger = CONFIG.fingers[0]
    section = SPHERE.section(finger.mount_angle, CONFIG.palm_radius)
    grasp = FingerGrasp(finger.design, section, CONFIG.max_pressure)
    solver = contact_model(finger.design)
    for force in (0.1, 0.4):
        pressure, reachable = grasp.pressure_for_force(force)
        assert reachable and 0.0 < pressure < grasp.touch_pressure
        # Independent: a cold contact solve at that pressure.
        assert solve_contact(solver, pressure, section).normal_force_total == pytest.approx(
            force, abs=1e-6)
    assert grasp.normal_force(grasp.touch_pressure + 1.0) == 0.0
    assert grasp.pressure_for_force(100.0) == (0.0, False)
    numeric = (grasp.normal_force(30e3 + 2e3) - grasp.normal_force(30e3 - 2e3)) / 4e3
    assert grasp.slope(30e3) == pytest.approx(numeric, rel=1e-3)


@pytest.mark.parametrize('kwargs, word', [
    ({'pressures': [-1.0]}, 'pressures'), ({'pressures': [500e3]}, 'pressures'),
    ({'mu': -0.5}, 'mu'), ({'mu': float('nan')}, 'mu'),
])
def test_bad_sweep_input_is_refused(kwargs, word):
    args = {'pressures': [0.0], 'mu': 0.5, **kwargs}
    with pytest.raises(ValueError, match=word):
        simulate_grasp(CONFIG, CYLINDER, args['pressures'], args['mu'])


def test_settings_are_validated():
    with pytest.raises(ValueError, match='pull_step'):
        GraspSettings(pull_step=0.0)


def test_cli_writes_the_columns_and_the_chart(tmp_path, capsys):
    out = tmp_path / 'run'
    code = main(['--object', 'cylinder', '--diameter', '0.040', '--mu', '0.5', '--pressure',
                 '0:100e3:50e3', '--out', str(out)])
    assert code == 0, capsys.readouterr().err
    with open(out / 'grasp.csv', newline='') as stream:
        rows = list(csv.reader(stream))
    assert tuple(rows[0]) == CSV_COLUMNS
    assert [float(r[0]) for r in rows[1:]] == [0.0, 50e3, 100e3]
    api = simulate_grasp(CONFIG, CYLINDER, [0.0, 50e3, 100e3], 0.5)
    for row, point in zip(rows[1:], api.points):
        assert float(row[1]) == pytest.approx(point.grasp_force, rel=1e-9)
        assert float(row[2]) == pytest.approx(point.holding_force, rel=1e-9)
        assert row[3:] == [str(point.fingers_in_contact), str(point.success),
                           point.status.name]
    assert (out / 'grasp.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert 'best grasp pressure 0.0 kPa' in capsys.readouterr().out


@pytest.mark.parametrize('args, word', [
    (['--diameter', '-0.04'], 'diameter'), (['--pressure', '0:1e3'], 'pressure'),
    (['--pressure', 'abc'], 'pressure'), (['--height', '-0.01'], 'palm'),
    (['--pressure', '0:300e3:10'], 'write 0:300e3/10 for 10 values, or 0:300e3:10.0'),
    (['--pressure', '0:5e6:1e5'], 'open pressure'),
])
def test_cli_bad_input_exits_2_with_one_line(tmp_path, capsys, args, word):
    base = {'--object': 'sphere', '--diameter': '0.05', '--mu': '0.5', '--pressure': '0',
            '--out': str(tmp_path / 'x')}
    for key, value in zip(args[::2], args[1::2]):
        base[key] = value
    argv = [item for pair in base.items() for item in pair]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith('fpc-grasp: error:') and word in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / 'x').exists()


def test_cli_a_sweep_with_no_usable_row_exits_1_and_says_why(tmp_path, capsys):
    out = tmp_path / 'g'
    code = main(['--object', 'cylinder', '--diameter', '5', '--mu', '0.5', '--pressure', '0',
                 '--out', str(out)])
    captured = capsys.readouterr()
    assert code == 1
    # Progress lines may come first on a slow machine; the failure is one line.
    lines = [line for line in captured.err.strip().splitlines()
             if not re.match(r'fpc-grasp: \d+/\d+ steps', line)]
    assert len(lines) == 1 and lines[0].startswith('fpc-grasp: failed: no grasp pressure')
    assert (out / 'FAILED.txt').is_file() and (out / 'grasp.csv').is_file()
