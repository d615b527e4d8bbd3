"""Actuator design: a frozen, validated dataclass of the paper's geometry and materials (SI)."""

import dataclasses
from dataclasses import dataclass, field
import math
import pathlib

import numpy as np

from .materials import check_emc_monotonic, default_emc_coefficients, Material
from .validation import real_number

__all__ = ['ActuatorDesign', 'PAPER_MATERIALS', 'safe_load_yaml']

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


def safe_load_yaml(text):
    """
    Parse YAML safely, reading 1e6-style numbers as floats (YAML 1.2) as users expect.

    PyYAML follows YAML 1.1, where ``263e6`` (no dot, no exponent sign) is a string.
    """
    import re

    import yaml

    class _Loader(yaml.SafeLoader):
        pass

    _Loader.add_implicit_resolver(
        'tag:yaml.org,2002:float',
        re.compile(r'^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)(?:[eE][-+]?[0-9]+)?$'
                   r'|^[-+]?\.(?:inf|Inf|INF)$|^\.(?:nan|NaN|NAN)$'),
        list('-+0123456789.'))
    # Integers keep their own resolver, registered first for the same characters.
    _Loader.yaml_implicit_resolvers = {
        key: sorted(value, key=lambda item: item[0] != 'tag:yaml.org,2002:int')
        for key, value in _Loader.yaml_implicit_resolvers.items()}
    return yaml.load(text, Loader=_Loader)


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
        coefficients = tuple(self.emc_coefficients) if np.ndim(self.emc_coefficients) else ()
        if len(coefficients) != 4:
            raise ValueError('`emc_coefficients` must be 4 numbers (a1, a2, a3, a4) [Pa], '
                             f'got {self.emc_coefficients!r}')
        object.__setattr__(self, 'emc_coefficients', tuple(
            real_number(f'emc_coefficients[{i}]', c, '[Pa]') for i, c in enumerate(coefficients)))
        if not isinstance(self.ribs, (bool, np.bool_)):
            raise TypeError(f'`ribs` must be a bool, got {self.ribs!r}')
        object.__setattr__(self, 'ribs', bool(self.ribs))
        for name in _MATERIAL_FIELDS:
            value = getattr(self, name)
            if isinstance(value, dict):
                value = Material(**value)
            if not isinstance(value, Material):
                raise TypeError(f'`{name}` must be a Material or a mapping of E1, E2, nu, '
                                f'got {value!r}')
            object.__setattr__(self, name, value)
        self._validate()

    def _validate(self):
        for name in ('Lx', 'Ly', 'Cx', 'Cy', 'H', 'w1', 'w2', 't'):
            if getattr(self, name) <= 0.0:
                raise ValueError(f'`{name}` must be > 0 [m], got {getattr(self, name)}')
        if not 0.0 <= self.Lc < self.Lx:
            raise ValueError(f'`Lc` must be in [0, Lx) = [0, {self.Lx}) [m], got {self.Lc}')
        if not self.Lc < self.Cx <= self.Lx:
            raise ValueError(f'`Cx` must be in (Lc, Lx] = ({self.Lc}, {self.Lx}] [m], '
                             f'got {self.Cx}')
        if not self.Cy < self.Ly:
            raise ValueError(f'`Cy` must be < `Ly` = {self.Ly} [m], got {self.Cy}')
        order = (self.H / 2, self.h1, self.h2, -self.h3, -self.H / 2)
        names = ('H/2', 'h1', 'h2', '-h3', '-H/2')
        for upper, lower, nu, nl in zip(order, order[1:], names, names[1:]):
            if not upper > lower:
                raise ValueError(f'layers must satisfy H/2 > h1 > h2 > -h3 > -H/2 [m]; '
                                 f'got {nu} = {upper} <= {nl} = {lower}')
        if not -self.h3 <= -self.h3b < self.h3a <= self.h2:
            raise ValueError('channel must lie inside the fluidic layer: '
                             f'-h3 <= -h3b < h3a <= h2 [m], got -h3 = {-self.h3}, '
                             f'-h3b = {-self.h3b}, h3a = {self.h3a}, h2 = {self.h2}')
        if self.ribs and 1.5 * self.t + self.w1 > self.Cy / 2:
            raise ValueError(f'ribs do not fit the channel: 3t/2 + w1 = '
                             f'{1.5 * self.t + self.w1:.6g} must be <= Cy/2 = '
                             f'{self.Cy / 2:.6g} [m]; reduce `w1` or set ribs=False')
        if not 0.0 <= self.prestrain < 1.0:
            raise ValueError(f'`prestrain` must be in [0, 1) [-], got {self.prestrain}')
        if self.max_pressure <= 0.0:
            raise ValueError(f'`max_pressure` must be > 0 [Pa], got {self.max_pressure}')
        if self.pressure_work_factor <= 0.0:
            raise ValueError('`pressure_work_factor` must be > 0 [-], got '
                             f'{self.pressure_work_factor}')
        check_emc_monotonic(self.emc_coefficients, self.prestrain + _MONOTONIC_MARGIN)

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
        if not self.ribs:
            return np.zeros((0, 2))
        end = self.channel_end
        # A relative slack keeps a rib that ends exactly at the channel end.
        count = int(math.floor((end - self.w2 - self.t) / (self.t + self.w2) * (1 + 1e-12)
                               + 1e-12)) + 1
        count = max(count, 0)
        start = self.w2 + np.arange(count) * (self.t + self.w2)
        return np.stack([start, start + self.t], axis=1)

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
    def from_dict(cls, data, source='mapping'):
        """Build a design from a mapping of fields; missing fields take the paper's values."""
        if not isinstance(data, dict):
            raise ValueError(f'{source}: expected a mapping of ActuatorDesign fields, '
                             f'got {type(data).__name__}')
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(map(str, data)) - known)
        if unknown:
            raise ValueError(f'{source}: unknown ActuatorDesign key(s): {", ".join(unknown)}')
        kwargs = dict(data)
        for name in _MATERIAL_FIELDS:
            if name in kwargs and isinstance(kwargs[name], dict):
                bad = sorted(set(kwargs[name]) - {'E1', 'E2', 'nu'})
                if bad:
                    raise ValueError(f'{source}: unknown key(s) in `{name}`: {", ".join(bad)}')
                kwargs[name] = Material(**kwargs[name])
        if 'emc_coefficients' in kwargs:
            kwargs['emc_coefficients'] = tuple(kwargs['emc_coefficients'] or ())
        return cls(**kwargs)

    @classmethod
    def from_yaml(cls, path):
        """Load a design from a YAML file of SI fields; unknown keys are rejected by name."""
        import yaml
        path = pathlib.Path(path)
        try:
            data = safe_load_yaml(path.read_text())
        except OSError as exc:
            raise ValueError(f'{path}: cannot read design: {exc}') from exc
        except yaml.YAMLError as exc:
            raise ValueError(f'{path}: malformed YAML: {exc}') from exc
        return cls.from_dict(data, source=str(path))

    def to_yaml(self, path):
        """Write every field to a YAML file that `from_yaml` reads back exactly."""
        import yaml
        text = yaml.safe_dump(self.to_dict(), sort_keys=False)
        pathlib.Path(path).write_text('# ActuatorDesign, SI units (m, Pa)\n' + text)
