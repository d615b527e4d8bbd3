"""Inverse design: reachable targets met, unreachable ones reported with the best margin."""

import numpy as np
import pytest

from fpc_gripper.design import optimize, Targets
from fpc_gripper.design.inverse import write_outputs
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.model import ActuatorDesign, CCMSolver

#: gripper_paper.yaml's palm radius [m].
PALM = 0.062
BUDGET = 200e3


def _aperture(design, pressure):
    """Independent: the paper CCM8 solved alone, aperture 2 (R + Z_tip) [m]."""
    result = CCMSolver(design, 8).solve(pressure)
    assert result.success
    return 2.0 * (PALM + result.tip[1])


def _grasp_force(design, aperture):
    gap = aperture / 2.0 - PALM - CCMSolver(design, 8).solve(0.0).tip[1]
    return CCMSolver(design, 8).rigidity(0.0, 'z', gap).force


@pytest.fixture(scope='module')
def reachable(tmp_path_factory):
    # Targets the paper finger (0.25) just misses, that a nearby design meets.
    paper = ActuatorDesign.paper(0.25)
    targets = Targets(closed_aperture=_aperture(paper, 0.0) + 0.004,
                      open_aperture=_aperture(paper, BUDGET) + 0.004,
                      pressure_budget=BUDGET,
                      tip_force=0.9 * _grasp_force(paper, 0.030), at_aperture=0.030)
    result = optimize(targets, ('prestrain', 'h3a'), model='paper', maxiter=3, popsize=5,
                      seed=1)
    out = tmp_path_factory.mktemp('optimize')
    return targets, result, write_outputs(result, out), out


def test_reachable_targets_are_met(reachable):
    targets, result, _, _ = reachable
    assert result.success and result.status == 'met', result.report()
    design = result.design
    # Every margin, recomputed by single solves of the returned design.
    grid = np.linspace(0.0, BUDGET, 21)
    assert _aperture(design, 0.0) <= targets.closed_aperture
    assert max(_aperture(design, p) for p in grid) >= targets.open_aperture
    assert _grasp_force(design, targets.at_aperture) >= targets.tip_force
    margins = result.margins.set_index('target')
    assert margins.loc['closed_aperture', 'value'] == pytest.approx(_aperture(design, 0.0),
                                                                    abs=1e-12)
    assert margins.loc['tip_force', 'value'] == pytest.approx(
        _grasp_force(design, targets.at_aperture), rel=1e-9)
    assert (margins['margin'] >= 0.0).all() and margins['met'].all()


def test_outputs_load_as_model_node_loads_them(reachable):
    _, result, files, out = reachable
    names = {f.name for f in files}
    assert {'actuator.yaml', 'gripper.yaml', 'margins.csv', 'pareto.csv',
            'pareto.png'} <= names
    assert ActuatorDesign.from_yaml(out / 'actuator.yaml') == result.design
    config = load_gripper_config(out / 'gripper.yaml')
    assert config.palm_radius == PALM and len(config.fingers) == 3
    assert all(f.design == result.design for f in config.fingers)


def test_pareto_points_are_not_dominated(reachable):
    pareto = reachable[1].pareto
    assert len(pareto) > 0
    s, p, k = (pareto[c].to_numpy() for c in ('stroke_m', 'pressure_budget_pa',
                                              'kx_closed_nm2'))
    for i in range(len(pareto)):
        dominates = (s >= s[i]) & (p <= p[i]) & (k >= k[i]) & \
            ((s > s[i]) | (p < p[i]) | (k > k[i]))
        assert not dominates.any()


def test_unreachable_targets_are_reported_with_the_best_margin():
    # A 0.5 m aperture on 50 kPa: beyond any finger of the search box.
    targets = Targets(open_aperture=0.5, pressure_budget=50e3, max_strain=0.6)
    result = optimize(targets, ('prestrain', 'Cy'), model='paper', maxiter=3, popsize=4,
                      polish=False)
    assert not result.success and result.status == 'unreachable'
    margins = result.margins.set_index('target')
    assert not margins.loc['open_aperture', 'met'] and margins.loc['max_strain', 'met']
    # The reported margin is the returned design's, recomputed alone ...
    best = max(_aperture(result.design, p) for p in np.linspace(0.0, 50e3, 21))
    assert margins.loc['open_aperture', 'margin'] == pytest.approx(best - 0.5, abs=1e-12)
    # ... and no evaluated candidate did better on the worst relative margin.
    worst = margins['relative_margin'].min()
    assert worst == pytest.approx(result.history['worst_relative_margin'].max(), abs=1e-12)
    assert 'open_aperture not reached' in result.message


def test_bad_targets():
    with pytest.raises(ValueError, match='at_aperture'):
        Targets(kx=1e-3)
    with pytest.raises(ValueError, match='at least one target'):
        Targets()
    with pytest.raises(ValueError, match='pressure_budget'):
        Targets(open_aperture=0.1, pressure_budget=-1.0)
    with pytest.raises(ValueError, match='parameters'):
        optimize(Targets(open_aperture=0.1), ('Lx',))
