"""Parameter declaration shared by the nodes: descriptor ranges and table-driven declaring."""

import dataclasses

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

from fpc_gripper.services.input_limits import DEFAULT_BOUNDS
from fpc_gripper.services.input_limits import InputBounds

__all__ = ['BOUND_NAMES', 'float_range', 'int_range', 'declare_table', 'input_bound_table',
           'input_bounds']

#: The parameters named as the `InputBounds` fields.
BOUND_NAMES = tuple(f.name for f in dataclasses.fields(InputBounds))


def float_range(low, high):
    """Return a ParameterDescriptor floating_point_range of [low, high]."""
    return [FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)]


def int_range(low, high):
    """Return a ParameterDescriptor integer_range of [low, high], step 1."""
    return [IntegerRange(from_value=int(low), to_value=int(high), step=1)]


_RANGES = {'floating_point_range': float_range, 'integer_range': int_range}


def declare_table(node, table, defaults=None):
    """
    Declare every ``(name, default, description, descriptor fields)`` row of a table.

    Parameters
    ----------
    node : rclpy.node.Node
    table : iterable of tuple
        Rows of name, default value, description and a dict of further
        ParameterDescriptor fields (ranges, read_only, additional_constraints). A range
        may be given as a ``(low, high)`` pair, so that a table can be free of ROS.
    defaults : dict, optional
        Default values that replace the table's, by name.

    """
    defaults = defaults or {}
    for name, default, description, extra in table:
        extra = {key: _RANGES[key](*value) if isinstance(value, tuple) else value
                 for key, value in extra.items()}
        node.declare_parameter(name, defaults.get(name, default),
                               ParameterDescriptor(description=description, **extra))


def input_bound_table(names=BOUND_NAMES):
    """
    Return the `declare_table` rows of the input-bound parameters in `names`.

    Every node that takes the bound declares it with the same description and range.
    """
    rows = {
        'min_absolute_pressure': (
            DEFAULT_BOUNDS.min_absolute_pressure,
            'Pressures below this absolute value are rejected [Pa]: vacuum, or a message '
            'whose pressure was never set (a default FluidPressure reads 0 Pa).',
            {'floating_point_range': float_range(0.0, 3.0e4)}),
        'max_tip_force': (
            DEFAULT_BOUNDS.max_tip_force,
            'Tip forces of a larger magnitude are rejected [N]; at most the model envelope, '
            '5 N.', {'floating_point_range': float_range(1.0e-3, DEFAULT_BOUNDS.max_tip_force)}),
        'max_frame_id_length': (
            DEFAULT_BOUNDS.max_frame_id_length,
            'Inputs whose header frame_id is longer are rejected [characters]; at least the '
            'longest finger frame.', {'integer_range': int_range(1, 65536)}),
        'max_payload_bytes': (
            DEFAULT_BOUNDS.max_payload_bytes,
            'Input messages whose serialized size is larger are rejected undecoded [bytes].',
            {'integer_range': int_range(64, 1 << 24)}),
    }
    return tuple((name, *rows[name]) for name in names)


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
