"""mcap_recorder with its executor stalled and a CPU hog: no probe sequence number is missing."""

import pathlib
import re
import signal
import struct
import subprocess
import sys
import time

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from nav_msgs.msg import Path
import pytest
import rclpy
from rclpy.duration import Duration
from rclpy.node import Node
from recorder_load import _Arc, start_hog, stop_hog

from fpc_gripper.io.messages import serialized_shape, STATE_QOS

pytestmark = pytest.mark.ros

HELPER = pathlib.Path(__file__).with_name('stalled_recorder.py')
TOPIC = '/stall/finger_0/shape'
BASE = 1_700_000_000_000_000_000
RATE = 500.0
COUNT = 2000
STALL_S = 3.0
STOP_LINE = re.compile(
    r'closed .*: received (\d+), written (\d+), dropped (\d+) \((\d+) queue full, (\d+) '
    r'failed writes\)')


def probe_numbers(path):
    """
    The probe's numbers in the file, in file order, read with mcap's reader.

    Each number is read from its CDR header stamp (int32 sec, uint32 nanosec after the
    4-byte encapsulation); every 100th message is decoded whole by mcap_ros2 as well.
    """
    numbers = []
    factory = DecoderFactory()
    with open(path, 'rb') as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            assert channel.topic == TOPIC
            sec, nanosec = struct.unpack_from('<iI', message.data, 4)
            numbers.append(sec * 1_000_000_000 + nanosec - BASE)
            if len(numbers) % 100 == 1:
                decoded = factory.decoder_for('cdr', schema)(message.data)
                assert len(decoded.poses) == 129
                stamp = decoded.header.stamp
                assert stamp.sec * 1_000_000_000 + stamp.nanosec - BASE == numbers[-1]
    return numbers


def wait_for(condition, process, what, timeout=30.0):
    deadline = time.monotonic() + timeout
    while not condition():
        assert process.poll() is None, process.stdout.read().decode()
        assert time.monotonic() < deadline, what
        time.sleep(0.02)


def test_a_stalled_recorder_keeps_every_message_of_a_reliable_topic(tmp_path):
    """
    Issue 22: 0 messages of a reliable topic missing from the recording, with a CPU hog.

    The probe publishes 2,000 shapes (129-pose Paths) numbered 0, 1, ... in their stamps,
    at 500 Hz, on model_node's own QoS (reliable, keep-last 1: the publisher cannot send
    one again), while the recorder's executor sleeps 3 s and a busy loop takes a core.
    With the old keep-last-1000 subscription the reader overwrote its oldest 500.
    """
    output = tmp_path / 'stalled.mcap'
    recorder = subprocess.Popen(
        [sys.executable, str(HELPER), str(STALL_S), '--ros-args', '-p',
         f'output_path:={output}', '-p', f'topics:=[{TOPIC!r}]', '-p', 'flush_period_s:=0.2',
         '-p', 'discovery_period_s:=0.1', '-p', 'diagnostics_period_s:=0.0'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    context = rclpy.Context()
    rclpy.init(context=context)
    probe = Node('stall_probe', context=context)
    publisher = probe.create_publisher(Path, TOPIC, STATE_QOS)
    arcs = [_Arc(5.0 + 0.01 * i) for i in range(50)]
    hogs = []
    try:
        wait_for(lambda: publisher.get_subscription_count() == 1, recorder,
                 'the recorder never subscribed')
        hogs = start_hog(1)
        t0 = time.monotonic()
        for i in range(COUNT):
            publisher.publish(serialized_shape(arcs[i % 50], 'finger_0', BASE + i))
            time.sleep(max(0.0, t0 + (i + 1) / RATE - time.monotonic()))
        # Acknowledged: every message is in the recorder's reader queue, taken or not.
        assert publisher.wait_for_all_acked(Duration(seconds=30.0))
        stop_hog(hogs)
        hogs = []
        recorder.send_signal(signal.SIGINT)
        code = recorder.wait(timeout=30.0)
    finally:
        stop_hog(hogs)
        if recorder.poll() is None:
            recorder.kill()
            recorder.wait()
        probe.destroy_node()
        rclpy.try_shutdown(context=context)
    log = recorder.stdout.read().decode()
    assert code == 0, log
    assert 'stalled the executor' in log and 'Traceback' not in log, log

    got = probe_numbers(output)
    missing = sorted(set(range(COUNT)) - set(got))
    assert not missing, f'{len(missing)} of {COUNT} missing: {missing[:10]}...'
    assert got == list(range(COUNT))        # in order, none twice

    lines = [line for line in log.splitlines() if STOP_LINE.search(line)]
    assert len(lines) == 1, log
    received, written, dropped, full, failed = map(int, STOP_LINE.search(lines[0]).groups())
    assert (received, written) == (COUNT, len(got))
    assert (dropped, full, failed) == (0, 0, 0)
