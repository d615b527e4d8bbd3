"""The QoS profiles of the gripper's topics, each defined once."""

from rclpy.qos import DurabilityPolicy
from rclpy.qos import HistoryPolicy
from rclpy.qos import QoSProfile
from rclpy.qos import ReliabilityPolicy

__all__ = ['RELIABLE_QOS', 'STATE_QOS', 'TF_QOS', 'TF_STATIC_QOS']

#: Commands, tip forces, controller outputs and diagnostics: reliable, the newest 10 kept
#: (a reader that falls further behind wants the newest, not a backlog).
RELIABLE_QOS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                          reliability=ReliabilityPolicy.RELIABLE)
#: The model's state (shape, curvature, rigidity, markers): a late joiner gets the newest
#: one from the publisher's history.
STATE_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: tf2_ros's TransformBroadcaster publisher on /tf (Jazzy: QoSProfile(depth=100)).
TF_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                    reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE)
#: tf2_ros's StaticTransformBroadcaster publisher on /tf_static.
TF_STATIC_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                           reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
