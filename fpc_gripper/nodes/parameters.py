"""Parameter declaration shared by the nodes: ROS-free tables declared with their ranges."""

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rcl_interfaces.msg import SetParametersResult

from fpc_gripper.services.input_limits import BOUND_NAMES
from fpc_gripper.services.input_limits import checked_bounds
from fpc_gripper.services.input_limits import InputBounds

__all__ = ['check_change', 'declare_table', 'input_bounds']


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


def check_change(node, parameters, refusal=None, frames=None):
    """
    Return the SetParametersResult of a parameter change: the node's refusal, then the bounds.

    Parameters
    ----------
    node : rclpy.node.Node
        Holds the current values of the parameters not changed.
    parameters : list of rclpy.parameter.Parameter
        The change.
    refusal : callable, optional
        ``refusal(changes)``, the changed values by name: why the node refuses them (a
        str), or None; a ValueError or TypeError it raises refuses with its message.
    frames : tuple of str, optional
        The finger frames, which the input bounds must admit (`checked_bounds`).

    """
    changes = {p.name: p.value for p in parameters}
    try:
        reason = None if refusal is None else refusal(changes)
        if reason is None:
            bounds = input_bounds(node, changes)
            if frames is not None:
                checked_bounds(bounds, frames)
    except (TypeError, ValueError) as exc:
        reason = str(exc)
    return SetParametersResult(successful=reason is None, reason=reason or '')
