"""The design parameters a calibration fits: names, design fields and section-law rows."""

import numpy as np

from ..model.section.law import SECTION_PARAMETERS
from ..model.section.materials import Material

__all__ = ['FIT_NAMES', 'FitParameters', 'parse_fit']

#: Names of the fittable parameters (the `--fit` names and the keys of report.json), in the
#: order the fit keeps them.
FIT_NAMES = ('prestrain', 'cl_modulus', 'fl_modulus', 'pressure_work_factor', 'emc')
#: What each name is: its unit and rows of `section_law.SECTION_PARAMETERS`.
_ROWS = {
    'prestrain': (SECTION_PARAMETERS.index('prestrain'),),
    'cl_modulus': (SECTION_PARAMETERS.index('cl_modulus'),),
    'fl_modulus': (SECTION_PARAMETERS.index('fl_modulus'),),
    'pressure_work_factor': (SECTION_PARAMETERS.index('pressure_work_factor'),),
    'emc': tuple(SECTION_PARAMETERS.index(f'emc_a{k}') for k in range(1, 5)),
}
UNITS = {'prestrain': '-', 'cl_modulus': 'Pa', 'fl_modulus': 'Pa', 'pressure_work_factor': '-',
         'emc': 'Pa'}
#: Bounds of each scalar relative to its base value: positive and within three decades.
_RELATIVE_BOUNDS = (1e-3, 1e3)
#: The prestrain stays in the open interval the design allows.
_PRESTRAIN_BOUNDS = (1e-4, 0.95)


def parse_fit(names):
    """
    Return fit names in `FIT_NAMES` order from 'a,b' text or a sequence; raise naming bad ones.

    Raises
    ------
    ValueError
        On an unknown, repeated or empty list.

    """
    if isinstance(names, str):
        names = [n.strip() for n in names.split(',') if n.strip()]
    names = list(names)
    unknown = [n for n in names if n not in FIT_NAMES]
    if unknown:
        raise ValueError(f'`fit` names unknown parameter(s) {", ".join(map(repr, unknown))}; '
                         f'choose from {", ".join(FIT_NAMES)}')
    if len(set(names)) != len(names):
        raise ValueError(f'`fit` repeats a parameter: {names}')
    if not names:
        raise ValueError(f'`fit` must name at least one of {", ".join(FIT_NAMES)}')
    return tuple(n for n in FIT_NAMES if n in names)


def _modulus_field(name):
    return 'constraining_layer' if name == 'cl_modulus' else 'fluidic_layer'


class FitParameters:
    """
    The fitted design parameters as one vector theta, and the design of any theta.

    `cl_modulus` and `fl_modulus` are E1 of the constraining and fluidic layer, E2 moving
    with it (E2 / E1 of the base design held: E1 = E2 for the isotropic PP and silicone);
    `emc` is the four PEMC coefficients (a1..a4) [Pa]; the rest are the design fields of
    the same name. Everything not fitted stays at the base design.

    Parameters
    ----------
    base : ActuatorDesign
    names : sequence of str
        A subset of `FIT_NAMES`.

    """

    def __init__(self, base, names):
        self.base = base
        self.names = parse_fit(names)
        self.sizes = [len(_ROWS[n]) for n in self.names]
        #: One label per component: 'prestrain', ..., 'emc[0]'..'emc[3]'.
        self.labels = [n if size == 1 else f'{n}[{k}]'
                       for n, size in zip(self.names, self.sizes) for k in range(size)]
        #: Row of `SECTION_PARAMETERS` of every component.
        self.rows = np.array([r for n in self.names for r in _ROWS[n]], dtype=np.int64)
        self.initial = self.values(base)
        # Typical magnitude of every component: the fit works in theta / scale.
        self.scale = np.where(self.initial != 0.0, np.abs(self.initial), 1.0)

    def __len__(self):
        return int(self.rows.size)

    def values(self, design):
        """Return theta of a design, shape (n,)."""
        out = []
        for name in self.names:
            if name == 'emc':
                out.extend(design.emc_coefficients)
            elif name in ('cl_modulus', 'fl_modulus'):
                out.append(getattr(design, _modulus_field(name)).E1)
            else:
                out.append(getattr(design, name))
        return np.array(out, dtype=float)

    def design(self, theta):
        """Return the base design with theta's values (validated: ValueError if invalid)."""
        fields = {}
        for name, value in self.split(theta).items():
            if name == 'emc':
                fields['emc_coefficients'] = tuple(value)
            elif name in ('cl_modulus', 'fl_modulus'):
                field = _modulus_field(name)
                old = getattr(self.base, field)
                fields[field] = Material(value, old.E2 * (value / old.E1), old.nu)
            else:
                fields[name] = value
        return self.base.replace(**fields)

    def split(self, vector):
        """Return a vector of components as {name: float, or list for emc}."""
        out, start = {}, 0
        for name, size in zip(self.names, self.sizes):
            part = [float(v) for v in vector[start:start + size]]
            out[name] = part[0] if size == 1 else part
            start += size
        return out

    def bounds(self):
        """Return (lower, upper) of theta: positive scalars within three decades of the base."""
        lower = np.full(len(self), -np.inf)
        upper = np.full(len(self), np.inf)
        for k, label in enumerate(self.labels):
            if label == 'prestrain':
                lower[k], upper[k] = _PRESTRAIN_BOUNDS
            elif not label.startswith('emc'):
                lower[k], upper[k] = (b * self.initial[k] for b in _RELATIVE_BOUNDS)
        return lower, upper
