"""Input checks shared by the core and its callers: real, finite numbers with units."""

import math

import numpy as np

__all__ = ['real_number']


def real_number(name, value, unit):
    """
    Return `value` as a float, or raise naming the argument, value and unit.

    Parameters
    ----------
    name : str
        Argument name, as the caller spells it.
    value : object
        Anything; numpy scalars are accepted, bools are not.
    unit : str
        Unit in brackets, e.g. '[Pa]'.

    Raises
    ------
    TypeError
        If `value` is not a real number.
    ValueError
        If it is NaN or infinite.

    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(
            value, (int, float, np.integer, np.floating)):
        raise TypeError(f'`{name}` must be a real number {unit}, got {value!r}')
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f'`{name}` must be finite {unit}, got {value}')
    return value
