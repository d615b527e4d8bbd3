"""Sweep axes: value lists from the command line, and the grid of designs they span."""

import dataclasses
import itertools
import pathlib

import numpy as np

from fpc_gripper.model import ActuatorDesign
from fpc_gripper.ranges import MAX_COUNT, parse_range

__all__ = ['DesignPoint', 'base_design', 'design_grid', 'parse_assignment', 'parse_values',
           'sweepable_fields', 'DEFAULT_PRESSURES', 'MAX_COUNT']

#: Default pressure axis: 0 to 400 kPa in 5 kPa steps [Pa].
DEFAULT_PRESSURES = np.linspace(0.0, 400e3, 81)
#: Design fields a sweep may vary: the numeric ones (lengths, prestrain, the pressure limit
#: and any scalar field a later ActuatorDesign adds).
_SKIP = {'emc_coefficients', 'ribs', 'constraining_layer', 'fluidic_layer', 'emc'}


def sweepable_fields():
    """Return the ActuatorDesign fields a sweep can vary, in declaration order."""
    return tuple(f.name for f in dataclasses.fields(ActuatorDesign) if f.name not in _SKIP)


def parse_values(text, name='values'):
    """
    Parse an axis: ``a,b,c``, ``start:stop:step`` or ``start:stop/count``.

    The syntax of every tool, `fpc_gripper.ranges.parse_range` (a plain integer step,
    once a count here, is refused).

    Raises
    ------
    ValueError
        Naming `name` and the text.

    """
    return parse_range(text, f'`{name}`' if not name.startswith(('`', '-')) else name)


def parse_assignment(text):
    """Parse ``FIELD=VALUES`` of ``--vary`` into (field, values); see `parse_values`."""
    field, sep, values = str(text).partition('=')
    field = field.strip()
    if not sep or not field:
        raise ValueError(f'`--vary` must be FIELD=VALUES, e.g. prestrain=0.15,0.25, got {text!r}')
    return _check_field(field), parse_values(values, f'--vary {field}')


def _check_field(field):
    fields = sweepable_fields()
    if field not in fields:
        raise ValueError(f'`{field}` is not an ActuatorDesign field a sweep can vary; choose '
                         f'from {", ".join(fields)}')
    return field


def base_design(design=None):
    """
    Return the base design of a sweep: a design, a YAML file's, or the paper's (0.25).

    A file is read by `ActuatorDesign.from_yaml`, which validates it.
    """
    if design is None:
        return ActuatorDesign.paper(prestrain=0.25)
    if isinstance(design, ActuatorDesign):
        return design
    if isinstance(design, (str, pathlib.PurePath)):
        return ActuatorDesign.from_yaml(design)
    raise TypeError(f'`design` must be an ActuatorDesign, a YAML path or None, got '
                    f'{type(design).__name__}')


@dataclasses.dataclass(frozen=True)
class DesignPoint:
    """
    One design of a sweep: the varied fields' values and the design, or why it is invalid.

    Attributes
    ----------
    values : dict
        Varied field -> value (SI), as the table's columns show them.
    design : ActuatorDesign or None
        None when the fields make no valid design.
    error : str
        ActuatorDesign's validation message ('' for a valid design).

    """

    values: dict
    design: object
    error: str = ''


def design_grid(base, vary, scale_w1=False):
    """
    Every combination of the varied fields, in order (the last field varies fastest).

    Parameters
    ----------
    base : ActuatorDesign
    vary : mapping of str to sequence of float
        Field -> values; empty: the base design alone.
    scale_w1 : bool
        Scale the transverse rib width with the channel width, w1 = base.w1 Cy / base.Cy,
        wherever Cy varies (then w1 is a column too). Off by default: a channel too
        narrow for the base design's ribs is an invalid design, reported as such.

    Returns
    -------
    columns : list of str
        The table's design columns.
    points : list of DesignPoint

    """
    vary = {_check_field(str(k)): np.atleast_1d(np.asarray(v, dtype=float))
            for k, v in dict(vary or {}).items()}
    for field, values in vary.items():
        if values.ndim != 1 or not values.size or not np.all(np.isfinite(values)):
            raise ValueError(f'`vary[{field!r}]` must be a non-empty list of finite numbers, '
                             f'got {values!r}')
    if scale_w1 and 'w1' in vary:
        raise ValueError('`scale_w1` sets w1 from Cy: do not also vary `w1`')
    columns = list(vary)
    scaled = bool(scale_w1) and 'Cy' in vary
    if scaled:
        columns.append('w1')
    points = []
    for combo in itertools.product(*vary.values()):
        fields = {k: float(v) for k, v in zip(vary, combo)}
        if scaled:
            fields['w1'] = base.w1 * fields['Cy'] / base.Cy
        try:
            design = base.replace(**fields) if fields else base
        except (ValueError, TypeError) as error:
            points.append(DesignPoint(fields, None, str(error)))
        else:
            points.append(DesignPoint(fields, design))
    return columns, points
