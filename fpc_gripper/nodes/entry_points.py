"""The nodes' console scripts: a stop signal while they import ends them at once, exit 0."""

import importlib
import signal

from fpc_gripper.nodes.middleware import apply_allocator_settings

__all__ = ['gripper', 'gripper_controller', 'gripper_demo', 'mcap_recorder', 'model_node',
           'regulator_bridge', 'virtual_object']

_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def _stop_while_importing(signum, frame):
    # Nothing is built yet, so there is nothing to shut down: a quiet exit, not a
    # KeyboardInterrupt traceback from the middle of scipy's imports (Ctrl-C under ros2
    # launch comes within a second of the start when a sibling dies at once).
    raise SystemExit(0)


def _run(module):
    """
    Import ``fpc_gripper.nodes.<module>`` under `_stop_while_importing`, then run main.

    The allocator settings come first: the imports start threads (numpy's BLAS, rclpy's),
    and a thread keeps the malloc arena it first allocates in.
    """
    apply_allocator_settings()
    for signum in _STOP_SIGNALS:
        signal.signal(signum, _stop_while_importing)
    # main replaces the handlers with its own (run_node's StopRequest, the demo's) before
    # it builds anything: left in place until then, no signal finds a default handler.
    return importlib.import_module(f'fpc_gripper.nodes.{module}').main()


def model_node():
    """``model_node``: see `fpc_gripper.nodes.model_node`."""
    return _run('model_node')


def regulator_bridge():
    """``regulator_bridge``: see `fpc_gripper.nodes.regulator_bridge`."""
    return _run('regulator_bridge')


def gripper_controller():
    """``gripper_controller``: see `fpc_gripper.nodes.gripper_controller`."""
    return _run('gripper_controller')


def mcap_recorder():
    """``mcap_recorder``: see `fpc_gripper.nodes.mcap_recorder`."""
    return _run('mcap_recorder')


def virtual_object():
    """``virtual_object``: see `fpc_gripper.nodes.virtual_object`."""
    return _run('virtual_object')


def gripper():
    """``gripper``: see `fpc_gripper.nodes.gripper`."""
    return _run('gripper')


def gripper_demo():
    """``gripper_demo``: see `fpc_gripper.nodes.gripper_demo`."""
    return _run('gripper_demo')
