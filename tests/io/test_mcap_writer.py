"""Rosbag2-form MCAP writing: schema text, records and metadata, flush and split behaviour."""

import types

from helpers import read_with_rosbags
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from mcap_test_utils import (assert_rosbags_reads, assert_same_fields, read_independently,
                             samples, summary_of)
import pytest
from rclpy.qos import qos_profile_sensor_data, QoSProfile
from rclpy.serialization import serialize_message
import yaml

from fpc_gripper.io.mcap_reader import McapFile, recover, TruncatedFileError
from fpc_gripper.io.mcap_writer import (atomic_mcap_writer, DEFINITION_SEPARATOR,
                                        message_definition, Rosbag2McapWriter,
                                        SchemaNotFoundError, serialize_qos_profiles,
                                        type_description_hash, type_hash_string,
                                        type_name_of)

SEP = '=' * 80


def test_path_definition_has_rosbag2_layout():
    text = message_definition('nav_msgs/msg/Path')
    assert DEFINITION_SEPARATOR == SEP
    blocks = text.split('\n' + SEP + '\n')
    assert 'geometry_msgs/PoseStamped[] poses' in blocks[0]
    headers = [b.splitlines()[0] for b in blocks[1:]]
    # Depth first, dependencies sorted, each once: what rosbag2's get_full_text produces.
    assert headers == ['MSG: geometry_msgs/PoseStamped', 'MSG: geometry_msgs/Pose',
                       'MSG: geometry_msgs/Point', 'MSG: geometry_msgs/Quaternion',
                       'MSG: std_msgs/Header', 'MSG: builtin_interfaces/Time']
    assert message_definition('nav_msgs/Path') == text


def test_unknown_types_raise():
    with pytest.raises(SchemaNotFoundError):
        message_definition('no_such_msgs/msg/Nothing')
    with pytest.raises(SchemaNotFoundError):
        message_definition('std_msgs/msg/NoSuchType')
    with pytest.raises(ValueError, match='type_name'):
        message_definition('not a type')


def test_every_gripper_type_decodes_with_mcap_ros2_and_rosbags(tmp_path):
    path = tmp_path / 'all.mcap'
    sent = samples(3)
    with Rosbag2McapWriter(path) as writer:
        for topic, msg in sent.items():
            name = '/' + topic.lstrip('/')
            writer.add_topic(name, type_name_of(msg))
            writer.write(name, serialize_message(msg), 1000, 2000)
    got = {topic: (schema, decoded) for topic, schema, _, _, decoded in
           read_independently(path)}
    assert len(got) == len(sent)
    for topic, msg in sent.items():
        schema, decoded = got['/' + topic.lstrip('/')]
        assert schema == type_name_of(msg)
        assert_same_fields(msg, decoded, topic)
    # rosbags builds its types from the file's schemas and checks their RIHS01 hashes.
    assert assert_rosbags_reads(path, tmp_path) == len(sent)


def test_records_are_in_rosbag2_form(tmp_path):
    path = tmp_path / 'form.mcap'
    msg = samples(1)['finger_0/pressure']
    with Rosbag2McapWriter(path, compression='lz4') as writer:
        writer.add_topic('/finger_0/pressure', 'sensor_msgs/msg/FluidPressure',
                         offered_qos_profiles=[qos_profile_sensor_data])
        for i in range(5):
            writer.write('/finger_0/pressure', serialize_message(msg), 10 + i, 5 + i)
    header, summary, metadata = summary_of(path)
    assert header.profile == 'ros2'
    (schema,) = summary.schemas.values()
    assert (schema.name, schema.encoding) == ('sensor_msgs/msg/FluidPressure', 'ros2msg')
    assert schema.data.decode() == message_definition('sensor_msgs/msg/FluidPressure')
    (channel,) = summary.channels.values()
    assert channel.message_encoding == 'cdr'
    assert channel.metadata['topic_type_hash'].startswith('RIHS01_')
    (qos,) = yaml.safe_load(channel.metadata['offered_qos_profiles'])
    assert qos['reliability'] == 'best_effort' and qos['history'] == 'keep_last'
    assert set(qos) == {'history', 'depth', 'reliability', 'durability', 'deadline',
                        'lifespan', 'liveliness', 'liveliness_lease_duration',
                        'avoid_ros_namespace_conventions'}
    assert {c.compression for c in summary.chunk_indexes} == {'lz4'}
    bag = yaml.safe_load(metadata['rosbag2']['serialized_metadata'])
    assert bag['version'] == 9 and bag['storage_identifier'] == 'mcap'
    assert bag['message_count'] == 5
    (topic,) = bag['topics_with_message_count']
    assert topic['message_count'] == 5
    assert topic['topic_metadata']['type'] == 'sensor_msgs/msg/FluidPressure'
    assert topic['topic_metadata']['offered_qos_profiles'] == \
        channel.metadata['offered_qos_profiles']
    assert bag['duration']['nanoseconds'] == 4
    assert bag['starting_time']['nanoseconds_since_epoch'] == 10
    with open(path, 'rb') as stream:
        times = [(m.log_time, m.publish_time) for _, _, m in make_reader(
            stream, decoder_factories=[DecoderFactory()]).iter_messages()]
    assert times == [(10 + i, 5 + i) for i in range(5)]


def test_qos_yaml_uses_policy_names():
    text = serialize_qos_profiles([QoSProfile(depth=7)])
    (qos,) = yaml.safe_load(text)
    assert qos['depth'] == 7 and qos['reliability'] == 'reliable'
    assert qos['durability'] == 'volatile'
    assert serialize_qos_profiles([]) == ''


def test_flushed_chunks_survive_a_crash(tmp_path):
    """A copy of the file taken while writing (a crash) has every flushed message."""
    path = tmp_path / 'live.mcap'
    msg = samples(2)['finger_0/curvature']
    writer = Rosbag2McapWriter(path, chunk_size=1 << 20)
    writer.add_topic('/c', 'std_msgs/msg/Float64')
    for i in range(30):
        writer.write('/c', serialize_message(msg), i)
        if i in (9, 19):
            writer.flush()
    assert writer.pending_count == 10
    crashed = tmp_path / 'crashed.mcap'
    crashed.write_bytes(path.read_bytes())
    writer.close()
    with pytest.raises(TruncatedFileError, match='recover'):
        McapFile(crashed)
    report = recover(crashed, tmp_path / 'recovered.mcap')
    assert (report.messages, report.complete) == (20, False)
    got = read_independently(tmp_path / 'recovered.mcap')
    assert [log for _, _, log, _, _ in got] == list(range(20))
    assert assert_rosbags_reads(tmp_path / 'recovered.mcap', tmp_path) == 20


def test_split_by_duration_into_a_directory(tmp_path):
    out = tmp_path / 'bag'
    msg = serialize_message(samples(0)['aperture'])
    with Rosbag2McapWriter(out, max_duration=10, chunk_size=100) as writer:
        writer.add_topic('/aperture', 'std_msgs/msg/Float64')
        for i in range(35):
            writer.write('/aperture', msg, i)
    files = sorted(out.glob('*.mcap'))
    assert [f.name for f in files] == [f'bag_{i}.mcap' for i in range(4)]
    counts = [McapFile(f).message_count for f in files]
    assert counts == [10, 10, 10, 5]
    meta = yaml.safe_load((out / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert meta['message_count'] == 35
    assert meta['relative_file_paths'] == [f.name for f in files]
    assert [f['message_count'] for f in meta['files']] == counts
    # As rosbag2 writes them, the last file embeds the whole bag's metadata.
    _, _, embedded = summary_of(files[-1])
    assert yaml.safe_load(embedded['rosbag2']['serialized_metadata']) == meta
    # The bag directory opens in rosbags, every split file in order.
    assert [log for _, _, log, _ in read_with_rosbags(out)] == list(range(35))
    # And each split file alone. (Its embedded metadata is the bag's when it was closed,
    # naming the earlier files too, as rosbag2's MCAP storage writes it.)
    assert [len(read_with_rosbags(f)) for f in files] == counts


def test_split_by_size_keeps_every_message(tmp_path):
    out = tmp_path / 'rec.mcap'
    msg = serialize_message(samples(4)['markers'])
    with Rosbag2McapWriter(out, max_file_size=4000, chunk_size=1000,
                           compression='none') as writer:
        writer.add_topic('/markers', 'visualization_msgs/msg/MarkerArray')
        for i in range(60):
            writer.write('/markers', msg, i)
        paths = writer.paths
    assert len(paths) > 2 and paths[0] == out and paths[1].name == 'rec_1.mcap'
    logs = [log for p in paths for _, _, log, _, _ in read_independently(p)]
    assert logs == list(range(60))


def test_refuses_to_overwrite(tmp_path):
    out = tmp_path / 'x.mcap'
    out.write_bytes(b'precious')
    with pytest.raises(FileExistsError):
        Rosbag2McapWriter(out)
    assert out.read_bytes() == b'precious'


def test_atomic_writer_names_the_final_file_and_refuses_to_replace(tmp_path):
    target = tmp_path / 'final.mcap'
    data = serialize_message(samples(1)['aperture'])
    with atomic_mcap_writer(target, compression='lz4') as writer:
        writer.add_topic('/aperture', 'std_msgs/msg/Float64')
        for i in range(3):
            writer.write('/aperture', data, 10 + i)
        # Written under a temporary name beside the target until complete.
        (tmp,) = [p for p in tmp_path.iterdir()]
        assert tmp.name.startswith('.final.mcap.') and not target.exists()
    assert [p.name for p in tmp_path.iterdir()] == ['final.mcap']
    _, _, metadata = summary_of(target)
    bag = yaml.safe_load(metadata['rosbag2']['serialized_metadata'])
    assert bag['relative_file_paths'] == ['final.mcap']
    assert [f['path'] for f in bag['files']] == ['final.mcap']
    assert assert_rosbags_reads(target, tmp_path) == 3
    before = target.read_bytes()
    with pytest.raises(FileExistsError, match='--force'):
        with atomic_mcap_writer(target):
            pass
    assert target.read_bytes() == before
    # A failing body leaves the old file, even with overwrite.
    with pytest.raises(RuntimeError):
        with atomic_mcap_writer(target, overwrite=True) as writer:
            raise RuntimeError('failed half way')
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag_of_final', 'final.mcap']
    with atomic_mcap_writer(target, overwrite=True) as writer:
        writer.add_topic('/aperture', 'std_msgs/msg/Float64')
        writer.write('/aperture', data, 99)
    assert [log for _, _, log, _ in read_with_rosbags(target)] == [99]


@pytest.mark.parametrize('field, value', [
    ('log_time', -1), ('publish_time', -1_000_000_000), ('log_time', 2**64),
    ('publish_time', float('nan')), ('log_time', 1.5)])
def test_times_outside_an_mcap_time_are_refused_by_name(tmp_path, field, value):
    """MCAP times are uint64 ns: mcap's struct.pack raised 'argument out of range' instead."""
    path = tmp_path / 'times.mcap'
    with Rosbag2McapWriter(path) as writer:
        writer.add_topic('/aperture', 'std_msgs/msg/Float64')
        data = serialize_message(samples(0)['aperture'])
        times = {'log_time': 5, 'publish_time': 5, field: value}
        with pytest.raises(ValueError, match=rf'`{field}` must be an integer in \[0, 2\*\*64\)'):
            writer.write('/aperture', data, times['log_time'], times['publish_time'])
        writer.write('/aperture', data, 2**64 - 1, 0)    # the extremes are times
    assert [(log, pub) for _, _, log, pub, _ in read_independently(path)] == [(2**64 - 1, 0)]


def test_the_type_hash_a_publisher_announces_is_spelled_as_rep_2011():
    announced = types.SimpleNamespace(version=1, value=bytes(range(32)))
    assert type_hash_string(announced, 'std_msgs/msg/Float64') == \
        'RIHS01_' + bytes(range(32)).hex()


@pytest.mark.parametrize('announced', [types.SimpleNamespace(version=0, value=b'\x01' * 32),
                                       types.SimpleNamespace(version=1, value=bytes(32)),
                                       None])
def test_no_announced_type_hash_falls_back_to_the_installed_description(announced):
    installed = type_description_hash('std_msgs/msg/Float64')
    assert installed.startswith('RIHS01_')
    assert type_hash_string(announced, 'std_msgs/msg/Float64') == installed
    assert type_hash_string(announced, 'no_such_pkg/msg/Thing') == ''
