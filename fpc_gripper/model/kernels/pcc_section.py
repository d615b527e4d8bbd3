"""Compiled (numba) section law of a PCC segment, W(eps, kappa, c1; k_p P), and its S(delta)."""

import math

import numpy as np

from ..compiled import jit

__all__ = ['section_arrays', 'half_angle_sinc_kernel']

# Built at install (`compiled`), once per argument types; nogil lets a caller thread them.
_jit = jit

#: Taylor coefficients (-1)^k / (2k + 1)! of sin(h)/h in h^2, k = 0..9: for |h| < 1 the
#: first omitted terms (of S and its derivatives) are below 1e-17 of S, S' / h and S''.
_SINC = np.array([(-1.0) ** k / math.factorial(2 * k + 1) for k in range(10)])
_K = np.arange(10)
#: The same series differentiated once (divided by h) and twice in h.
_SINC_D1 = (2 * _K * _SINC)[1:]
_SINC_D2 = (2 * _K * (2 * _K - 1) * _SINC)[1:]
#: |h| below which the series replaces the closed forms (which cancel as h -> 0).
_SERIES_BELOW = 1.0
# Layout of the PEMC vector of `section_arrays`: Gauss points z_j, weights w_j, z_j w_j,
# z_j^2 w_j (3 each), the prestrain eps0 and the stress law a1..a4.
_Z, _W, _ZW, _ZZW, _PRESTRAIN, _A1 = 0, 3, 6, 9, 12, 13
_PEMC_SIZE = 17


def section_arrays(law, types):
    """
    Return the section law of every segment as the kernels take it (once per solver).

    Parameters
    ----------
    law : SectionLaw
    types : ndarray of int, shape (N,)
        Section type of every segment.

    Returns
    -------
    stiffness : ndarray, shape (N, 3, 3)
        K of every segment [N, N m, N m^2].
    gas : ndarray, shape (N, 2)
        (g0 [m^2], g1 [m^3]) of every segment.
    pemc : ndarray, shape (17,)
        PEMC Gauss points z_j [m], weights w_j [m^2], z_j w_j [m^3], z_j^2 w_j [m^4],
        prestrain eps0 [-] and stress law (a1..a4) [Pa].

    """
    stiffness = np.ascontiguousarray(law.stiffness[types], dtype=float)
    gas = np.ascontiguousarray(law.gas[types], dtype=float)
    z, w = law.pemc_z, law.pemc_weights
    zw = z * w
    pemc = np.concatenate([z, w, zw, z * zw, [law.prestrain], law.emc]).astype(float)
    assert pemc.size == _PEMC_SIZE
    return stiffness, gas, pemc


# -- S(delta) -------------------------------------------------------------------------------
@_jit
def _horner(x, coefficients):
    """Return sum_k coefficients[k] x^k by Horner's rule."""
    k = coefficients.size - 1
    out = coefficients[k]
    for j in range(k - 1, -1, -1):
        out = out * x + coefficients[j]
    return out


@_jit
def _sinc0(delta):
    """S(delta) = sin(delta/2) / (delta/2): series for |delta/2| < 1, else the closed form."""
    h = 0.5 * delta
    if abs(h) < _SERIES_BELOW:
        return _horner(h * h, _SINC)
    return math.sin(h) / h


@_jit
def _sinc(delta):
    """S(delta) and its first two derivatives in delta [-, 1/rad, 1/rad^2]."""
    h = 0.5 * delta
    if abs(h) < _SERIES_BELOW:
        h2 = h * h
        return (_horner(h2, _SINC), 0.5 * (h * _horner(h2, _SINC_D1)),
                0.25 * _horner(h2, _SINC_D2))
    sn, cs = math.sin(h), math.cos(h)
    h2 = h * h
    d2 = -sn / h - 2.0 * cs / h2 + 2.0 * sn / math.pow(h, 3.0)
    return sn / h, 0.5 * ((h * cs - sn) / h2), 0.25 * d2


@_jit
def half_angle_sinc_kernel(delta, order):
    """
    S(delta) = sin(delta/2) / (delta/2) and its derivatives, exact and smooth at 0.

    Parameters
    ----------
    delta : ndarray, shape (M,)
        Turning angles [rad].
    order : int
        Highest derivative returned, 0..2.

    Returns
    -------
    ndarray, shape (order + 1, M)
        S, dS/ddelta, d2S/ddelta2 [-, 1/rad, 1/rad^2].

    """
    rows = 1 + min(max(order, 0), 2)
    out = np.empty((rows, delta.size))
    for k in range(delta.size):
        if rows == 1:
            out[0, k] = _sinc0(delta[k])
        else:
            s0, s1, s2 = _sinc(delta[k])
            out[0, k] = s0
            out[1, k] = s1
            if rows == 3:
                out[2, k] = s2
    return out


# -- the section law W(eps, kappa, c1; k_p P) of segment i -------------------------------------
@_jit
def _section_energy(stiffness, gas, pemc, i, eps, kappa, c1, work):
    """Energy per unit length W [J/m] of segment i (section_law.SectionLaw.energy)."""
    quad = 0.0
    for a in range(3):
        ya = eps if a == 0 else (kappa if a == 1 else c1)
        ky = stiffness[i, a, 0] * eps + stiffness[i, a, 1] * kappa + stiffness[i, a, 2] * c1
        quad += ya * ky
    a1, a2, a3, a4 = pemc[_A1], pemc[_A1 + 1], pemc[_A1 + 2], pemc[_A1 + 3]
    pemc_energy = 0.0
    for j in range(3):
        s = pemc[_PRESTRAIN] + eps - pemc[_Z + j] * kappa
        density = s * s * (a4 / 2.0 + s * (a3 / 3.0 + s * (a2 / 4.0 + s * a1 / 5.0)))
        pemc_energy += density * pemc[_W + j]
    gas_term = (1.0 + c1) * (gas[i, 0] * (1.0 + eps) - gas[i, 1] * kappa)
    return 0.5 * quad + pemc_energy - work * gas_term


@_jit
def _section_slopes(stiffness, gas, pemc, i, eps, kappa, c1, work, g, h):
    """Gradient g (3,) and Hessian h (3, 3) of W in (eps, kappa, c1) of segment i."""
    a1, a2, a3, a4 = pemc[_A1], pemc[_A1 + 1], pemc[_A1 + 2], pemc[_A1 + 3]
    sig_w = sig_zw = 0.0
    t0 = t1 = t2 = 0.0
    for j in range(3):
        s = pemc[_PRESTRAIN] + eps - pemc[_Z + j] * kappa
        sigma = s * (a4 + s * (a3 + s * (a2 + s * a1)))
        tangent = a4 + s * (2.0 * a3 + s * (3.0 * a2 + s * 4.0 * a1))
        sig_w += sigma * pemc[_W + j]
        sig_zw += sigma * pemc[_ZW + j]
        t0 += tangent * pemc[_W + j]
        t1 += tangent * pemc[_ZW + j]
        t2 += tangent * pemc[_ZZW + j]
    g0, g1 = gas[i, 0], gas[i, 1]
    lin = g0 * (1.0 + eps) - g1 * kappa
    push = work * (1.0 + c1)
    for a in range(3):
        g[a] = stiffness[i, a, 0] * eps + stiffness[i, a, 1] * kappa + stiffness[i, a, 2] * c1
        for b in range(3):
            h[a, b] = stiffness[i, a, b]
    g[0] += sig_w - push * g0
    g[1] += -sig_zw + push * g1
    g[2] += -work * lin
    h[0, 0] += t0
    h[0, 1] -= t1
    h[1, 0] -= t1
    h[1, 1] += t2
    h[0, 2] -= work * g0
    h[2, 0] -= work * g0
    h[1, 2] += work * g1
    h[2, 1] += work * g1
