"""The gripper_demo console script end to end, its recording read by an independent decoder."""

import math
import os
import pathlib
import signal
import struct
import subprocess
import sys

from helpers import read_with_rosbags
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest

from fpc_gripper.io.cli import replay_model
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.io.session_chart import message_count
from fpc_gripper.nodes.virtual_object import _path_tip_z

ATM = 101325.0
ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.mark.ros
@pytest.mark.slow
def test_demo_session_passes_and_records(tmp_path):
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    run = subprocess.run(
        [sys.executable, '-m', 'fpc_gripper.nodes.gripper_demo', '--output-dir', str(tmp_path)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=110)
    assert run.returncode == 0, run.stdout + run.stderr
    assert 'session PASSED' in run.stdout
    for phase in ('open', 'grasp', 'hold', 'release'):
        assert any(line.startswith(phase) and 'REACHED' in line
                   for line in run.stdout.splitlines()), run.stdout
    # The table gives each finger's contact arc (the 40 mm cylinder: the fingertips) and the
    # holding force of the hold.
    hold = next(line for line in run.stdout.splitlines() if line.startswith('hold'))
    assert hold.split()[-4:-1] == ['90.0'] * 3
    assert 0.1 < float(hold.split()[-1]) < 2.0
    png = tmp_path / 'session.png'
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    # rosbags, a second reader, decodes every message of the recording.
    decoded, count = len(read_with_rosbags(tmp_path / 'session.mcap')), message_count(
        tmp_path / 'session.mcap')
    print(f'rosbags decoded {decoded} of {count} messages of session.mcap')
    assert decoded == count > 1000
    topics = {}
    with open(tmp_path / 'session.mcap', 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, _, decoded in reader.iter_decoded_messages():
            topics.setdefault(channel.topic, []).append(decoded)
    limit = load_gripper_config().max_pressure
    for i in range(3):
        commands = topics[f'/finger_{i}/pressure_command']
        assert len(commands) > 100
        assert max(m.fluid_pressure for m in commands) <= ATM + limit
        forces = [math.hypot(m.wrench.force.x, m.wrench.force.z)
                  for m in topics[f'/finger_{i}/tip_force']]
        # Grasped (1.5 N in all: 0.5 N a finger), and released: out of contact the object
        # returns 0.0 itself (exact).
        assert max(forces) > 0.4 and min(forces) == 0.0
    states = [m for m in topics['/controller_state']]
    assert {kv.value for m in states for kv in m.values if kv.key == 'goal_status'} \
        >= {'active', 'reached'}
    assert_replay_reproduces_the_published_shapes(tmp_path)


@pytest.mark.ros
def test_ctrl_c_ends_the_session_with_130_and_a_closed_recording(tmp_path):
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    process = subprocess.Popen(
        [sys.executable, '-m', 'fpc_gripper.nodes.gripper_demo', '--output-dir', str(tmp_path)],
        cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    try:
        # Mid-session: once the first phase has started (a hang guard, not a timing).
        for line in process.stdout:
            lines.append(line)
            if 'phase open' in line:
                break
        process.send_signal(signal.SIGINT)
        lines.extend(process.stdout)
        code = process.wait(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    output = ''.join(lines)
    assert code == 130, output
    assert 'Traceback' not in output and 'session stopped by signal 2' in output, output
    assert message_count(tmp_path / 'session.mcap') > 0


def shapes_by_stamp(path, only=None):
    """{(topic, header stamp [ns]): (M, 2) midplane X, Z [m]} of every shape, or of `only`'s."""
    out = {}
    decoder = DecoderFactory()
    with open(path, 'rb') as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            if not channel.topic.endswith('/shape'):
                continue
            # A CDR Path begins with its encapsulation (little-endian: 00 01) and the header
            # stamp: decode only the shapes asked for (all of a replay took 6 s).
            assert message.data[:2] == b'\x00\x01'
            sec, nanosec = struct.unpack_from('<iI', message.data, 4)
            key = (channel.topic, sec * 10**9 + nanosec)
            if only is not None and key not in only:
                continue
            msg = decoder.decoder_for('cdr', schema)(message.data)
            assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (sec, nanosec)
            out[key] = np.array([(q.pose.position.x, q.pose.position.z) for q in msg.poses])
    return out


def assert_replay_reproduces_the_published_shapes(tmp_path):
    """replay-model on the recorded inputs gives the shapes model_node published, to 1e-9 m."""
    replayed = tmp_path / 'replayed.mcap'
    replay_model(tmp_path / 'session.mcap', replayed, source='pressure', rigidity=False)
    decoded, count = len(read_with_rosbags(replayed)), message_count(replayed)
    print(f'rosbags decoded {decoded} of {count} messages of replayed.mcap')
    assert decoded == count > 1000
    published = shapes_by_stamp(tmp_path / 'session.mcap')
    again = shapes_by_stamp(replayed, only=published)
    matched = [key for key in published if key in again]
    # A shape answers the newest input, whose stamp it carries, and the node publishes none
    # before the first pressure: replay answers every published shape.
    assert len(matched) == len(published) > 300, (len(published), len(matched))
    worst = max(float(np.max(np.abs(published[k] - again[k]))) for k in matched)
    print(f'replayed {len(matched)} of {len(published)} published shapes; largest '
          f'difference {worst:.3g} m')
    assert worst <= 1e-9


def test_path_tip_decoder_handles_empty_and_foreign_payloads():
    from nav_msgs.msg import Path
    from rclpy.serialization import serialize_message
    assert _path_tip_z(serialize_message(Path())) is None
    assert _path_tip_z(b'\x00\x02' + bytes(80)) is None
