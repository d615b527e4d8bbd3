"""Chunk indexes kept on disk: the same file byte for byte, and no memory per chunk."""

import gc
import tracemalloc

from mcap_test_utils import read_independently, summary_of
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64

from fpc_gripper.io import mcap_writer
from fpc_gripper.io.mcap_index_spill import SpilledRecords
from fpc_gripper.io.mcap_writer import Rosbag2McapWriter

TOPICS = ('/a/curvature', '/b/curvature', '/c/curvature')


def record(path, messages, start=0, flush_every=7):
    """Write `messages` per topic in chunks of a few messages; return the open writer's kind."""
    with Rosbag2McapWriter(path, chunk_size=256) as writer:
        for topic in TOPICS:
            writer.add_topic(topic, 'std_msgs/msg/Float64')
        kept = type(writer._file.writer._Writer__chunk_indices)
        for i in range(start, start + messages):
            for topic in TOPICS:
                writer.write(topic, serialize_message(Float64(data=i * 0.5)), 1000 + i)
            if i % flush_every == 0:
                writer.flush(fsync=False)
    return kept


def test_the_file_is_the_one_mcap_writes_with_its_indexes_in_memory(tmp_path, monkeypatch):
    (tmp_path / 'spilled').mkdir()
    (tmp_path / 'kept').mkdir()
    assert record(tmp_path / 'spilled' / 'run.mcap', 400) is SpilledRecords
    monkeypatch.setattr(mcap_writer, 'spill_chunk_indexes', lambda writer, directory: None)
    assert record(tmp_path / 'kept' / 'run.mcap', 400) is list
    spilled = (tmp_path / 'spilled' / 'run.mcap').read_bytes()
    assert spilled == (tmp_path / 'kept' / 'run.mcap').read_bytes()
    _, summary, _ = summary_of(tmp_path / 'spilled' / 'run.mcap')
    assert len(summary.chunk_indexes) == summary.statistics.chunk_count > 100
    got = [m.data for _, _, _, _, m in read_independently(tmp_path / 'spilled' / 'run.mcap')]
    assert got == [i * 0.5 for i in range(400) for _ in TOPICS]
    # Nothing is left beside the recording: the index file had no name.
    assert sorted(p.name for p in (tmp_path / 'spilled').iterdir()) == ['run.mcap']


def test_a_writer_keeps_no_memory_per_chunk(tmp_path):
    def traced_after(chunks):
        gc.collect()
        tracemalloc.start()
        with Rosbag2McapWriter(tmp_path / f'{chunks}.mcap', chunk_size=256) as writer:
            writer.add_topic(TOPICS[0], 'std_msgs/msg/Float64')
            data = serialize_message(Float64(data=1.0))
            for i in range(chunks):
                writer.write(TOPICS[0], data, 1000 + i)
                writer.flush(fsync=False)
            gc.collect()
            traced = tracemalloc.get_traced_memory()[0]
        tracemalloc.stop()
        return traced

    # mcap's ChunkIndex objects took some 500 bytes each with one channel.
    grown = traced_after(3000) - traced_after(1000)
    assert grown < 2000 * 16, f'{grown} bytes more for 2000 more chunks'
