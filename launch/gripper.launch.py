"""
Launch the gripper: regulator_bridge, model_node and gripper_controller (and mcap_recorder).

    ros2 launch fpc_gripper gripper.launch.py [backend:=sim|modbus] [modbus_config:=FILE]
        [namespace:=NS] [gripper_config:=FILE] [params_file:=FILE] [record:=true]
        [record_path:=FILE_OR_DIR] [use_sim_time:=true] [frame_prefix:=PREFIX]
        [autostart:=true|false] [composed:=true|false] [description:=true|false]
        [rviz:=true|false]

The regulator bridge is a lifecycle node. With autostart (the default) it configures and
activates itself as it starts (auto_activate), in its own process: no round trip through
its lifecycle services, whose discovery took about 2 s of the start-up; a configuration it
cannot activate ends it with exit code 2 (invalid) or 1 (device unreachable), which launch
reports, and which ends the launch (the others cannot drive the gripper without it).
autostart:=false starts it unconfigured, for a lifecycle manager or ``ros2
lifecycle set``. Every node reads share/fpc_gripper/config/<node>.yaml, then
params_file, then the launch arguments. composed:=true starts the same nodes as one
process, the ``gripper`` executable (one interpreter, one executor, one set of DDS
threads); its parameter files are the same, and its launch-argument values
reach the nodes as they would reach the separate ones (one more parameter file, keyed
/**/<node name>). description:=true (the default) also runs robot_state_publisher with the
gripper's URDF, generated from gripper_config with the frame prefix; rviz:=true starts RViz
with share/fpc_gripper/rviz/gripper.rviz (each where installed). Nothing is imported from
launch until
generate_launch_description() runs, so the file imports without launch installed.
"""


def generate_launch_description():
    """Return the launch description of the gripper."""
    from launch import LaunchDescription
    from launch.actions import OpaqueFunction
    from launch.actions import Shutdown
    from launch_ros.actions import LifecycleNode, Node

    from fpc_gripper.launch_support import (arguments, composed_parameters,
                                            description_actions, DESCRIPTION_ARGUMENTS,
                                            node_parameters)

    def nodes(context):
        value = context.launch_configurations.get
        namespace = value('namespace', '')
        autostart = value('autostart', 'true').lower() in ('true', '1', 'yes')
        record = value('record', 'false').lower() in ('true', '1', 'yes')
        bridge = node_parameters(context, 'regulator_bridge', backend=value('backend'),
                                 modbus_config=value('modbus_config') or None,
                                 auto_activate=autostart)
        recorder = node_parameters(context, 'mcap_recorder', frames=False,
                                   output_path=value('record_path') or None)
        if value('composed', 'false').lower() in ('true', '1', 'yes'):
            # One process: no name (a __node remap would rename every node in it).
            per_node = {'regulator_bridge': bridge,
                        'model_node': node_parameters(context, 'model_node'),
                        'gripper_controller': node_parameters(context, 'gripper_controller')}
            if record:
                per_node['mcap_recorder'] = recorder
            return [Node(package='fpc_gripper', executable='gripper', namespace=namespace,
                         output='screen', arguments=['--record'] if record else [],
                         parameters=composed_parameters(per_node)),
                    *description_actions(context)]
        actions = [
            LifecycleNode(
                package='fpc_gripper', executable='regulator_bridge', name='regulator_bridge',
                namespace=namespace, output='screen', parameters=bridge,
                on_exit=[Shutdown(reason='regulator_bridge ended')]),
            Node(package='fpc_gripper', executable='model_node', name='model_node',
                 namespace=namespace, output='screen',
                 parameters=node_parameters(context, 'model_node')),
            Node(package='fpc_gripper', executable='gripper_controller',
                 name='gripper_controller', namespace=namespace, output='screen',
                 parameters=node_parameters(context, 'gripper_controller'))]
        if record:
            actions.append(Node(
                package='fpc_gripper', executable='mcap_recorder', name='mcap_recorder',
                namespace=namespace, output='screen', parameters=recorder))
        return actions + description_actions(context)

    return LaunchDescription(arguments((
        ('backend', 'sim', 'Regulator backend.', ('sim', 'modbus')),
        ('modbus_config', '', 'Modbus register-map YAML (backend modbus).'),
        ('record', 'false', 'Also run mcap_recorder on every gripper topic.',
         ('true', 'false')),
        ('record_path', '', 'Recording file (*.mcap) or bag directory; default '
         'fpc_gripper_<date>.mcap in the working directory.'),
        ('autostart', 'true', 'Configure and activate the regulator bridge.',
         ('true', 'false')),
        ('composed', 'false', 'Run the nodes in one process (the gripper executable).',
         ('true', 'false')),
        *DESCRIPTION_ARGUMENTS,
    )) + [OpaqueFunction(function=nodes)])
