"""config/<node>.yaml: ROS parameter files that rcl parses, complete, and every value taken."""

import functools
import pathlib

import pytest
import rclpy
from rclpy.context import Context
import yaml

from fpc_gripper.nodes.gripper_controller import GripperController
from fpc_gripper.nodes.mcap_recorder import McapRecorder
from fpc_gripper.nodes.model_node import ModelNode
from fpc_gripper.nodes.regulator_bridge import RegulatorBridge

ROOT = pathlib.Path(__file__).resolve().parents[2]
CONFIG = ROOT / 'config'
GRIPPER = str(ROOT / 'msg_configs' / 'gripper_paper.yaml')
NODES = {
    'model_node': ModelNode,
    'regulator_bridge': functools.partial(RegulatorBridge, auto_activate_default=True),
    'gripper_controller': GripperController,
    'mcap_recorder': McapRecorder,
}
#: rclpy's own parameters, and those a launch argument sets (left out of the files).
NOT_IN_FILES = {'use_sim_time', 'start_type_description_service'}
LAUNCH_ARGUMENT = {'model_node': {'gripper_config'}, 'regulator_bridge': {'gripper_config'},
                   'gripper_controller': {'gripper_config'}, 'mcap_recorder': set()}
#: A valid value other than the shipped one for every parameter in the files.
CHANGED = {
    'model_node': {
        'tolerance': 0.0, 'n_segments': 12, 'pressure_model': 'isobaric', 'max_rate_hz': 150.0,
        'pressure_input': 'measured', 'atmospheric_pressure': 100000.0, 'stale_after_s': 2.5,
        'rigidity_rate_hz': 4.0, 'frame_prefix': 'left/', 'publish_tf': False,
        'future_limit_s': 0.5,
        'min_absolute_pressure': 2.0e4, 'max_tip_force': 2.5, 'max_frame_id_length': 64,
        'max_payload_bytes': 2048},
    'regulator_bridge': {
        # Not activated: a modbus backend without a register map would refuse to configure.
        'auto_activate': False, 'backend': 'modbus', 'modbus_config': GRIPPER,
        'modbus_host': '127.0.0.1', 'modbus_port': 1502, 'sim_time_constant_s': 0.2,
        'sim_slew_rate_pa_s': 1.0e6, 'sim_deadband_pa': 250.0, 'sim_noise_std_pa': 0.0,
        'sim_max_output_pa': 6.0e5, 'sim_full_scale_pa': 8.0e5, 'sim_adc_bits': 16,
        'sim_seed': 7, 'max_pressure': 3.0e5, 'rate_limit_pa_s': 5.0e5,
        'command_timeout_s': 0.25, 'safe_state': 'hold', 'publish_rate_hz': 100.0,
        'diagnostics_rate_hz': 1.0, 'atmospheric_pressure': 100000.0,
        'frame_prefix': 'left/', 'tracking_tolerance_pa': 1.0e4, 'tracking_timeout_s': 3.0,
        'overpressure_margin_pa': 2.5e4, 'min_absolute_pressure': 2.0e4,
        'max_frame_id_length': 64, 'max_payload_bytes': 2048},
    'gripper_controller': {
        'tolerance': 1.0e-4, 'n_segments': 4, 'pressure_model': 'isobaric',
        'max_pressure': 3.5e5, 'slew_rate_pa_s': 3.0e5, 'approach_rate_pa_s': 1.0e5, 'kp': 0.8,
        'ki': 1.5, 'kp_force': 0.4, 'ki_force': 2.0, 'control_rate_hz': 40.0,
        'goal_tolerance_m': 0.002, 'force_tolerance': 0.1, 'settle_time_s': 0.2,
        'stall_timeout_s': 8.0, 'feedback_timeout_s': 0.8, 'safe_state': 'hold',
        'contact_threshold_n': 0.03, 'object': 'sphere', 'object_diameter': 0.05,
        'object_height': 0.002, 'atmospheric_pressure': 100000.0, 'frame_prefix': 'left/',
        'min_absolute_pressure': 2.0e4, 'max_tip_force': 2.5, 'max_frame_id_length': 64,
        'max_payload_bytes': 2048},
    'mcap_recorder': {
        'output_path': '{tmp}/changed.mcap', 'overwrite': True, 'topics': ['/x', 'other'],
        'gripper_config': GRIPPER, 'flush_period_s': 0.5, 'max_file_size_mb': 10.0,
        'max_duration_s': 60.0, 'compression': 'lz4', 'discovery_period_s': 0.25,
        'max_queue_mb': 50.0, 'diagnostics_period_s': 0.0},
}


def load(path):
    """Return the parameters of a file's single ``/**/<node>`` section."""
    data = yaml.safe_load(path.read_text())
    (key,) = data
    assert list(data[key]) == ['ros__parameters'], path
    return key, data[key]['ros__parameters']


def start(node, *args):
    """Build a node in a new context whose rcl arguments are `args` (`--ros-args` first)."""
    context = Context()
    rclpy.init(context=context, args=['test', '--ros-args', *args])
    try:
        return NODES[node](context=context), context
    except BaseException:
        context.try_shutdown()
        raise


def values(node, names):
    return {name: node.get_parameter(name).value for name in names}


@pytest.mark.ros
@pytest.mark.parametrize('node_name', list(NODES))
def test_the_file_is_complete_and_in_the_ros_format(node_name, tmp_path):
    path = CONFIG / f'{node_name}.yaml'
    key, params = load(path)
    assert key == f'/**/{node_name}'
    extra = ['-p', f'output_path:={tmp_path / "x.mcap"}'] if node_name == 'mcap_recorder' \
        else []
    node, context = start(node_name, '--params-file', str(path), *extra)
    try:
        # Every declared parameter is documented there, and nothing else.
        declared = set(node._parameters) - NOT_IN_FILES - LAUNCH_ARGUMENT[node_name]
        assert sorted(params) == sorted(declared)
        # rcl parsed every value with its type; they are the node's defaults.
        got = values(node, params)
        if node_name == 'mcap_recorder':
            got['output_path'] = ''
        assert got == params
        assert {k: type(v) for k, v in got.items()} == {k: type(v) for k, v in params.items()}
    finally:
        node.destroy_node()
        context.try_shutdown()
    assert sorted(CHANGED[node_name]) == sorted(params)
    assert all(CHANGED[node_name][k] != v for k, v in params.items())


@pytest.mark.ros
@pytest.mark.parametrize('namespace', ['/', '/left/gripper'])
@pytest.mark.parametrize('node_name', list(NODES))
def test_every_value_takes_effect_through_params_file(node_name, namespace, tmp_path):
    """rcl parses ``--ros-args --params-file``; /**/<node> matches in any namespace."""
    _, shipped = load(CONFIG / f'{node_name}.yaml')
    changed = {k: v.format(tmp=tmp_path) if isinstance(v, str) else v
               for k, v in CHANGED[node_name].items()}
    path = tmp_path / 'changed.yaml'
    path.write_text(yaml.safe_dump({f'/**/{node_name}': {'ros__parameters': changed}}))
    node, context = start(node_name, '-r', f'__ns:={namespace}', '--params-file', str(path))
    try:
        assert node.get_namespace() == namespace
        assert values(node, changed) == changed
        # Types too: an int stays an int, a float a float.
        assert {k: type(v) for k, v in values(node, changed).items()} == \
            {k: type(v) for k, v in changed.items()}
    finally:
        node.destroy_node()
        context.try_shutdown()
