"""A lifecycle node that runs its own configure and activate transitions when asked."""

from rclpy.lifecycle import LifecycleNode
from rclpy.lifecycle import TransitionCallbackReturn

__all__ = ['SelfActivatingNode']


class SelfActivatingNode(LifecycleNode):
    """
    A LifecycleNode that can drive itself to active, as a launch file's events would.

    For a node in one process with others on one executor, and for a ``main`` that runs
    it alone: there is no lifecycle manager to send the transitions.
    """

    @classmethod
    def create_active(cls, *args, **kwargs):
        """
        Build a node, configure it and activate it (for single-process executors).

        Parameters
        ----------
        *args, **kwargs
            Passed to the constructor (node name, namespace, parameter_overrides,
            context, ...).

        Raises
        ------
        RuntimeError
            If configure or activate does not succeed (the node is destroyed).

        """
        node = cls(*args, **kwargs)
        try:
            node.configure_and_activate(raise_on_failure=True)
        except Exception:
            node.destroy_node()
            raise
        return node

    def configure_and_activate(self, raise_on_failure=False):
        """Run the configure and activate transitions that are still needed; return success."""
        for wanted, trigger in (('unconfigured', self.trigger_configure),
                                ('inactive', self.trigger_activate)):
            if self.lifecycle_state != wanted:
                continue
            result = trigger()
            if result != TransitionCallbackReturn.SUCCESS:
                message = (f'{trigger.__name__} of {self.get_name()} returned {result.name}; '
                           f'now {self.lifecycle_state}')
                if raise_on_failure:
                    raise RuntimeError(message)
                if trigger != self.trigger_configure:
                    # on_configure has logged its reason already: one line per failure.
                    self.get_logger().error(message)
                return False
        return self.lifecycle_state == 'active'

    @property
    def lifecycle_state(self):
        """Label of the current lifecycle state ('unconfigured', 'inactive', 'active', ...)."""
        return self._state_machine.current_state[1]
