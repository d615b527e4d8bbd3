"""The continuum rung on the paper's finger: issue 24's check, the rod's interior, its inputs."""

import sys

import numpy as np
from numpy.testing import assert_allclose
import pytest

from fpc_gripper.model import ActuatorDesign, RodSolver
from fpc_gripper.model.analysis import fit_circle

pytest.importorskip('skfem')

from fpc_gripper.model.continuum import ContinuumSolver  # noqa: E402, I100

#: Issue 24's FE, prestrain 0.25, unloaded: the tip at the midplane [m].
ISSUE_CHECK = {'average': (37.89e-3, -58.50e-3), 'exact': (36.81e-3, -58.69e-3)}
#: The suite's mesh: 2 mm elements (bench_continuum: within 0.03 mm of 0.5 mm elements).
COARSE = 2e-3


@pytest.fixture(scope='module')
def unloaded():
    """Solve the default finger unloaded with smeared and with discrete ribs, once."""
    design = ActuatorDesign.paper(prestrain=0.25)
    return {ribs: ContinuumSolver(design, ribs=ribs, element_size=COARSE).solve()
            for ribs in ISSUE_CHECK}


@pytest.mark.parametrize('ribs', sorted(ISSUE_CHECK))
def test_unloaded_tip_agrees_with_the_issue_check(unloaded, ribs):
    result = unloaded[ribs]
    assert result.success, result.message
    assert result.rung == 'continuum' and result.valid
    assert np.hypot(*(result.tip - ISSUE_CHECK[ribs])) < 0.3e-3


def test_interior_curvature_is_the_rods(unloaded):
    # Away from the clamp and the channel end plane sections hold, and the law gives every
    # fibre the section law's energy: the interior curls as the rod does.
    rod = RodSolver(ActuatorDesign.paper(prestrain=0.25), ribs='average').solve()
    s = np.linspace(0.010, 0.070, 61)
    fe = fit_circle(unloaded['average'].position_at(s)).curvature
    assert_allclose(fe, fit_circle(rod.position_at(s)).curvature, rtol=2e-3)


def test_the_end_zones_make_the_difference_to_the_rod(unloaded):
    # The clamp's shear and Saint-Venant zone and the solid tip: the FE's tip is off the
    # rod's by more than its interior curvature accounts for, in the direction of less curl.
    rod = RodSolver(ActuatorDesign.paper(prestrain=0.25), ribs='average').solve()
    gap = np.hypot(*(unloaded['average'].tip - rod.tip))
    assert 0.1e-3 < gap < 1e-3


def test_result_fields(unloaded):
    result = unloaded['exact']
    assert result.points.shape[1] == 2 and result.points[0] == pytest.approx((0.0, 0.0))
    assert_allclose(result.points[-1], result.tip, atol=1e-12)
    assert_allclose(result.position_at(result.segment_edges), result.nodes)
    assert result.curvature > 0.0 and result.fraction == 1.0


@pytest.mark.parametrize('kwargs, match', [
    ({'element_size': -1e-3}, 'element_size'),
    ({'element_size': 0.02}, 'element_size'),
    ({'ribs': 'some'}, 'ribs'),
    ({'pressure_model': 'adiabatc'}, 'pressure_model'),
    ({'gas_model': 'volume'}, 'gas_model'),
])
def test_bad_construction_is_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ContinuumSolver(ActuatorDesign.paper(), **{'element_size': 5e-3, **kwargs})


@pytest.mark.parametrize('kwargs, match', [
    ({'pressure': -1.0}, 'pressure'),
    ({'pressure': 1e6}, 'pressure'),
    ({'tip_force': (0.0,)}, 'tip_force'),
    ({'tip_force': (np.nan, 0.0)}, r'tip_force\[0\]'),
])
def test_bad_loads_are_refused(kwargs, match):
    solver = ContinuumSolver(ActuatorDesign.paper(), element_size=5e-3)
    with pytest.raises(ValueError, match=match):
        solver.solve(**kwargs)


def test_without_scikit_fem_the_package_imports_and_the_solver_says_what_is_missing(
        monkeypatch):
    import fpc_gripper.model.continuum as continuum
    for name in [m for m in sys.modules if m == 'skfem' or m.startswith('skfem.')]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, 'skfem', None)
    with pytest.raises(ImportError, match='scikit-fem'):
        continuum.require_skfem()
    assert 'ContinuumSolver' not in vars(continuum)     # resolved at each use (PEP 562)
    with pytest.raises(ImportError, match=r'fpc_gripper\[continuum\]'):
        continuum.ContinuumSolver
