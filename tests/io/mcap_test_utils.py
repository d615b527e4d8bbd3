"""Helpers of the MCAP tests: sample messages, field-by-field comparison, independent reading."""

import array
import functools
import pathlib
import shutil

from builtin_interfaces.msg import Duration
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, Vector3Stamped, WrenchStamped
from helpers import read_with_rosbags
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
from rclpy.serialization import serialize_message
from sensor_msgs.msg import FluidPressure
from std_msgs.msg import ColorRGBA, Float64, String
from visualization_msgs.msg import Marker, MarkerArray

import yaml

from fpc_gripper.io.mcap_writer import Rosbag2McapWriter, type_name_of
from fpc_gripper.io.messages import curvature_message, ns_to_time, shape_message

ATM = 101325.0


class FakeResult:
    """Stand-in for a CCMResult: an arc of constant curvature with exact tangents."""

    def __init__(self, kappa, n=17, length=0.09):
        s = np.linspace(0.0, length, n)
        if abs(kappa) < 1e-12:
            self.points = np.stack([s, np.zeros_like(s)], axis=1)
            self.tangent = np.zeros_like(s)
        else:
            self.tangent = -kappa * s
            self.points = np.stack([np.sin(kappa * s) / kappa,
                                    (np.cos(kappa * s) - 1.0) / kappa], axis=1)
        self.curvature = kappa


def stamp(i, base=1_700_000_000):
    """Header stamp of the i-th sample message."""
    return ns_to_time(base * 1_000_000_000 + i * 10_000_000 + 7)


def fluid_pressure(i, gauge):
    msg = FluidPressure()
    msg.header.stamp = stamp(i)
    msg.header.frame_id = 'finger_0'
    msg.fluid_pressure = ATM + gauge
    msg.variance = 25.0 + i
    return msg


def wrench(i, f0, p0):
    msg = WrenchStamped()
    msg.header.stamp = stamp(i)
    msg.header.frame_id = 'finger_0'
    msg.wrench.force.x = f0
    msg.wrench.force.z = p0
    msg.wrench.torque.y = 0.001 * i
    return msg


def vector(i):
    msg = Vector3Stamped()
    msg.header.stamp = stamp(i)
    msg.header.frame_id = 'finger_0'
    msg.vector.x = 1.5e-3 + i * 1e-6
    msg.vector.z = 4.0e-3 - i * 1e-6
    return msg


def markers(i):
    marker = Marker()
    marker.header.stamp = stamp(i)
    marker.header.frame_id = 'palm'
    marker.ns = 'fingers'
    marker.id = i
    marker.type = Marker.LINE_STRIP
    marker.pose.orientation.w = 1.0
    marker.scale.x = 0.002
    marker.color = ColorRGBA(r=0.125, g=0.25, b=0.375, a=1.0)  # exact in float32
    marker.lifetime = Duration(sec=1, nanosec=5)
    marker.points = [Point(x=0.01 * k, y=0.0, z=-0.001 * k * i) for k in range(5)]
    marker.colors = [ColorRGBA(r=1.0, g=0.5, b=0.25 * k, a=1.0) for k in range(5)]
    marker.text = f'finger {i}'
    return MarkerArray(markers=[marker])


def diagnostics(i):
    msg = DiagnosticArray()
    msg.header.stamp = stamp(i)
    status = DiagnosticStatus(level=DiagnosticStatus.WARN, name='fpc_gripper: regulator',
                              message=f'pressure error {i} Pa', hardware_id='sim')
    status.values = [KeyValue(key='pressure', value=str(1000.0 * i)),
                     KeyValue(key='state', value='ok')]
    msg.status = [status]
    return msg


def samples(i):
    """One sample of every message type the gripper records, by relative topic."""
    return {
        'finger_0/pressure_command': fluid_pressure(i, 1000.0 * i),
        'finger_0/pressure': fluid_pressure(i, 990.0 * i),
        'finger_0/tip_force': wrench(i, 0.01 * i, -0.02 * i),
        'finger_0/shape': shape_message(FakeResult(20.0 - i), 'finger_0',
                                        stamp(i).sec * 1_000_000_000 + stamp(i).nanosec),
        'finger_0/curvature': Float64(data=20.0 - i + 0.125),
        'finger_0/rigidity': vector(i),
        'markers': markers(i),
        'aperture_command': Float64(data=0.05 + 0.001 * i),
        'grasp_force_command': Float64(data=0.5 * i),
        'aperture': Float64(data=0.049 + 0.001 * i),
        'controller_state': String(data=f'state {i}: grasping'),
        '/diagnostics': diagnostics(i),
    }


def _as_list(value):
    if isinstance(value, (bytes, bytearray, array.array, np.ndarray)):
        return list(value)
    return value


def assert_same_fields(expected, actual, where='msg'):
    """
    Compare a generated rclpy message with a decoded mcap_ros2 message, field by field.

    Exact equality is right: CDR stores every number verbatim, and the samples' float32
    fields (colours) hold values exact in float32.
    """
    fields = expected.get_fields_and_field_types()
    assert fields, where
    for name, field_type in fields.items():
        a = getattr(expected, name)
        b = getattr(actual, name)
        here = f'{where}.{name}'
        if field_type == 'octet':
            # rclpy holds a ROS `byte` as a one-byte bytes object, mcap_ros2 as an int.
            assert (a[0] if isinstance(a, bytes) else a) == b, here
        elif hasattr(a, 'get_fields_and_field_types'):
            assert_same_fields(a, b, here)
        elif isinstance(a, (list, tuple)) and a and hasattr(a[0], 'get_fields_and_field_types'):
            assert len(a) == len(b), here
            for k, (x, y) in enumerate(zip(a, b)):
                assert_same_fields(x, y, f'{here}[{k}]')
        else:
            a, b = _as_list(a), _as_list(b)
            if isinstance(a, list):
                assert list(b) == a, here
            else:
                assert b == a, here


def read_independently(path):
    """Read every message with mcap's reader and mcap_ros2's decoder (no package code)."""
    out = []
    with open(pathlib.Path(path), 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            out.append((channel.topic, schema.name, message.log_time, message.publish_time,
                        decoded))
    return out


def summary_of(path):
    """Header, summary and metadata records read with mcap's own reader."""
    with open(pathlib.Path(path), 'rb') as stream:
        reader = make_reader(stream)
        header = reader.get_header()
        summary = reader.get_summary()
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return header, summary, metadata


def bag_from_embedded_metadata(path, bag_dir):
    """
    Make a rosbag2 bag directory of one MCAP file and the metadata embedded in it.

    rosbag2's metadata record names the file; a metadata.yaml built from it is what
    ``ros2 bag reindex`` would write. Returns the bag directory.
    """
    _, _, metadata = summary_of(path)
    bag = yaml.safe_load(metadata['rosbag2']['serialized_metadata'])
    bag_dir.mkdir()
    shutil.copyfile(path, bag_dir / pathlib.Path(path).name)
    (bag_dir / 'metadata.yaml').write_text(
        yaml.safe_dump({'rosbag2_bagfile_information': bag}, sort_keys=False))
    return bag_dir


def assert_rosbags_reads(path, tmp_path):
    """
    Assert that rosbags decodes every message of an MCAP file the package wrote.

    Directly, and as a bag directory built from its embedded metadata (which must name
    the file itself, not a temporary one); both give what mcap_ros2 decodes. Returns
    the number of messages.
    """
    ours = read_independently(path)
    direct = read_with_rosbags(path)
    assert [(t, s, log) for t, s, log, _, _ in ours] == [(t, s, log) for t, s, log, _ in direct]
    bag = read_with_rosbags(bag_from_embedded_metadata(path, tmp_path / f'bag_of_{path.stem}'))
    assert [(t, log) for t, _, log, _ in bag] == [(t, log) for t, _, log, _ in direct]
    for (_, _, _, _, expected), (_, _, _, got) in zip(ours, direct):
        assert_same_decoded(expected, got)
    return len(direct)


def assert_same_decoded(expected, actual, where='msg'):
    """Compare two decoded messages (mcap_ros2 and rosbags objects) field by field, exactly."""
    names = getattr(expected, '__slots__', None) or [
        n for n in vars(expected) if not n.startswith('_')]
    for name in names:
        a, b = getattr(expected, name), getattr(actual, name)
        here = f'{where}.{name}'
        if hasattr(a, '__slots__') and not isinstance(a, (str, bytes)):
            assert_same_decoded(a, b, here)
        elif isinstance(a, (list, tuple)) and a and hasattr(a[0], '__slots__'):
            assert len(a) == len(b), here
            for k, (x, y) in enumerate(zip(a, b)):
                assert_same_decoded(x, y, f'{here}[{k}]')
        elif isinstance(_as_list(a), (list, tuple)):
            assert list(_as_list(b)) == list(_as_list(a)), here
        else:
            assert b == a, here


BASE = 1_700_000_000_000_000_000
TOPICS = ('finger_0/pressure_command', 'finger_0/pressure', 'finger_0/curvature',
          'finger_0/shape', '/diagnostics')


@functools.lru_cache(maxsize=None)
def _rosbags_store():
    from rosbags.typesys import get_typestore, Stores
    return get_typestore(Stores.ROS2_JAZZY)


def canonical_cdr(message):
    """
    CDR of a message with zero alignment padding: the same bytes on every run.

    rclpy's serialize_message leaves the padding uninitialised, so files of the same
    messages differ from run to run; rosbags writes zeros.
    """
    store = _rosbags_store()
    name = type_name_of(message)
    return bytes(store.serialize_cdr(store.deserialize_cdr(serialize_message(message), name),
                                     name))


def write_recording(path, n=40, period=50_000_000, chunk_size=4096,
                    serialize=serialize_message, **kwargs):
    """N samples of a few gripper topics at 20 Hz, plus curvature and shape of finger_1."""
    with Rosbag2McapWriter(path, chunk_size=chunk_size, **kwargs) as writer:
        for topic in TOPICS:
            writer.add_topic('/' + topic.lstrip('/'), type_name_of(samples(0)[topic]))
        writer.add_topic('/finger_1/curvature', 'std_msgs/msg/Float64')
        writer.add_topic('/finger_1/shape', 'nav_msgs/msg/Path')
        for i in range(n):
            t = BASE + i * period
            sample = samples(i)
            for topic in TOPICS:
                writer.write('/' + topic.lstrip('/'), serialize(sample[topic]), t + 1)
            result = FakeResult(10.0 + 0.1 * i)
            writer.write('/finger_1/curvature', serialize(curvature_message(result)), t)
            writer.write('/finger_1/shape', serialize(shape_message(result, 'finger_1', t)), t)
    return path
