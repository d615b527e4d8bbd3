"""The gripper in one process: bridge, model, controller (recorder, object) on one executor."""

import argparse
import sys

from fpc_gripper.nodes.runner import own_arguments
from fpc_gripper.nodes.runner import run_node

__all__ = ['NODE_NAMES', 'compose', 'main']

#: Every node `compose` can build, in the order of the list it returns; the reverse is the
#: stop order: the controller's commands end first, the bridge vents, and the recorder
#: closes last with all of it on disk.
NODE_NAMES = ('mcap_recorder', 'regulator_bridge', 'model_node', 'virtual_object',
              'gripper_controller')
#: The recorder is built last: it subscribes to each topic once it sees the topic's type
#: and QoS in the graph, which holds the others' publishers only once they are built.
_BUILD_ORDER = NODE_NAMES[1:] + NODE_NAMES[:1]


def _builders():
    # Imported here: a caller that only names nodes needs no node module.
    from fpc_gripper.nodes.gripper_controller import GripperController
    from fpc_gripper.nodes.mcap_recorder import McapRecorder
    from fpc_gripper.nodes.model_node import ModelNode
    from fpc_gripper.nodes.regulator_bridge import RegulatorBridge
    from fpc_gripper.nodes.virtual_object import VirtualObjectNode
    return {'mcap_recorder': McapRecorder,
            'regulator_bridge': lambda **kw: RegulatorBridge(auto_activate_default=True, **kw),
            'model_node': ModelNode, 'virtual_object': VirtualObjectNode,
            'gripper_controller': GripperController}


def compose(record=False, virtual_object=False, overrides=None, **kwargs):
    """
    Build the gripper's nodes for one executor: the composition rclcpp_components gives C++.

    The regulator bridge configures and activates itself unless its ``auto_activate``
    parameter says otherwise; each node reads its parameters as it would in a process of
    its own (``--params-file`` sections keyed ``/**/<node name>`` reach only that node).
    A node that cannot be built destroys the ones built before it, then its error
    propagates. A bridge that was to activate itself and did not ends the build: the list
    holds it alone (`bridge_exit_code` says why).

    Parameters
    ----------
    record : bool
        Also build mcap_recorder.
    virtual_object : bool
        Also build the virtual object (a simulated object in the palm that answers each
        finger's measured pressure with its contact force).
    overrides : dict, optional
        Node name -> list of `rclpy.parameter.Parameter` for that node.
    **kwargs
        Passed to every node (context, namespace, ...).

    Returns
    -------
    list of rclpy.node.Node
        In `NODE_NAMES` order (built in `_BUILD_ORDER`).

    """
    wanted = {'mcap_recorder': record, 'virtual_object': virtual_object}
    overrides = dict(overrides or {})
    unknown = sorted(set(overrides) - set(NODE_NAMES))
    if unknown:
        raise ValueError(f'`overrides` names nodes compose does not build: {unknown}; '
                         f'the nodes are {list(NODE_NAMES)}')
    builders = _builders()
    built = {}
    try:
        for name in _BUILD_ORDER:
            if wanted.get(name, True):
                built[name] = builders[name](
                    parameter_overrides=list(overrides.get(name, ())), **kwargs)
                if name == 'regulator_bridge' and bridge_exit_code([built[name]]) is not None:
                    # It has logged why; the others would only announce that they are ready.
                    break
    except BaseException:
        for node in reversed(built.values()):
            node.destroy_node()
        raise
    return [built[name] for name in NODE_NAMES if name in built]


def bridge_exit_code(nodes):
    """Exit code when the composed bridge did not activate (see regulator_bridge.main)."""
    from fpc_gripper.nodes.regulator_bridge import activation_exit_code
    from fpc_gripper.nodes.regulator_bridge import RegulatorBridge
    for node in nodes:
        if isinstance(node, RegulatorBridge):
            return activation_exit_code(node)
    return None


def parse_arguments(argv):
    """Parse the executable's own options (the ROS arguments removed)."""
    parser = argparse.ArgumentParser(
        prog='gripper', description='Run regulator_bridge, model_node and gripper_controller '
        '(and, if asked, mcap_recorder and a virtual object) in one process on one executor. '
        'Parameters as for the separate nodes: --ros-args --params-file FILE with sections '
        '/**/<node name> (in any namespace), or -p <node name>:<parameter>:=<value> (no '
        'namespace: rcl matches the name against /<node name>).')
    parser.add_argument('--record', action='store_true', help='also run mcap_recorder')
    parser.add_argument('--virtual-object', action='store_true',
                        help='also run the virtual object (simulated contact forces)')
    return parser.parse_args(argv[1:])


def main(args=None):
    """Run the composed gripper until SIGINT or SIGTERM: 0 then, 2 on a bad config, else 1."""
    argv = own_arguments(args, 'gripper')
    if argv is None:
        return 1
    options = parse_arguments(argv)

    def build():
        return compose(record=options.record, virtual_object=options.virtual_object)

    return run_node(build, 'gripper', args, check=bridge_exit_code)


if __name__ == '__main__':
    sys.exit(main())
