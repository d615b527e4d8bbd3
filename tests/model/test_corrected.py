"""The continuum-corrected fast rung against the stored FE table, its parameters and its fit."""

import json
import pathlib

import numpy as np
from numpy.testing import assert_allclose
import pytest
from scipy.optimize import least_squares

from fpc_gripper.calibration.continuum import correction_tips, fe_scenes
from fpc_gripper.model import ActuatorDesign, batch, engine
from fpc_gripper.model.corrected import (_moment_rates, CONTINUUM_FIT, ContinuumCorrection,
                                         CorrectedSolver, PAPER_PHYSICS, PARAMETERS,
                                         shear_displacements)
from fpc_gripper.model.discretisations.pcc import PCCSolver
from fpc_gripper.model.kernels.shear import shear_moves
from fpc_gripper.model.pipeline import finger_model, ModelSettings
from fpc_gripper.model.section.materials import Material

TABLE = pathlib.Path(__file__).resolve().parents[2] / 'bench' / 'results' / 'continuum.json'
#: Largest tip distance to the FE the stored correction reaches on the unpressurised
#: scenes (0.188 mm, bench/results/continuum_fit.json), with a margin [m].
TOLERANCE = 0.2e-3


def _reference_moments(a, b, length):
    """
    int n n^T ds over arc parts from angle a to b, as (xx, xz, zz), shape (3, ...) [m].

    The closed form (l / 2)(I - [[C, S], [S, -C]]) in numpy, complex-safe: the slow
    reference the compiled kernel (`kernels.shear`) replaced.
    """
    d = b - a
    d = np.where(d == 0.0, 1e-300, d)
    half = 0.5 * np.asarray(length)
    sinc = np.sin(d) / d * half
    p = a + b
    c = np.cos(p) * sinc
    return np.stack([half - c, -np.sin(p) * sinc, half + c])


def _reference_moves(theta, lengths, s, force, compliance):
    """The shear move of the points at arc lengths s, each a sum over every segment [m]."""
    edges = np.concatenate([[0.0], np.cumsum(lengths)])
    start = np.concatenate([[0.0], theta[:-1]])
    out = np.zeros((len(s), 2))
    for k, value in enumerate(s):
        # The part of every segment before the point: 0, a partial segment or all of it.
        sigma = np.clip(value - edges[:-1], 0.0, lengths)
        xx, xz, zz = _reference_moments(
            start, start + (theta - start) * sigma / lengths, sigma).sum(axis=1)
        out[k] = compliance * np.array([[xx, xz], [xz, zz]]) @ force
    return out


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


def _loaded_state(correction, force=(0.3, -0.4)):
    solver = CorrectedSolver(ActuatorDesign.paper(prestrain=0.25), correction)
    result = solver.solve(0.0, force, outputs='tip')
    assert result.success
    return solver, solver.unknowns(result), solver.tip_loads(np.asarray(force))


@pytest.mark.parametrize('name', ['band_stiffness', 'clamp_stiffness',
                                  'channel_end_stiffness'])
def test_factor_gradients_against_finite_differences(name):
    # d gradient / d factor at a fixed state, against a central difference of the
    # gradient of solvers built with the factor moved (K is linear in it: exact to
    # rounding).
    correction = ContinuumCorrection(0.8, 1.4, 3.0, 0.02)
    solver, x, loads = _loaded_state(correction)
    rates = solver.parameter_gradient(x, 0.0, loads)
    assert rates.shape == (len(PARAMETERS), x.size)
    step = 1e-4

    def gradient(value):
        fields = dict(zip(('band_stiffness', 'clamp_stiffness', 'channel_end_stiffness',
                           'shear_compliance'), correction.values))
        fields[name] = value
        moved = CorrectedSolver(solver.design, ContinuumCorrection(**fields))
        return moved.derivatives(x, 0.0, loads)[1]

    value = getattr(correction, name)
    expected = (gradient(value + step) - gradient(value - step)) / (2 * step)
    got = rates[PARAMETERS.index(name)]
    assert_allclose(got, expected, atol=1e-7 * np.abs(expected).max())
    assert np.abs(got).max() > 0.0


def test_fl_modulus_gradient_carries_the_band_factor():
    # The band is fluidic layer, so its factor scales part of the fl_modulus direction.
    correction = ContinuumCorrection(0.6, 1.4, 3.0, 0.0)
    solver, x, loads = _loaded_state(correction)
    got = solver.parameter_gradient(x, 0.0, loads)[PARAMETERS.index('fl_modulus')]
    fl = solver.design.fluidic_layer
    step = 1e-4 * fl.E1

    def gradient(modulus):
        design = solver.design.replace(fluidic_layer=Material(
            modulus, fl.E2 * modulus / fl.E1, fl.nu))
        return CorrectedSolver(design, correction).derivatives(x, 0.0, loads)[1]

    expected = (gradient(fl.E1 + step) - gradient(fl.E1 - step)) / (2 * step)
    assert_allclose(got, expected, atol=1e-7 * np.abs(expected).max())


def test_moment_rates_against_complex_step():
    a = np.array([0.3, 0.3, -1.0, 0.0, 2.0])
    b = np.array([0.3 + 1e-5, 1.2, -0.2, 1e-3, -1.0])
    lengths = np.array([1.0, 2.0, 0.5, 1.0, 0.3])
    h = 1e-30
    d_a, d_b = _moment_rates(a, b, lengths)
    # The complex step of sin(d) / d itself cancels digits at small d (1e-10 relative at
    # d = 1e-3), hence the tolerance; the rates use the series there.
    assert_allclose(d_a, _reference_moments(a + 1j * h, b, lengths).imag / h, rtol=1e-9,
                    atol=1e-14)
    assert_allclose(d_b, _reference_moments(a, b + 1j * h, lengths).imag / h, rtol=1e-9,
                    atol=1e-14)


def test_shear_tip_jacobian_against_finite_differences():
    solver, x, _ = _loaded_state(CONTINUUM_FIT)
    force = np.array([0.3, -0.4])
    move, jac = solver.shear_tip(x, force)
    step = 1e-7
    expected = np.empty_like(jac)
    for i in range(x.size):
        e = np.zeros(x.size)
        e[i] = step
        expected[:, i] = (solver.shear_tip(x + e, force)[0]
                          - solver.shear_tip(x - e, force)[0]) / (2 * step)
    assert_allclose(jac, expected, atol=1e-8 * np.abs(expected).max())
    # The move is the tip's shear term: the quadrature test's integral at the tip.
    theta = x[2::3]
    assert_allclose(move, shear_displacements(theta, solver.lengths, [theta.size - 1],
                                              [solver.lengths[-1]], force, 1.0)[0],
                    rtol=1e-12)


def test_result_tip_is_the_rod_tip_plus_the_shear_move():
    solver, x, _ = _loaded_state(CONTINUUM_FIT)
    tip = solver.solve(0.0, (0.3, -0.4)).tip
    move = solver.shear_tip(x, (0.3, -0.4))[0]
    rod = solver.node_jacobian(x, solver.tip_node)[0]
    assert_allclose(tip, rod + CONTINUUM_FIT.shear_compliance * move, atol=1e-12)
    assert np.linalg.norm(CONTINUUM_FIT.shear_compliance * move) > 1e-4


def test_points_and_nodes_carry_the_same_shear_move_as_position_at():
    # The samples' and nodes' moves (one pass in _result) against position_at's, which
    # integrates each point on its own (shear_displacements).
    solver = CorrectedSolver(ActuatorDesign.paper(prestrain=0.4), CONTINUUM_FIT)
    result = solver.solve(0.0, (0.3, -0.4))
    s = np.linspace(0.0, solver.length, solver.samples)
    assert_allclose(result.points, result.position_at(s), atol=1e-12)
    assert_allclose(result.nodes, result.position_at(solver.edges), atol=1e-12)
    assert_allclose(result.nodes[-1], result.tip, atol=1e-12)
    plain = CorrectedSolver(solver.design, ContinuumCorrection(
        *CONTINUUM_FIT.values[:3])).solve(0.0, (0.3, -0.4))
    assert np.abs(result.points - plain.points).max() > 1e-4


def test_outputs_not_asked_for_stay_none_with_a_tip_load():
    solver = CorrectedSolver(ActuatorDesign.paper(prestrain=0.25), CONTINUUM_FIT)
    shape = solver.solve(0.0, (0.3, -0.4), outputs='shape')
    full = solver.solve(0.0, (0.3, -0.4))
    assert shape.curvature is None and shape.fit_rmsd is None
    assert_allclose(shape.points, full.points, atol=1e-15)
    assert full.curvature is not None and np.isfinite(full.curvature)


@pytest.mark.parametrize('force', [(0.3, -0.4), (0.0, 0.3), (-0.25, 0.0)])
def test_compiled_shear_moves_equal_the_numpy_closed_form_and_quadrature(force):
    # The kernel's running sums against every point summed on its own over the segments
    # (the numpy closed form it replaced), and against trapezoid quadrature of n n^T F.
    solver, x, _ = _loaded_state(CONTINUUM_FIT, force)
    theta, lengths, edges = x[2::3], solver.lengths, solver.edges
    force = np.array(force)
    s = np.concatenate([edges, np.linspace(0.0, solver.length, 37), [0.5 * edges[3]]])
    seg = np.clip(np.searchsorted(edges, s, side='right') - 1, 0, lengths.size - 1)
    nodes, points = shear_moves(x, lengths, seg, np.minimum(s - edges[seg], lengths[seg]),
                                force[0], force[1], 0.02)
    expected = _reference_moves(theta, lengths, s, force, 0.02)
    assert_allclose(points, expected, rtol=0, atol=1e-15)
    assert_allclose(nodes, expected[:edges.size], rtol=0, atol=1e-15)
    assert np.abs(points).max() > 1e-4
    grid = np.linspace(0.0, solver.length, 200001)
    i = np.clip(np.searchsorted(edges, grid, side='right') - 1, 0, lengths.size - 1)
    start = np.concatenate([[0.0], theta[:-1]])
    phi = start[i] + (theta[i] - start[i]) * (grid - edges[i]) / lengths[i]
    normal = np.stack([-np.sin(phi), np.cos(phi)], axis=1)
    shear = normal * (normal @ force)[:, None]
    tip = 0.02 * np.trapezoid(shear, grid, axis=0)
    assert_allclose(nodes[-1], tip, rtol=1e-8, atol=1e-14)


@pytest.mark.parametrize('outputs', ['tip', 'shape', 'all'])
@pytest.mark.parametrize('pressure, force', [(0.0, (0.3, -0.4)), (1.5e5, (0.0, 0.3)),
                                             (3.0e5, (-0.2, 0.0))])
def test_result_is_the_rod_plus_the_reference_shear_move(outputs, pressure, force):
    # Every field against the same solve without the shear term (the rod: the compliance
    # does not enter the equilibrium) plus the numpy reference move of its points.
    correction = ContinuumCorrection(0.8, 1.4, 3.0, 0.05)
    design = ActuatorDesign.paper(prestrain=0.25)
    got = CorrectedSolver(design, correction).solve(pressure, force, outputs=outputs)
    rod = CorrectedSolver(design, ContinuumCorrection(*correction.values[:3])).solve(
        pressure, force, outputs=outputs)
    solver = CorrectedSolver(design, correction)
    assert got.success and rod.success
    assert_allclose(got.x, rod.x, rtol=0, atol=0)
    theta, lengths = got.x[2::3], solver.lengths
    move = _reference_moves(theta, lengths, [solver.length], np.array(force), 0.05)[0]
    assert_allclose(got.tip, rod.tip + move, rtol=0, atol=1e-14)
    s = np.linspace(0.0, solver.length, solver.samples)
    if outputs == 'tip':
        assert got.nodes is None and got.points is None and got.curvature is None
    else:
        assert_allclose(got.nodes, rod.nodes + _reference_moves(
            theta, lengths, solver.edges, np.array(force), 0.05), rtol=0, atol=1e-14)
        assert_allclose(got.points, rod.points + _reference_moves(
            theta, lengths, s, np.array(force), 0.05), rtol=0, atol=1e-14)
        for name in ('energy', 'beta', 'theta', 'coefficients', 'tangent', 'strains'):
            assert_allclose(getattr(got, name), getattr(rod, name), rtol=0, atol=0)
    if outputs == 'all':
        # The circle through the moved samples, by an independent geometric fit.
        def distances(params):
            return np.hypot(*(got.points - params[:2]).T) - params[2]

        centre = np.array([0.0, -1.0 / got.curvature])
        fit = least_squares(distances, [*centre, abs(1.0 / got.curvature)], xtol=1e-15,
                            ftol=1e-15, gtol=1e-15)
        assert_allclose(abs(got.curvature), 1.0 / fit.x[2], rtol=1e-7)
        assert_allclose(got.fit_rmsd, np.sqrt(np.mean(fit.fun ** 2)), rtol=1e-6)
        assert abs(got.curvature - rod.curvature) > 1e-6 * abs(rod.curvature)
    else:
        assert got.curvature is None and got.fit_rmsd is None
    assert_allclose(got.position_at(s), rod.position_at(s) + _reference_moves(
        theta, lengths, s, np.array(force), 0.05), rtol=0, atol=1e-14)


def test_position_at_keeps_the_shape_of_its_argument():
    solver = CorrectedSolver(ActuatorDesign.paper(prestrain=0.25), CONTINUUM_FIT)
    result = solver.solve(0.0, (0.3, -0.4))
    s = np.linspace(0.0, solver.length, 6).reshape(2, 3)
    grid = result.position_at(s)
    assert grid.shape == (2, 3, 2)
    assert_allclose(grid.reshape(-1, 2), result.position_at(s.ravel()), rtol=0, atol=0)
    assert result.position_at(0.03).shape == (2,)
    assert_allclose(result.position_at(solver.length), result.tip, atol=1e-12)
    with pytest.raises(ValueError, match='`s`'):
        result.position_at(1.0)


def test_the_engine_stops_at_the_samples_where_the_shear_refits_the_circle(monkeypatch):
    # With a shear move the rod's circle would be dropped: the engine is not asked for it,
    # and the result still has the moved samples' circle.
    solver = CorrectedSolver(ActuatorDesign.paper(prestrain=0.25), CONTINUUM_FIT)
    plain = CorrectedSolver(solver.design, PAPER_PHYSICS)
    levels = []
    solve = engine.solve

    def spy(*args):
        levels.append(args[-1])
        return solve(*args)

    monkeypatch.setattr(engine, 'solve', spy)
    loaded = solver.solve(0.0, (0.0, 0.3))
    unloaded = solver.solve(0.0)
    tip = solver.solve(0.0, (0.0, 0.3), outputs='tip')
    rod = plain.solve(0.0, (0.0, 0.3))
    assert levels == [engine.SHAPE, engine.ALL, engine.TIP, engine.ALL]
    for result in (loaded, unloaded, rod):
        assert np.isfinite(result.curvature) and np.isfinite(result.fit_rmsd)
    assert tip.curvature is None and tip.points is None


def test_grids_of_the_corrected_rung_are_its_single_solves():
    # A batch row has no shear move: loaded scenes must come from single solves, and the
    # rigidity grid must refuse as the single call does, not return the uncorrected rod's.
    settings = ModelSettings(physics='continuum')
    designs = [ActuatorDesign.paper(0.25), ActuatorDesign.paper(0.4)]
    forces = [(0.0, 0.0), (0.0, 0.3), (0.2, 0.0)]
    grid = batch.solve_grid(designs, [0.0, 100e3], forces, settings=settings, outputs='all')
    for d, design in enumerate(designs):
        model = finger_model(design, settings)
        for p, pressure in enumerate(grid.pressures):
            for f, force in enumerate(forces):
                single = model.solve(float(pressure), force)
                assert np.abs(grid.tip[d, p, f] - single.tip).max() <= 1e-12
                assert grid.curvature[d, p, f] == pytest.approx(single.curvature, abs=1e-9)
                assert grid.models[d, p, f] == single.model
    with pytest.raises(NotImplementedError, match='shear correction'):
        batch.rigidity_grid(designs, [0.0], settings=settings)


def test_rigidity_without_a_shear_compliance_is_the_pcc_one():
    # No shear term to leave out: the corrected layout's own displacement control.
    design = ActuatorDesign.paper(0.25)
    mine = CorrectedSolver(design, PAPER_PHYSICS).rigidity(50e3, 'x', 0.010)
    paper = PCCSolver(design, 32).rigidity(50e3, 'x', 0.010)
    assert mine.success and mine.value == pytest.approx(paper.value, rel=1e-4)
