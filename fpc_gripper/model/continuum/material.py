"""Plane-strain hyperelastic law in the Biot strain U - I, with its exact stress and tangent."""

from dataclasses import dataclass

import numpy as np

__all__ = ['BiotMaterial', 'linear_material', 'pemc_material', 'biot_response',
           'volume_response', 'stretch_response']

# (a, b, d1, d2) = T (F11, F12, F21, F22): a = tr F, b = F21 - F12 carry the rotation,
# d1 = F11 - F22, d2 = F21 + F12 the deviatoric part.
_T = np.array([[1.0, 0.0, 0.0, 1.0],
               [0.0, -1.0, 1.0, 0.0],
               [1.0, 0.0, 0.0, -1.0],
               [0.0, 1.0, 1.0, 0.0]])
# (U11, U22, U12) = L (r, q1, q2).
_L = np.array([[0.5, 0.5, 0.0],
               [0.5, -0.5, 0.0],
               [0.0, 0.0, 0.5]])


@dataclass(frozen=True)
class BiotMaterial:
    """
    A plane-strain law psi(e) of the Biot strain e = U - I, per unit reference volume.

        psi = sum_k c_k s^k + mu_z e22^2 + 2 mu e12^2 + lam/2 (s + e22)^2,  s = e11 - eigenstrain,

    k = 2..5, axis 1 the finger's X (the fibre direction of the PEMC law), axis 2 its Z.
    A linear isotropic layer (Lame mu, lam) has c2 = mu and no higher terms, so that
    psi = mu e:e + lam/2 (tr e)^2 of the mechanical strain; under sigma_zz = 0 it carries
    the reduced stiffness E/(1 - nu^2) = Q11 along X (eq. 6 with eps_y = 0). The Biot
    strain of a fibre along X is its stretch minus one: in pure bending e11 = eps - z k,
    the section law's strain (docs/physics.md, section 11.2).

    Attributes
    ----------
    coefficients : tuple of float
        (c2, c3, c4, c5) [Pa].
    mu, lam : float
        [Pa].
    eigenstrain : float
        Stress-free strain along X [-]; the PEMC's is -prestrain.
    mu_z : float, optional
        Coefficient of e22^2 [Pa]; None (every lamina) is mu. An effective law sets it
        apart from the shear modulus: the side view's channel band, whose through-thickness
        stiffness is the channel cross-section's (`section.ChannelSection`).

    """

    coefficients: tuple
    mu: float
    lam: float
    eigenstrain: float = 0.0
    mu_z: float = None

    @property
    def params(self):
        """(c2, c3, c4, c5, mu, lam, eigenstrain, mu_z) as `biot_response` takes them."""
        mu_z = self.mu if self.mu_z is None else self.mu_z
        return np.array([*self.coefficients, self.mu, self.lam, self.eigenstrain, mu_z])


def linear_material(material, eigenstrain=0.0, poisson=True):
    """
    Return the plane-strain law of a lamina with (E1, nu), isotropic in the X-Z plane.

    Parameters
    ----------
    material : section.materials.Material
        E1 along X [Pa] (taken for Z too: the EMC's fibres run along Y) and nu [-].
    eigenstrain : float
        Stress-free strain along X [-].
    poisson : bool
        True: the isotropic plane-strain law, mu e:e + lam/2 (tr e)^2 (a layer stretched
        along X thins by nu/(1 - nu) of its stretch). False: no X-Z Poisson coupling,
        Q11/2 e11^2 + mu (e22^2 + 2 e12^2) with the shear modulus mu = E1/(2 (1 + nu)):
        a fibre along X carries exactly the section law's Q11 e^2/2 whatever its
        neighbours do, and layers keep their thickness in pure bending.

    """
    e, nu = material.E1, material.nu
    mu = e / (2.0 * (1.0 + nu))
    if not poisson:
        return BiotMaterial((0.5 * material.Q11, 0.0, 0.0, 0.0), mu, 0.0, float(eigenstrain))
    lam = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    return BiotMaterial((mu, 0.0, 0.0, 0.0), mu, lam, float(eigenstrain))


def pemc_material(emc_coefficients, prestrain):
    """
    Return the PEMC law: F(prestrain + e11) along X, and E = a4, nu = 0 across it.

    F is the project's energy density with F' = sigma = a1 s^4 + ... + a4 s (eq. 7 with
    SPEC's sign), so the stress along X is the project's; across X the layer is linear
    with the law's modulus at zero strain a4 and no Poisson coupling (as the EMC's nu = 0).

    Parameters
    ----------
    emc_coefficients : tuple of float
        (a1, a2, a3, a4) [Pa].
    prestrain : float
        eps0 [-].

    """
    a1, a2, a3, a4 = (float(c) for c in emc_coefficients)
    return BiotMaterial((a4 / 2.0, a3 / 3.0, a2 / 4.0, a1 / 5.0), a4 / 2.0, 0.0,
                        -float(prestrain))


def _law(params, e11, e22, e12):
    """Return psi, its gradient (3, ...) and Hessian (3, 3, ...) in (e11, e22, e12)."""
    c2, c3, c4, c5, mu, lam, eig = params[:7]
    # Seven parameters: mu_z is mu (every lamina's law).
    mu_z = params[7] if len(params) > 7 else mu
    s = e11 - eig
    tr = s + e22
    psi = s * s * (c2 + s * (c3 + s * (c4 + s * c5))) + mu_z * e22 * e22 \
        + 2.0 * mu * e12 * e12 + 0.5 * lam * tr * tr
    d1 = s * (2.0 * c2 + s * (3.0 * c3 + s * (4.0 * c4 + s * 5.0 * c5)))
    d2 = 2.0 * c2 + s * (6.0 * c3 + s * (12.0 * c4 + s * 20.0 * c5))
    zero = np.zeros_like(s)
    grad = np.stack([d1 + lam * tr, 2.0 * mu_z * e22 + lam * tr, 4.0 * mu * e12])
    hess = np.stack([np.stack([d2 + lam, lam + zero, zero]),
                     np.stack([lam + zero, 2.0 * mu_z + lam + zero, zero]),
                     np.stack([zero, zero, 4.0 * mu + zero])])
    return psi, grad, hess


def biot_response(grad_u, params):
    """
    Energy density, first Piola-Kirchhoff stress and tangent of the Biot law at F = I + grad u.

    In 2-D the polar decomposition is closed-form: with (a, b, d1, d2) = (F11 + F22,
    F21 - F12, F11 - F22, F21 + F12), r = |(a, b)|, n = (a, b)/r, t = (-b, a)/r,
    tr U = r, U11 - U22 = n.d and 2 U12 = t.d with d = (d1, d2). Those three are smooth
    wherever r > 0 (any rotation angle), and their first and second derivatives are
    written out below, so that the stress and the tangent are exact.

    Parameters
    ----------
    grad_u : ndarray, shape (2, 2, ...)
        Displacement gradient d u_i / d X_J [-].
    params : ndarray, shape (7, ...) or (8, ...)
        (c2, c3, c4, c5, mu, lam, eigenstrain[, mu_z]) broadcast against grad_u[0, 0]
        (`BiotMaterial.params`; without mu_z it is mu).

    Returns
    -------
    psi : ndarray, shape (...)
        [J/m^3].
    stress : ndarray, shape (2, 2, ...)
        P_iJ = d psi / d F_iJ [Pa].
    tangent : ndarray, shape (2, 2, 2, 2, ...)
        d^2 psi / d F_iJ d F_kL [Pa].

    """
    f = np.stack([1.0 + grad_u[0, 0], grad_u[0, 1], grad_u[1, 0], 1.0 + grad_u[1, 1]])
    a, b, d1, d2 = np.einsum('pf,f...->p...', _T, f)
    r = np.hypot(a, b)
    n = np.stack([a, b]) / r
    t = np.stack([-b, a]) / r
    d = np.stack([d1, d2])
    q1 = np.einsum('i...,i...->...', n, d)
    q2 = np.einsum('i...,i...->...', t, d)
    shape = r.shape
    zero2 = np.zeros((2,) + shape)
    # Jacobian of v = (r, q1, q2) in p = (a, b, d1, d2).
    jac = np.stack([np.concatenate([n, zero2]),
                    np.concatenate([q2 * t / r, n]),
                    np.concatenate([-q1 * t / r, t])])
    tt = np.einsum('i...,j...->ij...', t, t) / r
    tn = np.einsum('i...,j...->ij...', t, n) / r
    sym = tn + tn.swapaxes(0, 1)
    hv = np.zeros((3, 4, 4) + shape)
    hv[0, :2, :2] = tt
    hv[1, :2, :2] = -(q1 * tt + q2 * sym) / r
    hv[1, :2, 2:] = tt
    hv[1, 2:, :2] = tt
    hv[2, :2, :2] = (-q2 * tt + q1 * sym) / r
    hv[2, :2, 2:] = -tn
    hv[2, 2:, :2] = -tn.swapaxes(0, 1)

    e11 = 0.5 * (r + q1) - 1.0
    e22 = 0.5 * (r - q1) - 1.0
    e12 = 0.5 * q2
    psi, g_e, h_e = _law(params, e11, e22, e12)
    g_v = np.einsum('uv,u...->v...', _L, g_e)
    h_v = np.einsum('uv,uw...,wx->vx...', _L, h_e, _L)
    g_p = np.einsum('vp...,v...->p...', jac, g_v)
    h_p = np.einsum('vp...,vw...,wq...->pq...', jac, h_v, jac) \
        + np.einsum('v...,vpq...->pq...', g_v, hv)
    g_f = np.einsum('pf,p...->f...', _T, g_p)
    h_f = np.einsum('pf,pq...,qg->fg...', _T, h_p, _T)
    return psi, g_f.reshape((2, 2) + shape), h_f.reshape((2, 2, 2, 2) + shape)


def volume_response(grad_u):
    """
    Area ratio J = det F of the X-Z plane with its first and second derivatives in F.

    Returns
    -------
    j : ndarray, shape (...)
    cofactor : ndarray, shape (2, 2, ...)
        d J / d F (the cofactor of F).
    second : ndarray, shape (2, 2, 2, 2)
        d^2 J / d F_iJ d F_kL = e_ik e_JL (constant).

    """
    f11, f12 = 1.0 + grad_u[0, 0], grad_u[0, 1]
    f21, f22 = grad_u[1, 0], 1.0 + grad_u[1, 1]
    j = f11 * f22 - f12 * f21
    cof = np.stack([np.stack([f22, -f21]), np.stack([-f12, f11])])
    eps = np.array([[0.0, 1.0], [-1.0, 0.0]])
    return j, cof, np.einsum('ik,jl->ijkl', eps, eps)


def stretch_response(grad_u):
    """
    Stretch lambda = |F e_X| of a fibre along X with its first and second derivatives in F.

    The beam rungs' gas volume per unit reference volume, (1 + e) with e the fibre's
    strain (the section law's (1 + c1) is 1 in plane strain).

    Returns
    -------
    stretch : ndarray, shape (...)
    first : ndarray, shape (2, 2, ...)
        d lambda / d F (only the X column is non-zero).
    second : ndarray, shape (2, 2, 2, 2, ...)
        d^2 lambda / d F_iJ d F_kL.

    """
    column = np.stack([1.0 + grad_u[0, 0], grad_u[1, 0]])
    stretch = np.hypot(column[0], column[1])
    n = column / stretch
    first = np.zeros((2, 2) + stretch.shape)
    first[:, 0] = n
    second = np.zeros((2, 2, 2, 2) + stretch.shape)
    second[:, 0, :, 0] = (np.eye(2).reshape((2, 2) + (1,) * stretch.ndim)
                          - np.einsum('i...,k...->ik...', n, n)) / stretch
    return stretch, first, second
