"""fpc-mcap on damaged files: the reproducers of issue 12 finding 6, one test each."""

import io

from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import breakup_chunk
from mcap_test_utils import read_independently, write_recording
import pytest
import zstandard

from fpc_gripper.io.cli import main
from fpc_gripper.io.mcap_reader import McapFile

# Chunk record: opcode and length (9 bytes), then message start and end times, uncompressed
# size (8 bytes each), uncompressed CRC (4), compression string (4 + len), records length
# (8): the compressed records start this many bytes after the record's first byte.
_ZSTD_DATA = 9 + 8 + 8 + 8 + 4 + 4 + len('zstd') + 8


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def chunk_indexes(path):
    with open(path, 'rb') as stream:
        return make_reader(stream).get_summary().chunk_indexes


def chunk_messages(path, index):
    """(topic, log time, publish time) of the messages in one chunk, by mcap's own parser."""
    with open(path, 'rb') as stream:
        channels = make_reader(stream).get_summary().channels
    data = path.read_bytes()
    body = data[index.chunk_start_offset + 9:index.chunk_start_offset + index.chunk_length]
    chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
    return [(channels[r.channel_id].topic, r.log_time, r.publish_time)
            for r in breakup_chunk(chunk) if isinstance(r, Message)]


def keys(path):
    return [(topic, log_time, publish_time) for topic, _, log_time, publish_time, _ in
            read_independently(path)]


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    """945 messages of 7 topics in some 130 zstd chunks, with summary and index."""
    return write_recording(tmp_path_factory.mktemp('damaged') / 'rec.mcap', n=135)


def assert_clean_error(err, command, path, tmp_path, before):
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f'fpc-mcap {command}: error: {path}:'), err
    assert 'Traceback' not in err
    assert sorted(p.name for p in tmp_path.rglob('*')) == before    # no partial output


@pytest.fixture
def flipped(recording, tmp_path):
    """One flipped bit in the zstd frame header of chunk 5: zstandard.ZstdError, not a CRC."""
    data = bytearray(recording.read_bytes())
    index = chunk_indexes(recording)[5]
    at = index.chunk_start_offset + _ZSTD_DATA
    assert bytes(data[at:at + 4]) == b'\x28\xb5\x2f\xfd'     # the zstd magic number
    data[at] ^= 0x01
    with pytest.raises(zstandard.ZstdError):
        zstandard.decompress(bytes(data[at:index.chunk_start_offset + index.chunk_length]))
    bad = tmp_path / 'flipped.mcap'
    bad.write_bytes(bytes(data))
    return bad, chunk_messages(recording, index)


@pytest.mark.parametrize('command', ['info', 'export-csv'])
def test_a_zstd_error_is_one_line_naming_the_file(capsys, flipped, tmp_path, command):
    bad, _ = flipped
    before = sorted(p.name for p in tmp_path.rglob('*'))
    argv = [command, bad] + ([tmp_path / 'csv'] if command == 'export-csv' else [])
    code, _, err = run(capsys, *argv)
    assert code == 2
    assert_clean_error(err, command, bad, tmp_path, before)
    assert 'ZstdError' in err and 'fpc-mcap recover' in err


def test_recover_skips_a_chunk_zstd_cannot_read_and_counts_its_messages(
        capsys, recording, flipped, tmp_path):
    bad, lost = flipped
    out = tmp_path / 'fixed.mcap'
    code, stdout, err = run(capsys, 'recover', bad, out)
    assert code == 0, err
    assert f'1 damaged chunks skipped ({len(lost)} messages lost)' in stdout
    # Every message but those of the damaged chunk, from mcap's own reader.
    expected = [k for k in keys(recording) if k not in set(lost)]
    assert 0 < len(lost) and len(expected) == 945 - len(lost)
    assert keys(out) == expected


@pytest.mark.parametrize('fraction', [0.0, 0.01], ids=['magic_only', 'one_percent'])
def test_recover_refuses_when_nothing_is_recoverable(capsys, tmp_path, fraction):
    # The recorder's chunk size: 1 % of the file ends inside the first chunk.
    data = write_recording(tmp_path / 'rec.mcap', n=135, chunk_size=768 * 1024).read_bytes()
    (tmp_path / 'rec.mcap').unlink()
    bad = tmp_path / 'cut.mcap'
    bad.write_bytes(data[:max(8, int(len(data) * fraction))])
    before = sorted(p.name for p in tmp_path.rglob('*'))
    code, _, err = run(capsys, 'recover', bad, tmp_path / 'fixed.mcap')
    assert code == 2
    assert_clean_error(err, 'recover', bad, tmp_path, before)
    assert 'nothing recoverable' in err and 'cut off' in err


@pytest.mark.parametrize('target', ['chunk', 'message_index'])
def test_recover_reads_past_a_damaged_record_length_through_the_index(
        capsys, recording, tmp_path, target):
    """Once 449 of 949: a damaged length misaligned every record after it."""
    data = bytearray(recording.read_bytes())
    index = chunk_indexes(recording)[60]
    if target == 'chunk':
        at = index.chunk_start_offset + 1
    else:
        at = min(index.message_index_offsets.values()) + 1
    data[at:at + 8] = (123_456).to_bytes(8, 'little')
    bad = tmp_path / 'length.mcap'
    bad.write_bytes(bytes(data))
    out = tmp_path / 'fixed.mcap'
    code, stdout, err = run(capsys, 'recover', bad, out)
    assert code == 0, err
    assert 'read through its index' in stdout and '0 damaged chunks' in stdout
    assert keys(out) == keys(recording)


def test_recover_of_a_cut_file_with_a_damaged_chunk_still_counts(capsys, recording, tmp_path):
    """Without a summary, a skipped chunk's messages come from the message index after it."""
    data = bytearray(recording.read_bytes())
    indexes = chunk_indexes(recording)
    lost = chunk_messages(recording, indexes[3])
    middle = indexes[3].chunk_start_offset + indexes[3].chunk_length // 2
    data[middle:middle + 16] = bytes(16)
    bad = tmp_path / 'cut.mcap'
    bad.write_bytes(bytes(data[:indexes[40].chunk_start_offset + 20]))
    code, stdout, err = run(capsys, 'recover', bad, tmp_path / 'fixed.mcap')
    assert code == 0, err
    assert 'cut off' in stdout
    assert f'1 damaged chunks skipped ({len(lost)} messages lost)' in stdout
    assert len(keys(tmp_path / 'fixed.mcap')) == sum(
        len(chunk_messages(recording, c)) for c in indexes[:40]) - len(lost)


def test_an_empty_but_complete_recording_recovers_to_an_empty_one(capsys, tmp_path):
    """Nothing is damaged, so nothing is refused: the copy has no message, as the input."""
    empty = write_recording(tmp_path / 'empty.mcap', n=0)
    code, stdout, err = run(capsys, 'recover', empty, tmp_path / 'copy.mcap')
    assert code == 0, err
    assert stdout.startswith('recovered 0 messages') and 'input was complete' in stdout
    with McapFile(empty) as source, McapFile(tmp_path / 'copy.mcap') as copy:
        assert copy.message_count == 0 and sorted(copy.topics) == sorted(source.topics)
