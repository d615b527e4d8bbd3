"""Build the package with colcon into a temporary prefix and check what it installs."""

import importlib.util
import os
import pathlib
import re
import shutil
import signal
import subprocess
import sys
import threading
import time

from nav_msgs.msg import Path
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import FluidPressure

ROOT = pathlib.Path(__file__).resolve().parents[1]
BIN = pathlib.Path(sys.executable).parent
PYTHON_DIR = f'python{sys.version_info.major}.{sys.version_info.minor}'
# Source-tree entries that are not part of the package, or that a build would leave behind.
_NOT_COPIED = ('.venv', '.git', 'build', 'install', 'log', 'out', '*.egg-info', '__pycache__',
               '.pytest_cache')


def _console_scripts():
    text = (ROOT / 'setup.py').read_text()
    return re.findall(r"'([\w-]+) = fpc_gripper[\w.]*:\w+'", text)


# A requirement's name (PEP 508) at the start of a requirements.in line; a lock line exactly.
_NAME = re.compile(r'[A-Za-z0-9](?:[A-Za-z0-9._-]*[A-Za-z0-9])?')
_PIN = re.compile(rf'({_NAME.pattern})==([0-9][0-9A-Za-z.+!-]*)')


def _canonical(name):
    return re.sub(r'[-_.]+', '-', name).lower()


def _requirement_lines(path):
    lines = (line.split('#', 1)[0].strip() for line in path.read_text().splitlines())
    return [line for line in lines if line]


def test_requirements_lock_pins_every_requirement_exactly_once():
    """Each lock line is `name==version`, no name twice; each requirements*.in name is pinned."""
    # scripts/setup.sh refuses a .venv of another Python than the header's.
    assert re.search(r'^# Python 3\.\d+\.\d+ on ', (ROOT / 'requirements.lock').read_text(), re.M)
    pins = _requirement_lines(ROOT / 'requirements.lock')
    assert pins
    malformed = [line for line in pins if not _PIN.fullmatch(line)]
    assert not malformed, malformed
    names = [_canonical(_PIN.fullmatch(line).group(1)) for line in pins]
    assert sorted({name for name in names if names.count(name) > 1}) == []
    wanted = [_NAME.match(line) for source in ('requirements.in', 'requirements-nodeps.in')
              for line in _requirement_lines(ROOT / source)]
    assert all(wanted), 'a requirements line that does not start with a name'
    wanted = {_canonical(match.group()) for match in wanted}
    assert {'ros-jazzy-rclpy', 'numpy', 'hypothesis'} <= wanted
    assert sorted(wanted - set(names)) == []


@pytest.fixture(scope='module')
def prefix(tmp_path_factory):
    """Copy the repository (without .venv) and build it with colcon; return the prefix."""
    base = tmp_path_factory.mktemp('colcon')
    shutil.copytree(ROOT, base / 'src' / 'fpc_gripper',
                    ignore=shutil.ignore_patterns(*_NOT_COPIED))
    colcon = [str(BIN / 'colcon'), '--log-base', str(base / 'log')]
    command = colcon + ['build', '--base-paths', str(base / 'src'),
                        '--build-base', str(base / 'build'),
                        '--install-base', str(base / 'install')]
    # --packages-select comes with colcon-package-selection; the copy holds one package anyway.
    usage = subprocess.run(colcon + ['build', '--help'], capture_output=True, text=True,
                           timeout=60).stdout
    if '--packages-select' in usage:
        command += ['--packages-select', 'fpc_gripper']
    # The venv's interpreter first on PATH: the ament_python build runs with it.
    env = dict(os.environ, PATH=f'{BIN}{os.pathsep}{os.environ.get("PATH", "")}')
    build = subprocess.run(command, cwd=base, env=env, capture_output=True, text=True,
                           timeout=240)
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    return base / 'install' / 'fpc_gripper'


def _installed_env(prefix):
    site = prefix / 'lib' / PYTHON_DIR / 'site-packages'
    return dict(os.environ, AMENT_PREFIX_PATH=str(prefix), PYTHONPATH=str(site))


def test_the_install_carries_its_compiled_engine(prefix):
    """colcon build ran setup.py's engine build: the installed copy loads it, current."""
    site = prefix / 'lib' / PYTHON_DIR / 'site-packages'
    build = site / 'fpc_gripper' / 'model' / 'compiled'
    assert (build / 'manifest.json').is_file()
    assert len(list(build.glob('*.nbi'))) >= 10
    probe = ('from fpc_gripper.model import compiled; '
             'print(compiled.USABLE, compiled.BUILD_DIR, compiled.REASON)')
    done = subprocess.run([sys.executable, '-c', probe], env=_installed_env(prefix),
                          cwd=prefix, capture_output=True, text=True, check=True)
    usable, directory, reason = done.stdout.split(' ', 2)
    assert usable == 'True', reason
    assert pathlib.Path(directory) == build


def test_the_install_carries_its_fast_dds_profile(prefix):
    """Every node process points Fast DDS at the profile inside the installed package."""
    probe = 'from fpc_gripper.nodes.middleware import PROFILE; print(PROFILE)'
    done = subprocess.run([sys.executable, '-c', probe], env=_installed_env(prefix),
                          cwd=prefix, capture_output=True, text=True, check=True)
    profile = pathlib.Path(done.stdout.strip())
    assert profile.is_relative_to(prefix) and profile.is_file()


def test_console_scripts_are_installed_and_executable(prefix):
    scripts = _console_scripts()
    assert 'model_node' in scripts
    for name in scripts:
        path = prefix / 'lib' / 'fpc_gripper' / name
        assert path.is_file(), path
        assert os.access(path, os.X_OK), path
    shebang = (prefix / 'lib' / 'fpc_gripper' / 'model_node').read_text().splitlines()[0]
    assert pathlib.Path(shebang[2:]).parent == BIN, shebang


def test_share_and_resource_index(prefix):
    share = prefix / 'share' / 'fpc_gripper'
    assert (share / 'package.xml').read_text() == (ROOT / 'package.xml').read_text()
    configs = sorted(p.name for p in (ROOT / 'msg_configs').glob('*.yaml'))
    assert configs and sorted(p.name for p in (share / 'msg_configs').glob('*.yaml')) == configs
    assert (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
            / 'fpc_gripper').is_file()


@pytest.mark.parametrize('folder, pattern, expected', [
    ('launch', '*.launch.py', ['gripper.launch.py', 'model.launch.py']),
    ('config', '*.yaml', ['gripper_controller.yaml', 'mcap_recorder.yaml', 'model_node.yaml',
                          'regulator_bridge.yaml']),
    ('urdf', '*.urdf', ['fpc_gripper.urdf']),
    ('rviz', '*.rviz', ['gripper.rviz']),
])
def test_launch_and_parameter_files_are_installed(prefix, folder, pattern, expected):
    """Where ros2 launch and launch_support look: share/fpc_gripper/{launch,config,...}."""
    share = prefix / 'share' / 'fpc_gripper' / folder
    assert sorted(p.name for p in share.glob(pattern)) == expected
    for name in expected:
        assert (share / name).read_text() == (ROOT / folder / name).read_text()


def _import_launch_file(path):
    spec = importlib.util.spec_from_file_location(path.stem.replace('.', '_'), path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize('name', ['gripper.launch.py', 'model.launch.py'])
def test_launch_files_import_without_launch(prefix, name):
    """Nothing from launch at import time: the module loads wherever the package does."""
    code = ('import importlib.util, sys\n'
            f'spec = importlib.util.spec_from_file_location("lf", {str(prefix / "share" / "fpc_gripper" / "launch" / name)!r})\n'  # noqa: E501
            'module = importlib.util.module_from_spec(spec); spec.loader.exec_module(module)\n'
            'assert callable(module.generate_launch_description)\n'
            'assert not [m for m in sys.modules if m.split(".")[0] in ("launch", "launch_ros")]\n')
    subprocess.run([sys.executable, '-c', code], env=_installed_env(prefix), check=True,
                   timeout=60)


@pytest.mark.parametrize('name, arguments', [
    ('gripper.launch.py', ['namespace', 'gripper_config', 'params_file', 'use_sim_time',
                           'frame_prefix', 'backend', 'modbus_config', 'record', 'record_path',
                           'autostart', 'composed', 'description', 'rviz']),
    ('model.launch.py', ['namespace', 'gripper_config', 'params_file', 'use_sim_time',
                         'frame_prefix', 'pressure_input']),
])
def test_launch_descriptions_declare_their_arguments(prefix, name, arguments):
    """Only where launch is installed (a real Jazzy install, not CI)."""
    # (A launch/ folder in the working directory imports as a namespace package: ask for
    # what only the real one has.)
    pytest.importorskip('launch.actions')
    pytest.importorskip('launch_ros')
    module = _import_launch_file(prefix / 'share' / 'fpc_gripper' / 'launch' / name)
    description = module.generate_launch_description()
    assert [a.name for a in description.get_launch_arguments()] == arguments


def test_ament_index_finds_the_installed_package(prefix):
    code = ('from ament_index_python.packages import get_package_prefix, '
            'get_package_share_directory\n'
            'import fpc_gripper\n'
            'from fpc_gripper.io.config import default_gripper_config_path\n'
            "print(get_package_prefix('fpc_gripper'))\n"
            "print(get_package_share_directory('fpc_gripper'))\n"
            'print(fpc_gripper.__file__)\n'
            'print(default_gripper_config_path())\n')
    out = subprocess.run([sys.executable, '-c', code], env=_installed_env(prefix), cwd=prefix,
                         capture_output=True, text=True, timeout=60, check=True).stdout
    found_prefix, share, module, config = out.split('\n')[:4]
    assert pathlib.Path(found_prefix) == prefix
    assert pathlib.Path(share) == prefix / 'share' / 'fpc_gripper'
    assert pathlib.Path(module).is_relative_to(prefix)
    assert pathlib.Path(config) == prefix / 'share' / 'fpc_gripper' / 'msg_configs' / \
        'gripper_paper.yaml'


@pytest.mark.ros
def test_installed_model_node_runs_and_stops_on_sigint(prefix):
    """Run the installed node with the installed parameter file; command it; SIGINT twice: 0."""
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node('layout_probe', context=context)
    received = threading.Event()
    shapes = []

    def on_shape(msg):
        shapes.append(msg)
        received.set()

    node.create_subscription(Path, '/layout/finger_0/shape', on_shape, 10)
    command = node.create_publisher(FluidPressure, '/layout/finger_0/pressure_command', 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    process = subprocess.Popen(
        [str(prefix / 'lib' / 'fpc_gripper' / 'model_node'), '--ros-args', '--params-file',
         str(prefix / 'share' / 'fpc_gripper' / 'config' / 'model_node.yaml'),
         '-p', 'tolerance:=0.0', '-p', 'n_segments:=4', '-p', 'rigidity_rate_hz:=0.0',
         '-r', '__ns:=/layout'],
        env=_installed_env(prefix), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        # A hang guard, not a timing: the install carries the compiled engine (setup.py
        # builds it), so the first shape comes in about a second.
        deadline = time.monotonic() + 120.0
        while not received.wait(0.5):
            assert time.monotonic() < deadline, 'no shape from the installed model_node'
            assert process.poll() is None, process.communicate()[0]
            command.publish(FluidPressure(fluid_pressure=101325.0 + 50e3))
        # The parameter took: 4 segments of 16 samples, then the tip.
        assert len(shapes[0].poses) == 4 * 16 + 1
        assert shapes[0].header.frame_id == 'finger_0'
        # Ctrl-C as a terminal under ros2 launch delivers it: twice, 30 ms apart.
        process.send_signal(signal.SIGINT)
        time.sleep(0.030)
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate(timeout=60)
        assert process.returncode == 0, output
        assert 'ready: 3 fingers' in output and 'Traceback' not in output
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
        executor.shutdown(timeout_sec=5.0)
        spinner.join(timeout=5.0)
        node.destroy_node()
        context.try_shutdown()


@pytest.mark.ros
def test_installed_model_node_refuses_a_bad_parameter(prefix):
    process = subprocess.run(
        [str(prefix / 'lib' / 'fpc_gripper' / 'model_node'), '--ros-args',
         '-p', 'pressure_model:=polytropic'],
        env=_installed_env(prefix), capture_output=True, text=True, timeout=60)
    assert process.returncode == 1
    assert "`pressure_model` must be one of ['design', 'adiabatic', 'isobaric']" in process.stderr
