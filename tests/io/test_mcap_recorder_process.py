"""mcap_recorder as a process: kill -9 loses at most flush_period_s; SIGINT/SIGTERM close."""

import os
import signal
import subprocess
import sys
import time

from helpers import read_with_rosbags
from mcap_test_utils import read_independently, summary_of
import pytest
import rclpy
from rclpy.node import Node
from std_msgs.msg import Float64
import yaml

from fpc_gripper.io.cli import main as fpc_mcap
from fpc_gripper.io.mcap_reader import McapFile, TruncatedFileError

pytestmark = pytest.mark.ros

FLUSH_PERIOD = 1.0
RATE = 50.0


def start_recorder(output, namespace, *extra):
    cmd = [sys.executable, '-m', 'fpc_gripper.nodes.mcap_recorder', '--ros-args',
           '-r', f'__ns:={namespace}', '-p', f'output_path:={output}',
           '-p', f'flush_period_s:={FLUSH_PERIOD}', *extra]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


@pytest.fixture
def talker():
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = Node('process_talker', context=ctx)
    yield node
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)


def wait_for_subscriber(publisher, process, timeout=20.0):
    deadline = time.monotonic() + timeout
    while publisher.get_subscription_count() == 0:
        assert process.poll() is None, process.stdout.read().decode()
        assert time.monotonic() < deadline, 'recorder never subscribed'
        time.sleep(0.02)


def wait_until_recording(publisher, process, output, timeout=20.0):
    """
    Publish warm-up messages (data -1) until the recorder has flushed one to `output`.

    Graph discovery (which makes the recorder subscribe) can run ahead of the DDS
    endpoint matching that delivers data, so a subscription count on the publisher's side
    does not prove delivery; a flushed chunk (the file grows past its header) does.
    """
    deadline = time.monotonic() + timeout
    while not (output.exists() and output.stat().st_size > 200):
        assert process.poll() is None, process.stdout.read().decode()
        assert time.monotonic() < deadline, 'recorder never flushed a message'
        publisher.publish(Float64(data=-1.0))
        time.sleep(1.0 / RATE)


def publish_for(publisher, seconds, start=0):
    """Publish Float64(data=i) at RATE; return the monotonic publish time of each i."""
    times = {}
    t0 = time.monotonic()
    i = start
    while time.monotonic() - t0 < seconds:
        times[i] = time.monotonic()
        publisher.publish(Float64(data=float(i)))
        i += 1
        time.sleep(max(0.0, t0 + (i - start) / RATE - time.monotonic()))
    return times


def stop(process, sig):
    if process.poll() is None:
        os.kill(process.pid, sig)
    try:
        return process.wait(timeout=15.0)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def test_kill_9_loses_at_most_the_flush_period(talker, tmp_path):
    output = tmp_path / 'killed.mcap'
    publisher = talker.create_publisher(Float64, '/kill/finger_0/curvature', 10)
    process = start_recorder(output, '/kill')
    try:
        wait_for_subscriber(publisher, process)
        wait_until_recording(publisher, process, output)
        times = publish_for(publisher, 2.6)
        killed_at = time.monotonic()
        stop(process, signal.SIGKILL)
    finally:
        stop(process, signal.SIGKILL)
    assert process.returncode == -signal.SIGKILL
    with pytest.raises(TruncatedFileError):
        McapFile(output)
    recovered = tmp_path / 'recovered.mcap'
    assert fpc_mcap(['recover', str(output), str(recovered)]) == 0
    got = [int(m.data) for topic, _, _, _, m in read_independently(recovered)
           if topic == '/kill/finger_0/curvature' and m.data >= 0.0]
    assert got == sorted(got) and len(set(got)) == len(got)
    old = {i for i, t in times.items() if t < killed_at - FLUSH_PERIOD}
    assert len(old) > 40
    assert old <= set(got), f'lost {sorted(old - set(got))}'
    lost = len(times) - len(got)
    print(f'kill -9 after {len(times)} messages at {RATE:g} Hz, flush period '
          f'{FLUSH_PERIOD:g} s: {lost} lost ({lost / RATE:.2f} s of data)')


TOPIC = '/sig/finger_2/curvature'


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_signals_close_with_summary_and_index(talker, tmp_path, sig):
    """SIGINT into one file; SIGTERM into a bag directory split every 0.2 s."""
    split = sig == signal.SIGTERM
    output = tmp_path / ('closed' if split else 'closed.mcap')
    publisher = talker.create_publisher(Float64, TOPIC, 10)
    extra = ['-p', 'max_duration_s:=0.2'] if split else []
    process = start_recorder(output, '/sig', '-p', 'compression:=lz4', *extra)
    first = output / 'closed_0.mcap' if split else output
    try:
        wait_for_subscriber(publisher, process)
        wait_until_recording(publisher, process, first)
        times = publish_for(publisher, 0.4)
        time.sleep(0.3)
        code = stop(process, sig)
    finally:
        stop(process, signal.SIGKILL)
    log = process.stdout.read().decode()
    assert code == 0, log
    assert 'Traceback' not in log
    files = sorted(output.glob('*.mcap')) if split else [output]
    assert len(files) >= (2 if split else 1)
    got = []
    for path in files:
        header, summary, metadata = summary_of(path)
        assert header.profile == 'ros2'
        assert summary.chunk_indexes and {c.compression for c in summary.chunk_indexes} == \
            {'lz4'}
        assert all(c.message_index_offsets for c in summary.chunk_indexes)
        got += [m.data for topic, _, _, _, m in read_independently(path) if topic == TOPIC]
    # Exact: the published values (-1.0 and float(i)) come back verbatim through CDR.
    warm_up = got.count(-1.0)
    assert got[warm_up:] == [float(i) for i in sorted(times)]
    bag = yaml.safe_load(metadata['rosbag2']['serialized_metadata'])
    counts = {t['topic_metadata']['name']: t['message_count']
              for t in bag['topics_with_message_count']}
    assert counts[TOPIC] == warm_up + len(times)
    # The recorder's own diagnostics are recorded too (it records /diagnostics by default).
    assert set(counts) <= {TOPIC, '/diagnostics'}
    # rosbags reads the file, or the bag directory through the metadata.yaml written on close.
    assert [m.data for topic, _, _, m in read_with_rosbags(output) if topic == TOPIC] == got
