"""Raw input subscriptions of the nodes: payload size bound, guarded decoding, lost messages."""

from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.event_handler import UnsupportedEventTypeError
from rclpy.serialization import deserialize_message

from fpc_gripper.services.input_limits import DEFAULT_BOUNDS
from fpc_gripper.services.input_limits import InputCheck
from fpc_gripper.services.input_limits import Rejection
from fpc_gripper.services.logs import bounded

__all__ = ['InputGuard', 'decode']

# Characters of a deserialiser's error kept in a rejection.
_ERROR_CHARS = 160


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
    ``message_lost`` event of the subscription to ``on_lost`` (with the count), so the
    node reports them in its diagnostics.

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
            ``on_lost(count)`` when the middleware reports messages lost. Without it the
            subscription has no event handler: each one is a waitable that rclpy's
            executor re-adds to its wait set on every spin, which a fast control loop
            sharing the executor feels.

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

        def lost(info):
            count = int(info.total_count_change)
            self.lost += count
            if count > 0:
                on_lost(count)

        if on_lost is None:
            return node.create_subscription(msg_type, topic, callback, qos, raw=True)
        try:
            return node.create_subscription(
                msg_type, topic, callback, qos, raw=True,
                event_callbacks=SubscriptionEventCallbacks(message_lost=lost))
        except UnsupportedEventTypeError:
            # A middleware without the event: the inputs are still guarded.
            return node.create_subscription(msg_type, topic, callback, qos, raw=True)
