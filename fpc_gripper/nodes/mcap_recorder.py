"""ROS 2 node that records gripper topics to MCAP in rosbag2's form, crash-safely."""

import functools
import importlib
import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.exceptions import InvalidHandle
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from .lost_messages import LostMessages
from .parameters import declare_table
from .runner import run_node
from ..io.cdr import header_stamp, INVALID_STAMP
from ..io.mcap_writer import (McapWriterError, normalize_type_name, SchemaNotFoundError,
                              type_hash_string)
from ..io.qos import RELIABLE_QOS
from ..io.recorder_settings import (apply_settings, compression_refusal, default_topics,
                                    open_recording, PARAMETERS)
from ..io.recording_counts import Health, RecordingCounts

__all__ = ['McapRecorder', 'main']

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
_LEVELS = {Health.WRITES_FAILED: DiagnosticStatus.ERROR,
           Health.QUEUE_FULL: DiagnosticStatus.WARN,
           Health.MESSAGES_LOST: DiagnosticStatus.WARN,
           Health.INVALID_STAMPS: DiagnosticStatus.WARN,
           Health.RECORDING: DiagnosticStatus.OK}


def _message_class(type_name):
    package, namespace, name = normalize_type_name(type_name)
    module = importlib.import_module(f'{package}.{namespace}')
    return getattr(module, name)


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
    queue was full (``max_queue_mb``), failed writes and messages the middleware lost
    before the recorder had them (its message-lost event: a reliable publisher's
    keep-last history moved on, or best-effort samples did not arrive) are counted too,
    logged, and reported on ``/diagnostics`` every ``diagnostics_period_s``, with what
    each topic received, dropped and lost.
    """

    def __init__(self, **kwargs):
        super().__init__('mcap_recorder', **kwargs)
        self._writer = None
        self._background = None
        self._subs = {}
        self._counts = RecordingCounts()
        self._lost = LostMessages()
        self._stamped = {}
        self._params = {}
        self._diagnostics_pub = None
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._store_parameters)
        declare_table(self, PARAMETERS)
        self._wanted = self._topic_list()
        p = self._params
        self._background = open_recording(p, on_error=self._counts.write_failed)
        self._writer = self._background.writer
        if p['diagnostics_period_s'] > 0.0:
            self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics',
                                                          RELIABLE_QOS)
        # Losses are logged once a period even without diagnostics.
        self.create_timer(p['diagnostics_period_s'] or 1.0, self._report_health)
        self._discovery_timer = self.create_timer(p['discovery_period_s'], self._discover)
        self._discover()
        self.get_logger().info(
            f'recording {len(self._wanted)} topics to {self._writer.path} '
            f'({p["compression"]}, flush every {p["flush_period_s"]:.3g} s)')

    # -- parameters -----------------------------------------------------------------------

    def _validate_parameters(self, parameters):
        for param in parameters:
            reason = compression_refusal(param.value) if param.name == 'compression' else None
            if reason is not None:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _store_parameters(self, parameters):
        for param in parameters:
            value = param.value
            if param.name == 'topics':
                value = [t for t in value if t]
            self._params[param.name] = value
        if self._writer is not None:
            apply_settings(self._background, self._params)

    def _topic_list(self):
        topics = self._params['topics']
        if not topics:
            topics, problem = default_topics(self._params['gripper_config'])
            if problem is not None:
                self.get_logger().warning(problem)
        resolved = []
        for topic in topics:
            name = self.resolve_topic_name(topic)
            if name not in resolved:
                resolved.append(name)
        return resolved

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
                                       type_hash=type_hash_string(infos[0].topic_type_hash,
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
        self._counts.add_topic(topic)
        subscription = self.create_subscription(
            msg_class, topic, functools.partial(self._on_message, topic), qos, raw=True)
        self._subs[topic] = (subscription, msg_class, qos)
        # What the middleware lost before the reader had it is counted, not just missing.
        # It counts from the reader's match with a publisher: what a late transient-local
        # reader never saw of the publisher's past is no loss.
        self._lost.watch(self, subscription, functools.partial(self._counts.lose, topic))
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
            self._lost.forget(subscription)
            self.destroy_subscription(subscription)
            self._subscribe(topic, msg_class, wanted)

    def _on_message(self, topic, data):
        if self._writer is None:
            return
        log_time = self.get_clock().now().nanoseconds
        publish_time = log_time
        if self._stamped.get(topic):
            stamp = header_stamp(data)
            if stamp is INVALID_STAMP:
                self._counts.invalid_stamps += 1
                self.get_logger().warning(
                    f'{topic}: header stamp is not a valid time; recorded as received, '
                    f'with the receive time as publish time ({self.invalid_stamps} so far)',
                    throttle_duration_sec=5.0)
            elif stamp:
                publish_time = stamp
        dropped = False
        try:
            dropped = not self._background.put(topic, bytes(data), log_time, publish_time)
        except McapWriterError as error:
            self._counts.refuse(error)
        self._counts.count(topic, dropped)

    def _report_health(self):
        if self._writer is None:
            return
        report = self._counts.report(self._background)
        if report.health is Health.WRITES_FAILED:
            self.get_logger().error(report.log)
        elif report.health in (Health.QUEUE_FULL, Health.MESSAGES_LOST):
            self.get_logger().warning(report.log)
        if self._diagnostics_pub is None:
            return
        values = self._counts.values(self._writer.path, self._background)
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        array.status = [DiagnosticStatus(
            level=_LEVELS[report.health], name=f'{self.get_fully_qualified_name()}: recording',
            message=report.message, hardware_id=str(self._writer.path),
            values=[KeyValue(key=k, value=v) for k, v in values.items()])]
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
        return self._counts.received

    @property
    def invalid_stamps(self):
        """Messages whose header stamp was not a valid time, so far."""
        return self._counts.invalid_stamps

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
        self._lost.poll()
        writer, self._writer = self._writer, None
        background, self._background = self._background, None
        background.close()
        # After SIGINT/SIGTERM the context is shut down and /rosout cannot publish.
        logger = self.get_logger() if self.context.ok() else \
            rclpy.logging.get_logger('fpc_gripper.mcap_recorder')
        logger.info(self._counts.summary(writer.paths, writer.message_count, background.dropped))

    def destroy_node(self):
        """Close the recording and the lost-message handles, then destroy the node."""
        self.close()
        self._lost.close()
        return super().destroy_node()


def _starts_with_header(msg_class):
    """Whether a message type's first field is a std_msgs/Header."""
    fields = list(msg_class.get_fields_and_field_types().items())
    return bool(fields) and fields[0] == ('header', 'std_msgs/Header')


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
