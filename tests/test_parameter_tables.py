"""The ROS-free parameter tables of the nodes: every default inside its declared range."""

import pytest

from fpc_gripper.control import controller_parameters
from fpc_gripper.control import virtual_object_parameters
from fpc_gripper.io import recorder_settings
from fpc_gripper.io.config import default_gripper_config_path
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.regulators import bridge_parameters
from fpc_gripper.services import model_parameters
from fpc_gripper.services.input_limits import input_bound_table

CONFIG = load_gripper_config(default_gripper_config_path())
MODEL_TABLE = model_parameters.parameter_table(str(default_gripper_config_path()))
TABLES = {
    'gripper_controller': controller_parameters.parameter_table(CONFIG.max_pressure),
    'regulator_bridge': bridge_parameters.PARAMETERS,
    'model_node': MODEL_TABLE,
    'virtual_object': virtual_object_parameters.PARAMETERS,
    'mcap_recorder': recorder_settings.PARAMETERS,
    'input bounds': input_bound_table(),
}
ROWS = [(node, row) for node, table in TABLES.items() for row in table]


@pytest.mark.parametrize('node, row', ROWS, ids=lambda v: v if isinstance(v, str) else v[0])
def test_every_default_is_inside_its_range(node, row):
    name, default, description, extra = row
    assert description, (node, name)
    for key in ('floating_point_range', 'integer_range'):
        if key in extra:
            low, high = extra[key]
            assert low <= default <= high, (node, name)


@pytest.mark.parametrize('node', TABLES)
def test_names_are_unique_and_choices_hold_their_default(node):
    names = [row[0] for row in TABLES[node]]
    assert len(names) == len(set(names))
    for name, default, _, extra in TABLES[node]:
        choices = extra.get('additional_constraints', '')
        if choices.startswith('one of '):
            assert repr(default) in choices, (node, name)


@pytest.mark.parametrize('name, value, reason', [
    ('pressure_model', 'polytropic', 'must be one of'),
    ('pressure_input', 'both', 'must be one of'),
    ('tolerance', float('nan'), 'must be finite'),
    ('max_rate_hz', float('inf'), 'must be finite'),
])
def test_model_node_refuses_by_name(name, value, reason):
    refusal = model_parameters.refusal({'tolerance': 0.001, name: value})
    assert reason in refusal and f'`{name}`' in refusal


def test_model_node_accepts_its_defaults():
    assert model_parameters.refusal({name: default for name, default, *_ in MODEL_TABLE}) \
        is None
