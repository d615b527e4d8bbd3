"""Launch arguments and parameter lists shared by launch/gripper.launch.py and model.launch.py."""

import pathlib

__all__ = ['COMMON_ARGUMENTS', 'DESCRIPTION_ARGUMENTS', 'arguments', 'composed_parameters',
           'config_file', 'description_actions', 'node_parameters', 'share_directory']

PACKAGE = 'fpc_gripper'
#: ``(name, default, description)`` of the launch arguments every launch file declares;
#: a default of None is filled in by `arguments` (the package's own files).
COMMON_ARGUMENTS = (
    ('namespace', '', 'Namespace of every node (and so of every relative topic).'),
    ('gripper_config', None, 'Gripper YAML (fingers, palm radius, pressure limit); default '
     'share/fpc_gripper/msg_configs/gripper_paper.yaml.'),
    ('params_file', '', 'A ROS parameter file applied to every node after its own '
     'share/fpc_gripper/config/<node>.yaml; key its sections /**/<node name> so that they '
     'match in any namespace.'),
    ('use_sim_time', 'false', 'Use /clock.'),
    ('frame_prefix', '', 'Prefix of every frame id (<prefix>palm, <prefix>finger_<i>), so '
     'that two grippers can share a tf tree.'),
)

#: Launch arguments of `description_actions`.
DESCRIPTION_ARGUMENTS = (
    ('description', 'true', 'Publish the URDF of gripper_config (frames prefixed) on '
     'robot_description with robot_state_publisher, where it is installed.', ('true', 'false')),
    ('rviz', 'false', 'Start RViz with share/fpc_gripper/rviz/gripper.rviz, where it is '
     'installed.', ('true', 'false')),
)


def _true(text):
    return str(text).lower() in ('true', '1', 'yes')


def _installed(package):
    try:
        from ament_index_python.packages import get_package_prefix
        get_package_prefix(package)
    except (ImportError, LookupError, OSError):
        return False
    return True


def description_actions(context):
    """
    Return robot_state_publisher with the gripper's URDF and, with ``rviz:=true``, RViz.

    Each runs only where its package is installed; otherwise one log line says so.
    """
    from launch.actions import LogInfo
    from launch_ros.actions import Node

    from fpc_gripper.io.config import load_gripper_config
    from fpc_gripper.io.urdf import gripper_urdf

    def value(name, default=''):
        return context.launch_configurations.get(name, default)

    actions = []
    namespace = value('namespace')
    if _true(value('description', 'true')):
        if _installed('robot_state_publisher'):
            urdf = gripper_urdf(load_gripper_config(value('gripper_config') or None),
                                value('frame_prefix'))
            actions.append(Node(
                package='robot_state_publisher', executable='robot_state_publisher',
                namespace=namespace, output='screen',
                parameters=[{'robot_description': urdf,
                             'use_sim_time': _true(value('use_sim_time'))}]))
        else:
            actions.append(LogInfo(msg='robot_state_publisher is not installed: no '
                                       'robot_description (description:=false hides this)'))
    if _true(value('rviz', 'false')):
        if _installed('rviz2'):
            actions.append(Node(package='rviz2', executable='rviz2', namespace=namespace,
                                arguments=['-d', str(share_directory() / 'rviz' /
                                                     'gripper.rviz')]))
        else:
            actions.append(LogInfo(msg='rviz2 is not installed: no RViz'))
    return actions


def share_directory():
    """Return the installed share directory of fpc_gripper (ament index), else the source tree."""
    try:
        from ament_index_python.packages import get_package_share_directory
        return pathlib.Path(get_package_share_directory(PACKAGE))
    except (ImportError, LookupError, OSError):
        # OSError: no AMENT_PREFIX_PATH at all (a source checkout, not sourced).
        return pathlib.Path(__file__).resolve().parents[1]


def config_file(node_name):
    """Return the path of a node's parameter file, ``config/<node_name>.yaml``."""
    return share_directory() / 'config' / f'{node_name}.yaml'


def arguments(extra=()):
    """
    Declare the common launch arguments, then `extra`.

    Parameters
    ----------
    extra : iterable of tuple
        More ``(name, default, description)`` or ``(name, default, description,
        choices)`` rows.

    Returns
    -------
    list of launch.actions.DeclareLaunchArgument

    """
    from launch.actions import DeclareLaunchArgument

    defaults = {'gripper_config': str(share_directory() / 'msg_configs' / 'gripper_paper.yaml')}
    out = []
    for row in (*COMMON_ARGUMENTS, *extra):
        name, default, description = row[:3]
        kwargs = {'choices': list(row[3])} if len(row) > 3 else {}
        out.append(DeclareLaunchArgument(name, default_value=defaults.get(name, default),
                                         description=description, **kwargs))
    return out


def node_parameters(context, node_name, frames=True, **overrides):
    """
    Build a node's ``parameters`` list: its config file, the params_file, then overrides.

    Later entries win: the package's ``config/<node_name>.yaml`` first, then the
    ``params_file`` launch argument (if given), then the launch arguments that the nodes
    share (gripper_config, use_sim_time and, with `frames`, frame_prefix) and
    `overrides`.

    Parameters
    ----------
    context : launch.LaunchContext
        The context, to read the launch arguments.
    node_name : str
        Node name, which names its config file.
    frames : bool
        The node has a frame_prefix parameter.
    **overrides
        Further parameter values; None values are left out.

    Returns
    -------
    list
        Paths and one dict, as ``launch_ros.actions.Node(parameters=...)`` takes them.

    """
    def value(name):
        return context.launch_configurations.get(name, '')

    params = [str(config_file(node_name))]
    if value('params_file'):
        params.append(value('params_file'))
    shared = {'gripper_config': value('gripper_config'),
              'use_sim_time': value('use_sim_time').lower() in ('true', '1', 'yes')}
    if frames:
        shared['frame_prefix'] = value('frame_prefix')
    shared.update({k: v for k, v in overrides.items() if v is not None})
    params.append(shared)
    return params


def composed_parameters(per_node, directory=None):
    """
    Merge the nodes' `node_parameters` lists into the one list of a composed process.

    The files (each node's config file, the params_file) come once each, in order; each
    node's own values (the dict that ends its list) go into one more file, under the key
    ``/**/<node name>``, so that they reach that node only, in any namespace. (A dict
    given to launch_ros would be keyed ``/**`` and reach every node of the process that
    declares a parameter of that name.)

    Parameters
    ----------
    per_node : dict
        Node name -> its `node_parameters` list.
    directory : path-like, optional
        Where to write the file (default the system's temporary directory, as launch_ros
        does with its own parameter files).

    Returns
    -------
    list of str
        Parameter file paths for ``launch_ros.actions.Node(parameters=...)``.

    """
    import tempfile

    import yaml

    files, sections = [], {}
    for name, params in per_node.items():
        for entry in params:
            if isinstance(entry, dict):
                sections[f'/**/{name}'] = {'ros__parameters': dict(entry)}
            elif str(entry) not in files:
                files.append(str(entry))
    with tempfile.NamedTemporaryFile('w', prefix='fpc_gripper_composed_', suffix='.yaml',
                                     dir=directory, delete=False) as stream:
        yaml.safe_dump(sections, stream, sort_keys=False)
    return files + [stream.name]
