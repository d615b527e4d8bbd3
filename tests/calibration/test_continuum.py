"""The continuum correction's fit: its exact Jacobian and the stored values it reproduces."""

import json
import pathlib

import numpy as np
from numpy.testing import assert_allclose
import pytest
from scipy.optimize._numdiff import approx_derivative

from fpc_gripper.calibration import fit as calibration_fit
from fpc_gripper.calibration.continuum import (_CorrectionProblem, _SCALE, CalibrationStatus,
                                               fe_scenes, fit_correction)
from fpc_gripper.model.corrected import CONTINUUM_FIT, ContinuumCorrection

TABLE = pathlib.Path(__file__).resolve().parents[2] / 'bench' / 'results' / 'continuum.json'


@pytest.fixture(scope='module')
def scenes():
    return fe_scenes(json.loads(TABLE.read_text()))


@pytest.mark.parametrize('values', [(0.8, 1.4, 3.0, 0.02), (1.0, 1.0, 1.0, 0.0),
                                    (0.5, 2.5, 6.0, 0.05)])
def test_jacobian_against_finite_differences(scenes, values):
    # Every column exact: the factors' through engine.sensitivity, the compliance's the
    # shear move; against scipy's central difference of the residuals.
    problem = _CorrectionProblem(scenes, None)
    u = np.array(values) / _SCALE
    # Bounded at 0: one-sided in the compliance at the paper's physics (c = 0).
    expected = approx_derivative(problem.residuals, u, method='3-point', rel_step=1e-6,
                                 abs_step=1e-6, bounds=(0.0, np.inf))
    got = problem.jacobian(u)
    assert_allclose(got, expected, atol=1e-5 * np.abs(expected).max())
    assert np.all(np.abs(got).max(axis=0) > 0.0)


def test_fit_runs_the_calibrations_loop(scenes, monkeypatch):
    calls = []
    original = calibration_fit.least_squares

    def spy(*args, **kwargs):
        calls.append(kwargs)
        return original(*args, **kwargs)

    monkeypatch.setattr(calibration_fit, 'least_squares', spy)
    fit_correction(scenes, max_nfev=2)
    assert len(calls) == 1 and callable(calls[0]['jac']) and calls[0]['loss'] == 'linear'


def test_fit_from_the_paper_reproduces_the_stored_values(scenes):
    fit = fit_correction(scenes)
    assert fit.success and fit.status is CalibrationStatus.SUCCESS
    assert_allclose(fit.correction.values, CONTINUUM_FIT.values, rtol=0.02)
    # The FE tips are the table's (an independent 2-D FE): 0.19 mm at worst, from 2.6 mm.
    assert fit.errors.max() < 0.2e-3 < 2.4e-3 < fit.initial_errors.max()


def test_bad_max_nfev_is_refused(scenes):
    with pytest.raises(ValueError, match='max_nfev'):
        fit_correction(scenes, start=ContinuumCorrection(), max_nfev=0)
