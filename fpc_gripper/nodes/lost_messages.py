"""Lost-message counts of subscriptions, read on a steady timer instead of an armed event."""

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.clock import Clock
from rclpy.clock import ClockType
from rclpy.event_handler import EventHandler
from rclpy.event_handler import QoSSubscriptionEventType
from rclpy.event_handler import UnsupportedEventTypeError
from rclpy.exceptions import InvalidHandle

__all__ = ['LOST_POLL_PERIOD_S', 'LostMessages']

#: How often the lost-message counts are read [s] (steady time, also under use_sim_time).
LOST_POLL_PERIOD_S = 0.5


class LostMessages:
    """
    Read the middleware's lost-message count of each watched subscription, periodically.

    The counts are read every `LOST_POLL_PERIOD_S` (and by `poll` when asked), not
    delivered as events. An event handler in the node would be armed by rclpy's
    EventsExecutor, and rmw_fastrtps (the Jazzy wheels) then takes its event mutex and
    the DataReader's mutex in opposite orders on the executor thread and on the DDS
    thread that reports the loss: the process deadlocks under message loss (seen in a
    soak after 9 minutes of injected bursts; upstream ros2/rmw_fastrtps#890). Unarmed,
    Fast DDS still counts the losses, and a take reads them.
    """

    def __init__(self):
        self._events = {}
        self._timer = None

    def watch(self, node, subscription, on_lost):
        """
        Call ``on_lost(count)`` when the middleware has lost messages of `subscription`.

        The first watch creates the node's steady-time poll timer. Returns False, and
        watches nothing, for a middleware without the event.
        """
        try:
            # Neither the node's waitable nor in its callback groups, so no executor arms it.
            event = EventHandler(
                callback_group=MutuallyExclusiveCallbackGroup(), callback=None,
                event_type=QoSSubscriptionEventType.RCL_SUBSCRIPTION_MESSAGE_LOST,
                parent_impl=subscription.handle)
        except UnsupportedEventTypeError:
            return False
        self._events[subscription] = (event, on_lost)
        if self._timer is None:
            self._timer = node.create_timer(
                LOST_POLL_PERIOD_S, self.poll, clock=Clock(clock_type=ClockType.STEADY_TIME))
        return True

    def poll(self):
        """Read every watched subscription's lost-message count; ``on_lost`` for each > 0."""
        for subscription in tuple(self._events):
            self._read(subscription)

    def forget(self, subscription):
        """Read `subscription`'s last losses, then stop watching it (before destroying it)."""
        if subscription not in self._events:
            return
        self._read(subscription)
        entry = self._events.pop(subscription, None)
        if entry is not None:
            entry[0].destroy()

    def _read(self, subscription):
        event, on_lost = self._events[subscription]
        # take_data takes only what a wait set said was ready; here nothing waits.
        event._ready_to_take_data = True
        try:
            info = event.take_data()
        except InvalidHandle:
            del self._events[subscription]
            return
        count = 0 if info is None else int(info.total_count_change)
        if count > 0:
            on_lost(count)

    def close(self):
        """Destroy the lost-message handles (before their node: they hold its subscriptions)."""
        for event, _ in self._events.values():
            event.destroy()
        self._events.clear()
