"""Write the example recordings: a 3 s gripper session as model_node records it, and a crash."""

import argparse
import math
import pathlib
import tempfile

from rclpy.serialization import serialize_message
from sensor_msgs.msg import FluidPressure

from fpc_gripper.io.cli import replay_model
from fpc_gripper.io.mcap_reader import Recording
from fpc_gripper.io.mcap_writer import Rosbag2McapWriter
from fpc_gripper.io.messages import DEFAULT_ATMOSPHERIC_PRESSURE, ns_to_time

#: Start of the session [ns since the epoch] and its sample period [ns] (10 Hz).
START_NS = 1_767_225_600 * 1_000_000_000
PERIOD_NS = 100_000_000
#: Commanded gauge pressure of every finger: open to 200 kPa and back over 3 s [Pa].
SAMPLES = 31
FINGERS = ('finger_0', 'finger_1', 'finger_2')
#: Fraction of the bytes kept in crashed.mcap (a recorder killed mid-write), and its
#: chunk size [bytes]: a recorder flushes chunks as it goes, so a crash loses the last.
KEPT = 0.6
CHUNK = 16 * 1024


def command(k):
    """Return the commanded gauge pressure of sample `k` [Pa]: a half sine to 200 kPa."""
    return 200e3 * math.sin(math.pi * k / (SAMPLES - 1))


def _inputs(path):
    with Rosbag2McapWriter(path) as writer:
        for finger in FINGERS:
            writer.add_topic(f'/{finger}/pressure_command', 'sensor_msgs/msg/FluidPressure')
        for k in range(SAMPLES):
            t = START_NS + k * PERIOD_NS
            for finger in FINGERS:
                msg = FluidPressure()
                msg.header.stamp = ns_to_time(t)
                msg.header.frame_id = finger
                msg.fluid_pressure = DEFAULT_ATMOSPHERIC_PRESSURE + command(k)
                writer.write(f'/{finger}/pressure_command', serialize_message(msg), t)
    return path


def write_recordings(out_dir):
    """Write run.mcap (commands and the model's shapes) and crashed.mcap (cut short)."""
    out_dir = pathlib.Path(out_dir)
    run = out_dir / 'run.mcap'
    with tempfile.TemporaryDirectory() as tmp:
        inputs = _inputs(pathlib.Path(tmp) / 'inputs.mcap')
        # The model node's own pipeline writes the outputs it would have published.
        replay_model(inputs, run, copy_inputs=True, overwrite=True)
        chunked = pathlib.Path(tmp) / 'chunked.mcap'
        with Recording(run) as source, Rosbag2McapWriter(chunked, chunk_size=CHUNK) as copy:
            for name, info in sorted(source.topics.items()):
                copy.add_topic(name, info.type_name)
            for msg in source.messages(decode=False):
                copy.write(msg.topic, msg.data, msg.log_time, msg.publish_time)
        data = chunked.read_bytes()
    crashed = out_dir / 'crashed.mcap'
    crashed.write_bytes(data[:int(len(data) * KEPT)])
    return [run, crashed]


if __name__ == '__main__':
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--out', default=pathlib.Path(__file__).resolve().parent,
                        help='directory (default: beside this script)')
    for path in write_recordings(parser.parse_args().out):
        print(path)
