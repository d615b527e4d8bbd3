"""A virtual object in the palm: answers each finger's measured pressure with its contact force."""

import functools
import math
import struct
import sys

from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Path
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import FluidPressure

from fpc_gripper.control.virtual_object import VirtualObject
from fpc_gripper.control.virtual_object_parameters import METHODS
from fpc_gripper.control.virtual_object_parameters import PARAMETERS
from fpc_gripper.grasp.objects import make_object
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.io.qos import LATEST_QOS
from fpc_gripper.io.qos import MAX_STREAM_HZ
from fpc_gripper.io.qos import RELIABLE_QOS
from fpc_gripper.io.qos import writer_qos
from fpc_gripper.nodes.guard import InputGuard
from fpc_gripper.nodes.parameters import declare_table
from fpc_gripper.nodes.runner import run_node
from fpc_gripper.services.sample_ring import SampleRing

__all__ = ['RESIDUAL_SAMPLES', 'VirtualObjectNode', 'main']

#: Tip residuals kept (the newest; some 3 min of shapes in contact at 3 x 200 Hz), in arrays
#: of fixed size (1.6 MB) allocated at construction.
RESIDUAL_SAMPLES = 100_000


class VirtualObjectNode(Node):
    """
    A virtual object in the palm: publishes ``finger_<i>/tip_force`` for every finger.

    On each measured pressure ``finger_<i>/pressure`` it solves that finger's contact with
    the object (:class:`fpc_gripper.control.virtual_object.VirtualObject`: frictionless,
    along the whole finger, on the contact model) and publishes its resultant as a
    WrenchStamped in frame ``finger_<i>``: force.x, force.z the contact force on the
    finger [N], torque.y its moment about the fingertip [N m] (the wrench at the tip
    equivalent to the contact loads). It also reads the tip of the model node's
    ``finger_<i>/shape`` and records, while in contact, its distance from the contact
    model's tip (`residuals`): how far the model node's tip-force finger is from the
    finger in contact. Shapes are taken raw and only the tip is decoded (a 129-pose Path
    costs milliseconds as Python objects).

    Parameters
    ----------
    node_name : str
    **kwargs
        Passed to :class:`rclpy.node.Node`.

    """

    def __init__(self, node_name='virtual_object', **kwargs):
        super().__init__(node_name, **kwargs)
        declare_table(self, PARAMETERS)
        param = self.get_parameter
        config = load_gripper_config(param('gripper_config').value)
        method = param('method').value
        if method not in METHODS:
            raise ValueError(f'`method` must be one of {list(METHODS)}, got {method!r}')
        self._names = config.names
        self._palm_radius = config.palm_radius
        self.object = make_object(param('object').value, param('object_diameter').value,
                                  param('object_height').value)
        self.exact = method == 'exact'
        self.virtual = VirtualObject(self.object, config, penalty=0.0 if self.exact
                                     else param('stiffness_n_m').value)
        self.contacts = [None] * len(self._names)
        self.residuals = SampleRing(RESIDUAL_SAMPLES)
        # One force per measured pressure, at the bridge's rate, which this node never sees.
        self._pubs = tuple(self.create_publisher(WrenchStamped, f'{n}/tip_force',
                                                 writer_qos(RELIABLE_QOS, MAX_STREAM_HZ))
                           for n in self._names)
        # Raw through the guard, as every node's inputs: size-checked, decoded, and a
        # payload that does not decode is logged, not dropped without a word.
        self._guard = InputGuard()
        for i, name in enumerate(self._names):
            self._guard.subscribe(self, FluidPressure, f'{name}/pressure',
                                  qos_profile_sensor_data,
                                  functools.partial(self._on_pressure, i),
                                  functools.partial(self._on_refused, i))
            self.create_subscription(Path, f'{name}/shape', functools.partial(self._on_shape, i),
                                     LATEST_QOS, raw=True)
        self.get_logger().info(
            f'{param("object").value} D = {param("object_diameter").value * 1e3:.1f} mm '
            f'({method}); the free fingers touch it below '
            f'{self.virtual.touch_pressure:.0f} Pa gauge')

    @property
    def forces(self):
        """Latest normal force on every finger [N] (0 before any contact)."""
        return [0.0 if c is None else c.normal_force for c in self.contacts]

    def arcs(self):
        """Latest contact arc (start, end) [m] of every finger, or None."""
        return [None if c is None else c.arc for c in self.contacts]

    def _on_refused(self, index, check):
        self.get_logger().warning(f'{self._names[index]}/pressure refused '
                                  f'({check.rejection.value}): {check.detail}',
                                  throttle_duration_sec=2.0)

    def _on_pressure(self, index, msg):
        gauge = msg.fluid_pressure - self.get_parameter('atmospheric_pressure').value
        if not math.isfinite(gauge):
            return
        try:
            contact = self.virtual.contact(index, max(gauge, 0.0))
        except (RuntimeError, ValueError, ArithmeticError) as exc:
            # No contact force can be given for this pressure: publish none, so the model
            # node keeps the last one it had.
            self.get_logger().error(f'{self._names[index]}: no contact at {gauge:.0f} Pa '
                                    f'gauge: {exc}', throttle_duration_sec=2.0)
            return
        self.contacts[index] = contact
        out = WrenchStamped()
        out.header.stamp = self.get_clock().now().to_msg()
        out.header.frame_id = self._names[index]
        out.wrench.force.x, out.wrench.force.z = contact.force
        out.wrench.torque.y = contact.torque
        self._pubs[index].publish(out)

    def _on_shape(self, index, data):
        contact = self.contacts[index]
        if contact is None or not contact.in_contact or not self.exact:
            return
        z = _path_tip_z(data)
        if z is None:
            return
        self.residuals.append(self.get_clock().now().nanoseconds * 1e-9,
                              abs(z - contact.tip[1]))

    def residual(self, start, end):
        """Largest |Z_tip(model node) - Z_tip(contact)| of the shapes in [start, end] [m]."""
        return self.residuals.max_between(start, end, default=math.nan)


def _path_tip_z(data):
    """
    Z of the last pose of a serialized nav_msgs/Path, or None.

    The CDR payload ends with the last pose: position (x, y, z) then orientation
    (x, y, z, w), eight little- or big-endian doubles aligned to 8 bytes, so z is the
    fifth double from the end.
    """
    if len(data) < 20 or data[0] != 0 or data[1] not in (0, 1):
        return None
    order = '<' if data[1] == 1 else '>'
    # Payload (after the 4-byte encapsulation): stamp (8), frame_id (uint32 length + bytes),
    # then the uint32 pose count aligned to 4 from the payload start.
    offset = 16 + struct.unpack_from(order + 'I', data, 12)[0]
    offset += -(offset - 4) % 4
    if offset + 4 > len(data) or struct.unpack_from(order + 'I', data, offset)[0] == 0:
        return None
    return struct.unpack(order + 'd', data[-40:-32])[0]


def main(args=None):
    """Run the virtual object until SIGINT or SIGTERM."""
    return run_node(VirtualObjectNode, 'virtual_object', args)


if __name__ == '__main__':
    sys.exit(main())
