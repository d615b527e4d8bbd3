"""The composed gripper: its nodes, their parameters, one process end to end, its exit codes."""

import functools
import pathlib
import re
import signal
import subprocess
import sys
import threading
import time

from action_msgs.msg import GoalStatus
from control_msgs.action import GripperCommand
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import WrenchStamped
from helpers import read_with_rosbags
from helpers import send_goal
from helpers import spin_until
from nav_msgs.msg import Path
import pytest
import rclpy
from rclpy.action import ActionClient
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import Float64

from fpc_gripper.launch_support import composed_parameters
from fpc_gripper.launch_support import config_file
from fpc_gripper.launch_support import node_parameters
from fpc_gripper.nodes import gripper
from fpc_gripper.nodes.gripper import compose
from fpc_gripper.nodes.gripper import NODE_NAMES

ROOT = pathlib.Path(__file__).resolve().parents[2]
CONFIG = ROOT / 'config'
#: Hang guard for a start (a cold interpreter and its imports), not a timing.
STARTUP_S = 120.0


@pytest.fixture
def context():
    context = rclpy.Context()
    rclpy.init(context=context)
    yield context
    context.try_shutdown()


@pytest.mark.ros
def test_compose_builds_each_node_once_with_its_own_parameters(context):
    nodes = compose(virtual_object=True, context=context, overrides={
        'model_node': [Parameter('max_rate_hz', value=37.0), Parameter('tolerance', value=1e-4)],
        'gripper_controller': [Parameter('max_pressure', value=250e3)]})
    try:
        assert [n.get_name() for n in nodes] == ['regulator_bridge', 'model_node',
                                                 'virtual_object', 'gripper_controller']
        by_name = {n.get_name(): n for n in nodes}
        # An override reaches its node only: the controller declares a tolerance too, and
        # keeps config/gripper_controller.yaml's default.
        model, controller = by_name['model_node'], by_name['gripper_controller']
        assert model.get_parameter('max_rate_hz').value == pytest.approx(37.0)
        assert model.get_parameter('tolerance').value == pytest.approx(1e-4)
        assert controller.get_parameter('tolerance').value == pytest.approx(5e-5)
        assert controller.get_parameter('max_pressure').value == pytest.approx(250e3)
        # The bridge activates itself, as the regulator_bridge executable's does.
        assert by_name['regulator_bridge'].lifecycle_state == 'active'
        assert gripper.bridge_exit_code(nodes) is None
    finally:
        for node in reversed(nodes):
            node.destroy_node()


def test_compose_refuses_an_override_for_a_node_it_does_not_build():
    with pytest.raises(ValueError, match=r'`overrides` names nodes compose does not build: '
                                         r"\['model'\]"):
        compose(overrides={'model': []})


def test_compose_destroys_what_it_built_when_a_node_fails(monkeypatch):
    events = []

    class Fake:
        def __init__(self, name):
            self.name = name
            events.append(('built', name))

        def destroy_node(self):
            events.append(('destroyed', self.name))

    def failing(**kwargs):
        raise ValueError('`max_pressure` must be at most 400000 Pa, got 5e+05 Pa')

    builders = {name: (lambda name=name, **kw: Fake(name)) for name in NODE_NAMES}
    builders['model_node'] = failing
    monkeypatch.setattr(gripper, '_builders', lambda: builders)
    with pytest.raises(ValueError, match='max_pressure'):
        compose(record=True)
    assert events == [('built', 'regulator_bridge'), ('destroyed', 'regulator_bridge')]


def _gripper_process(tmp_path, *args):
    return subprocess.Popen([sys.executable, '-m', 'fpc_gripper.nodes.gripper', *args],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            cwd=tmp_path)


def _spin_for(executor, future, output):
    """Spin until `future` is done (a hang guard in wall time, no judgement); its result."""
    assert spin_until(executor, future.done, STARTUP_S, step=0.1), ''.join(output)
    return future.result()


@pytest.mark.ros
def test_the_gripper_executable_runs_the_loop_in_one_process(context, tmp_path):
    """Goals in (a topic, the action), shapes out, Ctrl-C twice: exit 0, a closed recording."""
    namespace = '/composed'
    recording = tmp_path / 'composed.mcap'
    # Each node's section reaches that node only, in the namespace too.
    ours = tmp_path / 'params.yaml'
    ours.write_text(f'/**/mcap_recorder:\n  ros__parameters:\n    output_path: {recording}\n'
                    '    flush_period_s: 0.2\n'
                    '/**/model_node:\n  ros__parameters:\n    max_rate_hz: 50.0\n')
    params = [arg for name in ('regulator_bridge', 'model_node', 'gripper_controller',
                               'mcap_recorder')
              for arg in ('--params-file', str(CONFIG / f'{name}.yaml'))]
    process = _gripper_process(
        tmp_path, '--record', '--virtual-object', '--ros-args', '-r', f'__ns:={namespace}',
        *params, '--params-file', str(ours))
    output = []
    reader = threading.Thread(target=lambda: output.extend(process.stdout), daemon=True)
    reader.start()
    probe = rclpy.create_node('composed_probe', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(probe)
    shapes, states, forces = [], [], []
    probe.create_subscription(Path, f'{namespace}/finger_0/shape', shapes.append, 10)
    probe.create_subscription(DiagnosticStatus, f'{namespace}/controller_state',
                              states.append, 10)
    # The object answers a pressure once it has the finger's shape: wait for its first.
    probe.create_subscription(WrenchStamped, f'{namespace}/finger_0/tip_force',
                              forces.append, 10)
    goal = probe.create_publisher(Float64, f'{namespace}/aperture_command', 10)
    try:
        deadline = time.monotonic() + STARTUP_S
        while not (shapes and states and forces):
            assert time.monotonic() < deadline, ''.join(output)
            assert process.poll() is None, ''.join(output)
            goal.publish(Float64(data=0.1))
            executor.spin_once(timeout_sec=0.2)
        # The graph's node names arrive by discovery, on their own time: data can come
        # first on a busy machine. Waited for under the same hang guard.
        expected = {'regulator_bridge', 'model_node', 'gripper_controller', 'virtual_object',
                    'mcap_recorder'}
        while not expected <= set(probe.get_node_names()):
            assert time.monotonic() < deadline, (set(probe.get_node_names()), ''.join(output))
            executor.spin_once(timeout_sec=0.2)
        # The GripperCommand action, served on the process's EventsExecutor.
        client = ActionClient(probe, GripperCommand,
                              f'{namespace}/gripper_controller/gripper_cmd')
        request = GripperCommand.Goal()
        request.command.position = 0.090
        handle = send_goal(client, request, functools.partial(spin_until, executor))
        assert handle.accepted
        done = _spin_for(executor, handle.get_result_async(), output)
        assert done.status == GoalStatus.STATUS_SUCCEEDED, ''.join(output)
        assert done.result.reached_goal
        assert done.result.position == pytest.approx(0.090, abs=1.0e-3)
        client.destroy()
        process.send_signal(signal.SIGINT)
        time.sleep(0.030)
        process.send_signal(signal.SIGINT)
        code = process.wait(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        reader.join(timeout=5)
        executor.shutdown()
        probe.destroy_node()
    log = ''.join(output)
    assert code == 0, log
    assert 'Traceback' not in log, log
    # Every node's topics went through the one process's recorder: the controller's
    # commands, the bridge's pressures, the object's forces and the model's shapes.
    topics = {topic for topic, *_ in read_with_rosbags(recording)}
    for suffix in ('pressure_command', 'pressure', 'tip_force', 'shape', 'curvature'):
        assert f'{namespace}/finger_0/{suffix}' in topics, sorted(topics)
    assert {'/tf', '/tf_static'} <= topics, sorted(topics)
    # The recorder's stop line: everything it received is in the file.
    stop = re.search(r'closed \S+: received (\d+), written (\d+), dropped (\d+)', log)
    assert stop and stop[1] == stop[2] and stop[3] == '0', log
    assert int(stop[2]) == len(read_with_rosbags(recording))


@pytest.mark.ros
def test_a_bridge_that_cannot_activate_ends_the_process_with_2(tmp_path):
    run = subprocess.run([sys.executable, '-m', 'fpc_gripper.nodes.gripper', '--ros-args',
                          '-p', 'regulator_bridge:backend:=modbus'],
                         capture_output=True, text=True, timeout=STARTUP_S, cwd=tmp_path)
    assert run.returncode == 2, run.stderr
    assert 'modbus_config' in run.stderr and 'Traceback' not in run.stderr
    # The build stopped at the bridge: no other node announced itself.
    assert 'ready:' not in run.stderr and 'waiting for pressure input' not in run.stderr


def test_ros_arguments_rcl_cannot_parse_end_the_process_with_1(tmp_path):
    # rcl's -p rule takes a node name without slashes.
    run = subprocess.run([sys.executable, '-m', 'fpc_gripper.nodes.gripper', '--ros-args',
                          '-p', '/ns/model_node:max_rate_hz:=50.0'],
                         capture_output=True, text=True, timeout=STARTUP_S, cwd=tmp_path)
    assert run.returncode == 1, run.stderr
    assert "cannot start: Failed to parse ROS arguments: Couldn't parse parameter override " \
        "rule: '-p /ns/model_node:max_rate_hz:=50.0'" in run.stderr
    assert 'Traceback' not in run.stderr


class _LaunchContext:
    """What node_parameters reads of a launch context: the launch arguments."""

    def __init__(self, **values):
        self.launch_configurations = values


@pytest.mark.ros
def test_the_composed_launch_parameters_reach_each_node_only(tmp_path):
    """gripper.launch.py composed:=true's parameter list, applied by rcl as a process would."""
    launch = _LaunchContext(gripper_config=str(ROOT / 'msg_configs' / 'gripper_paper.yaml'),
                            use_sim_time='false', frame_prefix='left/')
    per_node = {'regulator_bridge': node_parameters(launch, 'regulator_bridge', backend='sim',
                                                    auto_activate=False),
                'model_node': node_parameters(launch, 'model_node', tolerance=1e-4),
                'gripper_controller': node_parameters(launch, 'gripper_controller')}
    files = composed_parameters(per_node, directory=tmp_path)
    # Each config file once, then the file of the nodes' own values.
    assert files[:-1] == [str(config_file(name)) for name in per_node]
    context = rclpy.Context()
    rclpy.init(context=context, args=['gripper', '--ros-args', '-r', '__ns:=/left',
                                      *[a for f in files for a in ('--params-file', f)]])
    try:
        nodes = compose(context=context)
        try:
            by_name = {n.get_name(): n for n in nodes}
            assert by_name['model_node'].get_parameter('tolerance').value == pytest.approx(1e-4)
            # The controller declares a tolerance too: its file's default, not the model's.
            assert by_name['gripper_controller'].get_parameter('tolerance').value \
                == pytest.approx(5e-5)
            assert by_name['regulator_bridge'].lifecycle_state == 'unconfigured'
            assert all(n.get_parameter('frame_prefix').value == 'left/' for n in nodes)
            assert by_name['model_node'].get_namespace() == '/left'
        finally:
            for node in reversed(nodes):
                node.destroy_node()
    finally:
        context.try_shutdown()
