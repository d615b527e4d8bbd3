"""Actuator design: a frozen, validated dataclass of the paper's geometry and materials (SI)."""

import dataclasses
from dataclasses import dataclass, field
import math
import os
import pathlib

import numpy as np

from .section.materials import check_emc_monotonic, default_emc_coefficients, Material
from .validation import ArgumentError, check_interval, DESIGN_BOUNDS, real_number
from ..safe_yaml import brief

__all__ = ['ActuatorDesign', 'PAPER_MATERIALS']

#: Table III laminae: constraining layer, fluidic layer, regular (and prestressed) EMC.
PAPER_MATERIALS = {
    'constraining_layer': Material(263e6, 263e6, 0.43),
    'fluidic_layer': Material(1.2e6, 1.2e6, 0.48),
    'emc': Material(1.5e6, 170e6, 0.0),
}

_LENGTHS = ('Lx', 'Ly', 'Lc', 'Cx', 'Cy', 'H', 'h1', 'h2', 'h3', 'h3a', 'h3b', 'w1', 'w2', 't')
_MATERIAL_FIELDS = ('constraining_layer', 'fluidic_layer', 'emc')
#: Strain headroom above the prestrain on which the PEMC law must be monotonic [-].
_MONOTONIC_MARGIN = 0.2
_UNITS = {**{name: '[m]' for name in _LENGTHS}, 'prestrain': '[-]', 'max_pressure': '[Pa]'}


@dataclass(frozen=True)
class ActuatorDesign:
    """
    Geometry and materials of one FPC finger, SI units throughout.

    Field names follow the paper's symbols (Table II, Fig. 2). Heights are z
    coordinates measured from the midplane, z towards the constraining layer.

    Parameters
    ----------
    Lx, Ly, Lc : float
        Finger length, width and clamped length [m]; free length L = Lx - Lc.
    Cx, Cy : float
        Channel end (from the clamped root) and channel width [m].
    H, h1, h2, h3 : float
        Total height and layer interfaces [m]: PEMC [-H/2, -h3], FL [-h3, h2],
        EMC [h2, h1], CL [h1, H/2].
    h3a, h3b : float
        Channel ceiling and floor, channel z in [-h3b, h3a] [m].
    w1, w2, t : float
        Transverse rib width, rib spacing and rib thickness [m].
    prestrain : float
        PEMC prestrain eps0 [-], in [0, 1).
    emc_coefficients : tuple of float
        PEMC stress law (a1, a2, a3, a4) [Pa].
    ribs : bool
        False removes every channel rib.
    constraining_layer, fluidic_layer, emc : Material
        Laminae; the PEMC takes its transverse stiffness Q22 from `emc`.
    max_pressure : float
        Design limit of the gauge pressure [Pa].
    pressure_work_factor : float
        k_p > 0 of the pressure potential Pi_P = -k_p P V [-]; default 2.5, the paper's
        adiabatic 1/(gamma - 1). Solvers use it unless built with an explicit
        `pressure_model` ('adiabatic': 2.5, 'isobaric': 1).

    References
    ----------
    Zhou, Headings, Dapino (2022), Tables II-III; SPEC "Geometry"; docs/physics.md,
    sections 2, 3 and 6.

    """

    Lx: float = 0.110
    Ly: float = 0.03175
    Lc: float = 0.020
    Cx: float = 0.105
    Cy: float = 0.026
    H: float = 0.0082
    h1: float = 0.0037
    h2: float = 0.0018
    h3: float = 0.0021
    h3a: float = 0.0009
    h3b: float = 0.0011
    w1: float = 0.008
    w2: float = 0.006
    t: float = 0.002
    prestrain: float = 0.25
    emc_coefficients: tuple = field(default_factory=default_emc_coefficients)
    ribs: bool = True
    constraining_layer: Material = PAPER_MATERIALS['constraining_layer']
    fluidic_layer: Material = PAPER_MATERIALS['fluidic_layer']
    emc: Material = PAPER_MATERIALS['emc']
    max_pressure: float = 400e3
    pressure_work_factor: float = 2.5

    def __post_init__(self):
        for name in _LENGTHS:
            object.__setattr__(self, name, real_number(name, getattr(self, name), '[m]'))
        object.__setattr__(self, 'prestrain', real_number('prestrain', self.prestrain, '[-]'))
        object.__setattr__(self, 'max_pressure',
                           real_number('max_pressure', self.max_pressure, '[Pa]'))
        object.__setattr__(self, 'pressure_work_factor',
                           real_number('pressure_work_factor', self.pressure_work_factor, '[-]'))
        coefficients = self.emc_coefficients
        if not isinstance(coefficients, (tuple, list, np.ndarray)) or len(coefficients) != 4:
            raise ArgumentError('emc_coefficients', 'must be 4 numbers (a1, a2, a3, a4) [Pa], '
                                                    f'got {brief(coefficients)}')
        object.__setattr__(self, 'emc_coefficients', tuple(
            real_number(f'emc_coefficients[{i}]', c, '[Pa]') for i, c in enumerate(coefficients)))
        if not isinstance(self.ribs, (bool, np.bool_)):
            raise TypeError(f'`ribs` must be a bool, got {brief(self.ribs)}')
        object.__setattr__(self, 'ribs', bool(self.ribs))
        for name in _MATERIAL_FIELDS:
            value = getattr(self, name)
            if isinstance(value, dict):
                value = Material(**value)
            if not isinstance(value, Material):
                raise TypeError(f'`{name}` must be a Material or a mapping of E1, E2, nu, '
                                f'got {brief(value)}')
            object.__setattr__(self, name, value)
        self._validate()

    def _validate(self):
        """
        Raise an `ArgumentError` naming the field unless the design is buildable and plausible.

        The bounds (`validation.DESIGN_BOUNDS`) are wide around any finger one could make,
        and keep every solver finite and small: at most 200 ribs, layers and features of
        10 um or more, moduli of 1 kPa to 1 TPa, a rating of at most 2 MPa.
        """
        bounds = DESIGN_BOUNDS
        for name in ('Lx', 'Ly', 'Cx', 'Cy', 'H', 'w1', 'w2', 't'):
            if getattr(self, name) <= 0.0:
                raise ArgumentError(name, f'must be > 0 [m], got {getattr(self, name)!r}')
        for name in ('Lx', 'Ly'):
            check_interval(name, getattr(self, name), bounds.length, '[m]')
        check_interval('H', self.H, bounds.height, '[m]')
        if not 0.0 <= self.Lc < self.Lx:
            raise ArgumentError('Lc', f'must be in [0, Lx) = [0, {self.Lx}) [m], got {self.Lc}')
        if self.free_length < bounds.length[0]:
            raise ArgumentError('Lc', f'leaves a free length Lx - Lc = {self.free_length:.6g} '
                                      f'[m] shorter than {bounds.length[0]:g} m')
        if not self.Lc < self.Cx <= self.Lx:
            raise ArgumentError('Cx', f'must be in (Lc, Lx] = ({self.Lc}, {self.Lx}] [m], '
                                      f'got {self.Cx}')
        if not self.Cy < self.Ly:
            raise ArgumentError('Cy', f'must be < `Ly` = {self.Ly} [m], got {self.Cy}')
        for name, size in (('Cy', self.Cy), ('Cx', self.Cx - self.Lc), ('w1', self.w1),
                           ('w2', self.w2), ('t', self.t)):
            if size < bounds.feature:
                raise ArgumentError(name, f'gives a feature of {size:.6g} [m], smaller than '
                                          f'{bounds.feature:g} m')
        order = (self.H / 2, self.h1, self.h2, -self.h3, -self.H / 2)
        names = ('H/2', 'h1', 'h2', '-h3', '-H/2')
        blame = ('h1', 'h2', 'h3', 'h3')
        for upper, lower, nu, nl, field_name in zip(order, order[1:], names, names[1:], blame):
            if not upper - lower >= bounds.feature:
                raise ArgumentError(field_name, f'breaks the layers: H/2 > h1 > h2 > -h3 > -H/2 '
                                                f'[m], each layer at least '
                                                f'{bounds.feature:g} m thick; got {nu} = '
                                                f'{upper} and {nl} = {lower}')
        if not -self.h3 <= -self.h3b < self.h3a <= self.h2:
            raise ArgumentError('h3a' if self.h3a > self.h2 else 'h3b',
                                'channel must lie inside the fluidic layer: '
                                f'-h3 <= -h3b < h3a <= h2 [m], got -h3 = {-self.h3}, '
                                f'-h3b = {-self.h3b}, h3a = {self.h3a}, h2 = {self.h2}')
        if self.h3a + self.h3b < bounds.feature:
            raise ArgumentError('h3a', f'gives a channel height h3a + h3b = '
                                       f'{self.h3a + self.h3b:.6g} [m], smaller than '
                                       f'{bounds.feature:g} m')
        if self.ribs and 1.5 * self.t + self.w1 > self.Cy / 2:
            raise ArgumentError('w1', f'ribs do not fit the channel: 3t/2 + w1 = '
                                      f'{1.5 * self.t + self.w1:.6g} must be <= Cy/2 = '
                                      f'{self.Cy / 2:.6g} [m]; reduce `w1` or set ribs=False')
        ribs = self._rib_count()
        if ribs > bounds.max_ribs:
            raise ArgumentError('w2', f'and t = {self.t:g} m give {ribs} ribs along the '
                                      f'channel, more than {bounds.max_ribs}')
        if not 0.0 <= self.prestrain < 1.0:
            raise ArgumentError('prestrain', f'must be in [0, 1) [-], got {self.prestrain}')
        if self.max_pressure <= 0.0:
            raise ArgumentError('max_pressure', f'must be > 0 [Pa], got {self.max_pressure}')
        check_interval('max_pressure', self.max_pressure, bounds.max_pressure, '[Pa]')
        check_interval('pressure_work_factor', self.pressure_work_factor,
                       bounds.pressure_work_factor, '[-]')
        for name in _MATERIAL_FIELDS:
            material = getattr(self, name)
            for key in ('E1', 'E2'):
                check_interval(f'{name}.{key}', getattr(material, key), bounds.modulus, '[Pa]')
            check_interval(f'{name}.nu', material.nu, (-bounds.poisson, bounds.poisson), '[-]')
        for i, value in enumerate(self.emc_coefficients):
            check_interval(f'emc_coefficients[{i}]', value,
                           (-bounds.emc_coefficient, bounds.emc_coefficient), '[Pa]')
        try:
            check_emc_monotonic(self.emc_coefficients, self.prestrain + _MONOTONIC_MARGIN)
        except ValueError as exc:
            raise ArgumentError('emc_coefficients',
                                str(exc).removeprefix('`emc_coefficients` ')) from None
        check_interval('emc_coefficients[3]', self.emc_coefficients[3], bounds.modulus,
                       '[Pa] (the PEMC modulus at zero strain)')

    # -- derived geometry -------------------------------------------------
    @property
    def free_length(self):
        """Free length L = Lx - Lc [m]."""
        return self.Lx - self.Lc

    @property
    def channel_end(self):
        """End of the channel in the finger frame, min(Cx - Lc, L) [m]."""
        return min(self.Cx - self.Lc, self.free_length)

    def transverse_ribs(self):
        """
        Return the x-intervals of the transverse ribs in the finger frame.

        Returns
        -------
        ndarray, shape (K, 2)
            [x_k, x_k + t] with x_k = w2 + k (t + w2) while x_k + t <= channel end [m].

        """
        count = self._rib_count()
        start = self.w2 + np.arange(count) * (self.t + self.w2)
        return np.stack([start, start + self.t], axis=1)

    def _rib_count(self):
        """Return the number of transverse ribs that fit the channel (0 without ribs)."""
        if not self.ribs:
            return 0
        # A relative slack keeps a rib that ends exactly at the channel end.
        count = math.floor((self.channel_end - self.w2 - self.t) / (self.t + self.w2)
                           * (1 + 1e-12) + 1e-12) + 1
        return max(int(count), 0)

    # -- construction --------------------------------------------------------
    @classmethod
    def paper(cls, prestrain=0.25, **fields):
        """Return the paper's finger (Tables II-III) with SPEC's default PEMC law."""
        return cls(prestrain=prestrain, **fields)

    def replace(self, **fields):
        """Return a new, validated design with some fields changed."""
        unknown = sorted(set(fields) - {f.name for f in dataclasses.fields(self)})
        if unknown:
            raise TypeError(f'unknown ActuatorDesign field(s): {", ".join(unknown)}')
        return dataclasses.replace(self, **fields)

    def to_dict(self):
        """Return every field as plain Python data (SI), as written to YAML."""
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, Material):
                value = value.as_dict()
            elif isinstance(value, tuple):
                value = list(value)
            out[f.name] = value
        return out

    @classmethod
    def from_dict(cls, data, source='mapping', path=''):
        """
        Build a design from a mapping of fields; missing fields take the paper's values.

        Parameters
        ----------
        data : dict
            Field names to plain values (numbers, lists, bools, mappings), as YAML gives.
        source, path : str
            File and key path of `data`, for messages.

        Raises
        ------
        ValueError
            A `safe_yaml.ConfigError` naming the source and the key path of the field, e.g.
            ``g.yaml: fingers[1].design.Lx: must be > 0 [m], got -0.11``.

        """
        from ..safe_yaml import Where
        where = Where(source, path)
        data = where.mapping(data, {f.name for f in dataclasses.fields(cls)},
                             what='a mapping of ActuatorDesign fields')
        kwargs = {}
        for name, value in data.items():
            at = where / name
            if name in _MATERIAL_FIELDS:
                value = at.mapping(value, {'E1', 'E2', 'nu'})
                missing = sorted({'E1', 'E2', 'nu'} - set(value))
                if missing:
                    raise at.error(f'needs E1, E2 and nu; missing {", ".join(missing)}')
                numbers = {key: (at / key).number(v, '[-]' if key == 'nu' else '[Pa]')
                           for key, v in value.items()}
                try:
                    kwargs[name] = Material(**numbers)
                except ValueError as exc:
                    raise at.error(str(exc)) from None
            elif name == 'emc_coefficients':
                items = at.sequence(value, 4, 4, what='numbers (a1, a2, a3, a4) [Pa]')
                kwargs[name] = tuple((at / i).number(c, '[Pa]') for i, c in enumerate(items))
            elif name == 'ribs':
                kwargs[name] = at.boolean(value)
            else:
                kwargs[name] = at.number(value, _UNITS.get(name, '[-]'))
        try:
            return cls(**kwargs)
        except ArgumentError as exc:
            raise where.sub(exc.argument).error(exc.reason) from None

    @classmethod
    def from_yaml(cls, path):
        """
        Load a design from a YAML file of SI fields (`safe_yaml.load_yaml`, then `from_dict`).

        Raises
        ------
        ValueError
            A `safe_yaml.ConfigError`, one line naming the file, the key path and the
            problem, for anything wrong with the file.

        """
        from ..safe_yaml import load_yaml
        return cls.from_dict(load_yaml(path, what='actuator design'), source=os.fspath(path))

    def to_yaml(self, path):
        """Write every field to a YAML file that `from_yaml` reads back exactly."""
        import yaml
        text = yaml.safe_dump(self.to_dict(), sort_keys=False)
        pathlib.Path(path).write_text('# ActuatorDesign, SI units (m, Pa)\n' + text)
