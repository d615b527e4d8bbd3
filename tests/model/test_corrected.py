"""The continuum-corrected fast rung against the stored FE table, its parameters and its fit."""

import json
import pathlib

import numpy as np
from numpy.testing import assert_allclose
import pytest

from fpc_gripper.calibration.continuum import correction_tips, fe_scenes, fit_correction
from fpc_gripper.model import ActuatorDesign
from fpc_gripper.model.corrected import (CONTINUUM_FIT, ContinuumCorrection, CorrectedSolver,
                                         PAPER_PHYSICS, shear_displacements)
from fpc_gripper.model.discretisations.pcc import PCCSolver
from fpc_gripper.model.pipeline import finger_model, ModelSettings

TABLE = pathlib.Path(__file__).resolve().parents[2] / 'bench' / 'results' / 'continuum.json'
#: Largest tip distance to the FE the stored correction reaches on the unpressurised
#: scenes (0.188 mm, bench/results/continuum_fit.json), with a margin [m].
TOLERANCE = 0.2e-3


@pytest.fixture(scope='module')
def scenes():
    return fe_scenes(json.loads(TABLE.read_text()))


def test_table_scenes_are_the_unpressurised_fifteen(scenes):
    assert len(scenes) == 15
    assert sorted({s.prestrain for s in scenes}) == [0.15, 0.25, 0.40]


def test_corrected_rung_meets_the_fe(scenes):
    # The FE tips are the table's (an independent 2-D FE), not this model's output.
    tips = correction_tips(CONTINUUM_FIT, scenes)
    errors = np.linalg.norm(tips - np.array([s.tip for s in scenes]), axis=1)
    assert errors.max() < TOLERANCE


def test_paper_physics_keeps_the_beam_floor(scenes):
    # Without the correction the rung is the paper's PCC: 2.6 mm off at worst, as the rod.
    errors = np.linalg.norm(correction_tips(PAPER_PHYSICS, scenes)
                            - np.array([s.tip for s in scenes]), axis=1)
    assert 2.4e-3 < errors.max() < 2.8e-3


def test_paper_physics_is_the_pcc():
    design = ActuatorDesign.paper(prestrain=0.4)
    tip = CorrectedSolver(design, PAPER_PHYSICS).solve(0.0, (0.2, -0.3)).tip
    assert_allclose(tip, PCCSolver(design, 32).solve(0.0, (0.2, -0.3)).tip, atol=2e-6)


def test_off_by_default():
    design = ActuatorDesign.paper()
    assert ModelSettings().physics == 'paper'
    assert not isinstance(finger_model(design), CorrectedSolver)
    assert isinstance(finger_model(design, ModelSettings(physics='continuum')),
                      CorrectedSolver)
    with pytest.raises(ValueError, match='physics'):
        ModelSettings(physics='fe')


@pytest.mark.parametrize('field, value', [('band_stiffness', 0.0), ('clamp_stiffness', 50.0),
                                          ('channel_end_stiffness', float('nan')),
                                          ('shear_compliance', -0.01)])
def test_bounds_refused(field, value):
    with pytest.raises(ValueError, match=field):
        ContinuumCorrection(**{field: value})


def test_parameters_mean_what_they_say():
    # A softer band curls the finger more; a stiffer clamp zone less; shear compliance
    # moves a loaded tip along the force.
    design = ActuatorDesign.paper()

    def tip(**fields):
        return CorrectedSolver(design, ContinuumCorrection(**fields)).solve(
            0.0, (0.0, -0.5)).tip

    def curl(**fields):
        return CorrectedSolver(design, ContinuumCorrection(**fields)).solve().curvature

    assert curl(band_stiffness=0.7) > curl() > curl(clamp_stiffness=2.0)
    moved = tip(shear_compliance=0.02) - tip()
    assert moved[1] < 0.0


def test_shear_displacement_against_quadrature():
    theta = np.array([-0.3, -0.7, -1.6])
    lengths = np.array([0.02, 0.03, 0.04])
    force = np.array([0.3, -0.4])
    s = np.linspace(0.0, lengths.sum(), 40001)
    edges = np.concatenate([[0.0], np.cumsum(lengths)])
    seg = np.clip(np.searchsorted(edges, s, side='right') - 1, 0, 2)
    start = np.concatenate([[0.0], theta[:-1]])
    phi = start[seg] + (theta[seg] - start[seg]) * (s - edges[seg]) / lengths[seg]
    normal = np.stack([-np.sin(phi), np.cos(phi)], axis=1)
    expected = np.trapezoid((normal @ force)[:, None] * normal, s, axis=0)
    got = shear_displacements(theta, lengths, [2], [lengths[2]], force, 1.0)[0]
    assert_allclose(got, expected, rtol=1e-7)


def test_fit_from_the_paper_reproduces_the_stored_values(scenes):
    fit = fit_correction(scenes)
    assert fit.success
    assert_allclose(fit.correction.values, CONTINUUM_FIT.values, rtol=0.02)
    assert fit.errors.max() < TOLERANCE
