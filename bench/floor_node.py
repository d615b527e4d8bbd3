"""The least an rclpy node does per command: a raw take, and one shape's bytes published raw."""

# Started by bench_node.py --per-command beside the model node, with the same executor
# (rclpy's EventsExecutor), QoS and topics, so that its CPU per command is the floor that
# rclpy and the middleware put under any Python node on this machine.

import signal
import sys

from nav_msgs.msg import Path
import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import FluidPressure

from fpc_gripper.io.messages import serialized_shape
from fpc_gripper.io.qos import RELIABLE_QOS, STATE_QOS, writer_qos
from fpc_gripper.model import ActuatorDesign
from fpc_gripper.model.pipeline import finger_model
from fpc_gripper.nodes.middleware import apply_middleware_settings

FINGERS = 3
#: model_node's max_rate_hz in the per-command runs, which sizes its shape writers' history.
RATE_HZ = 1000.0


def main(namespace):
    apply_middleware_settings()
    rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
    node = Node('floor_node', namespace=namespace)
    shape = bytearray(serialized_shape(finger_model(ActuatorDesign()).solve(1e5),
                                       'finger_0', 0))
    qos = writer_qos(STATE_QOS, RATE_HZ)
    pubs = [node.create_publisher(Path, f'finger_{i}/shape', qos) for i in range(FINGERS)]

    def answer(i):
        def callback(payload):
            shape[4:12] = payload[4:12]   # the command's header stamp
            pubs[i].publish(bytes(shape))
        return callback

    for i in range(FINGERS):
        node.create_subscription(FluidPressure, f'finger_{i}/pressure_command', answer(i),
                                 RELIABLE_QOS, raw=True)
    executor = EventsExecutor()
    executor.add_node(node)
    stop = []
    signal.signal(signal.SIGINT, lambda *_: stop.append(True))
    while not stop:
        executor.spin_once(timeout_sec=0.1)
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == '__main__':
    main(sys.argv[1])
