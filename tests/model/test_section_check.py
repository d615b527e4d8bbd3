"""Independent check: uniform segments equal the minimiser of the cross-section energy."""

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import minimize

from fpc_gripper.model import ActuatorDesign, CCMSolver, PRESSURE_MODELS


def section_energy(design, eps, kappa, c, pressure, k_p):
    """Energy per unit length and its gradient, integrated layer by layer with quad."""
    a1, a2, a3, a4 = design.emc_coefficients
    cl, fl, emc = design.constraining_layer, design.fluidic_layer, design.emc

    def e(z):
        return eps - z * kappa

    def linear(mat, width, z0, z1):
        def psi(z):
            return width * (0.5 * mat.Q11 * e(z) ** 2 + mat.Q12 * e(z) * c
                            + 0.5 * mat.Q22 * c * c)

        def sx(z):
            return width * (mat.Q11 * e(z) + mat.Q12 * c)

        def sy(z):
            return width * (mat.Q12 * e(z) + mat.Q22 * c)
        return np.array([quad(psi, z0, z1)[0], quad(sx, z0, z1)[0],
                         -quad(lambda z: z * sx(z), z0, z1)[0], quad(sy, z0, z1)[0]])

    def pemc():
        z0, z1 = -design.H / 2, -design.h3
        s0 = design.prestrain

        def dens(z):
            s = s0 + e(z)
            return a1 * s ** 5 / 5 + a2 * s ** 4 / 4 + a3 * s ** 3 / 3 + a4 * s ** 2 / 2

        def sig(z):
            s = s0 + e(z)
            return a1 * s ** 4 + a2 * s ** 3 + a3 * s ** 2 + a4 * s
        w = design.Ly
        return np.array([
            w * quad(dens, z0, z1)[0] + 0.5 * emc.Q22 * c * c * w * (z1 - z0),
            w * quad(sig, z0, z1)[0],
            -w * quad(lambda z: z * sig(z), z0, z1)[0],
            emc.Q22 * c * w * (z1 - z0)])

    total = (linear(cl, design.Ly, design.h1, design.H / 2)
             + linear(emc, design.Ly, design.h2, design.h1)
             + linear(fl, design.Ly, -design.h3, design.h2)
             - linear(fl, design.Cy, -design.h3b, design.h3a)
             + pemc())
    # Pressure work per unit length: -k_p P (1 + c) * integral of (1 + e) over the channel.
    z0, z1 = -design.h3b, design.h3a
    area = design.Cy * (z1 - z0)
    first = design.Cy * ((1 + eps) * (z1 - z0) - kappa * (z1 ** 2 - z0 ** 2) / 2)
    cp = k_p * pressure
    total += np.array([-cp * (1 + c) * first, -cp * (1 + c) * area,
                       cp * (1 + c) * design.Cy * (z1 ** 2 - z0 ** 2) / 2, -cp * first])
    return total


def section_minimiser(design, pressure, k_p):
    scale = np.array([1.0, 1.0 / design.H, 1.0])

    def fun(u):
        eps, kappa, c = u * scale
        values = section_energy(design, eps, kappa, c, pressure, k_p)
        return values[0], values[1:] * scale

    res = minimize(fun, np.zeros(3), jac=True, method='BFGS',
                   options={'gtol': 1e-13, 'maxiter': 2000})
    res = minimize(fun, res.x, jac=True, method='BFGS',
                   options={'gtol': 1e-14, 'maxiter': 2000})
    return res.x * scale


@pytest.mark.parametrize('prestrain, pressure, model', [
    (0.15, 0.0, 'adiabatic'), (0.40, 0.0, 'adiabatic'), (0.25, 150e3, 'adiabatic'),
    (0.25, 150e3, 'isobaric')])
def test_uniform_segments_equal_section_minimiser(prestrain, pressure, model):
    design = ActuatorDesign.paper(prestrain).replace(ribs=False, Cx=0.110)
    result = CCMSolver(design, n_segments=32, pressure_model=model).solve(pressure)
    assert result.success, result.message
    eps, kappa, c = section_minimiser(design, pressure, PRESSURE_MODELS[model])
    middle = result.coefficients[12:20]
    np.testing.assert_allclose(middle[:, 0], eps, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(2.0 * middle[:, 3], kappa, rtol=1e-6)
    np.testing.assert_allclose(middle[:, 2], c, rtol=1e-6, atol=1e-10)
    # The uniform state has b3 = -2 d^2 / 3: the axial strain is constant along x.
    np.testing.assert_allclose(middle[:, 1], -2.0 * middle[:, 3] ** 2 / 3.0, rtol=1e-6)
