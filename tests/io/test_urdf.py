"""The gripper's URDF, read by a real parser (yourdfpy) against the gripper YAML itself."""

import math
import pathlib

import numpy as np
from numpy.testing import assert_allclose
import pytest
import yaml
import yourdfpy

from fpc_gripper.io.config import default_gripper_config_path, load_gripper_config
from fpc_gripper.io.urdf import gripper_urdf, main

ROOT = pathlib.Path(__file__).resolve().parents[2]
SHIPPED = ROOT / 'urdf' / 'fpc_gripper.urdf'


def expected_mount(palm_radius, angle):
    """Palm -> finger transform from the README's words, not the package's code."""
    radial = np.array([math.cos(angle), math.sin(angle), 0.0])
    x_axis = np.array([0.0, 0.0, 1.0])              # along the palm normal
    z_axis = radial                                 # radially outwards
    transform = np.eye(4)
    transform[:3, :3] = np.column_stack([x_axis, np.cross(z_axis, x_axis), z_axis])
    transform[:3, 3] = palm_radius * radial
    return transform


def load(path):
    return yourdfpy.URDF.load(str(path), build_scene_graph=True, load_meshes=False)


def test_the_shipped_urdf_is_the_generators_output():
    assert SHIPPED.read_text() == gripper_urdf(load_gripper_config()), (
        'urdf/fpc_gripper.urdf is stale: python -m fpc_gripper.io.urdf --out '
        'urdf/fpc_gripper.urdf')


def test_yourdfpy_finds_three_fingers_mounted_as_the_yaml_says():
    data = yaml.safe_load(default_gripper_config_path().read_text())
    robot = load(SHIPPED)
    fingers = [f['name'] for f in data['fingers']]
    assert len(fingers) == 3
    assert set(robot.link_map) == {'palm', *fingers, *(f'{f}_tip' for f in fingers)}
    assert robot.base_link == 'palm'
    for finger in data['fingers']:
        name = finger['name']
        mount = robot.get_transform(name, 'palm')
        assert_allclose(mount, expected_mount(data['palm_radius'], finger['mount_angle']),
                        rtol=0, atol=1e-12)
        bend = robot.joint_map[f'{name}_bend']
        assert (bend.type, bend.parent, bend.child) == ('planar', name, f'{name}_tip')
        # The finger bends in its X-Z plane: the planar joint's normal is its Y axis.
        assert_allclose(bend.axis, [0.0, 1.0, 0.0])


def test_the_prefix_reaches_every_frame(tmp_path):
    out = tmp_path / 'left.urdf'
    assert main(['--prefix', 'left/', '--out', str(out)]) == 0
    robot = load(out)
    assert all(name.startswith('left/') for name in robot.link_map)
    assert all(name.startswith('left/') for name in robot.joint_map)
    assert robot.base_link == 'left/palm'


def test_a_bad_config_exits_2_naming_it_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / 'x.urdf'
    bad = tmp_path / 'bad.yaml'
    bad.write_text('palm_radius: -1\nfingers:\n  - name: f\n')
    assert main(['--gripper-config', str(bad), '--out', str(out)]) == 2
    err = capsys.readouterr().err
    assert 'palm_radius' in err and len(err.strip().splitlines()) == 1
    assert not out.exists() and not list(tmp_path.glob('.x.urdf*'))


def test_an_unwritable_output_exits_1(tmp_path, capsys):
    assert main(['--out', str(tmp_path / 'missing' / 'x.urdf')]) == 1
    assert '--out' in capsys.readouterr().err


@pytest.mark.parametrize('angle', [0.3, -2.5, math.pi])
def test_a_mount_at_any_angle(tmp_path, angle):
    config = tmp_path / 'one.yaml'
    config.write_text(f'palm_radius: 0.05\nfingers:\n  - name: f\n    mount_angle: {angle!r}\n')
    out = tmp_path / 'one.urdf'
    assert main(['--gripper-config', str(config), '--out', str(out)]) == 0
    assert_allclose(load(out).get_transform('f', 'palm'), expected_mount(0.05, angle),
                    rtol=0, atol=1e-12)
