"""The topics' QoS profiles are the conventions the README's topic table states."""

from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy

from fpc_gripper.io import messages, tf
from fpc_gripper.io.qos import RELIABLE_QOS, STATE_QOS, TF_QOS, TF_STATIC_QOS


def test_the_profiles_are_the_conventions():
    assert (STATE_QOS.depth, STATE_QOS.reliability, STATE_QOS.durability) == (
        1, ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL)
    assert (RELIABLE_QOS.depth, RELIABLE_QOS.history, RELIABLE_QOS.reliability,
            RELIABLE_QOS.durability) == (10, HistoryPolicy.KEEP_LAST,
                                         ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE)
    # tf2_ros's broadcasters' own profiles.
    assert (TF_QOS.depth, TF_QOS.durability) == (100, DurabilityPolicy.VOLATILE)
    assert (TF_STATIC_QOS.depth, TF_STATIC_QOS.durability) == (
        1, DurabilityPolicy.TRANSIENT_LOCAL)


def test_the_old_import_paths_name_the_same_profiles():
    assert messages.STATE_QOS is STATE_QOS
    assert tf.TF_QOS is TF_QOS and tf.TF_STATIC_QOS is TF_STATIC_QOS
