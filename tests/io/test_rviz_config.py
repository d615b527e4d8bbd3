"""The shipped RViz config names the frames and topics the nodes really use."""

import pathlib

import yaml

from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.io.messages import GRIPPER_TOPICS
from fpc_gripper.io.urdf import gripper_urdf

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_rviz_shows_the_urdf_tf_and_markers_in_the_palm_frame():
    config = yaml.safe_load((ROOT / 'rviz' / 'gripper.rviz').read_text())
    manager = config['Visualization Manager']
    fixed = manager['Global Options']['Fixed Frame']
    # The URDF's root link is the frame the markers are drawn in.
    assert f'<link name="{fixed}">' in gripper_urdf(load_gripper_config())
    displays = {d['Class'].split('/')[-1]: d for d in manager['Displays']}
    assert {'RobotModel', 'TF', 'MarkerArray'} <= set(displays)
    assert displays['RobotModel']['Description Topic']['Value'] == '/robot_description'
    marker_topic = displays['MarkerArray']['Topic']
    assert marker_topic['Value'].lstrip('/') in GRIPPER_TOPICS
    # model_node's markers are transient local: RViz must ask for it to get the latest.
    assert marker_topic['Durability Policy'] == 'Transient Local'
