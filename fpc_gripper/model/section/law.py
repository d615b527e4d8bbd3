"""Cross-section energy per unit length W(eps, kappa, c1; P) of the laminate, with derivatives."""

from dataclasses import dataclass

import numpy as np

from .materials import emc_energy_density, emc_stress, emc_stress_derivative, Material
from .. import engine
from ..engine import NewtonOptions, SolverStatus

__all__ = ['SectionLaw', 'build_section_law', 'rib_coverage', 'station_layout',
           'section_minimiser', 'SECTION_PARAMETERS', 'MODULUS_LAMINAE']

#: Laminae whose Young's modulus E1 the section law is linear in (E2 / E1 and nu held):
#: the constraining and the fluidic layer.
MODULUS_LAMINAE = ('constraining_layer', 'fluidic_layer')
#: Parameters of `SectionLaw.parameter_gradients`, in order: the PEMC prestrain, its stress
#: law a1..a4, k_p, and E1 of each of `MODULUS_LAMINAE`.
SECTION_PARAMETERS = ('prestrain', 'emc_a1', 'emc_a2', 'emc_a3', 'emc_a4',
                      'pressure_work_factor', 'cl_modulus', 'fl_modulus')

# 3-point Gauss-Legendre in z is exact for the quintic PEMC energy density (SPEC "Energy").
_GL_Z = np.polynomial.legendre.leggauss(3)


@dataclass(frozen=True)
class SectionLaw:
    """
    Energy per unit reference length of S cross-section types of one finger.

    The axial strain of a fibre at height z is e = eps - z kappa (no x
    dependence), the transverse strain is c1, so with y = (eps, kappa, c1)

        W(y; P) = 1/2 y K y + sum_j w_j F(eps0 + eps - z_j kappa)
                  - k_p P (1 + c1) (g0 (1 + eps) - g1 kappa),

    the linear layers (eq. 6) in the 3x3 matrix K (z-moments in closed form),
    the prestressed EMC by a 3-point Gauss rule in z (exact for the quintic F),
    and the gas (channel minus ribs) through its area g0 and first moment g1.
    kappa = d theta / d s is the rotation per unit *reference* length, theta
    measured from +X towards +Z; it equals 2 d of the CCM. A finger curling
    towards -Z has kappa < 0; SPEC's signed curvature is -kappa / (1 + eps).

    Attributes
    ----------
    stiffness : ndarray, shape (S, 3, 3)
        K of the linear layers and the PEMC's transverse term [N, N m, N m^2].
    gas : ndarray, shape (S, 2)
        (g0 [m^2], g1 = int z dA [m^3]) of the gas region.
    pemc_z : ndarray, shape (3,)
        Gauss points of the PEMC in z [m].
    pemc_weights : ndarray, shape (3,)
        Gauss weights times the PEMC width [m^2].
    prestrain : float
        PEMC prestrain eps0 [-].
    emc : tuple of float
        PEMC stress law (a1..a4) [Pa].
    labels : tuple of str
        A name for every section type.
    modulus_directions : ndarray, shape (2, S, 3, 3), optional
        dK/dE1 of each of `MODULUS_LAMINAE` (K is linear in them) [m^2, m^3, m^4].

    References
    ----------
    Zhou, Headings, Dapino (2022), eqs. (5)-(12), (19)-(20); SPEC "Energy";
    docs/physics.md, section 11.2.

    """

    stiffness: np.ndarray
    gas: np.ndarray
    pemc_z: np.ndarray
    pemc_weights: np.ndarray
    prestrain: float
    emc: tuple
    labels: tuple
    modulus_directions: np.ndarray = None

    @property
    def n_types(self):
        """Number S of section types."""
        return self.stiffness.shape[0]

    def mean(self, weights):
        """
        Return the one-type law of the weighted mean of the types.

        W is affine in K and (g0, g1) and the PEMC is the same in every type,
        so the mean law is exactly the mean of the energies.

        Parameters
        ----------
        weights : array_like, shape (S,)
            Non-negative weights, e.g. the length of each type [m]; normalised here.

        """
        w = np.asarray(weights, dtype=float)
        w = w / w.sum()
        directions = None if self.modulus_directions is None else \
            np.einsum('s,lsij->lij', w, self.modulus_directions)[:, None]
        return SectionLaw(stiffness=np.einsum('s,sij->ij', w, self.stiffness)[None],
                          gas=(w @ self.gas)[None], pemc_z=self.pemc_z,
                          pemc_weights=self.pemc_weights, prestrain=self.prestrain,
                          emc=self.emc, labels=('mean',), modulus_directions=directions)

    def _pemc_strain(self, y):
        """PEMC mechanical strain eps0 + eps - z_j kappa at the Gauss points, (..., 3)."""
        return self.prestrain + y[..., 0, None] - self.pemc_z * y[..., 1, None]

    def energy(self, y, pressure_work=0.0, types=0):
        """
        Energy per unit length W(y) [J/m].

        Parameters
        ----------
        y : array_like, shape (..., 3)
            (eps [-], kappa [1/m], c1 [-]).
        pressure_work : float
            k_p P [Pa].
        types : int or array_like of int, broadcast against y[..., 0]
            Section type of every point.

        """
        y = np.asarray(y, dtype=float)
        k = self.stiffness[types]
        g = self.gas[types]
        quad = 0.5 * np.einsum('...i,...ij,...j->...', y, k, y)
        pemc = emc_energy_density(self.emc, self._pemc_strain(y)) @ self.pemc_weights
        gas = (1.0 + y[..., 2]) * (g[..., 0] * (1.0 + y[..., 0]) - g[..., 1] * y[..., 1])
        return quad + pemc - pressure_work * gas

    def derivatives(self, y, pressure_work=0.0, types=0):
        """
        Energy, gradient and Hessian per unit length in y = (eps, kappa, c1).

        Returns
        -------
        energy : ndarray, shape (...)
            [J/m].
        gradient : ndarray, shape (..., 3)
            (N, M, T) = (dW/deps [N], dW/dkappa [N m], dW/dc1 [N]).
        hessian : ndarray, shape (..., 3, 3)

        """
        y = np.asarray(y, dtype=float)
        k = self.stiffness[types]
        g = self.gas[types]
        if k.ndim < y.ndim + 1:
            k = np.broadcast_to(k, y.shape + (3,))
            g = np.broadcast_to(g, y.shape[:-1] + (2,))
        s = self._pemc_strain(y)
        wz = self.pemc_weights
        zw = self.pemc_z * wz
        ky = np.einsum('...ij,...j->...i', k, y)
        energy = 0.5 * np.einsum('...i,...i->...', y, ky)
        energy = energy + emc_energy_density(self.emc, s) @ wz
        g0, g1 = g[..., 0], g[..., 1]
        c1 = y[..., 2]
        lin = g0 * (1.0 + y[..., 0]) - g1 * y[..., 1]
        energy = energy - pressure_work * (1.0 + c1) * lin

        sig = emc_stress(self.emc, s)
        grad = ky.copy()
        grad[..., 0] += sig @ wz - pressure_work * (1.0 + c1) * g0
        grad[..., 1] += -(sig @ zw) + pressure_work * (1.0 + c1) * g1
        grad[..., 2] += -pressure_work * lin

        tan = emc_stress_derivative(self.emc, s)
        hess = np.array(k, dtype=float, copy=True)
        t0, t1, t2 = tan @ wz, tan @ zw, tan @ (self.pemc_z * zw)
        hess[..., 0, 0] += t0
        hess[..., 0, 1] -= t1
        hess[..., 1, 0] -= t1
        hess[..., 1, 1] += t2
        hess[..., 0, 2] -= pressure_work * g0
        hess[..., 2, 0] -= pressure_work * g0
        hess[..., 1, 2] += pressure_work * g1
        hess[..., 2, 1] += pressure_work * g1
        return energy, grad, hess

    def parameter_gradients(self, y, pressure, types=0):
        """
        Differentiate the gradient of W in y with respect to `SECTION_PARAMETERS`, exactly.

        W is linear in a1..a4, k_p and the moduli (through K), so these are exact
        partial gradients; the prestrain enters the PEMC strain only, where d/deps0 is
        d/deps of the PEMC term.

        Parameters
        ----------
        y : array_like, shape (..., 3)
            (eps [-], kappa [1/m], c1 [-]).
        pressure : float
            Gauge pressure P [Pa] (k_p multiplies it).
        types : int or array_like of int
            Section type of every point.

        Returns
        -------
        ndarray, shape (..., 8, 3)
            d(dW/deps, dW/dkappa, dW/dc1) / d(parameter), parameters in the order of
            `SECTION_PARAMETERS` [per unit of each parameter].

        References
        ----------
        docs/physics.md, section 14.

        """
        y = np.asarray(y, dtype=float)
        types = np.broadcast_to(types, y.shape[:-1])
        g = self.gas[types]
        out = np.zeros(y.shape[:-1] + (len(SECTION_PARAMETERS), 3))
        s = self._pemc_strain(y)
        wz = self.pemc_weights
        zw = self.pemc_z * wz
        tangent = emc_stress_derivative(self.emc, s)
        out[..., 0, 0] = tangent @ wz
        out[..., 0, 1] = -(tangent @ zw)
        # sigma = a1 s^4 + a2 s^3 + a3 s^2 + a4 s: d sigma/d a_k = s^(5 - k).
        for k in range(4):
            power = s ** (4 - k)
            out[..., 1 + k, 0] = power @ wz
            out[..., 1 + k, 1] = -(power @ zw)
        c1 = y[..., 2]
        out[..., 5, 0] = -pressure * (1.0 + c1) * g[..., 0]
        out[..., 5, 1] = pressure * (1.0 + c1) * g[..., 1]
        out[..., 5, 2] = -pressure * (g[..., 0] * (1.0 + y[..., 0]) - g[..., 1] * y[..., 1])
        if self.modulus_directions is None:
            raise ValueError('this SectionLaw has no `modulus_directions`')
        out[..., 6:, :] = np.einsum('l...ij,...j->...li', self.modulus_directions[:, types], y)
        return out


def _box_moments(z0, z1, width):
    """Return width * int z^k dz over [z0, z1] for k = 0, 1, 2 [m^(k+2)]."""
    return width * np.array([z1 - z0, (z1 ** 2 - z0 ** 2) / 2.0, (z1 ** 3 - z0 ** 3) / 3.0])


def _add_linear(k, moments, material, sign):
    """Add the quadratic form of a linear lamina box (eq. 6) to K in place."""
    m0, m1, m2 = sign * moments
    q11, q12, q22 = material.Q11, material.Q12, material.Q22
    k[0, 0] += q11 * m0
    k[0, 1] -= q11 * m1
    k[1, 0] -= q11 * m1
    k[1, 1] += q11 * m2
    k[0, 2] += q12 * m0
    k[2, 0] += q12 * m0
    k[1, 2] -= q12 * m1
    k[2, 1] -= q12 * m1
    k[2, 2] += q22 * m0


def _unit_modulus(material):
    """Return the lamina with E1 = 1 Pa (E2 / E1 and nu kept): its Q are dQ/dE1."""
    return Material(1.0, material.E2 / material.E1, material.nu)


def rib_coverage(design):
    """
    Fraction of the channel length covered by transverse ribs [-].

    The x-coverage sum_k t / channel length of the design's actual ribs
    (not t / (t + w2), which ignores the rib-free ends of the channel).

    """
    end = design.channel_end
    ribs = design.transverse_ribs()
    if ribs.size == 0 or end <= 0.0:
        return 0.0
    return float(np.sum(ribs[:, 1] - ribs[:, 0]) / end)


def build_section_law(design, channel_rib_fractions=(None,), solid=True):
    """
    Section law of a design: channel stations with given rib fractions, then a solid one.

    Parameters
    ----------
    design : ActuatorDesign
        The finger.
    channel_rib_fractions : sequence of float or None
        One channel section type per entry, with that x-coverage of transverse
        ribs in [0, 1]; None stands for the design's mean `rib_coverage`.
        Ignored rib fractions when ``design.ribs`` is False (no ribs at all).
    solid : bool
        Append the channel-free section (the tip beyond the channel end).

    Returns
    -------
    SectionLaw

    """
    cl, fl, emc = design.constraining_layer, design.fluidic_layer, design.emc
    base = np.zeros((3, 3))
    _add_linear(base, _box_moments(design.h1, design.H / 2, design.Ly), cl, 1.0)
    _add_linear(base, _box_moments(design.h2, design.h1, design.Ly), emc, 1.0)
    _add_linear(base, _box_moments(-design.h3, design.h2, design.Ly), fl, 1.0)
    base[2, 2] += emc.Q22 * design.Ly * (design.H / 2 - design.h3)
    # dK/dE1 of the CL and the FL: the same boxes with materials of unit E1.
    unit_cl, unit_fl = (_unit_modulus(getattr(design, name)) for name in MODULUS_LAMINAE)
    base_directions = np.zeros((2, 3, 3))
    _add_linear(base_directions[0], _box_moments(design.h1, design.H / 2, design.Ly), unit_cl,
                1.0)
    _add_linear(base_directions[1], _box_moments(-design.h3, design.h2, design.Ly), unit_fl,
                1.0)
    channel = (-design.h3b, design.h3a)
    stiffness, gas, labels, directions = [], [], [], []
    for fraction in channel_rib_fractions:
        rho = rib_coverage(design) if fraction is None else float(fraction)
        if not 0.0 <= rho <= 1.0:
            raise ValueError(f'rib fraction must be in [0, 1] [-], got {rho}')
        # Gas region of width Cy minus the longitudinal rib t and 2 w1 rho of transverse ribs;
        # FL energy = whole - channel + ribs (eq. 8) removes exactly the gas boxes.
        width = design.Cy
        if design.ribs:
            width -= design.t + 2.0 * design.w1 * rho
        else:
            rho = 0.0
        k = base.copy()
        moments = _box_moments(*channel, width)
        _add_linear(k, moments, fl, -1.0)
        stiffness.append(k)
        direction = base_directions.copy()
        _add_linear(direction[1], moments, unit_fl, -1.0)
        directions.append(direction)
        gas.append(moments[:2])
        labels.append(f'channel (rib fraction {rho:.4g})')
    if solid:
        stiffness.append(base.copy())
        directions.append(base_directions.copy())
        gas.append(np.zeros(2))
        labels.append('solid')
    zp0, zp1 = -design.H / 2, -design.h3
    z = zp0 + 0.5 * (_GL_Z[0] + 1.0) * (zp1 - zp0)
    w = 0.5 * (zp1 - zp0) * _GL_Z[1] * design.Ly
    return SectionLaw(stiffness=np.array(stiffness), gas=np.array(gas), pemc_z=z,
                      pemc_weights=w, prestrain=design.prestrain,
                      emc=tuple(design.emc_coefficients), labels=tuple(labels),
                      modulus_directions=np.stack(directions, axis=1))


def station_layout(design, ribs='exact'):
    """
    Piecewise-constant section layout along the free length.

    Parameters
    ----------
    design : ActuatorDesign
        The finger.
    ribs : {'exact', 'average'}
        'exact' resolves every transverse rib (stations inside a rib and between
        ribs are different types); 'average' smears the ribs over the channel with
        their x-coverage `rib_coverage(design)`.

    Returns
    -------
    breaks : ndarray, shape (K + 1,)
        Interval ends from 0 to the free length [m].
    types : ndarray of int, shape (K,)
        Section type of every interval.
    law : SectionLaw
        Types: 0 open channel (or averaged ribs), 1 channel with a rib (exact
        only), last: solid (no channel).

    """
    if ribs not in ('exact', 'average'):
        raise ValueError(f"`ribs` must be 'exact' or 'average', got {ribs!r}")
    length = design.free_length
    end = design.channel_end
    rib_x = design.transverse_ribs()
    if ribs == 'average' or rib_x.size == 0:
        law = build_section_law(design, (None,))
        breaks = [0.0, end]
        types = [0]
    else:
        law = build_section_law(design, (0.0, 1.0))
        breaks, types = [0.0], []
        for lo, hi in rib_x:
            if lo > breaks[-1]:
                breaks.append(float(lo))
                types.append(0)
            breaks.append(float(hi))
            types.append(1)
        if end > breaks[-1] * (1.0 + 1e-12):
            breaks.append(end)
            types.append(0)
        else:
            breaks[-1] = end
    if length > end * (1.0 + 1e-12):
        breaks.append(length)
        types.append(law.n_types - 1)
    else:
        breaks[-1] = length
    return np.array(breaks), np.array(types, dtype=int), law


class _Section:
    """One section type as a discretisation of the engine: unknowns (eps, kappa L_ref, c1)."""

    # y = scale * x: kappa in units of 1/(0.1 m)
    scale = np.array([1.0, 10.0, 1.0])

    @staticmethod
    def step(grad, hess):
        """Newton step where H is positive definite, else a scaled gradient step."""
        try:
            np.linalg.cholesky(hess)
        except np.linalg.LinAlgError:
            # Mirrored eigenvalues can lead into the tension range where the quintic PEMC
            # energy falls without bound; the gradient stays in the basin.
            return -grad / np.abs(np.diag(hess)).max(), -1.0
        return np.linalg.solve(hess, -grad), 1.0

    def __init__(self, law, pressure_work, types):
        self.law, self.pressure_work, self.types = law, pressure_work, types
        self.gradient_scale = float(np.abs(law.stiffness[types]).max())

    def flat(self):
        return np.zeros(3)

    def energy(self, x, pressure, loads):
        return float(self.law.energy(x * self.scale, self.pressure_work, self.types))

    def derivatives(self, x, pressure, loads):
        w, g, h = self.law.derivatives(x * self.scale, self.pressure_work, self.types)
        sc = self.scale
        return float(w), g * sc, h * sc[:, None] * sc[None, :]


def section_minimiser(law, pressure_work=0.0, types=0, initial=None, tol=1e-13,
                      max_iterations=60):
    """
    Minimise W(eps, kappa, c1) of one section type with the engine's damped Newton.

    Parameters
    ----------
    law : SectionLaw
    pressure_work : float
        k_p P [Pa].
    types : int
        Section type.
    initial : array_like, shape (3,), optional
        Start; default the unstrained state.
    tol : float
        Largest final Newton step in (eps, kappa L_ref, c1), L_ref = 0.1 m [-].
    max_iterations : int

    Returns
    -------
    y : ndarray, shape (3,)
        (eps [-], kappa [1/m], c1 [-]).
    converged : bool
        Newton converged to a minimum (positive-definite Hessian).

    """
    problem = _Section(law, pressure_work, types)
    start = problem.flat() if initial is None else np.array(initial, dtype=float) / problem.scale
    options = NewtonOptions(max_iterations=int(max_iterations), xtol=float(tol), max_step=0.2,
                            flat_slope=1e-15, energy_scale=1.0)
    out = engine.newton(problem, start, 0.0, [], options)
    return out.x * problem.scale, out.status is SolverStatus.SUCCESS
