"""MCAP writing in rosbag2's form: ros2msg schemas, QoS metadata, periodic flushes, splits."""

import contextlib
import json
import os
import pathlib
import re
import sys
import threading

from mcap.writer import CompressionType, Writer
import yaml

from .mcap_index_spill import spill_chunk_indexes

__all__ = [
    'BAG_METADATA_VERSION', 'COMPRESSIONS', 'DEFINITION_SEPARATOR', 'MESSAGE_ENCODING',
    'PROFILE', 'SCHEMA_ENCODING', 'McapWriterError', 'Rosbag2McapWriter', 'SchemaNotFoundError',
    'atomic_mcap_writer', 'atomic_output', 'message_definition', 'normalize_type_name',
    'qos_profile_to_dict',
    'serialize_qos_profiles', 'share_directory', 'type_description_hash', 'type_hash_string',
    'type_name_of',
]

#: MCAP profile, message encoding and schema encoding that rosbag2's MCAP storage writes.
PROFILE = 'ros2'
MESSAGE_ENCODING = 'cdr'
SCHEMA_ENCODING = 'ros2msg'
#: Line that separates the dependent definitions of a ros2msg schema.
DEFINITION_SEPARATOR = '=' * 80
#: rosbag2 metadata version of Jazzy (``rosbag2_storage::BagMetadata``).
BAG_METADATA_VERSION = 9

_COMPRESSION = {
    'zstd': CompressionType.ZSTD,
    'lz4': CompressionType.LZ4,
    'none': CompressionType.NONE,
}
#: Chunk compressions a writer takes, the default first.
COMPRESSIONS = tuple(_COMPRESSION)
_PRIMITIVE_TYPES = frozenset((
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'))
# Field types of a .msg file, as rosbag2's LocalMessageDefinitionSource finds them.
_MSG_FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
_ROS_NAME = r'[a-zA-Z][a-zA-Z0-9_]*'
_TYPE_NAME = re.compile(rf'^({_ROS_NAME})/(?:({_ROS_NAME})/)?({_ROS_NAME})$')
_MAX_DEPTH = 50


class SchemaNotFoundError(LookupError):
    """No installed .msg definition was found for a message type."""


class McapWriterError(RuntimeError):
    """The writer was used out of order (closed, unknown topic)."""


@contextlib.contextmanager
def atomic_output(target, suffix=None):
    """
    Yield a temporary path beside `target` that replaces `target` only on success.

    The temporary file is in the same directory, so `os.replace` is atomic; if the body
    raises, the temporary file is removed and `target` is left as it was.

    Parameters
    ----------
    target : str or os.PathLike
        Final path.
    suffix : str, optional
        Suffix of the temporary name (default: that of `target`).

    Yields
    ------
    pathlib.Path
        The temporary path to write.

    """
    target = pathlib.Path(target)
    if not target.parent.is_dir():
        raise FileNotFoundError(f'directory of {target} does not exist')
    if target.is_dir():
        raise IsADirectoryError(f'{target} is a directory')
    suffix = target.suffix if suffix is None else suffix
    tmp = target.with_name(f'.{target.name}.{os.getpid()}.{threading.get_ident()}.tmp{suffix}')
    try:
        yield tmp
        os.replace(tmp, target)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


@contextlib.contextmanager
def atomic_mcap_writer(target, *, overwrite=False, **kwargs):
    """
    Yield a `Rosbag2McapWriter` whose single file appears at `target` only when complete.

    The file is written under a temporary name beside `target` (`atomic_output`), closed
    with its summary and index, and moved into place; its rosbag2 metadata names
    `target`, the file that exists afterwards, never the temporary one. If the body
    raises, `target` is left as it was.

    Parameters
    ----------
    target : str or os.PathLike
        Final ``.mcap`` file.
    overwrite : bool
        Replace an existing `target`; otherwise refuse it before writing anything.
    **kwargs
        Passed to `Rosbag2McapWriter` (compression, chunk_size, library, ...).

    Yields
    ------
    Rosbag2McapWriter

    Raises
    ------
    FileExistsError
        If `target` exists and `overwrite` is false.

    """
    target = pathlib.Path(target)
    if not overwrite and (target.exists() or target.is_symlink()):
        raise FileExistsError(f'output {target} exists (give --force to replace it)')
    with atomic_output(target, suffix='.mcap') as tmp:
        writer = Rosbag2McapWriter(tmp, overwrite=True, final_name=target.name, **kwargs)
        try:
            yield writer
        finally:
            writer.close()


def normalize_type_name(type_name):
    """
    Split a ROS message type name into package, namespace and type.

    Parameters
    ----------
    type_name : str
        ``pkg/msg/Type`` or ``pkg/Type``.

    Returns
    -------
    tuple of str
        ``(package, namespace, type)``; the namespace defaults to ``msg``.

    Raises
    ------
    ValueError
        If the name is not of either form.

    """
    match = _TYPE_NAME.match(str(type_name))
    if match is None:
        raise ValueError(
            f'`type_name` must look like pkg/msg/Type or pkg/Type, got {type_name!r}')
    package, namespace, name = match.groups()
    return package, namespace or 'msg', name


def type_name_of(message):
    """
    Return the full type name (``pkg/msg/Type``) of a rosidl message class or instance.

    Parameters
    ----------
    message : type or object
        A generated Python message class, or an instance of one.

    Returns
    -------
    str
        The type name, for instance ``sensor_msgs/msg/FluidPressure``.

    """
    cls = message if isinstance(message, type) else type(message)
    parts = cls.__module__.split('.')
    if len(parts) < 2:
        raise ValueError(f'`message` is not a generated ROS message class, got {cls!r}')
    return f'{parts[0]}/{parts[1]}/{cls.__name__}'


def _ament_prefixes():
    prefixes = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    # Wheels of ROS put their share/ into the interpreter prefix without AMENT_PREFIX_PATH.
    for prefix in (sys.prefix, sys.base_prefix):
        if prefix not in prefixes:
            prefixes.append(prefix)
    return prefixes


def share_directory(package):
    """
    Find the share directory of an installed ROS package through the ament index.

    Parameters
    ----------
    package : str
        Package name.

    Returns
    -------
    pathlib.Path
        ``<prefix>/share/<package>`` of the first ament prefix that registers it.

    Raises
    ------
    SchemaNotFoundError
        If no prefix registers the package.

    """
    try:
        from ament_index_python.packages import get_package_share_directory
        return pathlib.Path(get_package_share_directory(package))
    except (ImportError, LookupError, OSError, ValueError):
        pass
    for prefix in _ament_prefixes():
        marker = pathlib.Path(prefix, 'share', 'ament_index', 'resource_index', 'packages',
                              package)
        if marker.is_file():
            return pathlib.Path(prefix, 'share', package)
    raise SchemaNotFoundError(f'package {package!r} is not in the ament index '
                              f'(prefixes: {", ".join(_ament_prefixes())})')


def _read_definition(type_name):
    package, namespace, name = normalize_type_name(type_name)
    path = share_directory(package) / namespace / f'{name}.msg'
    try:
        return path.read_text(encoding='utf-8'), package
    except OSError:
        raise SchemaNotFoundError(f'no .msg definition for {type_name!r} at {path}') from None


def _dependencies(text, package):
    found = set()
    for match in _MSG_FIELD_TYPE.finditer(text):
        field_type = match.group(1)
        if field_type in _PRIMITIVE_TYPES:
            continue
        found.add(field_type if '/' in field_type else f'{package}/{field_type}')
    return sorted(found)


def message_definition(type_name):
    """
    Build the complete ros2msg definition of a type as rosbag2's MCAP storage writes it.

    The root .msg text comes first; every dependency, found recursively and depth first
    in sorted order, follows once behind a line of 80 ``=`` and a ``MSG: pkg/Type`` line,
    exactly as ``rosbag2_cpp::LocalMessageDefinitionSource::get_full_text`` does.

    Parameters
    ----------
    type_name : str
        ``pkg/msg/Type`` or ``pkg/Type``.

    Returns
    -------
    str
        The schema text (encoding ``ros2msg``).

    Raises
    ------
    SchemaNotFoundError
        If the type or one of its dependencies has no installed .msg file.

    """
    seen = set()

    def append(name, depth):
        if depth <= 0:
            raise SchemaNotFoundError(f'definition of {type_name!r} nests deeper than '
                                      f'{_MAX_DEPTH} levels')
        text, package = _read_definition(name)
        out = text
        for dep in _dependencies(text, package):
            if dep not in seen:
                seen.add(dep)
                out += f'\n{DEFINITION_SEPARATOR}\nMSG: {dep}\n' + append(dep, depth - 1)
        return out

    return append(type_name, _MAX_DEPTH)


def type_description_hash(type_name):
    """
    Return the REP-2011 type hash (``RIHS01_...``) of an installed type, or '' if unknown.

    Parameters
    ----------
    type_name : str
        ``pkg/msg/Type`` or ``pkg/Type``.

    Returns
    -------
    str
        The hash string from the type's installed ``.json`` description.

    """
    try:
        package, namespace, name = normalize_type_name(type_name)
        path = share_directory(package) / namespace / f'{name}.json'
        data = json.loads(path.read_text(encoding='utf-8'))
    except (ValueError, OSError, SchemaNotFoundError):
        return ''
    full = f'{package}/{namespace}/{name}'
    for entry in data.get('type_hashes', ()):
        if entry.get('type_name') == full:
            return entry.get('hash_string', '')
    return ''


def type_hash_string(type_hash, type_name):
    """
    Return the REP-2011 hash string of a type as a publisher announces it, or as installed.

    Parameters
    ----------
    type_hash : object
        The ``topic_type_hash`` of an rclpy TopicEndpointInfo (``version`` and ``value``
        bytes); one of version 0 or all zeros is not a hash.
    type_name : str
        ``pkg/msg/Type``: its installed description gives the hash otherwise
        (`type_description_hash`).

    """
    value = bytes(getattr(type_hash, 'value', b'') or b'')
    version = int(getattr(type_hash, 'version', 0) or 0)
    if version > 0 and any(value):
        return f'RIHS{version:02d}_{value.hex()}'
    return type_description_hash(type_name)


def _policy_name(value):
    name = getattr(value, 'name', value)
    return str(name).lower()


def _duration(value):
    nanoseconds = int(getattr(value, 'nanoseconds', value or 0))
    return {'sec': nanoseconds // 1_000_000_000, 'nsec': nanoseconds % 1_000_000_000}


def qos_profile_to_dict(profile):
    """
    Convert a QoS profile to the mapping rosbag2 stores (metadata version 9).

    Parameters
    ----------
    profile : rclpy.qos.QoSProfile or Mapping
        A QoS profile, or a mapping already in rosbag2's form.

    Returns
    -------
    dict
        Keys ``history, depth, reliability, durability, deadline, lifespan, liveliness,
        liveliness_lease_duration, avoid_ros_namespace_conventions``; policies as lower-case
        names (``keep_last``, ``reliable``), durations as ``{sec, nsec}``.

    """
    if isinstance(profile, dict):
        return dict(profile)
    return {
        'history': _policy_name(profile.history),
        'depth': int(profile.depth),
        'reliability': _policy_name(profile.reliability),
        'durability': _policy_name(profile.durability),
        'deadline': _duration(profile.deadline),
        'lifespan': _duration(profile.lifespan),
        'liveliness': _policy_name(profile.liveliness),
        'liveliness_lease_duration': _duration(profile.liveliness_lease_duration),
        'avoid_ros_namespace_conventions': bool(profile.avoid_ros_namespace_conventions),
    }


def serialize_qos_profiles(profiles):
    """
    Serialise offered QoS profiles to the YAML string of the ``offered_qos_profiles`` key.

    Parameters
    ----------
    profiles : iterable
        QoS profiles (see `qos_profile_to_dict`).

    Returns
    -------
    str
        A YAML sequence, '' for no profiles (what rosbag2 writes for none).

    """
    items = [qos_profile_to_dict(p) for p in profiles]
    if not items:
        return ''
    return yaml.safe_dump(items, sort_keys=False, default_flow_style=False)


def _bag_metadata(topics, counts, start, end, files, ros_distro):
    """Build rosbag2's ``BagMetadata`` mapping (version 9) for the given statistics."""
    start = start or 0
    end = end or start
    return {
        'version': BAG_METADATA_VERSION,
        'storage_identifier': 'mcap',
        'duration': {'nanoseconds': int(end - start)},
        'starting_time': {'nanoseconds_since_epoch': int(start)},
        'message_count': int(sum(counts.values())),
        'topics_with_message_count': [
            {'topic_metadata': {
                'name': topic,
                'type': info['type'],
                'serialization_format': MESSAGE_ENCODING,
                'offered_qos_profiles': info['qos'],
                'type_description_hash': info['hash'],
            }, 'message_count': int(counts.get(topic, 0))}
            for topic, info in topics.items()],
        'compression_format': '',
        'compression_mode': '',
        'relative_file_paths': [f['path'] for f in files],
        'files': files,
        'custom_data': {},
        'ros_distro': ros_distro,
    }


def _time_ns(name, value):
    """Check a record time: MCAP stores it as an unsigned 64-bit count of nanoseconds."""
    try:
        valid = not isinstance(value, bool) and int(value) == value and 0 <= value < 2**64
    except (TypeError, ValueError, OverflowError):
        valid = False
    if not valid:
        raise ValueError(f'`{name}` must be an integer in [0, 2**64) [ns], got {value!r}')
    return int(value)


class _File:
    """One open MCAP file and its own statistics."""

    def __init__(self, path, compression, chunk_size, profile, library):
        self.path = path
        self.stream = open(path, 'wb')
        self.writer = Writer(self.stream, chunk_size=chunk_size,
                             compression=_COMPRESSION[compression])
        # A chunk index per chunk until the summary: on disk, not in memory.
        self.spilled = spill_chunk_indexes(self.writer, path.parent)
        self.writer.start(profile=profile, library=library)
        # The magic and header go to disk now, so even an early crash leaves an MCAP file.
        self.stream.flush()
        self.schemas = {}
        self.channels = {}
        self.counts = {}
        self.sequences = {}
        self.start = None
        self.end = None
        self.pending = 0
        self.oldest_pending = None

    def size(self):
        return self.stream.tell()


class Rosbag2McapWriter:
    """
    Write ROS 2 messages to MCAP files in the form rosbag2's MCAP storage plugin writes.

    The header carries profile ``ros2``; each type gets one ``ros2msg`` schema with its
    complete dependent definitions; each topic one ``cdr`` channel with the
    ``offered_qos_profiles`` and ``topic_type_hash`` metadata; on close a ``rosbag2``
    metadata record with ``serialized_metadata`` precedes the summary and index.
    Messages go into compressed chunks; `flush` closes the open chunk and writes it to
    disk, so a file cut off by a crash loses only messages written after the last flush.

    Parameters
    ----------
    output_path : str or os.PathLike
        A ``.mcap`` file, or a directory (existing, ending in a separator, or without the
        ``.mcap`` suffix) that receives ``<name>_<i>.mcap`` files and a rosbag2
        ``metadata.yaml``. Split files of a file path are ``<stem>_<i>.mcap`` beside it.
    compression : {'zstd', 'lz4', 'none'}
        Chunk compression.
    chunk_size : int
        Uncompressed chunk size that closes a chunk [bytes].
    max_file_size : int
        Split to a new file once the file reaches this size [bytes]; 0 never splits.
    max_duration : int
        Split to a new file once its messages span this much log time [ns]; 0 never splits.
    overwrite : bool
        Replace an existing non-empty file (or reuse a non-empty directory).
    library : str, optional
        Header library string.
    ros_distro : str, optional
        ROS distribution recorded in the metadata (default ``$ROS_DISTRO`` or ``jazzy``).
    final_name : str, optional
        File name recorded in the rosbag2 metadata instead of `output_path`'s: the name
        the file will have once moved into place (see `atomic_mcap_writer`). Single
        files only, without splitting.

    """

    def __init__(self, output_path, *, compression='zstd', chunk_size=768 * 1024,
                 max_file_size=0, max_duration=0, overwrite=False, library=None,
                 ros_distro=None, final_name=None):
        if compression not in _COMPRESSION:
            raise ValueError(f'`compression` must be one of {sorted(_COMPRESSION)}, '
                             f'got {compression!r}')
        for name, value, unit in (('chunk_size', chunk_size, '[bytes]'),
                                  ('max_file_size', max_file_size, '[bytes]'),
                                  ('max_duration', max_duration, '[ns]')):
            if isinstance(value, bool) or int(value) != value or value < 0:
                raise ValueError(f'`{name}` must be an integer >= 0 {unit}, got {value!r}')
        raw = os.fspath(output_path)
        path = pathlib.Path(raw)
        self._directory_mode = (path.is_dir() or raw.endswith(os.sep)
                                or path.suffix != '.mcap')
        if self._directory_mode:
            if path.exists() and any(path.iterdir()) and not overwrite:
                raise FileExistsError(f'output directory {path} exists and is not empty')
            path.mkdir(parents=True, exist_ok=True)
        else:
            if path.exists() and path.stat().st_size > 0 and not overwrite:
                raise FileExistsError(f'output file {path} exists')
            if not path.parent.is_dir():
                raise FileNotFoundError(f'directory of {path} does not exist')
        if final_name is not None and (self._directory_mode or max_file_size or max_duration):
            raise ValueError(f'`final_name` is for a single file without splits, got '
                             f'{final_name!r} for {path}')
        self._final_name = final_name
        self._path = path
        self._compression = compression
        self._chunk_size = int(chunk_size)
        self.max_file_size = int(max_file_size)
        self.max_duration = int(max_duration)
        self._library = library or 'fpc_gripper rosbag2-form writer (mcap-python)'
        self._ros_distro = ros_distro or os.environ.get('ROS_DISTRO', 'jazzy')
        self._topics = {}
        self._files = []
        self._file = None
        self._closed = False
        self._lock = threading.RLock()
        self._open_next()

    # -- public API -------------------------------------------------------------------

    @property
    def paths(self):
        """Every file written so far, in order (list of pathlib.Path)."""
        return [pathlib.Path(f['abs']) for f in self._files] + (
            [self._file.path] if self._file else [])

    @property
    def path(self):
        """The file being written (pathlib.Path)."""
        return self._file.path if self._file else None

    @property
    def message_count(self):
        """Messages written, over every file."""
        with self._lock:
            done = sum(f['message_count'] for f in self._files)
            return done + (sum(self._file.counts.values()) if self._file else 0)

    @property
    def pending_count(self):
        """Messages written since the last flush."""
        return self._file.pending if self._file else 0

    @property
    def oldest_pending_log_time(self):
        """Log time of the oldest message not yet flushed, or None [ns]."""
        return self._file.oldest_pending if self._file else None

    @property
    def topics(self):
        """Type name of every topic added."""
        return {t: info['type'] for t, info in self._topics.items()}

    def add_topic(self, topic, type_name, *, definition=None, schema_encoding=SCHEMA_ENCODING,
                  offered_qos_profiles='', type_hash=None):
        """
        Register a topic (and its type's schema) in this and every later split file.

        Parameters
        ----------
        topic : str
            Fully qualified topic name.
        type_name : str
            ``pkg/msg/Type``.
        definition : str, optional
            Schema text; built from the installed .msg files when omitted.
        schema_encoding : str
            Schema encoding of `definition`.
        offered_qos_profiles : str or iterable
            YAML string, or QoS profiles to serialise with `serialize_qos_profiles`.
        type_hash : str, optional
            ``RIHS01_`` type hash; looked up from the installed description when omitted.

        Raises
        ------
        SchemaNotFoundError
            If `definition` is omitted and the type is not installed.

        """
        with self._lock:
            self._check_open()
            if topic in self._topics:
                return
            package, namespace, name = normalize_type_name(type_name)
            full = f'{package}/{namespace}/{name}'
            if definition is None:
                definition = message_definition(full)
            if not isinstance(offered_qos_profiles, str):
                offered_qos_profiles = serialize_qos_profiles(offered_qos_profiles)
            if type_hash is None:
                type_hash = type_description_hash(full)
            self._topics[topic] = {'type': full, 'definition': definition,
                                   'encoding': schema_encoding, 'qos': offered_qos_profiles,
                                   'hash': type_hash}
            self._register(self._file, topic)

    def write(self, topic, data, log_time, publish_time=None, sequence=None):
        """
        Append one serialised message.

        Parameters
        ----------
        topic : str
            A topic registered with `add_topic`.
        data : bytes
            CDR-serialised message.
        log_time : int
            Receive time, in [0, 2**64) [ns].
        publish_time : int, optional
            Publish (header) time, in [0, 2**64) [ns]; defaults to `log_time`.
        sequence : int, optional
            Sequence number; defaults to a per-topic counter from 1.

        Raises
        ------
        ValueError
            If a time is out of range, naming it; nothing is written then.

        """
        with self._lock:
            self._check_open()
            if topic not in self._topics:
                raise McapWriterError(f'topic {topic!r} was not added with add_topic()')
            log_time = _time_ns('log_time', log_time)
            publish_time = log_time if publish_time is None else _time_ns('publish_time',
                                                                          publish_time)
            if self._should_split(log_time):
                self._close_file()
                self._open_next()
            f = self._file
            channel_id = f.channels[topic]
            if sequence is None:
                sequence = f.sequences.get(topic, 0) + 1
                f.sequences[topic] = sequence
            f.writer.add_message(channel_id=channel_id, log_time=log_time,
                                 publish_time=publish_time, data=bytes(data),
                                 sequence=int(sequence) & 0xFFFFFFFF)
            f.counts[topic] = f.counts.get(topic, 0) + 1
            f.start = log_time if f.start is None else min(f.start, log_time)
            f.end = log_time if f.end is None else max(f.end, log_time)
            if f.pending == 0:
                f.oldest_pending = log_time
            f.pending += 1

    def add_metadata(self, name, data):
        """
        Write a metadata record into the current file.

        Parameters
        ----------
        name : str
            Record name (``rosbag2`` is written by `close`).
        data : dict of str to str
            Key-value pairs.

        """
        with self._lock:
            self._check_open()
            self._file.writer.add_metadata(str(name), {str(k): str(v) for k, v in data.items()})

    def flush(self, fsync=True):
        """
        Close the open chunk (even if not full), write it with its index and flush the file.

        Parameters
        ----------
        fsync : bool
            Also ask the OS to put the data on the disk.

        """
        with self._lock:
            if self._closed or self._file is None:
                return
            f = self._file
            f.writer.flush()
            if fsync:
                os.fsync(f.stream.fileno())
            f.pending = 0
            f.oldest_pending = None

    def close(self):
        """Write the metadata record, summary and index of the open file, and close it."""
        with self._lock:
            if self._closed:
                return
            self._close_file()
            self._closed = True
            if self._directory_mode:
                self._write_metadata_yaml()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- internals -----------------------------------------------------------------------

    def _check_open(self):
        if self._closed:
            raise McapWriterError('the writer is closed')

    def _next_path(self):
        index = len(self._files)
        if self._directory_mode:
            return self._path / f'{self._path.name}_{index}.mcap'
        if index == 0:
            return self._path
        return self._path.with_name(f'{self._path.stem}_{index}.mcap')

    def _open_next(self):
        self._file = _File(self._next_path(), self._compression, self._chunk_size, PROFILE,
                           self._library)
        for topic in self._topics:
            self._register(self._file, topic)

    def _register(self, f, topic):
        info = self._topics[topic]
        schema_id = f.schemas.get(info['type'])
        if schema_id is None:
            schema_id = f.writer.register_schema(
                name=info['type'], encoding=info['encoding'],
                data=info['definition'].encode('utf-8'))
            f.schemas[info['type']] = schema_id
        f.channels[topic] = f.writer.register_channel(
            topic=topic, message_encoding=MESSAGE_ENCODING, schema_id=schema_id,
            metadata={'offered_qos_profiles': info['qos'], 'topic_type_hash': info['hash']})

    def _should_split(self, log_time):
        f = self._file
        if not f.counts:
            return False
        if self.max_duration and log_time - f.start >= self.max_duration:
            return True
        return bool(self.max_file_size and f.size() >= self.max_file_size)

    def _file_info(self, f):
        start = f.start or 0
        return {'path': self._final_name or f.path.name,
                'starting_time': {'nanoseconds_since_epoch': int(start)},
                'duration': {'nanoseconds': int((f.end or start) - start)},
                'message_count': int(sum(f.counts.values()))}

    def _close_file(self):
        f = self._file
        if f is None:
            return
        info = self._file_info(f)
        info.update(abs=str(f.path), counts=dict(f.counts), start=f.start, end=f.end)
        # As rosbag2 does, each file carries the bag's metadata so far: every file up to
        # and including this one, and their messages.
        f.writer.add_metadata('rosbag2', {
            'serialized_metadata': yaml.safe_dump(self._bag_metadata([*self._files, info]),
                                                  sort_keys=False)})
        f.writer.finish()
        f.stream.flush()
        os.fsync(f.stream.fileno())
        f.stream.close()
        if f.spilled is not None:
            f.spilled.close()
        self._files.append(info)
        self._file = None

    def _bag_metadata(self, files):
        """Return rosbag2's BagMetadata mapping of the given closed files."""
        counts = {}
        for f in files:
            for topic, n in f['counts'].items():
                counts[topic] = counts.get(topic, 0) + n
        starts = [f['start'] for f in files if f['start'] is not None]
        ends = [f['end'] for f in files if f['end'] is not None]
        return _bag_metadata(
            self._topics, counts, min(starts, default=0), max(ends, default=0),
            [{k: v for k, v in f.items() if k not in ('abs', 'counts', 'start', 'end')}
             for f in files], self._ros_distro)

    def _write_metadata_yaml(self):
        target = self._path / 'metadata.yaml'
        tmp = target.with_name('.metadata.yaml.tmp')
        tmp.write_text(yaml.safe_dump({'rosbag2_bagfile_information':
                                       self._bag_metadata(self._files)}, sort_keys=False),
                       encoding='utf-8')
        os.replace(tmp, target)
