"""MCAP reading with clear errors for bad files, and recovery of files cut off by a crash."""

import dataclasses
import io
import pathlib
import struct
import zlib

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Header, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk
from mcap_ros2.decoder import DecoderFactory

from .mcap_writer import atomic_output, MESSAGE_ENCODING, Rosbag2McapWriter, SCHEMA_ENCODING

__all__ = [
    'CorruptFileError', 'McapFile', 'McapInputError', 'MissingSchemaError',
    'RecordedMessage', 'RecoveryReport', 'TopicInfo', 'TruncatedFileError',
    'UnknownTopicError', 'recover',
]

_MAGIC = bytes((137, 77, 67, 65, 80, 48, 13, 10))
_FOOTER_RECORD_SIZE = 1 + 8 + 8 + 8 + 4
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


class McapFile:
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
    def topics(self):
        """Every topic in the file, by name (TopicInfo)."""
        return dict(self._topics)

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

    def check_topics(self, topics):
        """
        Check that every topic is in the file.

        Raises
        ------
        UnknownTopicError
            Naming the missing topics and the ones the file has.

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

    def close(self):
        """Close the file."""
        self._stream.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


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
        Whether the input had its footer (it was not cut off).
    dropped_bytes : int
        Bytes after the last whole record that could not be read [bytes].
    topics : dict of str to int
        Messages per topic in the output.

    """

    messages: int = 0
    chunks: int = 0
    corrupt_chunks: int = 0
    skipped_messages: int = 0
    complete: bool = False
    dropped_bytes: int = 0
    topics: dict = dataclasses.field(default_factory=dict)


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


def recover(in_path, out_path, *, compression='zstd'):
    """
    Rewrite a possibly truncated MCAP file into a complete, indexed one.

    Reads record by record up to the last whole record; chunks whose CRC or decompression
    fails are skipped and counted. Schemas, channels (with their metadata), messages and
    metadata records are written to `out_path` in rosbag2's form with a fresh summary,
    index and ``rosbag2`` metadata record. The output is written to a temporary file
    beside `out_path` and moved into place only when complete.

    Parameters
    ----------
    in_path, out_path : str or os.PathLike
        Input and output files.
    compression : {'zstd', 'lz4', 'none'}
        Chunk compression of the output.

    Returns
    -------
    RecoveryReport

    Raises
    ------
    McapInputError
        If the input is missing, not MCAP, or has no readable message at all.

    """
    in_path = pathlib.Path(in_path)
    out_path = pathlib.Path(out_path)
    if in_path.resolve() == out_path.resolve():
        raise McapInputError(f'{in_path}: input and output must differ')
    try:
        stream = open(in_path, 'rb')
    except FileNotFoundError:
        raise McapInputError(f'{in_path}: no such file') from None
    except IsADirectoryError:
        raise McapInputError(f'{in_path}: is a directory, not an MCAP file') from None
    report = RecoveryReport()
    with stream, atomic_output(out_path, suffix='.mcap') as tmp:
        size = in_path.stat().st_size
        if size == 0:
            raise CorruptFileError(f'{in_path}: empty file, not an MCAP file')
        if stream.read(len(_MAGIC)) != _MAGIC:
            raise CorruptFileError(f'{in_path}: not an MCAP file (bad magic bytes)')
        writer = Rosbag2McapWriter(tmp, compression=compression, overwrite=True,
                                   library='fpc-mcap recover (mcap-python)')
        try:
            _copy_records(stream, size, writer, report)
        finally:
            writer.close()
        if report.messages == 0 and report.corrupt_chunks:
            raise CorruptFileError(f'{in_path}: no readable chunk '
                                   f'({report.corrupt_chunks} damaged)')
    return report


def _copy_records(stream, size, writer, report):
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

    for opcode, body in _records(stream, size, report):
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
