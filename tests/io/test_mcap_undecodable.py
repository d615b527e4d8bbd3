"""A payload the CDR decoder rejects: the readers name it; fpc-mcap skips it and goes on."""

import csv

from mcap.reader import make_reader
from mcap_test_utils import ATM, BASE, fluid_pressure, read_independently, write_recording
import pytest
from rclpy.serialization import serialize_message

from fpc_gripper.io.cli import main
from fpc_gripper.io.mcap_reader import CorruptFileError, McapFile, Recording
from fpc_gripper.io.mcap_writer import Rosbag2McapWriter

#: The sample whose measured pressure is damaged, and that message's log time [ns]
#: (`write_recording`: samples every 50 ms, its topics at t + 1).
BAD = 7
BAD_LOG_TIME = BASE + BAD * 50_000_000 + 1


def _cut(data):
    # The CDR header and half a stamp: the decoder runs out of bytes.
    return data[:10]


def damaging(msg):
    """Serialise as usual, except the measured pressure of sample BAD (990 Pa per sample)."""
    data = serialize_message(msg)
    if getattr(msg, 'fluid_pressure', None) == ATM + 990.0 * BAD:
        return _cut(data)
    return data


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    """40 samples of 7 topics; one message of /finger_0/pressure cannot be decoded."""
    return write_recording(tmp_path_factory.mktemp('undecodable') / 'rec.mcap',
                           serialize=damaging)


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def named_in(err):
    return f'/finger_0/pressure at log time {BAD_LOG_TIME // 10**9}.' \
           f'{BAD_LOG_TIME % 10**9:09d} s'


def test_a_reader_names_the_message_and_fails_by_default(recording):
    with McapFile(recording) as f:
        with pytest.raises(CorruptFileError) as error:
            for _ in f.messages(topics=['/finger_0/pressure']):
                pass
    text = str(error.value)
    assert str(recording) in text and named_in(text) in text


def test_a_reader_told_to_go_on_skips_only_that_message(recording):
    with Recording(recording, skip_undecodable=True) as f:
        got = [m for m in f.messages()]
        skipped = f.undecodable
    assert len(got) == 40 * 7 - 1
    assert [(s.topic, s.log_time) for s in skipped] == [('/finger_0/pressure', BAD_LOG_TIME)]
    # mcap's own reader, not decoding, sees the same messages and the damaged one's bytes.
    with open(recording, 'rb') as stream:
        raw = [(channel.topic, message.log_time)
               for _, channel, message in make_reader(stream).iter_messages(log_time_order=True)]
    assert ('/finger_0/pressure', BAD_LOG_TIME) in raw
    expected = [key for key in raw if key != ('/finger_0/pressure', BAD_LOG_TIME)]
    assert [(m.topic, m.log_time) for m in got] == expected


def test_export_csv_writes_every_other_message_and_exits_3(capsys, recording, tmp_path):
    code, out, err = run(capsys, 'export-csv', recording, tmp_path / 'csv')
    assert code == 3, err
    assert 'skipped 1 undecodable message,' in err and named_in(err) in err
    assert 'Traceback' not in err
    with open(tmp_path / 'csv' / 'finger_0__pressure.csv', newline='') as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 39
    assert str(BAD_LOG_TIME) not in {row['log_time_ns'] for row in rows}
    assert float(rows[BAD]['fluid_pressure']) == pytest.approx(ATM + 990.0 * (BAD + 1))
    with open(tmp_path / 'csv' / 'finger_0__pressure_command.csv', newline='') as handle:
        assert len(list(csv.DictReader(handle))) == 40


def test_plot_draws_the_rest_and_exits_3(capsys, recording, tmp_path):
    code, out, err = run(capsys, 'plot', recording, tmp_path / 'plots', '--size', '160x120',
                         '--dpi', '40')
    assert code == 3, err
    assert named_in(err) in err
    assert sorted(p.name for p in (tmp_path / 'plots').iterdir() if p.name[0] != '.') == [
        'curvature.png', 'pressure.png', 'shapes.png']


def test_replay_model_solves_the_other_inputs_and_exits_3(capsys, tmp_path):
    source = tmp_path / 'in.mcap'
    gauges = [0.0, 40e3, 80e3, 120e3, 160e3]
    with Rosbag2McapWriter(source) as writer:
        writer.add_topic('/finger_0/pressure_command', 'sensor_msgs/msg/FluidPressure')
        for i, gauge in enumerate(gauges):
            data = serialize_message(fluid_pressure(i, gauge))
            writer.write('/finger_0/pressure_command', _cut(data) if i == 2 else data,
                         BASE + i * 20_000_000)
    code, out, err = run(capsys, 'replay-model', source, tmp_path / 'out.mcap',
                         '--no-rigidity', '--quiet')
    assert code == 3, err
    assert 'replayed 4 inputs' in out and '4 solves, 0 not converged' in out
    assert f'/finger_0/pressure_command at log time {BASE // 10**9}.040000000 s' in err
    shapes = [log for t, _, log, _, _ in read_independently(tmp_path / 'out.mcap')
              if t == '/finger_0/shape']
    assert shapes == [BASE + i * 20_000_000 for i in (0, 1, 3, 4)]


def test_a_clean_recording_still_exits_0(capsys, tmp_path):
    clean = write_recording(tmp_path / 'clean.mcap', n=5)
    code, out, err = run(capsys, 'export-csv', clean, tmp_path / 'csv')
    assert code == 0 and not err.strip(), err
