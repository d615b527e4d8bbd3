"""Raw input subscriptions of the nodes: payload size bound, guarded decoding, lost messages."""

from geometry_msgs.msg import WrenchStamped
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import FluidPressure

from fpc_gripper.io import cdr
from fpc_gripper.nodes.lost_messages import LostMessages
from fpc_gripper.services.input_limits import DEFAULT_BOUNDS
from fpc_gripper.services.input_limits import InputCheck
from fpc_gripper.services.input_limits import Rejection
from fpc_gripper.services.logs import bounded

__all__ = ['InputGuard', 'decode']

# Characters of a deserialiser's error kept in a rejection.
_ERROR_CHARS = 160
#: Per-command inputs decoded by struct (a tenth of rclpy's time); what these decline, and
#: every other type, goes through rclpy's decoder.
_FAST_DECODERS = {FluidPressure: cdr.fluid_pressure, WrenchStamped: cdr.wrench_stamped}


def decode(payload, msg_type, max_bytes=DEFAULT_BOUNDS.max_payload_bytes):
    """
    Deserialise a payload, refusing one that is too large or not a message of the type.

    Parameters
    ----------
    payload : bytes
        Serialized (CDR) message, as a raw subscription delivers it.
    msg_type : type
        ROS message class.
    max_bytes : int
        Largest payload decoded [bytes]; a larger one is refused unread.

    Returns
    -------
    (message or None, InputCheck or None)
        The message and None, or None and the rejection (``OVERSIZED`` or ``MALFORMED``).
        A ``FluidPressure`` or ``WrenchStamped`` may come as its read-only fields
        (`fpc_gripper.io.cdr`), with the same attributes and values.

    """
    name = getattr(msg_type, '__name__', str(msg_type))
    try:
        size = len(payload)
    except TypeError:
        return None, InputCheck(None, Rejection.MALFORMED,
                                f'payload of type {type(payload).__name__} is no byte string')
    if size > max_bytes:
        return None, InputCheck(None, Rejection.OVERSIZED,
                                f'{size}-byte payload is larger than max_payload_bytes = '
                                f'{max_bytes}; not decoded')
    fast = _FAST_DECODERS.get(msg_type)
    fields = None if fast is None else fast(payload)
    if fields is not None:
        return fields, None
    try:
        return deserialize_message(bytes(payload), msg_type), None
    except Exception as exc:  # noqa: B902 -- rclpy raises RMWError, and others for junk
        return None, InputCheck(None, Rejection.MALFORMED,
                                f'{size}-byte payload is no {name}: '
                                f'{bounded(exc, _ERROR_CHARS)}')


class InputGuard:
    """
    Subscribe a node's inputs raw, so that no payload reaches rclpy's typed take unchecked.

    A typed subscription drops a payload it cannot deserialise without a word (the take
    returns nothing), deserialises a payload of any size, and says nothing of messages
    the middleware lost. Through the guard each payload is size-checked and decoded by
    `decode`; a refused one goes to ``on_reject`` (with its `InputCheck`), and every
    lost-message count of the subscription to ``on_lost`` (with the count), so the node
    reports them in its diagnostics. The counts are polled (`LostMessages`), never
    delivered by an executor-armed event, which deadlocks under loss.

    Parameters
    ----------
    max_payload_bytes : int
        Largest payload decoded [bytes]; may be changed at any time.

    """

    def __init__(self, max_payload_bytes=DEFAULT_BOUNDS.max_payload_bytes):
        self.max_payload_bytes = int(max_payload_bytes)
        self.decoded = 0
        self.refused = 0
        self.lost = 0
        self._lost = LostMessages()

    def subscribe(self, node, msg_type, topic, qos, on_message, on_reject, on_lost=None):
        """
        Create a raw subscription of `msg_type` on `topic` whose payloads are guarded.

        Parameters
        ----------
        node : rclpy.node.Node
        msg_type : type
            ROS message class.
        topic : str
        qos : QoSProfile or int
        on_message : callable
            ``on_message(message)`` for every payload that decodes.
        on_reject : callable
            ``on_reject(check)`` for every payload refused (an `InputCheck`).
        on_lost : callable, optional
            ``on_lost(count)`` when the middleware has lost messages, read every
            `LOST_POLL_PERIOD_S` on a steady-time timer of the node (one per guard).

        Returns
        -------
        rclpy.subscription.Subscription

        """
        def callback(payload):
            message, check = decode(payload, msg_type, self.max_payload_bytes)
            if check is not None:
                self.refused += 1
                on_reject(check)
                return
            self.decoded += 1
            on_message(message)

        def lost(count):
            self.lost += count
            on_lost(count)

        subscription = node.create_subscription(msg_type, topic, callback, qos, raw=True)
        if on_lost is not None:
            # A middleware without the event watches nothing: the inputs are still guarded.
            self._lost.watch(node, subscription, lost)
        return subscription

    def poll_lost(self):
        """Read every guarded subscription's lost-message count; ``on_lost`` for each > 0."""
        self._lost.poll()

    def forget(self, subscription):
        """Read `subscription`'s last losses, then stop watching it (before destroying it)."""
        self._lost.forget(subscription)

    def close(self):
        """Destroy the lost-message handles (before their node: they hold its subscriptions)."""
        self._lost.close()
