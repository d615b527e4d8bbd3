"""Independent check: uniform segments equal the minimiser of the cross-section energy."""

import numpy as np
import pytest
from section_reference import quad_minimiser

from fpc_gripper.model import ActuatorDesign, CCMSolver, PRESSURE_MODELS


@pytest.mark.parametrize('prestrain, pressure, model', [
    (0.15, 0.0, 'adiabatic'), (0.40, 0.0, 'adiabatic'), (0.25, 150e3, 'adiabatic'),
    (0.25, 150e3, 'isobaric')])
def test_uniform_segments_equal_section_minimiser(prestrain, pressure, model):
    design = ActuatorDesign.paper(prestrain).replace(ribs=False, Cx=0.110)
    result = CCMSolver(design, n_segments=32, pressure_model=model).solve(pressure)
    assert result.success, result.message
    eps, kappa, c = quad_minimiser(design, PRESSURE_MODELS[model] * pressure)
    middle = result.coefficients[12:20]
    np.testing.assert_allclose(middle[:, 0], eps, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(2.0 * middle[:, 3], kappa, rtol=1e-6)
    np.testing.assert_allclose(middle[:, 2], c, rtol=1e-6, atol=1e-10)
    # The uniform state has b3 = -2 d^2 / 3: the axial strain is constant along x.
    np.testing.assert_allclose(middle[:, 1], -2.0 * middle[:, 3] ** 2 / 3.0, rtol=1e-6)
