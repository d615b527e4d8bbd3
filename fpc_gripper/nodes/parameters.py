"""Parameter declaration shared by the nodes: descriptor ranges and table-driven declaring."""

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

__all__ = ['float_range', 'int_range', 'declare_table']


def float_range(low, high):
    """Return a ParameterDescriptor floating_point_range of [low, high]."""
    return [FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)]


def int_range(low, high):
    """Return a ParameterDescriptor integer_range of [low, high], step 1."""
    return [IntegerRange(from_value=int(low), to_value=int(high), step=1)]


def declare_table(node, table, defaults=None):
    """
    Declare every ``(name, default, description, descriptor fields)`` row of a table.

    Parameters
    ----------
    node : rclpy.node.Node
    table : iterable of tuple
        Rows of name, default value, description and a dict of further
        ParameterDescriptor fields (ranges, read_only, additional_constraints).
    defaults : dict, optional
        Default values that replace the table's, by name.

    """
    defaults = defaults or {}
    for name, default, description, extra in table:
        node.declare_parameter(name, defaults.get(name, default),
                               ParameterDescriptor(description=description, **extra))
