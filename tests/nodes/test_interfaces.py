"""control_msgs and tf2_msgs as a PyPI install builds them carry upstream Jazzy's type hashes."""

import json

from control_msgs.action import GripperCommand
import pytest
import rclpy
from rclpy.action import ActionServer
from rclpy.context import Context
from tf2_msgs.msg import TFMessage

from fpc_gripper.io.mcap_writer import share_directory
from fpc_gripper.io.tf import TF_QOS

# RIHS01 hashes of upstream's definitions, computed by Jazzy's rosidl_generator_type_description
# (4.6.6) over the files as upstream ships them: tf2_msgs/msg/TFMessage.msg of ros2/geometry2,
# branch jazzy (0.36.4), and control_msgs/msg/GripperCommand.msg and
# action/GripperCommand.action of ros-controls/control_msgs 5.8.0. The TFMessage hash is
# also the type_description_hash that Jazzy's rosbag2 writes into a recording's
# metadata.yaml (seen in a published one). interfaces/ holds unchanged copies of those
# files; this test catches a copy, a generator or a build that would drift from them.
UPSTREAM = {
    'tf2_msgs/msg/TFMessage':
        'RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087',
    'control_msgs/msg/GripperCommand':
        'RIHS01_57eb8f326c9889ca8bb34ead82cc94cc09bf6bc5c3b6c09546dca3a00b589890',
    'control_msgs/action/GripperCommand':
        'RIHS01_e17c0e644eccf14bea84a0a93e0977182872c2eb7873ca6694900059b46dbc84',
    'control_msgs/action/GripperCommand_FeedbackMessage':
        'RIHS01_392ff03fcd872f9dc2405cbeb2897fcf011ad9998458b6aa85c603b8a49e431d',
}


def _installed_hashes(type_name):
    package, kind, name = type_name.split('/')
    path = share_directory(package) / kind / f'{name}.json'
    return {h['type_name']: h['hash_string']
            for h in json.loads(path.read_text())['type_hashes']}


@pytest.mark.parametrize('type_name', ['tf2_msgs/msg/TFMessage',
                                       'control_msgs/msg/GripperCommand',
                                       'control_msgs/action/GripperCommand'])
def test_installed_type_descriptions_carry_upstreams_hashes(type_name):
    hashes = _installed_hashes(type_name)
    for name, expected in UPSTREAM.items():
        if name in hashes:
            assert hashes[name] == expected, name
    assert hashes[type_name] == UPSTREAM[type_name]


@pytest.mark.ros
def test_the_middleware_announces_upstreams_hashes():
    """What a Jazzy subscriber elsewhere matches on: the hashes the graph reports."""
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node('hash_probe', context=context)
    try:
        node.create_publisher(TFMessage, '/tf', TF_QOS)
        server = ActionServer(node, GripperCommand, 'probe/gripper_cmd',
                              lambda goal: GripperCommand.Result())
        try:
            for topic, type_name in (
                    ('/tf', 'tf2_msgs/msg/TFMessage'),
                    ('/probe/gripper_cmd/_action/feedback',
                     'control_msgs/action/GripperCommand_FeedbackMessage')):
                (info,) = node.get_publishers_info_by_topic(topic)
                assert info.topic_type == type_name
                assert str(info.topic_type_hash) == UPSTREAM[type_name], topic
        finally:
            server.destroy()
    finally:
        node.destroy_node()
        context.try_shutdown()
