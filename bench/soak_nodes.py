"""The soak's two extra node processes: the regulator bridge with a fault hook, the object."""

# Run by bench/soak.py, one process each:
#   python bench/soak_nodes.py regulator_bridge --ros-args ...   (the bridge, sim backend)
#   python bench/soak_nodes.py virtual_object --ros-args ...     (gripper_demo's object)
# or, with soak.py --composed, every node in one process as the `gripper` executable runs
# them (with --record --virtual-object):
#   python bench/soak_nodes.py gripper --ros-args ...
# The bridge is fpc_gripper's RegulatorBridge, unchanged, built and spun by the package's
# run_node exactly as `regulator_bridge` is; it only gets one more subscription,
# `soak/regulator_fault` (std_msgs/String, JSON), through which the soak injects faults
# into the simulated backend (SimulatedRegulator.inject_fault) from another process:
#   {"kind": "disconnect" | "bad_readback" | "leak" | "stuck_sensor", "channel": 0,
#    "value": NaN, "rate": 1e5, "duration_s": 0.5}
# and clears them all after duration_s.

import functools
import json
import sys

from rclpy.qos import QoSProfile
from rclpy.qos import ReliabilityPolicy
from std_msgs.msg import String

from fpc_gripper.nodes.gripper import bridge_exit_code
from fpc_gripper.nodes.gripper import compose
from fpc_gripper.nodes.regulator_bridge import activation_exit_code
from fpc_gripper.nodes.regulator_bridge import RegulatorBridge
from fpc_gripper.nodes.runner import run_node
from fpc_gripper.nodes.virtual_object import VirtualObjectNode

FAULT_TOPIC = 'soak/regulator_fault'
_FAULT_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


class FaultHook:
    """Inject the faults asked on `FAULT_TOPIC` into a bridge's simulated backend."""

    def __init__(self, node):
        self.node = node
        self._clear_timer = None
        node.create_subscription(String, FAULT_TOPIC, self._on_fault, _FAULT_QOS)

    def _on_fault(self, msg):
        log = self.node.get_logger()
        backend = self.node.backend
        if backend is None or not hasattr(backend, 'inject_fault'):
            log.warning(f'soak fault ignored, no simulated backend: {msg.data}')
            return
        try:
            spec = json.loads(msg.data)
            backend.inject_fault(spec['kind'], channel=spec.get('channel'),
                                 rate=spec.get('rate'), value=spec.get('value'))
        except (KeyError, TypeError, ValueError) as exc:
            log.warning(f'soak fault {msg.data!r} not injected: {exc}')
            return
        log.info(f'soak fault injected: {msg.data}')
        if self._clear_timer is not None:
            self.node.destroy_timer(self._clear_timer)
        self._clear_timer = self.node.create_timer(float(spec.get('duration_s', 0.5)),
                                                   self._clear)

    def _clear(self):
        self.node.destroy_timer(self._clear_timer)
        self._clear_timer = None
        backend = self.node.backend
        if backend is not None:
            backend.clear_faults()
            self.node.get_logger().info('soak faults cleared')


def _gripper_with_hook():
    nodes = compose(record=True, virtual_object=True)
    for node in nodes:
        if isinstance(node, RegulatorBridge):
            node.soak_fault_hook = FaultHook(node)
    return nodes


def _bridge_with_hook():
    node = RegulatorBridge(auto_activate_default=True)
    node.soak_fault_hook = FaultHook(node)
    return node


def main(argv=None):
    """Run the node named by the first argument until SIGINT or SIGTERM."""
    argv = sys.argv if argv is None else argv
    kind = argv[1] if len(argv) > 1 else ''
    if kind == 'regulator_bridge':
        # The same exit-code check as the package's regulator_bridge main.
        return run_node(_bridge_with_hook, 'regulator_bridge', argv,
                        check=activation_exit_code)
    if kind == 'gripper':
        return run_node(_gripper_with_hook, 'gripper', argv, check=bridge_exit_code)
    if kind == 'virtual_object':
        return run_node(functools.partial(VirtualObjectNode, 'virtual_object'),
                        'virtual_object', argv)
    print('usage: soak_nodes.py {regulator_bridge|virtual_object|gripper} [--ros-args ...]',
          file=sys.stderr)
    return 2


if __name__ == '__main__':
    sys.exit(main())
