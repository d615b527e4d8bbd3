"""The model node's outputs: every finger's shape, curvature, tip tf, rigidity, markers, health."""

import math
import time

from diagnostic_msgs.msg import DiagnosticArray
from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_msgs.msg import KeyValue
from geometry_msgs.msg import Vector3Stamped
from nav_msgs.msg import Path
from rclpy.serialization import deserialize_message
from std_msgs.msg import Float64
from visualization_msgs.msg import MarkerArray

from fpc_gripper.io.messages import ns_to_time
from fpc_gripper.io.messages import rigidity_message
from fpc_gripper.io.messages import serialized_curvature
from fpc_gripper.io.messages import serialized_gripper_shape
from fpc_gripper.io.messages import serialized_shape
from fpc_gripper.io.messages import serialized_shape_markers
from fpc_gripper.io.messages import shape_message
from fpc_gripper.io.qos import RELIABLE_QOS
from fpc_gripper.io.qos import STATE_QOS
from fpc_gripper.io.qos import TF_QOS
from fpc_gripper.io.qos import TF_STATIC_QOS
from fpc_gripper.io.qos import writer_qos
from fpc_gripper.io.tf import palm_transform
from fpc_gripper.io.tf import serialized_tip_tf
from fpc_gripper.services.model_core import Level

__all__ = ['ModelOutputs', 'SlowOutput']

# Slow outputs, at most once per period and the last update always sent: markers are for
# people, and rigidity (two displacement-controlled solves) must not hold up the shapes [s].
_MARKER_PERIOD_S = 1.0 / 30.0
# Markers cost some 0.4 ms a send (serialized, three circle fits): with nobody watching,
# the newest state still reaches the transient-local history, but at 1 Hz.
_UNWATCHED_MARKER_PERIOD_S = 1.0
_LEVELS = {Level.OK: DiagnosticStatus.OK, Level.WARN: DiagnosticStatus.WARN,
           Level.ERROR: DiagnosticStatus.ERROR}
_VALID_COLOR = (0.1, 0.7, 0.2, 1.0)
_INVALID_COLOR = (1.0, 0.55, 0.0, 1.0)


class SlowOutput:
    """
    Fingers whose slow output is out of date, sent at most once per `period_s` [s].

    An update is sent at once when a period has passed since the last send; else a timer of
    its own (steady time, running only while something is out of date) sends it later, so
    the last update is always sent and nothing polls in between.
    """

    def __init__(self, node, period_s, publish, clock, lock):
        self.period_s = period_s
        self.publish = publish
        self.dirty = set()
        self.last_ns = None
        self._lock = lock
        self.timer = node.create_timer(self._timer_period(), self._on_timer, clock=clock)
        self.timer.cancel()

    def _timer_period(self):
        return self.period_s if math.isfinite(self.period_s) else 1.0

    def set_period(self, period_s):
        """Change the period [s] (inf: never sent)."""
        if period_s != self.period_s:
            self.period_s = period_s
            self.timer.timer_period_ns = int(round(self._timer_period() * 1e9))
            if not math.isfinite(period_s):
                self.dirty.clear()

    def due(self, now_ns):
        """Whether a period has passed since the last send [ns]."""
        return self.last_ns is None or (now_ns - self.last_ns) * 1e-9 >= self.period_s

    def take(self, now_ns):
        """Mark a send at `now_ns` [ns] and return the out-of-date finger indices."""
        self.last_ns = now_ns
        indices = sorted(self.dirty)
        self.dirty.clear()
        return indices

    def update(self, indices, now_ns):
        """Mark fingers out of date and send them if due, else let the timer send them."""
        if not math.isfinite(self.period_s):
            return
        self.dirty.update(indices)
        if not self.dirty:
            return
        if self.due(now_ns):
            self.publish(self.take(now_ns))
        elif self.timer.is_canceled():
            self.timer.reset()

    def _on_timer(self):
        with self._lock:
            if self.dirty:
                self.publish(self.take(time.monotonic_ns()))
            else:
                self.timer.cancel()


class ModelOutputs:
    """
    Publish what a `ModelCore`'s fingers answer, on a node's topics.

    Per solve: ``shape`` (serialized Path), ``curvature`` and the tip on /tf. At slower
    rates (`SlowOutput`): ``rigidity`` and the palm-frame ``markers`` and
    ``gripper_shape``. ``/diagnostics`` on every change of a finger's health and when
    forced (the node's 1 Hz timer).

    Parameters
    ----------
    node : rclpy.node.Node
        Creates the publishers and timers.
    core : ModelCore
    frames : tuple of str
        Every finger's frame id.
    palm_frame : str
    placements : tuple of FingerPlacement
    lock : threading.RLock
        The node's lock, taken by the slow outputs' timers.
    steady : rclpy.clock.Clock
        Steady clock of the timers.
    now_ns : callable
        The node clock [ns], which stamps the mounts and the diagnostics.
    rigidity_period_s : float
        Shortest period of the rigidity output [s]; inf for none.
    publish_tf : bool
        Send the mounts on /tf_static and the tips on /tf (where tf2_msgs imports).
    rate_hz : float
        Most solves per finger per second [Hz]: it sizes the per-solve writers' history
        (`~fpc_gripper.io.qos.writer_qos`).

    """

    def __init__(self, node, core, frames, palm_frame, placements, lock, steady, now_ns,
                 rigidity_period_s, publish_tf, rate_hz):
        self._node, self._core, self._lock, self._now_ns = node, core, lock, now_ns
        self._frames, self._palm_frame, self._placements = frames, palm_frame, placements
        self._markers = SlowOutput(node, _UNWATCHED_MARKER_PERIOD_S, self._publish_markers,
                                   steady, lock)
        self._rigidities = SlowOutput(node, rigidity_period_s, self._publish_rigidities,
                                      steady, lock)
        self._last_kinds = None
        self._serialize_shapes = None
        names = core.names
        state = writer_qos(STATE_QOS, rate_hz)
        self.shape_publishers = tuple(
            node.create_publisher(Path, f'{name}/shape', state) for name in names)
        self._curvature_pubs = tuple(
            node.create_publisher(Float64, f'{name}/curvature', state) for name in names)
        rigidity = writer_qos(STATE_QOS, 1.0 / rigidity_period_s) if math.isfinite(
            rigidity_period_s) else STATE_QOS
        self._rigidity_pubs = tuple(
            node.create_publisher(Vector3Stamped, f'{name}/rigidity', rigidity)
            for name in names)
        markers = writer_qos(STATE_QOS, 1.0 / _MARKER_PERIOD_S)
        self._markers_pub = node.create_publisher(MarkerArray, 'markers', markers)
        self._gripper_shape_pub = node.create_publisher(MarkerArray, 'gripper_shape', markers)
        self.diagnostics_publisher = node.create_publisher(
            DiagnosticArray, '/diagnostics', RELIABLE_QOS)
        self._tf_pub, self.tf_state = self._create_tf(
            writer_qos(TF_QOS, len(names) * rate_hz)) if publish_tf else (
            None, 'publish_tf false: no tf')

    def _create_tf(self, qos):
        """
        Send palm -> finger_<i> on /tf_static; return the /tf publisher and what was done.

        tf2_ros's static broadcaster sends them where it imports. Otherwise this publishes
        tf2_msgs/TFMessage itself, with tf2_ros's QoS (a PyPI install gets tf2_msgs from
        scripts/build_interfaces.sh). Without tf2_msgs there is no tf.
        """
        try:
            from tf2_msgs.msg import TFMessage
        except ImportError:
            return None, 'tf2_msgs not importable: no tf'
        stamp = self._now_ns()
        mounts = [palm_transform(placement, self._palm_frame, frame, stamp)
                  for placement, frame in zip(self._placements, self._frames)]
        try:
            from tf2_ros.static_transform_broadcaster import StaticTransformBroadcaster
        except ImportError:
            self._static_tf_pub = self._node.create_publisher(TFMessage, '/tf_static',
                                                              TF_STATIC_QOS)
            self._static_tf_pub.publish(TFMessage(transforms=mounts))
            how = 'tf2_msgs'
        else:
            self._static_tf_pub = StaticTransformBroadcaster(self._node)
            self._static_tf_pub.sendTransform(mounts)
            how = 'tf2_ros'
        return (self._node.create_publisher(TFMessage, '/tf', qos),
                f'tf through {how}: mounts on /tf_static, finger -> tip on /tf')

    def set_rigidity_period(self, period_s):
        """Change the shortest period of the rigidity output [s] (inf: none)."""
        self._rigidities.set_period(period_s)

    def publish(self, updates):
        """Publish the answers of one `ModelCore.process` (failed ones change health only)."""
        good = [u for u in updates if u.result is not None]
        for update in good:
            self._publish_shape(update)
        for update in good:
            self._curvature_pubs[update.index].publish(serialized_curvature(update.result))
        self.publish_diagnostics()
        indices = [u.index for u in good]
        now = time.monotonic_ns()
        watched = (self._markers_pub.get_subscription_count()
                   or self._gripper_shape_pub.get_subscription_count())
        self._markers.set_period(_MARKER_PERIOD_S if watched else _UNWATCHED_MARKER_PERIOD_S)
        self._markers.update(indices, now)
        self._rigidities.update(indices, now)

    def _shape_payload(self, result, frame_id, stamp_ns):
        if self._serialize_shapes is None:
            # The fast serializer must decode to the reference message; else fall back.
            reference = shape_message(result, frame_id, stamp_ns)
            decoded = deserialize_message(serialized_shape(result, frame_id, stamp_ns), Path)
            self._serialize_shapes = decoded == reference
            if not self._serialize_shapes:
                self._node.get_logger().warning(
                    'serialized_shape does not decode to shape_message; publishing Path '
                    'objects (slower)')
        if self._serialize_shapes:
            return serialized_shape(result, frame_id, stamp_ns)
        return shape_message(result, frame_id, stamp_ns)

    def _publish_shape(self, update):
        frame = self._frames[update.index]
        self.shape_publishers[update.index].publish(
            self._shape_payload(update.result, frame, update.stamp_ns))
        if self._tf_pub is not None:
            self._tf_pub.publish(serialized_tip_tf(update.result, frame, update.stamp_ns))

    def _publish_rigidities(self, indices):
        for index in indices:
            state = self._core.fingers[index]
            if state.result is None:
                continue
            k_x = self._core.rigidity(index, 'x')
            k_z = self._core.rigidity(index, 'z')
            self._rigidity_pubs[index].publish(
                rigidity_message(k_x, k_z, self._frames[index], state.result_stamp_ns))

    def _publish_markers(self, indices):
        """Send ``markers`` and ``gripper_shape`` with every finger that has a state."""
        fingers = [
            (i, state.result, state.result_stamp_ns, self._placements[i],
             _VALID_COLOR if state.result.valid else _INVALID_COLOR)
            for i, state in enumerate(self._core.fingers) if state.result is not None]
        if not fingers:
            return
        self._markers_pub.publish(serialized_shape_markers(fingers, self._palm_frame))
        self._gripper_shape_pub.publish(serialized_gripper_shape(fingers, self._palm_frame))

    def publish_diagnostics(self, force=False):
        """Send every finger's status when a finger's health changed, or when forced."""
        with self._lock:
            core = self._core
            kinds = tuple(core.health(i) for i in range(len(core.fingers)))
            if not force and kinds == self._last_kinds:
                return
            self._last_kinds = kinds
            statuses = [core.status(i) for i in range(len(kinds))]
            array = DiagnosticArray()
            array.header.stamp = ns_to_time(self._now_ns())
            node_name = self._node.get_fully_qualified_name()
            array.status = [
                DiagnosticStatus(
                    level=_LEVELS[s.level], name=f'{node_name}: {name}',
                    message=s.message, hardware_id=name,
                    values=[KeyValue(key=k, value=v) for k, v in s.values.items()])
                for name, s in zip(core.names, statuses)]
            self.diagnostics_publisher.publish(array)
