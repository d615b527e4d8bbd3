"""The ROS-free parameter tables of the nodes: every default inside its declared range."""

import pytest

from fpc_gripper.control.controller_parameters import parameter_table
from fpc_gripper.io.config import default_gripper_config_path
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.regulators.bridge_parameters import PARAMETERS

CONFIG = load_gripper_config(default_gripper_config_path())
ROWS = [('gripper_controller', row) for row in parameter_table(CONFIG.max_pressure)] + [
    ('regulator_bridge', row) for row in PARAMETERS]


@pytest.mark.parametrize('node, row', ROWS, ids=lambda v: v if isinstance(v, str) else v[0])
def test_every_default_is_inside_its_range(node, row):
    name, default, description, extra = row
    assert description, (node, name)
    for key in ('floating_point_range', 'integer_range'):
        if key in extra:
            low, high = extra[key]
            assert low <= default <= high, (node, name)
