"""ROS 2 node that records gripper topics to MCAP in rosbag2's form, crash-safely."""

import functools
import importlib
import struct
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
import rclpy
from rclpy.exceptions import InvalidHandle
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from .parameters import float_range
from .runner import run_node
from ..io.background_writer import BackgroundWriter
from ..io.mcap_writer import (McapWriterError, normalize_type_name, Rosbag2McapWriter,
                              SchemaNotFoundError, type_description_hash)
from ..io.messages import gripper_topics

__all__ = ['McapRecorder', 'main']

_COMPRESSIONS = ('zstd', 'lz4', 'none')
_DEFAULT_FINGERS = ('finger_0', 'finger_1', 'finger_2')
# Subscriptions keep every message until it is taken: while the executor lags (a CPU hog,
# a burst), the reader's queue is what keeps the messages, and a keep-last queue drops its
# oldest silently (1000 deep, a 3 s stall at 500 Hz lost 500 of a reliable topic). Fast DDS
# holds at most 5000 samples per reader by default (25 s of a 200 Hz topic); past that a
# reliable reader stops acknowledging and the publisher's own history decides. The queue's
# memory is not given back when it drains: rmw_fastrtps's history keeps each sample buffer
# it allocated, at the largest payload it ever held (PREALLOCATED_WITH_REALLOC), so the
# process keeps the deepest backlog it had, in its largest messages (a reader 180 samples
# behind on 0.1-1 MB payloads held 110 MiB, drained or not; see README, Soak).
_HISTORY = HistoryPolicy.KEEP_ALL
# Most messages taken per topic at a stop: ends a take that races a publisher.
_STOP_TAKE_LIMIT = 100_000
_RCLError = rclpy_implementation.RCLError
_DIAGNOSTICS_QOS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                              reliability=ReliabilityPolicy.RELIABLE)


def _message_class(type_name):
    package, namespace, name = normalize_type_name(type_name)
    module = importlib.import_module(f'{package}.{namespace}')
    return getattr(module, name)


def _hash_string(type_hash, type_name):
    value = bytes(getattr(type_hash, 'value', b'') or b'')
    version = int(getattr(type_hash, 'version', 0) or 0)
    if version > 0 and any(value):
        return f'RIHS{version:02d}_{value.hex()}'
    return type_description_hash(type_name)


def adapt_qos_to_publishers(profiles):
    """
    Choose a subscription QoS that connects to every publisher, as rosbag2 does.

    Reliable only if every publisher is reliable, transient-local only if every publisher
    is; keep-all history (see `_HISTORY`); deadline and liveliness left unspecified.

    Parameters
    ----------
    profiles : sequence of rclpy.qos.QoSProfile
        Offered profiles of the publishers.

    Returns
    -------
    rclpy.qos.QoSProfile

    """
    reliable = bool(profiles) and all(
        p.reliability == ReliabilityPolicy.RELIABLE for p in profiles)
    latched = bool(profiles) and all(
        p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in profiles)
    return QoSProfile(
        history=_HISTORY,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


class McapRecorder(Node):
    """
    Record a list of topics to MCAP, subscribing to each with a QoS its publishers accept.

    Topics without a publisher yet are looked for again every ``discovery_period_s``.
    Subscriptions keep every message until it is taken (keep-all history), whatever the
    reliability. Callbacks only queue the raw CDR with its receive time (a
    `BackgroundWriter`) and never wait for it; its thread compresses the chunks and, every
    ``flush_period_s / 2``, closes the open chunk, writes it with its index and fsyncs the
    file, so a ``kill -9`` loses at most the last ``flush_period_s`` of messages.
    Destroying the node (`main` does on SIGINT and SIGTERM, once or repeated) takes what
    is left in the subscriptions' queues, writes it, then the summary and index, and logs
    one line: messages received, written and dropped.

    Message content never stops it: log time is the node clock at reception, and a
    header stamp that is not a valid time (negative seconds, nanoseconds past a second)
    is kept as it is in the payload while the record's publish time falls back to the
    log time; such stamps are counted (`invalid_stamps`). Messages dropped because the
    queue was full (``max_queue_mb``) and failed writes are counted too, logged, and
    reported on ``/diagnostics`` every ``diagnostics_period_s``, with what each topic
    received and dropped.
    """

    def __init__(self, **kwargs):
        super().__init__('mcap_recorder', **kwargs)
        self._writer = None
        self._background = None
        self._subs = {}
        # Per topic: [messages received, of them dropped because the queue was full].
        self._counts = {}
        self._stamped = {}
        self._params = {}
        self.invalid_stamps = 0
        self._refused = 0
        self._diagnostics_pub = None
        self._last_error = None
        self._reported = (0, 0, 0)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._store_parameters)
        self._declare_parameters()
        self._wanted = self._topic_list()
        p = self._params
        output = p['output_path'] or time.strftime('fpc_gripper_%Y_%m_%d-%H_%M_%S.mcap')
        self._writer = Rosbag2McapWriter(
            output, compression=p['compression'],
            max_file_size=int(p['max_file_size_mb'] * 1024 * 1024),
            max_duration=int(p['max_duration_s'] * 1e9), overwrite=p['overwrite'],
            library='fpc_gripper mcap_recorder (mcap-python)')
        self._background = BackgroundWriter(
            self._writer, flush_period_s=p['flush_period_s'],
            max_queue_bytes=int(p['max_queue_mb'] * 1024 * 1024), on_error=self._write_failed)
        if p['diagnostics_period_s'] > 0.0:
            self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics',
                                                          _DIAGNOSTICS_QOS)
        # Losses are logged once a period even without diagnostics.
        self.create_timer(p['diagnostics_period_s'] or 1.0, self._report_health)
        self._discovery_timer = self.create_timer(p['discovery_period_s'], self._discover)
        self._discover()
        self.get_logger().info(
            f'recording {len(self._wanted)} topics to {self._writer.path} '
            f'({p["compression"]}, flush every {p["flush_period_s"]:.3g} s)')

    # -- parameters -----------------------------------------------------------------------

    def _declare_parameters(self):
        positive = float_range(0.001, 3600.0)
        non_negative = float_range(0.0, 1.0e9)
        self.declare_parameter('output_path', '', ParameterDescriptor(
            description='MCAP file (*.mcap), or a directory for split files '
                        '(default: fpc_gripper_<date>.mcap in the working directory)',
            read_only=True))
        self.declare_parameter('topics', [''], ParameterDescriptor(
            description='Topics to record, relative to the node namespace; empty for every '
                        'fpc_gripper input and output of the configured fingers',
            read_only=True))
        self.declare_parameter('flush_period_s', 1.0, ParameterDescriptor(
            description='Longest time a received message waits before it is on disk '
                        'in a completed chunk [s]', floating_point_range=positive))
        self.declare_parameter('max_file_size_mb', 0.0, ParameterDescriptor(
            description='Split to a new file at this size [MiB]; 0 never splits',
            floating_point_range=non_negative))
        self.declare_parameter('max_duration_s', 0.0, ParameterDescriptor(
            description='Split to a new file after this much recording time [s]; 0 never',
            floating_point_range=non_negative))
        self.declare_parameter('compression', 'zstd', ParameterDescriptor(
            description='Chunk compression: zstd, lz4 or none', read_only=True))
        self.declare_parameter('discovery_period_s', 0.5, ParameterDescriptor(
            description='Period of the search for publishers of topics not yet recorded [s]',
            floating_point_range=positive, read_only=True))
        self.declare_parameter('gripper_config', '', ParameterDescriptor(
            description='Gripper configuration YAML whose fingers give the default topics '
                        '(default: the package default)', read_only=True))
        self.declare_parameter('overwrite', False, ParameterDescriptor(
            description='Replace an existing output file', read_only=True))
        self.declare_parameter('diagnostics_period_s', 1.0, ParameterDescriptor(
            description='Period of the status on /diagnostics (recorded too if /diagnostics '
                        'is among the topics) [s]; 0 publishes none',
            floating_point_range=float_range(0.0, 3600.0), read_only=True))
        self.declare_parameter('max_queue_mb', 100.0, ParameterDescriptor(
            description='Bound of the messages received but not yet written [MiB]; a '
                        'message that finds it full is dropped and counted',
            floating_point_range=float_range(1.0, 1.0e6), read_only=True))

    def _validate_parameters(self, parameters):
        for param in parameters:
            if param.name == 'compression' and param.value not in _COMPRESSIONS:
                return SetParametersResult(
                    successful=False,
                    reason=f'`compression` must be one of {", ".join(_COMPRESSIONS)}, '
                           f'got {param.value!r}')
        return SetParametersResult(successful=True)

    def _store_parameters(self, parameters):
        for param in parameters:
            value = param.value
            if param.name == 'topics':
                value = [t for t in value if t]
            self._params[param.name] = value
        if self._writer is not None:
            self._writer.max_file_size = int(self._params['max_file_size_mb'] * 1024 * 1024)
            self._writer.max_duration = int(self._params['max_duration_s'] * 1e9)
            self._background.flush_period_s = self._params['flush_period_s']

    def _topic_list(self):
        topics = self._params['topics']
        if not topics:
            topics = gripper_topics(self._finger_names())
        resolved = []
        for topic in topics:
            name = self.resolve_topic_name(topic)
            if name not in resolved:
                resolved.append(name)
        return resolved

    def _finger_names(self):
        try:
            from ..io.config import default_gripper_config_path, load_gripper_config
            path = self._params['gripper_config'] or default_gripper_config_path()
            return [f.name for f in load_gripper_config(path).fingers]
        except (ImportError, OSError, ValueError) as error:
            self.get_logger().warning(
                f'gripper configuration unavailable ({error}); recording fingers '
                f'{", ".join(_DEFAULT_FINGERS)}')
            return list(_DEFAULT_FINGERS)

    # -- recording ------------------------------------------------------------------------

    def _discover(self):
        for topic in self._wanted:
            infos = self.get_publishers_info_by_topic(topic)
            if not infos:
                continue
            profiles = [info.qos_profile for info in infos]
            if topic in self._subs:
                self._adapt_subscription(topic, profiles)
                continue
            types = sorted({info.topic_type for info in infos})
            if len(types) > 1:
                self.get_logger().warning(
                    f'{topic} has publishers of several types ({", ".join(types)}); '
                    'not recorded', throttle_duration_sec=10.0)
                continue
            type_name = types[0]
            try:
                msg_class = _message_class(type_name)
                self._writer.add_topic(topic, type_name, offered_qos_profiles=profiles,
                                       type_hash=_hash_string(infos[0].topic_type_hash,
                                                              type_name))
            except (ImportError, AttributeError, ValueError, SchemaNotFoundError) as error:
                self.get_logger().error(f'cannot record {topic} ({type_name}): {error}',
                                        throttle_duration_sec=10.0)
                continue
            self._subscribe(topic, msg_class, adapt_qos_to_publishers(profiles))

    def _subscribe(self, topic, msg_class, qos):
        # Raw subscriptions hand over the CDR bytes: nothing is deserialised and
        # serialised again, which for a 129-pose Path costs milliseconds per message.
        self._stamped[topic] = _starts_with_header(msg_class)
        self._counts.setdefault(topic, [0, 0])
        self._subs[topic] = (self.create_subscription(
            msg_class, topic, functools.partial(self._on_message, topic), qos, raw=True),
            msg_class, qos)
        self.get_logger().info(
            f'recording {topic} [{self._writer.topics[topic]}] '
            f'({qos.reliability.name.lower()}, {qos.durability.name.lower()})')

    def _adapt_subscription(self, topic, profiles):
        """Re-subscribe if a publisher that joined later cannot serve the current QoS."""
        subscription, msg_class, qos = self._subs[topic]
        wanted = adapt_qos_to_publishers(profiles)
        stricter = (
            (qos.reliability == ReliabilityPolicy.RELIABLE
             and wanted.reliability != ReliabilityPolicy.RELIABLE)
            or (qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
                and wanted.durability != DurabilityPolicy.TRANSIENT_LOCAL))
        if stricter:
            self.destroy_subscription(subscription)
            self._subscribe(topic, msg_class, wanted)

    def _on_message(self, topic, data):
        if self._writer is None:
            return
        log_time = self.get_clock().now().nanoseconds
        counts = self._counts[topic]
        counts[0] += 1
        publish_time = log_time
        if self._stamped.get(topic):
            stamp = _cdr_header_stamp(data)
            if stamp is _INVALID:
                self.invalid_stamps += 1
                self.get_logger().warning(
                    f'{topic}: header stamp is not a valid time; recorded as received, '
                    f'with the receive time as publish time ({self.invalid_stamps} so far)',
                    throttle_duration_sec=5.0)
            elif stamp:
                publish_time = stamp
        try:
            if not self._background.put(topic, bytes(data), log_time, publish_time):
                counts[1] += 1
        except McapWriterError as error:
            self._refused += 1
            self._write_failed(error)

    def _write_failed(self, error):
        """Keep the last error for the diagnostics (called from the writer thread too)."""
        self._last_error = f'{type(error).__name__}: {error}'

    def _report_health(self):
        background = self._background
        if self._writer is None:
            return
        counts = (background.dropped, self.invalid_stamps, background.errors + self._refused)
        dropped, invalid, errors = (now - before for now, before in zip(counts,
                                                                        self._reported))
        self._reported = counts
        if errors:
            level, message = DiagnosticStatus.ERROR, f'{errors} writes failed: {self._last_error}'
            self.get_logger().error(f'{message} ({counts[2]} lost so far)')
        elif dropped:
            level, message = DiagnosticStatus.WARN, f'{dropped} messages dropped: queue full'
            self.get_logger().warning(f'{message} ({counts[0]} so far; raise max_queue_mb)')
        elif invalid:
            level = DiagnosticStatus.WARN
            message = f'{invalid} header stamps not a valid time (publish time = log time)'
        else:
            level, message = DiagnosticStatus.OK, 'recording'
        if self._diagnostics_pub is None:
            return
        values = {'file': str(self._writer.path),
                  'messages received': sum(c[0] for c in self._counts.values()),
                  'messages written': background.written,
                  'queued': background.queued, 'queued bytes': background.queued_bytes,
                  'dropped (queue full)': counts[0], 'invalid stamps': counts[1],
                  'failed writes': counts[2], 'topics': len(self._subs)}
        for topic, (received, dropped) in self._counts.items():
            values[topic] = f'received {received}, dropped {dropped} (queue full)'
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        array.status = [DiagnosticStatus(
            level=level, name=f'{self.get_fully_qualified_name()}: recording',
            message=message, hardware_id=str(self._writer.path),
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])]
        self._diagnostics_pub.publish(array)

    @property
    def writer(self):
        """The Rosbag2McapWriter of the recording (for tests and tools)."""
        return self._writer

    @property
    def background(self):
        """The BackgroundWriter that writes the recording (for tests and tools)."""
        return self._background

    @property
    def received(self):
        """Messages received so far, over every topic."""
        return sum(c[0] for c in self._counts.values())

    @property
    def recorded_topics(self):
        """Topics subscribed so far."""
        return list(self._subs)

    def close(self):
        """Record what the subscriptions still hold, then close the file (idempotent)."""
        if self._writer is None:
            return
        # Messages the middleware has received but the executor has not handed over yet
        # are the recording's too: on a loaded machine, hundreds at a stop.
        for topic, (subscription, _, _) in list(self._subs.items()):
            for _ in range(_STOP_TAKE_LIMIT):
                taken = _take(subscription)
                if taken is None:
                    break
                self._on_message(topic, taken[0])
        writer, self._writer = self._writer, None
        background, self._background = self._background, None
        background.close()
        received = self.received
        full = background.dropped
        written = writer.message_count
        # Whatever was received and neither written nor refused by the full queue failed
        # (a write error, or a put after the writer thread died).
        failed = received - written - full
        # After SIGINT/SIGTERM the context is shut down and /rosout cannot publish.
        logger = self.get_logger() if self.context.ok() else \
            rclpy.logging.get_logger('fpc_gripper.mcap_recorder')
        logger.info(
            f'closed {", ".join(str(p) for p in writer.paths)}: received {received}, '
            f'written {written}, dropped {full + failed} ({full} queue full, {failed} '
            f'failed writes); {self.invalid_stamps} invalid header stamps')

    def destroy_node(self):
        """Close the recording, then destroy the node."""
        self.close()
        return super().destroy_node()


def _starts_with_header(msg_class):
    """Whether a message type's first field is a std_msgs/Header."""
    fields = list(msg_class.get_fields_and_field_types().items())
    return bool(fields) and fields[0] == ('header', 'std_msgs/Header')


#: What `_cdr_header_stamp` returns for a stamp that is not a valid time.
_INVALID = object()


def _cdr_header_stamp(data):
    """
    Header stamp [ns] of a serialised message that starts with a std_msgs/Header.

    CDR: a 4-byte encapsulation header (byte 1 is 1 for little endian), then the
    stamp's int32 sec and uint32 nanosec. Returns 0 if the data is too short, and
    `_INVALID` for negative seconds or nanoseconds of a second or more: no valid
    builtin_interfaces/Time (an MCAP time is an unsigned 64-bit count).
    """
    if len(data) < 12:
        return 0
    sec, nanosec = struct.unpack_from('<iI' if data[1] == 1 else '>iI', data, 4)
    if sec < 0 or nanosec >= 1_000_000_000:
        return _INVALID
    return sec * 1_000_000_000 + nanosec


def _take(subscription):
    """Take one queued raw message and its info from a subscription, or None if none."""
    try:
        with subscription.handle:
            return subscription.handle.take_message(subscription.msg_type, subscription.raw)
    except (InvalidHandle, _RCLError):
        # Destroyed, or its context shut down already (an external shutdown).
        return None


def main(args=None):
    """Run the recorder until SIGINT or SIGTERM, then close the file with its index."""
    return run_node(McapRecorder, 'mcap_recorder', args)


if __name__ == '__main__':
    sys.exit(main())
