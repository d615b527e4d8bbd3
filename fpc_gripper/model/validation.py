"""Input checks shared by the core and its callers: numbers with units, and the model's bounds."""

import dataclasses
import math

import numpy as np

from ..safe_yaml import brief

__all__ = ['ArgumentError', 'arc_lengths', 'DESIGN_BOUNDS', 'DesignBounds', 'ENVELOPE',
           'InputLimits', 'UNIQUE_LOAD', 'check_force', 'check_interval', 'check_load',
           'real_number', 'real_pair', 'warm_start_allowed', 'check_pressure_model',
           'PRESSURE_MODELS', 'PRESSURE_MODEL_NAMES', 'OUTPUT_LEVELS', 'check_outputs',
           'ATMOSPHERIC_RANGE', 'STANDARD_ATMOSPHERE']

#: Standard atmosphere [Pa]: the default of every absolute-to-gauge conversion.
STANDARD_ATMOSPHERE = 101325.0
#: Atmospheric pressure anywhere people work, from 9 km up to below sea level [Pa]: the
#: range of a configured atmospheric pressure.
ATMOSPHERIC_RANGE = (3.0e4, 1.2e5)

#: Pressure-work coefficient k_p of Pi_P = -k_p P V by name (SPEC "Pressure work"):
#: 1/(gamma - 1) with gamma = 1.4, exactly 2.5 (1/(1.4 - 1) rounds to 2.5000000000000004).
PRESSURE_MODELS = {'adiabatic': 2.5, 'isobaric': 1.0}
#: Every `pressure_model` a solver takes: 'design' (the design's `pressure_work_factor`,
#: also spelt None) or a name of `PRESSURE_MODELS`.
PRESSURE_MODEL_NAMES = ('design',) + tuple(PRESSURE_MODELS)


def check_pressure_model(pressure_model):
    """
    Return the name of a pressure model, 'design' for None; raise naming the argument.

    Parameters
    ----------
    pressure_model : {None, 'design', 'adiabatic', 'isobaric'}
        None and 'design' use the design's `pressure_work_factor`; the names fix k_p.

    """
    name = 'design' if pressure_model is None else pressure_model
    if not isinstance(name, str) or name not in PRESSURE_MODEL_NAMES:
        raise ValueError(f'`pressure_model` must be one of {list(PRESSURE_MODEL_NAMES)}, '
                         f'got {pressure_model!r}')
    return name


class ArgumentError(ValueError):
    """
    A value outside its bounds: a ValueError that also says which argument and why.

    ``str(error)`` is "`name` reason", e.g. "`Lx` must be in [0.001, 2] [m], got 1e+30";
    a config loader re-words it as "file: key.path.Lx: reason".

    Attributes
    ----------
    argument : str
        The argument, as a path below its owner ('Lx', 'emc.E1', 'emc_coefficients[2]').
    reason : str
        What is wrong, with the bound, the unit and the value.

    """

    def __init__(self, argument, reason):
        self.argument, self.reason = str(argument), str(reason)
        super().__init__(f'`{self.argument}` {self.reason}')


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
        If it is NaN or infinite (an `ArgumentError`).

    """
    # A Python float first: every solve checks its inputs, and this case is most of them.
    if type(value) is float and math.isfinite(value):
        return value
    if isinstance(value, (bool, np.bool_)) or not isinstance(
            value, (int, float, np.integer, np.floating)):
        raise TypeError(f'`{name}` must be a real number {unit}, got {brief(value)}')
    try:
        number = float(value)
    except OverflowError:
        number = math.copysign(math.inf, value)
    if not math.isfinite(number):
        raise ArgumentError(name, f'must be finite {unit}, got {number}')
    return number


def integer(name, value, low, high=None, unit=''):
    """
    Return `value` as an int in [low, high], or raise naming the argument, value and unit.

    Parameters
    ----------
    name : str
        Argument name, as the caller spells it.
    value : object
        Anything; numpy integers are accepted, bools are not.
    low : int
    high : int, optional
        None for no upper bound.
    unit : str
        Unit in brackets, e.g. '[samples]', or ''.

    Raises
    ------
    ValueError
        If `value` is no integer in range.

    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
            or value < low or (high is not None and value > high):
        bound = f'>= {low}' if high is None else f'in [{low}, {high}]'
        raise ValueError(f'`{name}` must be an integer {bound}{" " * bool(unit)}{unit}, '
                         f'got {value!r}')
    return int(value)


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
    if type(value) is tuple and len(value) == 2:
        first, second = value
        # Two finite Python floats: what every solve after the first passes on.
        if type(first) is float and type(second) is float and math.isfinite(first) \
                and math.isfinite(second):
            return value
    if not (isinstance(value, tuple) and len(value) == 2) and np.shape(value) != (2,):
        raise ValueError(f'`{name}` must be a pair of real numbers {unit}, got '
                         f'{brief(value)}')
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
        raise TypeError(f'`{name}` must be real numbers [m], got {brief(value)}')
    values = array.astype(float).ravel()
    slack = _ARC_SLACK * length
    bad = ~(np.isfinite(values) & (values >= -slack) & (values <= length + slack))
    if bad.any():
        raise ValueError(f'`{name}` must lie in [0, {length:g}] [m] (the free length), got '
                         f'{values[bad][0]!r}')
    return np.clip(values, 0.0, length), array.shape


# -- the model's validity envelope -----------------------------------------------------------

# The envelope's bounds, (value, unit): no InputLimits may be wider.
_WIDEST = {'max_tip_force': (5.0, '[N]'), 'pressure_factor': (2.0, '[-]')}


@dataclasses.dataclass(frozen=True)
class InputLimits:
    """
    Bounds on the loads of a finger; the defaults (`ENVELOPE`) are the model's envelope.

    Every solver refuses loads outside `ENVELOPE` with a ValueError (no solve is tried):
    beyond them the answer is not physics (a soft finger of any plausible design has
    folded over or burst long before), and a solve could take minutes. Callers may
    tighten them (nodes: configurable, with a diagnostic), never widen them.

    Attributes
    ----------
    max_tip_force : float
        Largest magnitude of the tip force, and of any point load [N].
    pressure_factor : float
        Largest gauge pressure as a multiple of the design's `max_pressure` [-].

    References
    ----------
    docs/physics.md, section 16.

    """

    max_tip_force: float = _WIDEST['max_tip_force'][0]
    pressure_factor: float = _WIDEST['pressure_factor'][0]

    def __post_init__(self):
        for name, (widest, unit) in _WIDEST.items():
            value = real_number(name, getattr(self, name), unit)
            if not 0.0 < value <= widest:
                raise ArgumentError(name, f'must be in (0, {widest:g}] {unit} (the envelope '
                                          f'of the model), got {value!r}')
            object.__setattr__(self, name, value)


#: The model's validity envelope: the widest `InputLimits`.
ENVELOPE = InputLimits()

#: Largest total load [N] up to which the equilibrium was unique on the paper's fingers
#: (prestrain 0.15-0.40, 0-400 kPa, 12 directions, warm starts from 3-5 other answers; the
#: first history-dependent answer came at 1.75 N): beyond it a compressive load can hold
#: the finger on two stable branches, so a warm start could change the answer. Solves
#: with more load start cold (`warm_start_allowed`), which keeps them history-free.
UNIQUE_LOAD = 1.5


def check_load(pressure, tip_force, max_pressure, limits=ENVELOPE):
    """
    Return (pressure, (f0, p0)) as floats inside `limits`, or raise naming the bound.

    Parameters
    ----------
    pressure : float
        Gauge pressure [Pa], >= 0.
    tip_force : (float, float)
        (f0, p0) [N].
    max_pressure : float
        The design's pressure rating [Pa]; the bound is ``limits.pressure_factor`` times it.
    limits : InputLimits

    Raises
    ------
    TypeError
        If a value is not a real number.
    ValueError
        If it is not finite or outside the limits (an `ArgumentError`).

    """
    pressure = real_number('pressure', pressure, '[Pa]')
    if pressure < 0.0:
        raise ArgumentError('pressure', f'must be >= 0 (gauge) [Pa], got {pressure!r}')
    top = limits.pressure_factor * max_pressure
    if pressure > top:
        raise ArgumentError('pressure', f'must be <= {top:.6g} (gauge) [Pa], '
                                        f'{limits.pressure_factor:g} x max_pressure of the '
                                        f'design (the envelope of the model), got {pressure!r}')
    force = real_pair('tip_force', tip_force, '[N]')
    check_force('tip_force', force, limits)
    return pressure, force


def check_force(name, force, limits=ENVELOPE):
    """Raise an `ArgumentError` if the magnitude of `force` (fx, fz) [N] exceeds the limit."""
    magnitude = math.hypot(*force)
    if not magnitude <= limits.max_tip_force:
        raise ArgumentError(name, f'magnitude must be <= {limits.max_tip_force:g} [N] (the '
                                  f'envelope of the model), got {magnitude:.6g} N')


#: What a solve computes besides the state, cheapest first (`engine.OUTPUTS`'s levels): the
#: chain ('tip': tip, nodes, rotations, coefficients, validity), then the energy and the
#: midplane samples ('shape'), then their circle fit ('all').
OUTPUT_LEVELS = {'tip': 0, 'shape': 1, 'all': 2}


def check_outputs(outputs):
    """Return the level of an `outputs` name ('tip', 'shape' or 'all'); raise naming it."""
    level = OUTPUT_LEVELS.get(outputs) if isinstance(outputs, str) else None
    if level is None:
        raise ValueError(f'`outputs` must be one of {list(OUTPUT_LEVELS)}, got {outputs!r}')
    return level


def warm_start_allowed(total_load):
    """Whether a solve with this total load magnitude [N] may start from a caller's state."""
    return total_load <= UNIQUE_LOAD


# -- plausibility of a design ---------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class DesignBounds:
    """
    What an `ActuatorDesign` may be: wide around any buildable finger, finite for the solvers.

    Attributes
    ----------
    length : (float, float)
        Finger length Lx, width Ly and free length Lx - Lc [m].
    height : (float, float)
        Total height H [m].
    feature : float
        Smallest Cy, Cx - Lc, w1, w2, t, layer thickness and channel height [m].
    max_ribs : int
        Most transverse ribs (each adds elements to every solver).
    modulus : (float, float)
        Young's moduli of the laminae [Pa].
    poisson : float
        Largest |nu| [-].
    emc_coefficient : float
        Largest |a_i| of the PEMC law [Pa].
    max_pressure : (float, float)
        Pressure rating [Pa].
    pressure_work_factor : (float, float)
        k_p of Pi_P = -k_p P V [-] (isobaric 1, adiabatic 2.5).

    """

    length: tuple = (1e-3, 2.0)
    height: tuple = (1e-4, 0.2)
    feature: float = 1e-5
    max_ribs: int = 200
    modulus: tuple = (1e3, 1e12)
    poisson: float = 0.9
    emc_coefficient: float = 1e10
    max_pressure: tuple = (1e3, 2e6)
    pressure_work_factor: tuple = (0.1, 10.0)


#: The bounds `ActuatorDesign` enforces.
DESIGN_BOUNDS = DesignBounds()


def check_interval(name, value, bounds, unit):
    """Raise an `ArgumentError` unless low <= value <= high for ``bounds = (low, high)``."""
    low, high = bounds
    if not low <= value <= high:
        raise ArgumentError(name, f'must be in [{low:g}, {high:g}] {unit}, got {value!r}')
