"""Lamina stiffnesses and the prestressed-EMC stress polynomial (paper eqs. 6-7, Table III)."""

from dataclasses import dataclass
import math

import numpy as np

__all__ = [
    'DEFAULT_EMC_COEFFICIENTS',
    'Material',
    'default_emc_coefficients',
    'emc_stress',
    'emc_stress_derivative',
    'emc_energy_density',
    'fit_emc_polynomial',
    'check_emc_monotonic',
]

#: SPEC's default PEMC law (a1, a2, a3, a4) [Pa], about (-1.1052, 2.2207, -1.9992, 1.4856) MPa.
#: Written out, not refitted at import: a least-squares fit's last digits depend on the
#: BLAS/LAPACK build, and designs are compared and hashed by value. Recipe (SPEC
#: "Materials", checked in tests/model/test_materials.py): quartic without constant term,
#: least squares through the planar-tension neo-Hookean curve sigma = mu ((1 + s) -
#: (1 + s)^-3), mu = E1/4 = 0.375 MPa, on 121 evenly spaced s in [0, 0.6].
DEFAULT_EMC_COEFFICIENTS = (
    -1105183.749342006,
    2220741.75487717,
    -1999219.6554144165,
    1485624.9757942066,
)


@dataclass(frozen=True)
class Material:
    """
    Orthotropic lamina in plane stress.

    Parameters
    ----------
    E1 : float
        Young's modulus along X [Pa].
    E2 : float
        Young's modulus along Y [Pa].
    nu : float
        Poisson's ratio, nu12 = nu21 = nu [-].

    References
    ----------
    Zhou, Headings, Dapino (2022), eq. (6); docs/physics.md, section 3.

    """

    E1: float
    E2: float
    nu: float

    def __post_init__(self):
        for name in ('E1', 'E2', 'nu'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating,
                                                                 np.integer)):
                raise TypeError(f'`{name}` must be a real number, got {value!r}')
            object.__setattr__(self, name, float(value))
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f'`{name}` must be finite, got {value}')
        if self.E1 <= 0.0 or self.E2 <= 0.0:
            raise ValueError(f'`E1` and `E2` must be > 0 [Pa], got {self.E1}, {self.E2}')
        if not -1.0 < self.nu < 1.0:
            raise ValueError(f'`nu` must be in (-1, 1) [-], got {self.nu}')

    @property
    def Q11(self):
        """Reduced stiffness along X [Pa]."""
        return self.E1 / (1.0 - self.nu * self.nu)

    @property
    def Q12(self):
        """Reduced coupling stiffness [Pa]."""
        return self.nu * self.E2 / (1.0 - self.nu * self.nu)

    @property
    def Q22(self):
        """Reduced stiffness along Y [Pa]."""
        return self.E2 / (1.0 - self.nu * self.nu)

    def as_dict(self):
        """Return the fields as a plain dict (SI)."""
        return {'E1': self.E1, 'E2': self.E2, 'nu': self.nu}


def _design_matrix(strain):
    s = np.asarray(strain, dtype=float)
    return np.stack([s ** 4, s ** 3, s ** 2, s], axis=-1)


def emc_stress(coefficients, strain):
    """
    Evaluate sigma(s) = a1 s^4 + a2 s^3 + a3 s^2 + a4 s.

    Parameters
    ----------
    coefficients : array_like, shape (4,)
        (a1, a2, a3, a4) [Pa].
    strain : array_like
        Mechanical strain s [-].

    Returns
    -------
    ndarray
        Stress [Pa].

    """
    a1, a2, a3, a4 = coefficients
    s = np.asarray(strain, dtype=float)
    return s * (a4 + s * (a3 + s * (a2 + s * a1)))


def emc_stress_derivative(coefficients, strain):
    """Tangent modulus d sigma / d s [Pa]."""
    a1, a2, a3, a4 = coefficients
    s = np.asarray(strain, dtype=float)
    return a4 + s * (2.0 * a3 + s * (3.0 * a2 + s * 4.0 * a1))


def emc_energy_density(coefficients, strain):
    """Strain-energy density F(s) with F' = sigma, F(0) = 0 [J/m^3]."""
    a1, a2, a3, a4 = coefficients
    s = np.asarray(strain, dtype=float)
    return s * s * (a4 / 2.0 + s * (a3 / 3.0 + s * (a2 / 4.0 + s * a1 / 5.0)))


def check_emc_monotonic(coefficients, upper_strain):
    """
    Raise ValueError unless sigma(s) increases on [0, upper_strain].

    Parameters
    ----------
    coefficients : array_like, shape (4,)
        (a1, a2, a3, a4) [Pa].
    upper_strain : float
        Upper end of the strain range that must be monotonic [-].

    """
    a1, a2, a3, a4 = (float(c) for c in coefficients)
    # Critical points of sigma' plus the ends bound its minimum exactly.
    candidates = [0.0, float(upper_strain)]
    for root in np.roots([12.0 * a1, 6.0 * a2, 2.0 * a3]) if (a1 or a2) else []:
        if abs(root.imag) < 1e-12 and 0.0 < root.real < upper_strain:
            candidates.append(float(root.real))
    slopes = emc_stress_derivative((a1, a2, a3, a4), np.array(candidates))
    worst = int(np.argmin(slopes))
    if not slopes[worst] > 0.0:
        raise ValueError(
            '`emc_coefficients` must give a stress that increases on '
            f'[0, {upper_strain:.3g}] [-]; d sigma/d s = {slopes[worst]:.4g} Pa at '
            f's = {candidates[worst]:.4g}')


def fit_emc_polynomial(strain, stress, check_range=None):
    """
    Least-squares fit of the quartic PEMC stress law without constant term.

    Parameters
    ----------
    strain : array_like, shape (M,)
        Tensile-test strain [-], M >= 4.
    stress : array_like, shape (M,)
        Measured stress [Pa].
    check_range : float, optional
        Require sigma to increase on [0, check_range]; default max(strain).

    Returns
    -------
    tuple of float
        (a1, a2, a3, a4) [Pa].

    Raises
    ------
    ValueError
        On mismatched, non-finite or too few samples, or a non-monotonic fit.

    References
    ----------
    Zhou, Headings, Dapino (2022), Table I and eq. (7); docs/physics.md, section 3.

    """
    s = np.asarray(strain, dtype=float).ravel()
    y = np.asarray(stress, dtype=float).ravel()
    if s.shape != y.shape:
        raise ValueError(f'`strain` and `stress` must have equal lengths, got {s.size} '
                         f'and {y.size}')
    if s.size < 4:
        raise ValueError(f'`strain` needs at least 4 samples, got {s.size}')
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(y))):
        raise ValueError('`strain` and `stress` must be finite')
    from scipy.linalg import lstsq
    coefficients, *_ = lstsq(_design_matrix(s), y)
    coefficients = tuple(float(c) for c in coefficients)
    check_emc_monotonic(coefficients, float(s.max()) if check_range is None else check_range)
    return coefficients


def default_emc_coefficients():
    """
    Return SPEC's default PEMC law, `DEFAULT_EMC_COEFFICIENTS`.

    The constants are the quartic fit of a planar-tension neo-Hookean curve (see
    `DEFAULT_EMC_COEFFICIENTS`), written in the source so that they are the same on
    every machine.

    Returns
    -------
    tuple of float
        (a1, a2, a3, a4) [Pa], about (-1.1052, 2.2207, -1.9992, 1.4856) MPa.

    """
    return DEFAULT_EMC_COEFFICIENTS
