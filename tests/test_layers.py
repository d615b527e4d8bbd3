"""The package's imports point down its layers, and the layers below the nodes are ROS-free."""

import ast
import pathlib

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parents[1] / 'fpc_gripper'
#: Layers, bottom up: a package imports only from its own or a lower one. The command-line
#: tools (every `cli.py`) sit above all but the nodes; the launch files' support (it builds
#: the URDF from the gripper config) sits with the nodes.
RANK = {'safe_yaml': 0, 'data': 0, 'ranges': 0, 'progress': 0,
        'model': 1, 'io': 2, 'services': 2, 'grasp': 3, 'regulators': 3, 'control': 4,
        'design': 4, 'calibration': 4, 'tools': 5, 'nodes': 6, 'launch_support': 6}
#: Packages below the nodes: ROS-free services, physics, studies and tools' cores.
ROS_FREE = ('model', 'services', 'regulators', 'control', 'grasp', 'design', 'calibration')
ROS_MODULES = ('rclpy', 'std_msgs', 'sensor_msgs', 'geometry_msgs', 'nav_msgs',
               'visualization_msgs', 'diagnostic_msgs', 'rcl_interfaces', 'lifecycle_msgs',
               'tf2_ros', 'tf2_msgs', 'control_msgs', 'action_msgs', 'launch', 'launch_ros')


def _module(path):
    return '.'.join(path.relative_to(PACKAGE.parent).with_suffix('').parts)


def _imports(path, module=None):
    """Every module `path` imports, absolute (relative imports resolved)."""
    package = (module or _module(path)).split('.')[:-1]
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out.extend(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                out.append('.'.join(base + ([node.module] if node.module else [])))
            else:
                out.append(node.module)
    return out


def _layer(module):
    """The layer of a module of the package: its subpackage's, or 'tools' for a cli."""
    parts = module.split('.')
    if parts[-1] == 'cli':
        return 'tools'
    return parts[1] if len(parts) > 1 else 'fpc_gripper'


SOURCES = sorted(p for p in PACKAGE.rglob('*.py') if p.name != '__init__.py' or
                 p.parent != PACKAGE)


def test_every_package_has_a_layer():
    subpackages = {p.name for p in PACKAGE.iterdir()
                   if p.is_dir() and (p / '__init__.py').exists()}
    modules = {p.stem for p in PACKAGE.glob('*.py') if p.name != '__init__.py'}
    assert subpackages | modules <= set(RANK), sorted((subpackages | modules) - set(RANK))


def _upward(module, imports):
    """The imports of `module` from its own layer's level or above."""
    source = _layer(module)
    return [target for target in imports if target.startswith('fpc_gripper.')
            and _layer(target) != source and RANK.get(_layer(target), 99) >= RANK[source]]


@pytest.mark.parametrize('path', SOURCES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_point_down(path):
    module = _module(path)
    assert _upward(module, _imports(path)) == [], f'{module} imports up'


@pytest.mark.parametrize('path', [p for p in SOURCES
                                  if p.relative_to(PACKAGE).parts[0] in ROS_FREE
                                  and p.name != 'cli.py'],
                         ids=lambda p: str(p.relative_to(PACKAGE)))
def test_the_layers_below_the_nodes_are_ros_free(path):
    ros = [m for m in _imports(path) if m.split('.')[0] in ROS_MODULES]
    assert ros == [], f'{path.relative_to(PACKAGE)} imports ROS: {ros}'


def test_the_check_finds_an_upward_import(tmp_path):
    # The checker itself, on a services module that imports a node and a relative cli.
    source = tmp_path / 'model_core.py'
    source.write_text('from fpc_gripper.model import pipeline\n'
                      'from ..nodes import model_node\n'
                      'from ..io.cli import main\n'
                      'from .input_limits import Rejection\n')
    module = 'fpc_gripper.services.model_core'
    imports = _imports(source, module)
    assert imports == ['fpc_gripper.model', 'fpc_gripper.nodes', 'fpc_gripper.io.cli',
                       'fpc_gripper.services.input_limits']
    assert _upward(module, imports) == ['fpc_gripper.nodes', 'fpc_gripper.io.cli']
