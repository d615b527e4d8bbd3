"""ActuatorDesign validation, YAML round trips and the EMC fit."""

from helpers import assert_designs_close
import numpy as np
import pytest

from fpc_gripper.model import ActuatorDesign, fit_emc_polynomial, Material
from fpc_gripper.model.section.materials import emc_stress


def test_paper_design_matches_tables():
    d = ActuatorDesign.paper(prestrain=0.25)
    assert d.free_length == pytest.approx(0.090)
    assert d.channel_end == pytest.approx(0.085)
    ribs = d.transverse_ribs()
    assert ribs.shape == (10, 2)
    np.testing.assert_allclose(ribs[0], (0.006, 0.008))
    np.testing.assert_allclose(ribs[-1], (0.078, 0.080))
    # Table III through eq. (6).
    assert d.constraining_layer.Q11 == pytest.approx(263e6 / (1 - 0.43 ** 2))
    assert d.fluidic_layer.Q12 == pytest.approx(0.48 * 1.2e6 / (1 - 0.48 ** 2))
    # Exact: nu = 0.0 makes Q12 = 0 * E2 / 1 and Q22 = E2 / (1 - 0) without rounding.
    assert d.emc.Q12 == 0.0 and d.emc.Q22 == 170e6


def test_replace_returns_new_validated_design():
    d = ActuatorDesign.paper()
    wide = d.replace(Cy=0.028)
    assert wide.Cy == 0.028 and d.Cy == 0.026      # passed through unchanged: exact
    with pytest.raises(TypeError, match='unknown ActuatorDesign field'):
        d.replace(Cz=0.1)
    assert isinstance(d.replace(Cy=np.float64(0.027)).Cy, float)


@pytest.mark.parametrize('fields, message', [
    ({'h1': 0.005}, 'H/2 > h1'),
    ({'h2': 0.004}, 'h1'),
    ({'h3a': 0.002}, 'channel must lie inside the fluidic layer'),
    ({'h3b': 0.003}, 'channel must lie inside the fluidic layer'),
    ({'Cy': 0.020}, 'ribs do not fit the channel'),
    ({'Cy': 0.040}, '`Cy` must be < `Ly`'),
    ({'Lx': -0.1}, '`Lx` must be > 0'),
    ({'Lx': 1e30}, r'`Lx` must be in \[0.001, 2\] \[m\], got 1e\+30'),
    ({'w2': 1e-12, 't': 1e-12}, '`w2` gives a feature of 1e-12'),
    ({'w2': 5e-5, 't': 5e-5}, '`w2` and t = 5e-05 m give 850 ribs along the channel'),
    ({'max_pressure': 1e30}, r'`max_pressure` must be in \[1000, 2e\+06\] \[Pa\]'),
    ({'emc_coefficients': (1e308,) * 4}, r'`emc_coefficients\[0\]` must be in \[-1e\+10, 1e'),
    ({'fluidic_layer': Material(1.2e6, 1.2e6, 0.95)}, r'`fluidic_layer.nu` must be in \[-0.9'),
    ({'emc': Material(1.5e6, 1e30, 0.0)}, r'`emc.E2` must be in \[1000, 1e\+12\]'),
    ({'t': 0.0}, '`t` must be > 0'),
    ({'prestrain': 1.0}, '`prestrain` must be in'),
    ({'prestrain': -0.1}, '`prestrain` must be in'),
    ({'Cx': 0.015}, '`Cx` must be in'),
    ({'H': float('nan')}, '`H` must be finite'),
    ({'emc_coefficients': (1e6, 0, 0, -1e5)}, 'increases on'),
    ({'emc_coefficients': (1.0, 2.0)}, '4 numbers'),
    ({'pressure_work_factor': 0.0}, r'`pressure_work_factor` must be in \[0.1, 10\]'),
    ({'pressure_work_factor': float('inf')}, '`pressure_work_factor` must be finite'),
])
def test_invalid_designs_name_the_problem(fields, message):
    with pytest.raises(ValueError, match=message):
        ActuatorDesign.paper().replace(**fields)


def test_narrow_channel_is_valid_without_ribs():
    d = ActuatorDesign.paper().replace(Cy=0.020, ribs=False)
    assert d.transverse_ribs().shape == (0, 2)


def test_material_validation():
    with pytest.raises(ValueError, match='`nu` must be in'):
        Material(1e6, 1e6, 1.0)
    with pytest.raises(ValueError, match='> 0'):
        Material(-1e6, 1e6, 0.3)


def test_yaml_round_trip_is_exact(tmp_path):
    d = ActuatorDesign.paper(prestrain=0.37).replace(
        Cy=0.0271, fluidic_layer=Material(1.3e6, 1.3e6, 0.49), ribs=False,
        emc_coefficients=(-1.0e6, 2.1e6, -1.9e6, 1.5e6), pressure_work_factor=1.7)
    path = tmp_path / 'd.yaml'
    d.to_yaml(path)
    back = ActuatorDesign.from_yaml(path)
    # Exact by construction: to_yaml writes every float with repr, which reads back to the
    # same double; equal designs are what the solver caches key on.
    assert_designs_close(back, d, rtol=0.0)
    assert back == d


def test_yaml_errors_are_named(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('Lx: 0.11\nwidth: 0.03\n')
    with pytest.raises(ValueError, match="unknown key.*'width'"):
        ActuatorDesign.from_yaml(bad)
    bad.write_text('Lx: [0.11\n')
    with pytest.raises(ValueError, match='malformed YAML'):
        ActuatorDesign.from_yaml(bad)
    bad.write_text('- 1\n- 2\n')
    with pytest.raises(ValueError, match='expected a mapping'):
        ActuatorDesign.from_yaml(bad)
    bad.write_text('fluidic_layer: {E1: 1.0e6, E2: 1.0e6, nu: 0.4, G: 3}\n')
    with pytest.raises(ValueError, match="fluidic_layer: unknown key.*'G'"):
        ActuatorDesign.from_yaml(bad)


def test_shipped_actuator_yaml_is_the_paper_design():
    import pathlib
    path = pathlib.Path(__file__).resolve().parents[2] / 'msg_configs' / 'actuator_paper.yaml'
    assert_designs_close(ActuatorDesign.from_yaml(path), ActuatorDesign.paper(prestrain=0.25))


def test_fit_emc_polynomial_recovers_a_quartic():
    truth = (-0.9e6, 2.0e6, -1.8e6, 1.4e6)
    s = np.linspace(0, 0.7, 50)
    fitted = fit_emc_polynomial(s, emc_stress(truth, s))
    np.testing.assert_allclose(fitted, truth, rtol=1e-9)


def test_fit_emc_polynomial_rejects_bad_data():
    s = np.linspace(0, 0.5, 20)
    with pytest.raises(ValueError, match='equal lengths'):
        fit_emc_polynomial(s, s[:-1])
    with pytest.raises(ValueError, match='at least 4'):
        fit_emc_polynomial(s[:3], s[:3])
    with pytest.raises(ValueError, match='finite'):
        fit_emc_polynomial(s, np.where(s > 0.2, np.nan, s))
    with pytest.raises(ValueError, match='increases'):
        fit_emc_polynomial(s, -1e6 * s)


def test_yaml_reads_exponent_numbers_as_floats(tmp_path):
    path = tmp_path / 'e.yaml'
    path.write_text('constraining_layer: {E1: 263e6, E2: 263e6, nu: 0.43}\nLy: 3.175e-2\n')
    d = ActuatorDesign.from_yaml(path)
    # Exact: each is the double nearest to the decimal written, parsed like a literal.
    assert d.constraining_layer.E1 == 263e6 and d.Ly == 0.03175


@pytest.mark.parametrize('fields, name', [
    ({'Cy': 0.026 * (1 + 1e-10)}, 'design.Cy'),
    ({'emc_coefficients': (-1.1e6, 2.2e6, -2.0e6, 1.5e6)}, r'design.emc_coefficients\[0\]'),
    ({'fluidic_layer': Material(1.2e6, 1.2e6, 0.47)}, 'design.fluidic_layer.nu'),
    ({'ribs': False}, 'design.ribs'),
])
def test_design_comparison_names_the_field_that_differs(fields, name):
    d = ActuatorDesign.paper(prestrain=0.25)
    assert_designs_close(d.replace(Cy=0.026 * (1 + 1e-13)), d)     # round-off passes
    with pytest.raises(AssertionError, match=name):
        assert_designs_close(d.replace(**fields), d)
