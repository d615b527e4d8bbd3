"""choose_model against the continuum: the beam floor from the stored FE table, and refusals."""

import json
import pathlib

import numpy as np
import pytest

from fpc_gripper.calibration.continuum import correction_tips, fe_scenes
from fpc_gripper.model import ActuatorDesign, choose_model, Scene
from fpc_gripper.model.corrected import CONTINUUM_FIT
from fpc_gripper.model.reference import CONTINUUM_FLOOR, CORRECTED_FLOOR, rod_tolerance

TABLE = pathlib.Path(__file__).resolve().parents[2] / 'bench' / 'results' / 'continuum.json'
FIT = TABLE.with_name('continuum_fit.json')


def test_the_floor_is_the_stored_tables():
    rows = json.loads(TABLE.read_text())['table']['rows']
    unpressurised = [row for row in rows if row['pressure_kpa'] == 0.0]
    assert len(unpressurised) == 15 and all(row['success'] for row in unpressurised)
    worst = max(row['rungs']['rod']['error_mm'] for row in unpressurised) * 1e-3
    assert CONTINUUM_FLOOR == pytest.approx(worst, abs=1e-6)


def test_the_corrected_floor_is_the_stored_fits():
    stored = json.loads(FIT.read_text())['stored']
    assert stored['parameters'] == dict(zip(('band_stiffness', 'clamp_stiffness',
                                             'channel_end_stiffness', 'shear_compliance'),
                                            CONTINUUM_FIT.values.tolist()))
    assert CORRECTED_FLOOR == pytest.approx(stored['max_error_mm'] * 1e-3, abs=1e-6)
    # And the rung today: its tips against the table's FE tips (independent 2-D FE).
    scenes = fe_scenes(json.loads(TABLE.read_text()))
    errors = np.linalg.norm(correction_tips(CONTINUUM_FIT, scenes)
                            - np.array([s.tip for s in scenes]), axis=1)
    assert CORRECTED_FLOOR == pytest.approx(errors.max(), abs=1e-6)
    assert CORRECTED_FLOOR < 0.1 * CONTINUUM_FLOOR


@pytest.mark.parametrize('tolerance', [1e-3, CONTINUUM_FLOOR])
def test_between_the_floors_the_refusal_names_the_corrected_rung(tolerance):
    scene = Scene(ActuatorDesign.paper(prestrain=0.25), 0.0, (0.0, 0.0))
    with pytest.raises(ValueError, match="below the beam floor.*physics='continuum'.*meets it"):
        choose_model(scene, tolerance, reference='continuum')


def test_below_the_corrected_floor_nothing_is_offered():
    with pytest.raises(ValueError, match='even the continuum-corrected rung'):
        rod_tolerance(0.5 * CORRECTED_FLOOR, 'continuum', 0.0)


def test_the_rod_reference_leaves_the_tolerance_alone():
    assert rod_tolerance(5e-5, 'rod', 1e5) == 5e-5


@pytest.mark.parametrize('tolerance', [5e-5, 1e-3, CONTINUUM_FLOOR])
def test_a_tolerance_below_the_beam_floor_is_refused(tolerance):
    scene = Scene(ActuatorDesign.paper(prestrain=0.25), 0.0, (0.0, 0.0))
    with pytest.raises(ValueError, match='`tolerance`.*below the beam floor'):
        choose_model(scene, tolerance, reference='continuum')


def test_pressure_outside_the_continuum_reference_is_refused():
    scene = Scene(ActuatorDesign.paper(prestrain=0.25), 50e3, (0.0, 0.0))
    with pytest.raises(ValueError, match='`pressure`'):
        choose_model(scene, 1e-2, reference='continuum')


def test_unknown_reference_is_refused():
    scene = Scene(ActuatorDesign.paper(prestrain=0.25), 0.0, (0.0, 0.0))
    with pytest.raises(ValueError, match='`reference`'):
        choose_model(scene, 1e-2, reference='fe')


def test_above_the_floor_the_choice_meets_the_rest_against_the_rod():
    scene = Scene(ActuatorDesign.paper(prestrain=0.25), 0.0, (0.3, 0.0))
    tolerance = CONTINUUM_FLOOR + 1e-4
    choice = choose_model(scene, tolerance, reference='continuum')
    against_rod = choose_model(scene, 1e-4)
    assert (choice.rung, choice.n_segments) == (against_rod.rung, against_rod.n_segments)
    assert choice.predicted_error == pytest.approx(against_rod.predicted_error
                                                   + CONTINUUM_FLOOR)
    assert choice.predicted_error <= tolerance * (1 + 1e-12)
    assert 'continuum' in choice.reason and np.isfinite(choice.cost)
