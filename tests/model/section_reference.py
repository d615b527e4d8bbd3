"""Independent cross-section reference for tests: layer-by-layer quad and a BFGS minimiser."""

import numpy as np
from scipy.integrate import quad
from scipy.optimize import minimize


def quad_section(design, eps, kappa, c1, work, rib_width=0.0, channel=True):
    """Energy per unit length and (dW/deps, dW/dkappa, dW/dc1) by quad, layer by layer."""
    a1, a2, a3, a4 = design.emc_coefficients
    cl, fl, emc = design.constraining_layer, design.fluidic_layer, design.emc

    def e(z):
        return eps - z * kappa

    def linear(mat, width, z0, z1):
        def psi(z):
            return width * (0.5 * mat.Q11 * e(z) ** 2 + mat.Q12 * e(z) * c1
                            + 0.5 * mat.Q22 * c1 * c1)

        def sx(z):
            return width * (mat.Q11 * e(z) + mat.Q12 * c1)
        return np.array([quad(psi, z0, z1)[0], quad(sx, z0, z1)[0],
                         -quad(lambda z: z * sx(z), z0, z1)[0],
                         quad(lambda z: width * (mat.Q12 * e(z) + mat.Q22 * c1), z0, z1)[0]])

    def pemc():
        z0, z1 = -design.H / 2, -design.h3
        s0, w = design.prestrain, design.Ly

        def dens(z):
            s = s0 + e(z)
            return a1 * s ** 5 / 5 + a2 * s ** 4 / 4 + a3 * s ** 3 / 3 + a4 * s ** 2 / 2

        def sig(z):
            s = s0 + e(z)
            return a1 * s ** 4 + a2 * s ** 3 + a3 * s ** 2 + a4 * s
        return np.array([w * quad(dens, z0, z1)[0] + 0.5 * emc.Q22 * c1 * c1 * w * (z1 - z0),
                         w * quad(sig, z0, z1)[0], -w * quad(lambda z: z * sig(z), z0, z1)[0],
                         emc.Q22 * c1 * w * (z1 - z0)])

    total = (linear(cl, design.Ly, design.h1, design.H / 2)
             + linear(emc, design.Ly, design.h2, design.h1)
             + linear(fl, design.Ly, -design.h3, design.h2) + pemc())
    if channel:
        gas_width = design.Cy - rib_width
        z0, z1 = -design.h3b, design.h3a
        total -= linear(fl, gas_width, z0, z1)
        first = gas_width * quad(lambda z: 1.0 + e(z), z0, z1)[0]
        total += -work * np.array([(1 + c1) * first,
                                   (1 + c1) * gas_width * (z1 - z0),
                                   -(1 + c1) * gas_width * (z1 ** 2 - z0 ** 2) / 2, first])
    return total


def quad_minimiser(design, work):
    """Independent section minimiser: BFGS on the quad energy."""
    scale = np.array([1.0, 1.0 / design.H, 1.0])

    def fun(u):
        values = quad_section(design, *(u * scale), work)
        return values[0], values[1:] * scale

    res = minimize(fun, np.zeros(3), jac=True, method='BFGS', options={'gtol': 1e-13})
    res = minimize(fun, res.x, jac=True, method='BFGS', options={'gtol': 1e-14})
    return res.x * scale
