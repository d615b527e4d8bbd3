"""The gripper controller's parameters without ROS: the table, the law config, the law made."""

import dataclasses

import pytest

from fpc_gripper.control.controller import ControllerConfig
from fpc_gripper.control.controller_parameters import law_config
from fpc_gripper.control.controller_parameters import LAW_PARAMETERS
from fpc_gripper.control.controller_parameters import make_law
from fpc_gripper.control.controller_parameters import parameter_table
from fpc_gripper.io.config import default_gripper_config_path
from fpc_gripper.io.config import load_gripper_config

CONFIG = load_gripper_config(default_gripper_config_path())
TABLE = parameter_table(CONFIG.max_pressure)
DEFAULTS = {name: default for name, default, _, _ in TABLE}


def values(**changes):
    """Parameter values: the table's defaults, then `changes`."""
    return {**DEFAULTS, **changes}


def test_max_pressure_defaults_to_the_config_limit_and_stops_there():
    _, default, _, extra = next(row for row in TABLE if row[0] == 'max_pressure')
    assert default == pytest.approx(CONFIG.max_pressure)
    assert extra['floating_point_range'][1] == pytest.approx(CONFIG.max_pressure)
    assert parameter_table(2.0e5)[3][1] == pytest.approx(2.0e5)


def test_the_law_parameters_are_controller_config_fields_with_its_defaults():
    fields = {f.name for f in dataclasses.fields(ControllerConfig)}
    assert set(LAW_PARAMETERS) <= fields
    defaults = ControllerConfig()
    for name in LAW_PARAMETERS:
        if name != 'max_pressure':
            assert DEFAULTS[name] == getattr(defaults, name), name


def test_law_config_takes_the_law_parameters():
    config = law_config(values(kp=0.8, safe_state='hold', max_pressure=3.0e5),
                        CONFIG.max_pressure)
    assert config.kp == pytest.approx(0.8)
    assert config.max_pressure == pytest.approx(3.0e5)
    assert config.safe_state == 'hold'


@pytest.mark.parametrize('changes, word', [
    ({'max_pressure': 4.5e5}, 'gripper config limit 400000'),
    ({'kp': -1.0}, 'kp'), ({'safe_state': 'explode'}, 'safe_state')])
def test_law_config_refuses_naming_the_parameter(changes, word):
    with pytest.raises(ValueError, match=word):
        law_config(values(**changes), CONFIG.max_pressure)


@pytest.fixture(scope='module')
def law():
    return make_law(CONFIG, values(tolerance=0.0, n_segments=2))


def test_make_law_shares_one_inverse_model_per_design(law):
    designs = [f.design for f in CONFIG.fingers]
    for i, j in ((i, j) for i in range(len(designs)) for j in range(len(designs))):
        assert (law.models[i] is law.models[j]) == (designs[i] == designs[j])
    assert law.grasps is None
    assert law.geometry.n_fingers == len(CONFIG.fingers)
    assert law.config.max_pressure == pytest.approx(CONFIG.max_pressure)


def test_make_law_grasps_a_declared_object_with_every_finger():
    law = make_law(CONFIG, values(tolerance=0.0, n_segments=2, object='sphere',
                                  object_diameter=0.05))
    assert len(law.grasps) == len(CONFIG.fingers)


def test_make_law_refuses_an_unknown_object_naming_it():
    with pytest.raises(ValueError, match="`object` must be 'unknown' or one of"):
        make_law(CONFIG, values(tolerance=0.0, n_segments=2, object='cone'))
