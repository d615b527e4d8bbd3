"""BackgroundWriter: order kept, flushed on its own, bounded, failures counted, never blocking."""

import threading
import time

from mcap_test_utils import read_independently, samples
import pytest
from rclpy.serialization import serialize_message

from fpc_gripper.io.background_writer import BackgroundWriter
from fpc_gripper.io.mcap_reader import McapFile, TruncatedFileError
from fpc_gripper.io.mcap_writer import McapWriterError, Rosbag2McapWriter

BASE = 1_700_000_000_000_000_000


def wait_until(condition, timeout=10.0):
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, 'condition never met'
        time.sleep(0.01)


class GatedWriter:
    """Stand-in for Rosbag2McapWriter whose writes wait for a gate, or fail on request."""

    def __init__(self, fail=()):
        self.gate = threading.Event()
        self.written = []
        self.fail = set(fail)
        self.pending_count = 0
        self.closed = False

    def write(self, topic, data, log_time, publish_time):
        self.gate.wait()
        if log_time in self.fail:
            raise OSError(28, 'No space left on device')
        self.written.append(log_time)

    def flush(self):
        pass

    def close(self):
        self.closed = True


def test_writes_in_order_and_flushes_without_being_asked(tmp_path):
    path = tmp_path / 'bg.mcap'
    writer = Rosbag2McapWriter(path)
    writer.add_topic('/aperture', 'std_msgs/msg/Float64')
    background = BackgroundWriter(writer, flush_period_s=0.05)
    sent = [serialize_message(samples(i)['aperture']) for i in range(50)]
    for i, data in enumerate(sent):
        assert background.put('/aperture', data, BASE + i, BASE + i)
    # On disk in a completed chunk, before any close: what `kill -9` would leave.
    wait_until(lambda: background.written == 50 and writer.pending_count == 0)
    with pytest.raises(TruncatedFileError):
        McapFile(path)
    background.close()
    got = read_independently(path)
    assert [log for _, _, log, _, _ in got] == [BASE + i for i in range(50)]
    # Verbatim through CDR: exact.
    assert [m.data for _, _, _, _, m in got] == [samples(i)['aperture'].data for i in range(50)]
    assert (background.dropped, background.errors) == (0, 0)


def test_a_full_queue_drops_and_counts_and_never_blocks():
    stub = GatedWriter()
    background = BackgroundWriter(stub, max_queue_bytes=1000)
    # Bytes count until written, and the gate holds every write: 3 x 300 fit in 1000.
    accepted = [background.put('/t', bytes(300), i, i) for i in range(10)]
    assert accepted == [True] * 3 + [False] * 7 and background.dropped == 7
    stub.gate.set()
    background.close()
    assert stub.written == [0, 1, 2] and stub.closed
    assert background.queued_bytes == 0


def test_failed_writes_are_counted_and_the_thread_goes_on():
    stub = GatedWriter(fail={3, 4})
    stub.gate.set()
    errors = []
    background = BackgroundWriter(stub, on_error=errors.append)
    for i in range(8):
        background.put('/t', b'x', i, i)
    background.close()
    assert stub.written == [0, 1, 2, 5, 6, 7]
    assert background.errors == 2 and all(isinstance(e, OSError) for e in errors)
    with pytest.raises(McapWriterError, match='closed'):
        background.put('/t', b'x', 9, 9)


def test_a_thread_that_died_is_reported_by_put():
    class Broken(GatedWriter):
        def write(self, *args):
            raise RuntimeError('a bug')

    errors = []
    background = BackgroundWriter(Broken(), on_error=errors.append)
    background.put('/t', b'x', 0, 0)
    wait_until(lambda: errors)
    assert background.errors == 1
    with pytest.raises(McapWriterError, match='RuntimeError: a bug'):
        background.put('/t', b'x', 1, 1)
