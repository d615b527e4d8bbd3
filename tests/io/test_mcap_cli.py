"""The fpc-mcap command: info, export-csv, plot, recover, and its errors on bad input."""

import csv
import json
import shutil

from helpers import read_with_rosbags
import matplotlib.image
from mcap.writer import Writer
from mcap_test_utils import (assert_rosbags_reads, BASE, read_independently, samples,
                             write_recording)
import pytest
from rclpy.serialization import serialize_message

from fpc_gripper.io.cli import main
from fpc_gripper.io.mcap_reader import McapFile
from fpc_gripper.io.mcap_writer import Rosbag2McapWriter
from fpc_gripper.tools import OUTPUT_MARKER


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    return write_recording(tmp_path_factory.mktemp('rec') / 'rec.mcap')


@pytest.fixture(scope='module')
def bag_directory(tmp_path_factory):
    """The same recording split every 0.5 s into a rosbag2 bag directory (4 files)."""
    path = write_recording(tmp_path_factory.mktemp('bag') / 'rec', max_duration=500_000_000)
    assert len(list(path.glob('rec_*.mcap'))) == 4 and (path / 'metadata.yaml').is_file()
    return path


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_help_of_every_command(capsys):
    for command in ([], ['info'], ['plot'], ['export-csv'], ['recover'], ['replay-model']):
        with pytest.raises(SystemExit) as exit_info:
            main(command + ['--help'])
        assert exit_info.value.code == 0
        assert 'usage: fpc-mcap' in capsys.readouterr().out


def test_info_counts_and_rates(capsys, recording):
    code, out, err = run(capsys, 'info', recording, '--json')
    assert code == 0, err
    info = json.loads(out)
    assert info['profile'] == 'ros2' and info['message_count'] == 40 * 7
    assert info['duration_s'] == pytest.approx(39 * 0.05, abs=1e-8)
    topic = info['topics']['/finger_0/pressure']
    assert topic['type'] == 'sensor_msgs/msg/FluidPressure' and topic['count'] == 40
    assert topic['rate_hz'] == pytest.approx(20.0)
    code, out, _ = run(capsys, 'info', recording)
    assert code == 0 and '/finger_1/shape' in out and '20.00 Hz' in out


def test_export_csv_flattens_fields(capsys, recording, tmp_path):
    out_dir = tmp_path / 'csv'
    code, _, err = run(capsys, 'export-csv', recording, out_dir, '--topics',
                       '/finger_0/pressure', '/finger_1/shape')
    assert code == 0, err
    names = sorted(p.name for p in out_dir.iterdir() if p.name[0] != '.')
    assert names == ['finger_0__pressure.csv', 'finger_1__shape.csv']
    with open(out_dir / 'finger_0__pressure.csv', newline='') as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 40
    # Exact: the CSV holds repr(float), which parses back to the same double.
    assert float(rows[3]['fluid_pressure']) == samples(3)['finger_0/pressure'].fluid_pressure
    assert int(rows[3]['log_time_ns']) == BASE + 3 * 50_000_000 + 1
    assert rows[3]['header.frame_id'] == 'finger_0'
    with open(out_dir / 'finger_1__shape.csv', newline='') as handle:
        poses = json.loads(next(csv.DictReader(handle))['poses'])
    # Exact: the first pose has tangent 0, so w = cos(0) = 1.0 in every libm.
    assert len(poses) == 17 and poses[0]['pose']['orientation']['w'] == 1.0


@pytest.mark.parametrize('size', [(640, 480), (1000, 300)])
def test_plot_writes_pngs_of_the_requested_size(capsys, recording, tmp_path, size):
    out_dir = tmp_path / 'plots'
    code, out, err = run(capsys, 'plot', recording, out_dir, '--times', '0,0.5,1.9',
                         '--size', f'{size[0]}x{size[1]}')
    assert code == 0, err
    names = sorted(p.name for p in out_dir.iterdir() if p.name[0] != '.')
    assert names == ['curvature.png', 'pressure.png', 'shapes.png']
    for name in names:
        image = matplotlib.image.imread(out_dir / name)
        assert image.shape[:2] == (size[1], size[0])
        assert image[..., :3].std() > 0.01   # not blank


# -- bad input ----------------------------------------------------------------------------

def _truncated(src, dst):
    data = src.read_bytes()
    dst.write_bytes(data[:int(len(data) * 0.6)])
    return dst


def _corrupt(src, dst):
    data = bytearray(src.read_bytes())
    with McapFile(src) as f:
        chunk = f.summary.chunk_indexes[1]
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[middle:middle + 16] = bytes(16)
    dst.write_bytes(bytes(data))
    return dst


def _not_mcap(src, dst):
    dst.write_bytes(b'this is not an MCAP file at all' * 10)
    return dst


def _no_schema(src, dst):
    with open(dst, 'wb') as stream:
        writer = Writer(stream)
        writer.start(profile='ros2', library='test')
        channel = writer.register_channel('/finger_0/pressure', 'cdr', schema_id=0)
        writer.add_message(channel, log_time=1, publish_time=1,
                           data=serialize_message(samples(0)['finger_0/pressure']))
        writer.finish()
    return dst


BAD_INPUTS = {'truncated': _truncated, 'corrupt': _corrupt, 'not_mcap': _not_mcap,
              'no_schema': _no_schema}
REASONS = {'truncated': 'truncated', 'corrupt': 'damaged', 'not_mcap': 'not an MCAP file',
           'no_schema': 'has no schema'}


def _commands(bad, out):
    return {
        'info': ['info', bad],
        # --force: even allowed to replace them, a failed run leaves the old outputs.
        'plot': ['plot', bad, out, '--force'],
        'export-csv': ['export-csv', bad, out, '--force'],
        'replay-model': ['replay-model', bad, out / 'replayed.mcap', '--quiet', '--force'],
    }


# `info` decodes nothing, so a schema-less channel is listed, not an error (tested below).
@pytest.mark.parametrize('kind, command', [
    (kind, command) for kind in sorted(BAD_INPUTS)
    for command in ('info', 'plot', 'export-csv', 'replay-model')
    if (kind, command) != ('no_schema', 'info')])
def test_bad_input_fails_cleanly(capsys, recording, tmp_path, kind, command):
    bad = BAD_INPUTS[kind](recording, tmp_path / f'{kind}.mcap')
    out = tmp_path / 'out'
    out.mkdir()
    sentinel = out / 'replayed.mcap'
    sentinel.write_bytes(b'previous output')
    (out / 'curvature.png').write_bytes(b'previous plot')
    (out / OUTPUT_MARKER).write_text('an earlier run')
    before = sorted(p.name for p in tmp_path.rglob('*'))
    code, _, err = run(capsys, *_commands(bad, out)[command])
    assert code == 2
    assert f'fpc-mcap {command}: error:' in err and 'Traceback' not in err
    assert REASONS[kind] in err
    assert sorted(p.name for p in tmp_path.rglob('*')) == before   # no temp files left
    assert sentinel.read_bytes() == b'previous output'
    assert (out / 'curvature.png').read_bytes() == b'previous plot'


def test_info_flags_a_missing_schema(capsys, recording, tmp_path):
    bad = _no_schema(recording, tmp_path / 'no_schema.mcap')
    code, out, err = run(capsys, 'info', bad)
    assert code == 0, err
    assert '(no schema)' in out


@pytest.mark.parametrize('argv', [
    ['export-csv', '{rec}', '{out}', '--topics', '/finger_0/nothing'],
    ['plot', '{rec}', '{out}', '--times', '99'],
    ['replay-model', '{rec}', '{out}/r.mcap', '--source', 'pressure_command',
     '--config', '{missing}'],
])
def test_unknown_topics_and_bad_options_fail_cleanly(capsys, recording, tmp_path, argv):
    out = tmp_path / 'out'
    argv = [a.format(rec=recording, out=out, missing=tmp_path / 'missing.yaml') for a in argv]
    code, _, err = run(capsys, *argv)
    assert code == 2 and 'error:' in err
    assert not out.exists()


def test_recover_truncated_file(capsys, recording, tmp_path):
    bad = _truncated(recording, tmp_path / 'cut.mcap')
    out = tmp_path / 'fixed.mcap'
    code, stdout, err = run(capsys, 'recover', bad, out)
    assert code == 0, err
    assert 'cut off' in stdout
    with McapFile(out) as f:
        assert 0 < f.message_count < 280
        logs = [m.log_time for m in f.messages(decode=False)]
        count = f.message_count
    assert logs == sorted(logs)
    # The embedded metadata names fixed.mcap, not the temporary file it was written as.
    assert assert_rosbags_reads(out, tmp_path) == count


def test_recover_skips_a_damaged_chunk(capsys, recording, tmp_path):
    bad = _corrupt(recording, tmp_path / 'bad.mcap')
    code, stdout, err = run(capsys, 'recover', bad, tmp_path / 'fixed.mcap')
    assert code == 0, err
    assert '1 damaged chunks skipped' in stdout
    with McapFile(tmp_path / 'fixed.mcap') as f:
        chunks = McapFile(recording).chunk_count
        assert f.message_count < 280 and chunks > 2


def test_recover_rejects_a_non_mcap_file(capsys, recording, tmp_path):
    bad = _not_mcap(recording, tmp_path / 'junk.mcap')
    code, _, err = run(capsys, 'recover', bad, tmp_path / 'out.mcap')
    assert code == 2 and 'not an MCAP file' in err
    assert not (tmp_path / 'out.mcap').exists()


# -- exact times, bag directories, refusing to overwrite --------------------------------------

def test_info_prints_exact_times(capsys, tmp_path):
    path = tmp_path / 'times.mcap'
    start, end = 1_700_000_000_123_456_789, 1_700_000_003_987_654_321
    with Rosbag2McapWriter(path) as writer:
        writer.add_topic('/aperture', 'std_msgs/msg/Float64')
        for t in (start, end):
            writer.write('/aperture', serialize_message(samples(0)['aperture']), t)
    # A double holds ~16 digits: start * 1e-9 prints as 1700000000.123456717.
    assert f'{start * 1e-9:.9f}' != '1700000000.123456789'
    code, out, err = run(capsys, 'info', path)
    assert code == 0, err
    assert 'start:     1700000000.123456789 s' in out
    assert 'end:       1700000003.987654321 s' in out
    assert 'duration:  3.864197532 s' in out
    code, out, _ = run(capsys, 'info', path, '--json')
    info = json.loads(out)
    assert (info['start_ns'], info['end_ns'], info['duration_ns']) == (
        start, end, end - start)


def test_every_command_reads_a_bag_directory_as_the_single_file(
        capsys, recording, bag_directory, tmp_path):
    code, out, err = run(capsys, 'info', bag_directory, '--json')
    assert code == 0, err
    split = json.loads(out)
    code, out, _ = run(capsys, 'info', recording, '--json')
    whole = json.loads(out)
    assert len(split['files']) == 4 and split['chunk_count'] >= 4
    for key in ('message_count', 'start_ns', 'end_ns', 'topics'):
        assert split[key] == whole[key], key
    code, out, _ = run(capsys, 'info', bag_directory)
    assert 'bag:' in out and '(4 files: rec_0.mcap, rec_1.mcap, rec_2.mcap, rec_3.mcap)' in out
    for source, name in ((recording, 'whole'), (bag_directory, 'split')):
        assert run(capsys, 'export-csv', source, tmp_path / name)[0] == 0
    for csv_file in sorted((tmp_path / 'whole').iterdir()):
        assert (tmp_path / 'split' / csv_file.name).read_text() == csv_file.read_text()
    code, _, err = run(capsys, 'plot', bag_directory, tmp_path / 'plots')
    assert code == 0, err
    assert sorted(p.name for p in (tmp_path / 'plots').iterdir() if p.name[0] != '.') == [
        'curvature.png', 'pressure.png', 'shapes.png']
    code, out, err = run(capsys, 'recover', bag_directory, tmp_path / 'joined.mcap')
    assert code == 0, err
    assert 'chunks of 4 files' in out
    assert [m[:4] for m in read_independently(tmp_path / 'joined.mcap')] == \
        [m[:4] for m in read_independently(recording)]
    assert assert_rosbags_reads(tmp_path / 'joined.mcap', tmp_path) == 280


def test_recover_a_crashed_bag_directory(capsys, bag_directory, tmp_path):
    """A recorder killed mid-split leaves no metadata.yaml and a cut-off last file."""
    crashed = tmp_path / 'crashed'
    shutil.copytree(bag_directory, crashed)
    (crashed / 'metadata.yaml').unlink()
    last = crashed / 'rec_3.mcap'
    last.write_bytes(last.read_bytes()[:int(last.stat().st_size * 0.6)])
    code, out, err = run(capsys, 'recover', crashed, tmp_path / 'fixed.mcap')
    assert code == 0, err
    assert 'chunks of 4 files' in out and 'cut off' in out
    fixed = read_with_rosbags(tmp_path / 'fixed.mcap')
    complete = sum(len(read_with_rosbags(bag_directory / f'rec_{i}.mcap')) for i in range(3))
    assert complete < len(fixed) < 280
    logs = [log for _, _, log, _ in fixed]
    assert logs == sorted(logs)


def test_recover_refuses_an_existing_output_unless_forced(capsys, recording, tmp_path):
    bad = _truncated(recording, tmp_path / 'cut.mcap')
    out = tmp_path / 'fixed.mcap'
    out.write_bytes(b'precious')
    code, _, err = run(capsys, 'recover', bad, out)
    assert code == 2 and 'exists' in err and '--force' in err
    assert out.read_bytes() == b'precious'
    assert sorted(p.name for p in tmp_path.iterdir()) == ['cut.mcap', 'fixed.mcap']
    code, _, err = run(capsys, 'recover', bad, out, '--force')
    assert code == 0, err
    assert 0 < assert_rosbags_reads(out, tmp_path) < 280
