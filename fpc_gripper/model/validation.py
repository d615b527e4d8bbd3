"""Input checks shared by the core and its callers: real, finite numbers with units."""

import math

import numpy as np

__all__ = ['arc_lengths', 'real_number', 'real_pair']

#: Round-off slack of `arc_lengths` at the ends of [0, L], relative to L.
_ARC_SLACK = 1e-12


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


def real_pair(name, value, unit):
    """
    Return `value` as a pair of floats, or raise naming the argument, value and unit.

    Parameters
    ----------
    name : str
        Argument name, e.g. 'tip_force'; items are named 'tip_force[0]' and 'tip_force[1]'.
    value : object
        A sequence or array of two real numbers.
    unit : str

    Raises
    ------
    ValueError, TypeError
        If `value` is not two finite real numbers.

    """
    if not (isinstance(value, tuple) and len(value) == 2) and np.shape(value) != (2,):
        raise ValueError(f'`{name}` must be a pair of real numbers {unit}, got {value!r}')
    return (real_number(f'{name}[0]', value[0], unit), real_number(f'{name}[1]', value[1], unit))


def arc_lengths(name, value, length):
    """
    Return reference arc lengths in [0, `length`] as a flat float array, and their shape.

    Values within 1e-12 L outside the interval (round-off) are clipped onto it.

    Parameters
    ----------
    name : str
        Argument name, e.g. 's'.
    value : float or array_like
        Arc lengths [m].
    length : float
        Free length L [m].

    Returns
    -------
    values : ndarray, shape (K,)
        [m].
    shape : tuple
        Shape of `value`.

    Raises
    ------
    TypeError
        If `value` holds anything but real numbers.
    ValueError
        If a value is not finite or lies outside [0, L], naming the first one.

    """
    array = np.asarray(value)
    if array.dtype == object or array.dtype.kind not in 'iuf':
        raise TypeError(f'`{name}` must be real numbers [m], got {value!r}')
    values = array.astype(float).ravel()
    slack = _ARC_SLACK * length
    bad = ~(np.isfinite(values) & (values >= -slack) & (values <= length + slack))
    if bad.any():
        raise ValueError(f'`{name}` must lie in [0, {length:g}] [m] (the free length), got '
                         f'{values[bad][0]!r}')
    return np.clip(values, 0.0, length), array.shape
