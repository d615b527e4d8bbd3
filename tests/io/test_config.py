"""Gripper configuration loading and its error messages."""

import math

from helpers import assert_designs_close
import pytest

from fpc_gripper.io.config import default_gripper_config_path, load_gripper_config
from fpc_gripper.model import ActuatorDesign


def test_shipped_gripper_has_three_fingers_at_prestrain_025():
    cfg = load_gripper_config()
    assert cfg.names == ('finger_0', 'finger_1', 'finger_2')
    for finger in cfg.fingers:
        assert_designs_close(finger.design, ActuatorDesign.paper(prestrain=0.25),
                             where=finger.name)
    angles = [f.mount_angle for f in cfg.fingers]
    assert angles[1] - angles[0] == pytest.approx(2 * math.pi / 3)
    # Exact: read verbatim from gripper_paper.yaml, not computed.
    assert cfg.max_pressure == 400e3 and cfg.atmospheric_pressure == 101325.0
    assert default_gripper_config_path().name == 'gripper_paper.yaml'


def write(tmp_path, text):
    path = tmp_path / 'g.yaml'
    path.write_text(text)
    return path


@pytest.mark.parametrize('text, message', [
    ('fingers: [\n', 'malformed YAML'),
    ('- a\n', 'expected a mapping'),
    ('fingers: []\n', 'fingers: must hold 1 to 16 finger mappings, got 0'),
    ('fingerz: []\n', 'unknown key.*fingerz'),
    ('fingers: [{name: f0, colour: red}]\n', r'fingers\[0\]: unknown key.*colour'),
    ('fingers: [{name: 0bad}]\n', 'valid ROS name'),
    ('fingers: [{name: a}, {name: a}]\n', 'unique'),
    ('fingers: [{name: a, design: {prestrain: 1.5}}]\n', 'prestrain'),
    ('fingers: [{name: a, design: {Cq: 1}}]\n', r"fingers\[0\]\.design: unknown key.*'Cq'"),
    ('palm_radius: -1\nfingers: [{name: a}]\n', 'palm_radius'),
    ('actuator: missing.yaml\nfingers: [{name: a}]\n', 'cannot read'),
])
def test_bad_configs_name_the_problem(tmp_path, text, message):
    with pytest.raises(ValueError, match=message):
        load_gripper_config(write(tmp_path, text))


def test_inline_actuator_and_overrides(tmp_path):
    cfg = load_gripper_config(write(tmp_path, (
        'actuator: {prestrain: 0.3, Cy: 0.027}\n'
        'fingers: [{name: a, design: {prestrain: 0.15}}, {name: b}]\n')))
    # Exact: the overrides are read verbatim from the YAML text above.
    assert cfg.fingers[0].design.prestrain == 0.15 and cfg.fingers[0].design.Cy == 0.027
    assert cfg.fingers[1].design.prestrain == 0.3
