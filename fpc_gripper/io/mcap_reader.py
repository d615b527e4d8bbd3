"""MCAP reading (single files and rosbag2 bag directories), and recovery after a crash."""

import contextlib
import dataclasses
import heapq
import io
import os
import pathlib
import re
import struct
import zlib

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Message, MessageIndex, Metadata, Schema
from mcap.stream_reader import breakup_chunk
from mcap_ros2.decoder import DecoderFactory
import yaml
import zstandard

from .mcap_writer import atomic_mcap_writer, MESSAGE_ENCODING, SCHEMA_ENCODING

__all__ = [
    'CorruptFileError', 'McapFile', 'McapInputError', 'MissingSchemaError',
    'RecordedMessage', 'Recording', 'RecoveryReport', 'TopicInfo', 'TruncatedFileError',
    'Undecodable', 'UnknownTopicError', 'recording_files', 'recover',
]

_MAGIC = bytes((137, 77, 67, 65, 80, 48, 13, 10))
_FOOTER_RECORD_SIZE = 1 + 8 + 8 + 8 + 4
_BAG_METADATA = 'metadata.yaml'
_SPLIT_INDEX = re.compile(r'_(\d+)\.mcap$')
# The mcap library, its decompressors and the CDR decoder were not written for hostile
# bytes: besides McapError they raise struct, zstd, lz4 (RuntimeError), zlib, Unicode,
# Key, Index, Type, Overflow and Memory errors, among others. Whatever they raise while
# parsing a file's bytes means that the bytes are damaged; `_damaged` says so, naming the
# file. Only the parsing calls are guarded, never this package's own code.
_PARSE_ERRORS = (Exception,)
#: Bound of a chunk's uncompressed size [bytes]: a damaged size must not allocate exabytes.
_MAX_CHUNK_BYTES = 1 << 30
#: Opcodes of the MCAP records (0x80 and up are private records, skipped).
_KNOWN_OPCODES = frozenset(int(op) for op in Opcode)


class McapInputError(Exception):
    """An input MCAP file cannot be used; the message says why and what to do."""


class TruncatedFileError(McapInputError):
    """The file ends before its footer (for instance the recorder was killed)."""


class CorruptFileError(McapInputError):
    """The file is not MCAP, or a record in it is damaged."""


class MissingSchemaError(McapInputError):
    """A channel has no schema, or one this package cannot decode."""


class UnknownTopicError(McapInputError):
    """A requested topic is not in the file."""


def _one_line(error, limit=200):
    text = ' '.join(str(error).split())
    return f'{type(error).__name__}: {text[:limit]}{"..." if len(text) > limit else ""}'


@contextlib.contextmanager
def _damaged(path, what, hint=''):
    """Raise what the mcap library raises on damaged bytes as one CorruptFileError line."""
    try:
        yield
    except McapInputError:
        raise
    except _PARSE_ERRORS as err:
        raise CorruptFileError(f'{path}: {what} ({_one_line(err)}){hint}') from None


class _SizedFile(io.BufferedReader):
    """
    A file opened for reading whose large reads past its end fail before they allocate.

    A damaged length field can ask the mcap library for up to 2**64 bytes, which
    ``read`` would try to allocate before finding the end of the file.
    """

    def __init__(self, path):
        super().__init__(io.FileIO(path, 'rb'))
        self.size = os.fstat(self.fileno()).st_size

    def read(self, size=-1):
        """Read like BufferedReader, but refuse a read larger than what is left."""
        if size is not None and size > 4096 and size > self.size - self.tell():
            raise EOFError(f'a record asks for {size} bytes, beyond the end of the file')
        return super().read(size)


@dataclasses.dataclass(frozen=True)
class TopicInfo:
    """One topic of a file: name, type name, message count and encodings."""

    topic: str
    type_name: str
    message_count: int
    message_encoding: str
    schema_encoding: str
    offered_qos_profiles: str


@dataclasses.dataclass(frozen=True)
class RecordedMessage:
    """
    One message read from a file.

    Attributes
    ----------
    topic, type_name : str
        Channel topic and schema name.
    log_time, publish_time : int
        Receive and publish times [ns].
    sequence : int
        Sequence number.
    data : bytes
        CDR payload.
    ros_msg : object or None
        Decoded message (mcap_ros2 dynamic type), None if not decoded.

    """

    topic: str
    type_name: str
    log_time: int
    publish_time: int
    sequence: int
    data: bytes
    ros_msg: object = None


@dataclasses.dataclass(frozen=True)
class Undecodable:
    """
    A message whose payload the CDR decoder rejected, skipped by a reader told to go on.

    Attributes
    ----------
    topic : str
    log_time : int
        Receive time [ns].
    sequence : int
    error : str
        What the decoder raised, on one line.

    """

    topic: str
    log_time: int
    sequence: int
    error: str

    def __str__(self):
        seconds, nanoseconds = divmod(self.log_time, 1_000_000_000)
        return (f'{self.topic} at log time {seconds}.{nanoseconds:09d} s (sequence '
                f'{self.sequence}): {self.error}')


class _TopicChecks:
    """Checks of a topic list against a recording's `_topics` (TopicInfo by name)."""

    def check_topics(self, topics):
        """
        Check that every topic is in the recording.

        Raises
        ------
        UnknownTopicError
            Naming the missing topics and the ones the recording has.

        """
        missing = [t for t in topics if t not in self._topics]
        if missing:
            raise UnknownTopicError(
                f'{self.path}: unknown topic(s) {", ".join(missing)}; '
                f'the file has {", ".join(sorted(self._topics)) or "no topics"}')

    def check_decodable(self, topics):
        """
        Check that the topics carry CDR messages with a ros2msg schema.

        Raises
        ------
        MissingSchemaError
            If a topic's channel has no schema, or an encoding this package cannot decode.

        """
        for topic in topics:
            info = self._topics[topic]
            if not info.type_name:
                raise MissingSchemaError(f'{self.path}: topic {topic} has no schema')
            if info.schema_encoding != SCHEMA_ENCODING:
                raise MissingSchemaError(
                    f'{self.path}: topic {topic} has schema encoding '
                    f'{info.schema_encoding!r}, not {SCHEMA_ENCODING!r}')
            if info.message_encoding != MESSAGE_ENCODING:
                raise MissingSchemaError(
                    f'{self.path}: topic {topic} has message encoding '
                    f'{info.message_encoding!r}, not {MESSAGE_ENCODING!r}')

    @property
    def topics(self):
        """Every topic, by name (TopicInfo)."""
        return dict(self._topics)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class McapFile(_TopicChecks):
    """
    A complete, indexed MCAP file opened for reading.

    Opening checks the magic bytes, the footer and the summary, so that a truncated or
    damaged file fails at once with a `McapInputError` instead of half way through a job.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    skip_undecodable : bool
        A payload the decoder rejects: skipped and listed in `undecodable` when True,
        else (the default) a `CorruptFileError` that names its topic and log time.

    Raises
    ------
    TruncatedFileError
        If the file has no footer (run ``fpc-mcap recover`` on it).
    CorruptFileError
        If it is not an MCAP file or its summary is damaged.

    """

    def __init__(self, path, skip_undecodable=False):
        self.path = pathlib.Path(path)
        self.skip_undecodable = bool(skip_undecodable)
        #: The `Undecodable` messages skipped so far, in the order met.
        self.undecodable = []
        try:
            self._stream = _SizedFile(self.path)
        except FileNotFoundError:
            raise McapInputError(f'{self.path}: no such file') from None
        except IsADirectoryError:
            raise McapInputError(f'{self.path}: is a directory, not an MCAP file') from None
        try:
            self._open()
        except BaseException:
            self._stream.close()
            raise

    def _open(self):
        size = self.path.stat().st_size
        if size == 0:
            raise CorruptFileError(f'{self.path}: empty file, not an MCAP file')
        head = self._stream.read(len(_MAGIC))
        if head != _MAGIC:
            raise CorruptFileError(f'{self.path}: not an MCAP file (bad magic bytes)')
        self._stream.seek(max(size - len(_MAGIC), 0))
        tail = self._stream.read(len(_MAGIC))
        if size < 2 * len(_MAGIC) + _FOOTER_RECORD_SIZE or tail != _MAGIC:
            raise TruncatedFileError(
                f'{self.path}: truncated, no footer or summary (was the recorder killed?); '
                f'run "fpc-mcap recover {self.path} OUT" to rebuild its index')
        self._stream.seek(0)
        with _damaged(self.path, 'damaged header or summary'):
            self._reader = SeekingReader(self._stream, validate_crcs=True,
                                         decoder_factories=[DecoderFactory()],
                                         record_size_limit=size)
            self.header = self._reader.get_header()
            self.summary = self._reader.get_summary()
        if self.summary is None:
            raise TruncatedFileError(
                f'{self.path}: has no summary section; '
                f'run "fpc-mcap recover {self.path} OUT" to rebuild its index')
        self._topics = self._build_topics()

    def _build_topics(self):
        stats = self.summary.statistics
        counts = dict(stats.channel_message_counts) if stats else {}
        topics = {}
        for channel_id, channel in self.summary.channels.items():
            schema = self.summary.schemas.get(channel.schema_id)
            topics[channel.topic] = TopicInfo(
                topic=channel.topic,
                type_name=schema.name if schema else '',
                message_count=int(counts.get(channel_id, 0)),
                message_encoding=channel.message_encoding,
                schema_encoding=schema.encoding if schema else '',
                offered_qos_profiles=channel.metadata.get('offered_qos_profiles', ''))
        return topics

    # -- properties ---------------------------------------------------------------------

    @property
    def message_count(self):
        """Messages in the file."""
        stats = self.summary.statistics
        return int(stats.message_count) if stats else 0

    @property
    def start_time(self):
        """Log time of the first message [ns]."""
        stats = self.summary.statistics
        return int(stats.message_start_time) if stats else 0

    @property
    def end_time(self):
        """Log time of the last message [ns]."""
        stats = self.summary.statistics
        return int(stats.message_end_time) if stats else 0

    @property
    def chunk_count(self):
        """Chunks in the file."""
        return len(self.summary.chunk_indexes)

    @property
    def compressions(self):
        """Chunk compressions used ('' is none)."""
        return {c.compression for c in self.summary.chunk_indexes}

    def metadata(self):
        """
        Read the metadata records.

        Returns
        -------
        list of (str, dict)
            Name and key-value pairs of each record.

        """
        with _damaged(self.path, 'damaged metadata record'):
            return [(m.name, dict(m.metadata)) for m in self._reader.iter_metadata()]

    # -- messages -----------------------------------------------------------------------

    def messages(self, topics=None, decode=True):
        """
        Iterate over messages in log-time order.

        Parameters
        ----------
        topics : iterable of str, optional
            Topics to read (all when omitted).
        decode : bool
            Decode each message with mcap_ros2's decoder.

        Yields
        ------
        RecordedMessage

        Raises
        ------
        UnknownTopicError, MissingSchemaError
            Before the first message, for a bad topic list.
        CorruptFileError
            For a schema that cannot be parsed (before the first message), when a damaged
            chunk or message record is met, or for a payload the decoder rejects unless
            the file skips those (`skip_undecodable`).

        """
        topics = list(self._topics) if topics is None else list(topics)
        self.check_topics(topics)
        decoders = self._decoders(topics) if decode else {}
        with _damaged(self.path, 'damaged data', '; "fpc-mcap recover" keeps the readable '
                                                 'chunks'):
            for schema, channel, message in self._reader.iter_messages(topics=topics):
                ros_msg = None
                if decode:
                    try:
                        ros_msg = decoders[channel.id](message.data)
                    except _PARSE_ERRORS as err:
                        bad = Undecodable(channel.topic, message.log_time, message.sequence,
                                          _one_line(err))
                        if not self.skip_undecodable:
                            raise CorruptFileError(
                                f'{self.path}: undecodable payload of {bad}') from None
                        self.undecodable.append(bad)
                        continue
                yield RecordedMessage(
                    topic=channel.topic, type_name=schema.name if schema else '',
                    log_time=message.log_time, publish_time=message.publish_time,
                    sequence=message.sequence, data=message.data, ros_msg=ros_msg)

    def _decoders(self, topics):
        """Build the decoder of each topic's channel: a damaged schema fails here, named."""
        self.check_decodable(topics)
        factory = DecoderFactory()
        decoders = {}
        for channel in self.summary.channels.values():
            if channel.topic in topics:
                schema = self.summary.schemas.get(channel.schema_id)
                # The rosidl parser that mcap_ros2 vendors prints its error, then raises it.
                with _damaged(self.path, f'damaged schema of {channel.topic}'), \
                        contextlib.redirect_stderr(io.StringIO()):
                    decoders[channel.id] = factory.decoder_for(channel.message_encoding, schema)
        return decoders

    def schema(self, topic):
        """Return the Schema record (name, encoding, data) of a topic's channel, or None."""
        for channel in self.summary.channels.values():
            if channel.topic == topic:
                return self.summary.schemas.get(channel.schema_id)
        return None

    def close(self):
        """Close the file."""
        self._stream.close()


def _split_key(path):
    match = _SPLIT_INDEX.search(path.name)
    return (int(match.group(1)) if match else -1, path.name)


def recording_files(path):
    """
    List the MCAP files of a recording, in order.

    Parameters
    ----------
    path : str or os.PathLike
        An MCAP file, or a rosbag2 bag directory: its ``metadata.yaml`` names the files
        (``relative_file_paths``); without one (a recorder killed before it wrote it),
        every ``*.mcap`` file in it, by split index (``<name>_<i>.mcap``).

    Returns
    -------
    list of pathlib.Path

    Raises
    ------
    McapInputError
        If the path does not exist, the metadata is unreadable or not an MCAP bag, or a
        file it names is missing.

    """
    path = pathlib.Path(path)
    if not path.exists():
        raise McapInputError(f'{path}: no such file or directory')
    if not path.is_dir():
        return [path]
    meta = path / _BAG_METADATA
    if not meta.is_file():
        files = sorted(path.glob('*.mcap'), key=_split_key)
        if not files:
            raise McapInputError(f'{path}: a directory without {_BAG_METADATA} or .mcap files, '
                                 'not a rosbag2 bag')
        return files
    try:
        info = yaml.safe_load(meta.read_text(encoding='utf-8'))['rosbag2_bagfile_information']
        storage = info.get('storage_identifier', '')
        names = [pathlib.PurePath(str(n)).name for n in info['relative_file_paths']]
    except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError) as err:
        raise McapInputError(f'{meta}: not rosbag2 bag metadata ({type(err).__name__}: '
                             f'{err})') from None
    if storage != 'mcap':
        raise McapInputError(f"{meta}: storage_identifier {storage!r} is not 'mcap'")
    files = [path / name for name in names]
    missing = [f.name for f in files if not f.is_file()]
    if missing or not files:
        raise McapInputError(f'{meta}: names files that are missing: '
                             f'{", ".join(missing) or "none listed"}')
    return files


class Recording(_TopicChecks):
    """
    A recording opened for reading: one MCAP file, or a rosbag2 bag directory of splits.

    Reads like a `McapFile` (topics, counts, times, decoded messages in log-time order),
    over every file of the recording; each file is checked when opened.

    Parameters
    ----------
    path : str or os.PathLike
        See `recording_files`.
    skip_undecodable : bool
        As `McapFile`'s: skip (and list) payloads the decoder rejects instead of failing.

    Raises
    ------
    McapInputError
        As `recording_files` and `McapFile` raise them.

    """

    def __init__(self, path, skip_undecodable=False):
        self.path = pathlib.Path(path)
        self.files = recording_files(self.path)
        self._parts = []
        try:
            for file in self.files:
                self._parts.append(McapFile(file, skip_undecodable=skip_undecodable))
        except BaseException:
            self.close()
            raise
        self.header = self._parts[0].header
        self._topics = {}
        for part in self._parts:
            for name, info in part.topics.items():
                known = self._topics.get(name)
                if known is not None:
                    info = dataclasses.replace(
                        known, message_count=known.message_count + info.message_count)
                self._topics[name] = info

    @property
    def message_count(self):
        """Messages in every file."""
        return sum(p.message_count for p in self._parts)

    @property
    def start_time(self):
        """Log time of the first message [ns]."""
        return min((p.start_time for p in self._parts if p.message_count), default=0)

    @property
    def end_time(self):
        """Log time of the last message [ns]."""
        return max((p.end_time for p in self._parts if p.message_count), default=0)

    @property
    def chunk_count(self):
        """Chunks in every file."""
        return sum(p.chunk_count for p in self._parts)

    @property
    def compressions(self):
        """Chunk compressions used ('' is none)."""
        return set().union(*(p.compressions for p in self._parts))

    def metadata(self):
        """Read the metadata records of every file: list of (name, dict)."""
        return [record for part in self._parts for record in part.metadata()]

    def schema(self, topic):
        """Return the Schema record of a topic (from the first file that has it), or None."""
        return next((s for s in (p.schema(topic) for p in self._parts) if s is not None), None)

    @property
    def undecodable(self):
        """The `Undecodable` messages skipped so far, of every file, in log-time order."""
        return sorted((bad for part in self._parts for bad in part.undecodable),
                      key=lambda bad: bad.log_time)

    def messages(self, topics=None, decode=True):
        """
        Iterate over the messages of every file in log-time order.

        Parameters and errors as `McapFile.messages`; messages of equal log time keep the
        order of their files.
        """
        topics = list(self._topics) if topics is None else list(topics)
        self.check_topics(topics)
        if decode:
            self.check_decodable(topics)
        streams = [p.messages([t for t in topics if t in p.topics], decode)
                   for p in self._parts]
        return heapq.merge(*streams, key=lambda m: m.log_time)

    def close(self):
        """Close every file."""
        for part in self._parts:
            part.close()


@dataclasses.dataclass
class RecoveryReport:
    """
    What `recover` found and kept.

    Attributes
    ----------
    messages : int
        Messages written to the output.
    chunks : int
        Readable chunks.
    corrupt_chunks : int
        Chunks skipped because their CRC, compression or record failed.
    lost_messages : int
        Messages of the skipped chunks, as their message indexes count them.
    uncounted_chunks : int
        Skipped chunks whose message index was unreadable too (their messages are not in
        `lost_messages`).
    indexed_chunks : int
        Chunks read through the summary's chunk index, after a damaged record ended the
        record-by-record read (the output has them too).
    skipped_messages : int
        Messages of channels without a usable schema.
    complete : bool
        Whether every input file had its footer (none was cut off).
    dropped_bytes : int
        Bytes after the last whole record of each cut-off file that could not be read
        [bytes].
    topics : dict of str to int
        Messages per topic in the output.
    files : int
        Input files read (the split files of a bag directory).

    """

    messages: int = 0
    chunks: int = 0
    corrupt_chunks: int = 0
    lost_messages: int = 0
    uncounted_chunks: int = 0
    indexed_chunks: int = 0
    skipped_messages: int = 0
    complete: bool = False
    dropped_bytes: int = 0
    topics: dict = dataclasses.field(default_factory=dict)
    files: int = 0

    @property
    def damaged(self):
        """Whether anything of the input could not be read."""
        return bool(not self.complete or self.corrupt_chunks or self.indexed_chunks
                    or self.skipped_messages)


def _parse(cls, body, *args):
    return cls.read(ReadDataStream(io.BytesIO(body)), *args)


def _chunk_records(chunk):
    """Return the records of a chunk, its CRC checked; refuse a size that cannot be true."""
    if chunk.uncompressed_size > _MAX_CHUNK_BYTES:
        raise CorruptFileError(f'a chunk claims {chunk.uncompressed_size} bytes')
    if chunk.compression == 'zstd':
        # zstd allocates the size its frame header claims, whatever the chunk says.
        claimed = zstandard.frame_content_size(chunk.data)
        if claimed not in (-1, chunk.uncompressed_size):
            raise CorruptFileError(f'a zstd frame claims {claimed} bytes, its chunk '
                                   f'{chunk.uncompressed_size}')
    return breakup_chunk(chunk, validate_crc=True)


def recover(in_path, out_path, *, compression='zstd', overwrite=False):
    """
    Rewrite a possibly truncated or damaged recording into one complete, indexed MCAP file.

    Reads each file record by record up to its last whole record; chunks whose record,
    CRC or decompression fails are skipped, and their messages counted from their message
    indexes. A record whose length or opcode is damaged ends that read (nothing after it
    can be trusted); if the file still has its summary (footer and summary CRC intact),
    every chunk after it is then read at the offset and length its chunk index gives.
    Schemas, channels (with their metadata), messages and metadata records are written to
    `out_path` in rosbag2's form with a fresh summary, index and ``rosbag2`` metadata
    record (which names `out_path`). The output is written to a temporary file beside
    `out_path` and moved into place only when complete.

    Parameters
    ----------
    in_path : str or os.PathLike
        An MCAP file, or a bag directory whose split files are read in order (see
        `recording_files`; a recorder killed before it wrote metadata.yaml left one).
    out_path : str or os.PathLike
        Output file.
    compression : {'zstd', 'lz4', 'none'}
        Chunk compression of the output.
    overwrite : bool
        Replace an existing `out_path`; otherwise it is refused.

    Returns
    -------
    RecoveryReport

    Raises
    ------
    McapInputError
        If the input is missing or not MCAP, or if it is damaged and not one message of
        it can be read (nothing is written then).
    FileExistsError
        If `out_path` exists and `overwrite` is false.

    """
    in_path = pathlib.Path(in_path)
    out_path = pathlib.Path(out_path)
    files = recording_files(in_path)
    if out_path.resolve() in {in_path.resolve(), *(f.resolve() for f in files)}:
        raise McapInputError(f'{in_path}: input and output must differ')
    report = RecoveryReport(complete=True)
    with atomic_mcap_writer(out_path, overwrite=overwrite, compression=compression,
                            library='fpc-mcap recover (mcap-python)') as writer:
        for file in files:
            part = _recover_file(file, writer, report)
            report.files += 1
            report.complete &= part.complete
            report.dropped_bytes += part.dropped_bytes
        if report.messages == 0 and report.damaged:
            raise CorruptFileError(f'{in_path}: nothing recoverable, not one readable message '
                                   f'({_damage_summary(report)})')
    return report


def _damage_summary(report):
    parts = []
    if not report.complete:
        parts.append(f'cut off, {report.dropped_bytes} bytes unreadable')
    if report.corrupt_chunks:
        parts.append(f'{report.corrupt_chunks} damaged chunks')
    if report.skipped_messages:
        parts.append(f'{report.skipped_messages} messages without schema')
    return ', '.join(parts) or 'no message in it'


def _recover_file(path, writer, report):
    """Copy what is readable of one file; return its own report (completeness, bytes lost)."""
    try:
        stream = _SizedFile(path)
    except IsADirectoryError:
        raise McapInputError(f'{path}: is a directory, not an MCAP file') from None
    with stream:
        if stream.size == 0:
            raise CorruptFileError(f'{path}: empty file, not an MCAP file')
        if stream.read(len(_MAGIC)) != _MAGIC:
            raise CorruptFileError(f'{path}: not an MCAP file (bad magic bytes)')
        part = RecoveryReport()
        _Salvage(stream, writer, part, report).run()
    return part


def _summary(stream):
    """
    Return the summary of a file whose footer and summary CRC are intact, or None.

    A damaged summary is worse than none: its chunk offsets would be trusted.
    """
    size = stream.size
    footer_at = size - len(_MAGIC) - _FOOTER_RECORD_SIZE
    if footer_at < len(_MAGIC):
        return None
    stream.seek(footer_at)
    tail = stream.read(_FOOTER_RECORD_SIZE + len(_MAGIC))
    if tail[-len(_MAGIC):] != _MAGIC or tail[:9] != struct.pack('<BQ', Opcode.FOOTER, 20):
        return None
    summary_start, _, crc = struct.unpack_from('<QQI', tail, 9)
    if not len(_MAGIC) < summary_start < footer_at:
        return None
    stream.seek(summary_start)
    covered = stream.read(footer_at - summary_start) + tail[:_FOOTER_RECORD_SIZE - 4]
    if crc and zlib.crc32(covered) != crc:
        return None
    try:
        stream.seek(0)
        return SeekingReader(stream, record_size_limit=size).get_summary()
    except _PARSE_ERRORS:
        return None


class _Salvage:
    """
    Copy the readable records of one file into a writer.

    `part` gets the file's completeness and bytes lost, `report` the counts.
    """

    def __init__(self, stream, writer, part, report):
        self.stream = stream
        self.writer = writer
        self.part = part
        self.report = report
        self.schemas = {}
        self.channels = {}
        self.summary = _summary(stream)
        self.chunk_index = {} if self.summary is None else {
            c.chunk_start_offset: c for c in self.summary.chunk_indexes}
        # Offsets of the chunks that the record-by-record read met.
        self.seen = set()

    def run(self):
        """Read record by record; after a damaged record, read the rest by the index."""
        if self.summary is not None:
            for record in (*self.summary.schemas.values(), *self.summary.channels.values()):
                self.handle(record)
        self.sequential()
        for offset, index in sorted(self.chunk_index.items()):
            if offset not in self.seen:
                self.report.indexed_chunks += 1
                self.indexed_chunk(index)

    def sequential(self):
        """Copy whole records from the magic on; stop at the end, a cut or a damaged record."""
        size = self.stream.size
        offset = len(_MAGIC)
        self.stream.seek(offset)
        # A skipped chunk's messages are counted by the message indexes after it:
        # None when there is no skipped chunk, else whether they counted it.
        skipped = None
        while True:
            head = self.stream.read(9)
            if len(head) < 9:
                break
            opcode, length = struct.unpack('<BQ', head)
            if length > size - offset - 9 or not self.plausible(opcode, offset, length):
                break
            body = self.stream.read(length)
            start, offset = offset, offset + 9 + length
            if opcode == Opcode.MESSAGE_INDEX:
                if skipped is not None:
                    skipped = self.count_lost(body) or skipped
                continue
            self.settle(skipped)
            skipped = None
            if opcode == Opcode.CHUNK:
                self.seen.add(start)
                if not self.chunk(body):
                    skipped = False
                continue
            self.record(opcode, body)
            if opcode in (Opcode.DATA_END, Opcode.FOOTER):
                self.part.complete = True
                return
        self.settle(skipped)
        # Cut off, or a damaged record: what follows is lost unless the index has it.
        self.part.complete = self.summary is not None
        if self.summary is None:
            self.part.dropped_bytes = size - offset

    def plausible(self, opcode, offset, length):
        """Whether a record header can be trusted (a damaged length misaligns the rest)."""
        if opcode not in _KNOWN_OPCODES and opcode < 0x80:
            return False
        if opcode == Opcode.CHUNK and self.chunk_index:
            index = self.chunk_index.get(offset)
            return index is not None and index.chunk_length == 9 + length
        # Writers put every message of a chunked file in a chunk, where a CRC checks it;
        # one outside is bytes read out of step, and would be copied as a message.
        return opcode != Opcode.MESSAGE or not (self.chunk_index or self.seen)

    def settle(self, skipped):
        if skipped is False:
            self.report.uncounted_chunks += 1

    def count_lost(self, body):
        """Add the messages of a skipped chunk's message index record; False if unreadable."""
        try:
            self.report.lost_messages += len(_parse(MessageIndex, body).records)
        except _PARSE_ERRORS:
            return False
        return True

    def chunk(self, body):
        """Copy the records of one chunk record's body; False (and counted) if damaged."""
        try:
            records = _chunk_records(_parse(Chunk, body))
        except _PARSE_ERRORS:
            self.report.corrupt_chunks += 1
            return False
        self.report.chunks += 1
        for record in records:
            self.handle(record)
        return True

    def indexed_chunk(self, index):
        """Copy a chunk at the offset and length its chunk index gives, or count it lost."""
        body = self.read_record(Opcode.CHUNK, index.chunk_start_offset, index.chunk_length)
        if body is None:
            self.report.corrupt_chunks += 1
        elif self.chunk(body):
            return
        counted = True
        for offset in index.message_index_offsets.values():
            found = self.read_record(Opcode.MESSAGE_INDEX, offset)
            counted = counted and found is not None and self.count_lost(found)
        self.settle(None if counted else False)

    def read_record(self, opcode, offset, length=None):
        """Return the body of the record of an opcode at an offset (and length), or None."""
        size = self.stream.size
        if not len(_MAGIC) <= offset <= size - 9:
            return None
        self.stream.seek(offset)
        found, body_length = struct.unpack('<BQ', self.stream.read(9))
        if length is not None:
            body_length = length - 9     # the index's length: the record's may be damaged
        if found != opcode or not 0 <= body_length <= size - offset - 9:
            return None
        return self.stream.read(body_length)

    def record(self, opcode, body):
        """Copy a schema, channel, message or metadata record met outside a chunk."""
        kinds = {Opcode.SCHEMA: Schema, Opcode.CHANNEL: Channel, Opcode.MESSAGE: Message,
                 Opcode.METADATA: Metadata}
        kind = kinds.get(opcode)
        if kind is None:
            return
        try:
            record = _parse(kind, body, len(body)) if kind is Message else _parse(kind, body)
        except _PARSE_ERRORS:
            return
        if kind is not Metadata:
            self.handle(record)
        elif record.name != 'rosbag2':
            # The output gets a rosbag2 record of its own on close.
            self.writer.add_metadata(record.name, record.metadata)

    def handle(self, record):
        """Register a schema or channel, or write a message of a known channel."""
        if isinstance(record, Schema):
            self.schemas[record.id] = record
        elif isinstance(record, Channel):
            self.add_channel(record)
        elif isinstance(record, Message):
            self.add_message(record)

    def add_channel(self, channel):
        self.channels[channel.id] = channel
        schema = self.schemas.get(channel.schema_id)
        if schema is None or not schema.name:
            return
        try:
            self.writer.add_topic(
                channel.topic, schema.name, definition=schema.data.decode(),
                schema_encoding=schema.encoding,
                offered_qos_profiles=channel.metadata.get('offered_qos_profiles', ''),
                type_hash=channel.metadata.get('topic_type_hash', ''))
        except (ValueError, UnicodeDecodeError):
            return

    def add_message(self, message):
        channel = self.channels.get(message.channel_id)
        report = self.report
        if channel is None or channel.topic not in self.writer.topics:
            report.skipped_messages += 1
            return
        self.writer.write(channel.topic, message.data, message.log_time, message.publish_time,
                          message.sequence)
        report.messages += 1
        report.topics[channel.topic] = report.topics.get(channel.topic, 0) + 1
