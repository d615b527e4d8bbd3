"""The compiled circle fit and CCM samples against their scipy and numpy references."""

import ccm_reference
import circle_reference
import numpy as np
import pytest
from scipy.optimize._numdiff import approx_derivative

from fpc_gripper.model import ActuatorDesign, batch, CCMSolver, fit_circle
from fpc_gripper.model.kernels import circle as circle_kernels
from fpc_gripper.model.pipeline import ModelSettings

#: Both fits stop at the orthogonal-distance minimum; MINPACK stops a little earlier
#: (its relative gradient seen up to 3e-10), which leaves up to 1.9e-8 relative in a
#: curvature near zero (1.4e-10 1/m absolute) and 6e-11 elsewhere.
CURVATURE_ATOL = 1e-9
CURVATURE_RTOL = 1e-9


def _scaled(points):
    centroid = points.mean(axis=0)
    scale = np.abs(points - centroid).max()
    x, z = ((points - centroid) / scale).T
    return np.ascontiguousarray(x), np.ascontiguousarray(z), x * x + z * z


def _finger_points():
    """Midplane samples of CCM8 and default-model fingers, flat to curled, loaded too."""
    designs = [ActuatorDesign.paper(e) for e in (0.15, 0.25, 0.40)]
    pressures = [0.0, 150e3, 317e3, 400e3]
    forces = [(0.0, 0.0), (0.3, -0.2)]
    out = []
    for settings in (ModelSettings(tolerance=0.0), ModelSettings()):
        grid = batch.solve_grid(designs, pressures, forces, settings, outputs='all')
        for index in np.ndindex(grid.shape):
            out.append((grid, index, grid.result(*index).points))
    return out


FINGERS = _finger_points()


@pytest.mark.parametrize('k', range(0, len(FINGERS), 3))
def test_compiled_fit_equals_scipy_reference_on_finger_shapes(k):
    _, _, points = FINGERS[k]
    fit = fit_circle(points)
    ref = circle_reference.fit_circle(points)
    assert fit.curvature == pytest.approx(ref.curvature, rel=CURVATURE_RTOL,
                                          abs=CURVATURE_ATOL)
    assert fit.rmsd == pytest.approx(ref.rmsd, rel=1e-9, abs=1e-15)
    if np.all(np.isfinite(ref.center)) and abs(ref.curvature) > 1.0:
        np.testing.assert_allclose(fit.center, ref.center, rtol=1e-8, atol=1e-10)


def test_compiled_fit_is_the_least_squares_minimum():
    # Independent of any reference fit: the gradient J^T r of the sum of squared
    # orthogonal distances (J by finite differences of the reference distances) vanishes
    # at the compiled fit's parameters, to round-off of J and r.
    for _, _, points in FINGERS[::5]:
        x, z, r2 = _scaled(points)
        start = circle_kernels._pratt(x, z, r2)
        params, cost = circle_kernels._levenberg_marquardt(
            np.array([start[0], start[3], np.arctan2(start[2], start[1])]), x, z, r2)
        dist = circle_reference._signed_distances(params, x, z, r2)
        jac = approx_derivative(lambda p: circle_reference._signed_distances(p, x, z, r2),
                                params, method='3-point', abs_step=1e-6)
        gradient = np.abs(jac.T @ dist).max()
        assert gradient < 1e-9 * np.linalg.norm(jac) * max(np.linalg.norm(dist), 1e-6)
        # The cost it reports is the sum of squared distances (at the last evaluated
        # parameters, within its final step of these).
        assert cost == pytest.approx(float(dist @ dist), rel=1e-9, abs=1e-30)


def test_pratt_start_matches_the_generalised_eigenproblem():
    from scipy.linalg import eig
    for _, _, points in FINGERS[::7]:
        x, z, r2 = _scaled(points)
        vec = circle_kernels._pratt(x, z, r2)
        design = np.column_stack([r2, x, z, np.ones_like(x)])
        values, vectors = eig(design.T @ design, circle_reference._PRATT)
        best = min((abs(v), w.real) for v, w in zip(values, vectors.T)
                   if np.isfinite(v) and w.real @ circle_reference._PRATT @ w.real > 0)[1]
        best = best / np.sqrt(best @ circle_reference._PRATT @ best)
        # The same circle up to the sign of (A, B, C, D).
        sign = np.sign(vec @ best)
        np.testing.assert_allclose(sign * vec, best, atol=1e-6)


@pytest.mark.parametrize('points', [
    np.stack([np.linspace(0.0, 0.09, 30), np.zeros(30)], axis=1),
    np.stack([np.linspace(0.0, 0.09, 30), 0.3 * np.linspace(0.0, 0.09, 30) + 0.01], axis=1),
], ids=['horizontal', 'sloped'])
def test_a_straight_line_is_a_regular_point(points):
    fit = fit_circle(points)
    assert abs(fit.curvature) < 1e-9
    assert fit.rmsd < 1e-12
    # The centre is at infinity, or as far as round-off in A leaves it.
    assert not np.all(np.abs(fit.center) < 1e6)


def test_fit_rejects_bad_points():
    with pytest.raises(ValueError, match='points'):
        fit_circle(np.zeros((2, 2)))
    with pytest.raises(ValueError, match='finite'):
        fit_circle([[0.0, 0.0], [1.0, np.nan], [2.0, 0.0]])
    # The batched kernel does not raise: a non-finite scene gets NaN.
    assert np.all(np.isnan(circle_kernels.circle_fit(np.full((5, 2), np.nan))))


@pytest.mark.parametrize('reconstruction', ['paper', 'consistent'])
def test_ccm_samples_equal_the_numpy_reference(reconstruction):
    solver = CCMSolver(ActuatorDesign.paper(0.40), 8, reconstruction=reconstruction)
    for pressure in (0.0, 250e3):
        result = solver.solve(pressure, (0.2, -0.3))
        ref_points, ref_tangent = ccm_reference.midplane_samples(
            result.state, solver.segments.lengths, 16)
        # The result's samples, computed in the solve's compiled call (`kernels.ccm.ccm_outputs`).
        np.testing.assert_allclose(result.points, ref_points, rtol=0, atol=1e-15)
        np.testing.assert_allclose(result.tangent, ref_tangent, rtol=0, atol=1e-14)


def test_batched_curvature_equals_every_scenes_result():
    # The sweep's column and a single result's `curvature` are the same quantity.
    for grid, index, _ in FINGERS:
        result = grid.result(*index)
        assert grid.curvature[index] == pytest.approx(result.curvature, rel=1e-12,
                                                      abs=1e-12)
        assert grid.fit_rmsd[index] == pytest.approx(result.fit_rmsd, rel=1e-12, abs=1e-18)
        assert grid.valid[index] == result.valid
