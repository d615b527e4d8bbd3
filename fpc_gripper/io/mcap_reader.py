"""MCAP reading (single files and rosbag2 bag directories), and recovery after a crash."""

import dataclasses
import heapq
import io
import pathlib
import re
import struct
import zlib

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Header, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk
from mcap_ros2.decoder import DecoderFactory
import yaml

from .mcap_writer import atomic_mcap_writer, MESSAGE_ENCODING, SCHEMA_ENCODING

__all__ = [
    'CorruptFileError', 'McapFile', 'McapInputError', 'MissingSchemaError',
    'RecordedMessage', 'Recording', 'RecoveryReport', 'TopicInfo', 'TruncatedFileError',
    'UnknownTopicError', 'recording_files', 'recover',
]

_MAGIC = bytes((137, 77, 67, 65, 80, 48, 13, 10))
_FOOTER_RECORD_SIZE = 1 + 8 + 8 + 8 + 4
_BAG_METADATA = 'metadata.yaml'
_SPLIT_INDEX = re.compile(r'_(\d+)\.mcap$')
# Everything a damaged file can make the mcap library raise while parsing.
_PARSE_ERRORS = (McapError, struct.error, ValueError, EOFError, KeyError, IndexError,
                 UnicodeDecodeError, RuntimeError, MemoryError, zlib.error)


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

    Raises
    ------
    TruncatedFileError
        If the file has no footer (run ``fpc-mcap recover`` on it).
    CorruptFileError
        If it is not an MCAP file or its summary is damaged.

    """

    def __init__(self, path):
        self.path = pathlib.Path(path)
        try:
            self._stream = open(self.path, 'rb')
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
        try:
            self._reader = make_reader(self._stream, validate_crcs=True,
                                       decoder_factories=[DecoderFactory()])
            self.header = self._reader.get_header()
            self.summary = self._reader.get_summary()
        except _PARSE_ERRORS as err:
            raise CorruptFileError(f'{self.path}: damaged header or summary ({err})') from None
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
        try:
            return [(m.name, dict(m.metadata)) for m in self._reader.iter_metadata()]
        except _PARSE_ERRORS as err:
            raise CorruptFileError(f'{self.path}: damaged metadata record ({err})') from None

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
            When a damaged chunk or message is met.

        """
        topics = list(self._topics) if topics is None else list(topics)
        self.check_topics(topics)
        if decode:
            self.check_decodable(topics)
        decoders = DecoderFactory()
        try:
            for schema, channel, message in self._reader.iter_messages(topics=topics):
                ros_msg = None
                if decode:
                    decoder = decoders.decoder_for(channel.message_encoding, schema)
                    ros_msg = decoder(message.data)
                yield RecordedMessage(
                    topic=channel.topic, type_name=schema.name if schema else '',
                    log_time=message.log_time, publish_time=message.publish_time,
                    sequence=message.sequence, data=message.data, ros_msg=ros_msg)
        except _PARSE_ERRORS as err:
            raise CorruptFileError(f'{self.path}: damaged data ({type(err).__name__}: {err}); '
                                   f'"fpc-mcap recover" keeps the readable chunks') from None

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

    Raises
    ------
    McapInputError
        As `recording_files` and `McapFile` raise them.

    """

    def __init__(self, path):
        self.path = pathlib.Path(path)
        self.files = recording_files(self.path)
        self._parts = []
        try:
            for file in self.files:
                self._parts.append(McapFile(file))
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
        Chunks skipped because their CRC or compression failed.
    skipped_messages : int
        Messages of channels without a usable schema.
    complete : bool
        Whether every input file had its footer (none was cut off).
    dropped_bytes : int
        Bytes after the last whole record of each file that could not be read [bytes].
    topics : dict of str to int
        Messages per topic in the output.
    files : int
        Input files read (the split files of a bag directory).

    """

    messages: int = 0
    chunks: int = 0
    corrupt_chunks: int = 0
    skipped_messages: int = 0
    complete: bool = False
    dropped_bytes: int = 0
    topics: dict = dataclasses.field(default_factory=dict)
    files: int = 0


def _records(stream, size, report):
    """Yield (opcode, body) of every whole record after the magic; stop at a cut-off one."""
    offset = len(_MAGIC)
    while True:
        head = stream.read(9)
        if len(head) < 9:
            report.dropped_bytes = size - offset
            return
        opcode, length = struct.unpack('<BQ', head)
        if length > size - offset - 9:
            report.dropped_bytes = size - offset
            return
        body = stream.read(length)
        offset += 9 + length
        yield opcode, body
        if opcode in (Opcode.DATA_END, Opcode.FOOTER):
            report.complete = True
            report.dropped_bytes = 0
            return


def _parse(cls, body, *args):
    return cls.read(ReadDataStream(io.BytesIO(body)), *args)


def recover(in_path, out_path, *, compression='zstd', overwrite=False):
    """
    Rewrite a possibly truncated recording into one complete, indexed MCAP file.

    Reads each file record by record up to its last whole record; chunks whose CRC or
    decompression fails are skipped and counted. Schemas, channels (with their metadata),
    messages and metadata records are written to `out_path` in rosbag2's form with a
    fresh summary, index and ``rosbag2`` metadata record (which names `out_path`). The
    output is written to a temporary file beside `out_path` and moved into place only
    when complete.

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
        If the input is missing, not MCAP, or has no readable message at all.
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
        if report.messages == 0 and report.corrupt_chunks:
            raise CorruptFileError(f'{in_path}: no readable chunk '
                                   f'({report.corrupt_chunks} damaged)')
    return report


def _recover_file(path, writer, report):
    """Copy what is readable of one file; return its own report (completeness, bytes lost)."""
    try:
        stream = open(path, 'rb')
    except IsADirectoryError:
        raise McapInputError(f'{path}: is a directory, not an MCAP file') from None
    with stream:
        size = path.stat().st_size
        if size == 0:
            raise CorruptFileError(f'{path}: empty file, not an MCAP file')
        if stream.read(len(_MAGIC)) != _MAGIC:
            raise CorruptFileError(f'{path}: not an MCAP file (bad magic bytes)')
        part = RecoveryReport()
        _copy_records(stream, size, writer, part, report)
    return part


def _copy_records(stream, size, writer, part, report):
    """Copy one file's readable records; `part` gets its completeness, `report` the counts."""
    schemas = {}
    channels = {}

    def add_channel(channel):
        channels[channel.id] = channel
        schema = schemas.get(channel.schema_id)
        if schema is None or not schema.name:
            return
        try:
            writer.add_topic(channel.topic, schema.name, definition=schema.data.decode(),
                             schema_encoding=schema.encoding,
                             offered_qos_profiles=channel.metadata.get(
                                 'offered_qos_profiles', ''),
                             type_hash=channel.metadata.get('topic_type_hash', ''))
        except (ValueError, UnicodeDecodeError):
            return

    def add_message(message):
        channel = channels.get(message.channel_id)
        if channel is None or channel.topic not in writer.topics:
            report.skipped_messages += 1
            return
        writer.write(channel.topic, message.data, message.log_time, message.publish_time,
                     message.sequence)
        report.messages += 1
        report.topics[channel.topic] = report.topics.get(channel.topic, 0) + 1

    def handle(record):
        if isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            add_channel(record)
        elif isinstance(record, Message):
            add_message(record)

    for opcode, body in _records(stream, size, part):
        try:
            if opcode == Opcode.HEADER:
                _parse(Header, body)
            elif opcode == Opcode.SCHEMA:
                handle(_parse(Schema, body))
            elif opcode == Opcode.CHANNEL:
                handle(_parse(Channel, body))
            elif opcode == Opcode.MESSAGE:
                handle(_parse(Message, body, len(body)))
            elif opcode == Opcode.METADATA:
                record = _parse(Metadata, body)
                if record.name != 'rosbag2':
                    writer.add_metadata(record.name, record.metadata)
            elif opcode == Opcode.CHUNK:
                chunk = _parse(Chunk, body)
                inner = breakup_chunk(chunk, validate_crc=True)
            else:
                continue
        except _PARSE_ERRORS:
            if opcode == Opcode.CHUNK:
                report.corrupt_chunks += 1
            continue
        if opcode == Opcode.CHUNK:
            report.chunks += 1
            for record in inner:
                handle(record)
