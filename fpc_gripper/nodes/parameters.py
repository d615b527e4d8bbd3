"""Parameter declaration shared by the nodes: ROS-free tables declared with their ranges."""

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

from fpc_gripper.services.input_limits import BOUND_NAMES
from fpc_gripper.services.input_limits import InputBounds

__all__ = ['declare_table', 'input_bounds']


def _float_range(low, high):
    return [FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)]


def _int_range(low, high):
    return [IntegerRange(from_value=int(low), to_value=int(high), step=1)]


_RANGES = {'floating_point_range': _float_range, 'integer_range': _int_range}


def declare_table(node, table, defaults=None):
    """
    Declare every ``(name, default, description, descriptor fields)`` row of a table.

    Parameters
    ----------
    node : rclpy.node.Node
    table : iterable of tuple
        Rows of name, default value, description and a dict of further
        ParameterDescriptor fields (read_only, additional_constraints, and the ranges
        ``floating_point_range`` and ``integer_range`` as ``(low, high)`` pairs), so that
        the tables below the nodes are free of ROS.
    defaults : dict, optional
        Default values that replace the table's, by name.

    """
    defaults = defaults or {}
    for name, default, description, extra in table:
        extra = {key: _RANGES[key](*value) if key in _RANGES else value
                 for key, value in extra.items()}
        node.declare_parameter(name, defaults.get(name, default),
                               ParameterDescriptor(description=description, **extra))


def input_bounds(node, overrides=None):
    """
    Return the `InputBounds` of a node's bound parameters, with values replaced by name.

    Bounds the node does not declare keep their defaults.

    Raises
    ------
    ValueError, TypeError
        If a value is out of its bounds (naming it).

    """
    values = {name: node.get_parameter(name).value for name in BOUND_NAMES
              if node.has_parameter(name)}
    values.update({k: v for k, v in (overrides or {}).items() if k in BOUND_NAMES})
    return InputBounds(**values)
