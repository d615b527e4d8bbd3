"""SPEC's default PEMC law: source constants, the fit that produced them, the curve they fit."""

import pathlib

import numpy as np

from fpc_gripper.model import ActuatorDesign, default_emc_coefficients, fit_emc_polynomial
from fpc_gripper.model.section.materials import DEFAULT_EMC_COEFFICIENTS
from fpc_gripper.safe_yaml import parse_yaml

#: Planar-tension neo-Hookean reference of SPEC "Materials": mu = E1/4 with E1 = 1.5 MPa.
MU = 1.5e6 / 4.0
SHIPPED = pathlib.Path(__file__).resolve().parents[2] / 'msg_configs' / 'actuator_paper.yaml'


def neo_hookean(s):
    """Reference stress sigma = mu ((1 + s) - (1 + s)^-3) [Pa]."""
    return MU * ((1.0 + s) - (1.0 + s) ** -3)


def test_default_is_the_source_constant():
    assert default_emc_coefficients() is DEFAULT_EMC_COEFFICIENTS
    assert len(DEFAULT_EMC_COEFFICIENTS) == 4
    assert all(type(c) is float for c in DEFAULT_EMC_COEFFICIENTS)
    assert ActuatorDesign().emc_coefficients == DEFAULT_EMC_COEFFICIENTS  # passed through


def test_shipped_yaml_holds_the_same_constants():
    # Both are decimal literals of the same doubles (repr precision), so they must agree
    # exactly: this keeps the two written copies from drifting apart.
    coefficients = parse_yaml(SHIPPED.read_text())['emc_coefficients']
    assert tuple(coefficients) == DEFAULT_EMC_COEFFICIENTS


def test_constants_are_spec_fit_of_the_neo_hookean_curve():
    # SPEC's recipe: least-squares quartic without constant term on 121 evenly spaced
    # strains in [0, 0.6]. Different BLAS/LAPACK builds move the fit by ~1e-14 relative
    # (a1 differed by 1.7e-8 Pa of 1.1e6 Pa between two machines); rtol 1e-9 is far above
    # that round-off and far below any physical meaning (2e-3 Pa on a2).
    s = np.linspace(0.0, 0.6, 121)
    refit = fit_emc_polynomial(s, neo_hookean(s))
    np.testing.assert_allclose(DEFAULT_EMC_COEFFICIENTS, refit, rtol=1e-9, atol=0.0)


def test_constants_follow_the_neo_hookean_curve():
    # Independent of the fit: the quartic evaluated term by term on a grid 50 times finer
    # than the fit's stays within 500 Pa of the curve (0.1 % of its 0.51 MPa at s = 0.6;
    # the least-squares optimum reaches 343 Pa, near s = 0.6).
    a1, a2, a3, a4 = DEFAULT_EMC_COEFFICIENTS
    s = np.linspace(0.0, 0.6, 6001)
    quartic = a1 * s ** 4 + a2 * s ** 3 + a3 * s ** 2 + a4 * s
    deviation = np.abs(quartic - neo_hookean(s))
    assert deviation.max() < 500.0


def test_constants_match_spec_rounded_values():
    np.testing.assert_allclose(np.array(DEFAULT_EMC_COEFFICIENTS) / 1e6,
                               (-1.1052, 2.2207, -1.9992, 1.4856), rtol=0.0, atol=1e-4)
