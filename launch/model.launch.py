"""
Launch model_node alone.

    ros2 launch fpc_gripper model.launch.py [namespace:=NS] [gripper_config:=FILE]
        [params_file:=FILE] [use_sim_time:=true] [frame_prefix:=PREFIX]
        [pressure_input:=command|measured]

The node reads share/fpc_gripper/config/model_node.yaml, then params_file, then the
launch arguments. Nothing is imported from launch until generate_launch_description()
runs, so the file imports without launch installed.
"""


def generate_launch_description():
    """Return the launch description of model_node alone."""
    from launch import LaunchDescription
    from launch.actions import OpaqueFunction
    from launch_ros.actions import Node

    from fpc_gripper.launch_support import arguments, node_parameters

    def nodes(context):
        value = context.launch_configurations.get
        return [Node(package='fpc_gripper', executable='model_node', name='model_node',
                     namespace=value('namespace', ''), output='screen',
                     parameters=node_parameters(
                         context, 'model_node',
                         pressure_input=value('pressure_input') or None))]

    return LaunchDescription(arguments((
        ('pressure_input', '', "'command' (pressure_command) or 'measured' (pressure); "
         'default: as the parameter files say.'),
    )) + [OpaqueFunction(function=nodes)])
