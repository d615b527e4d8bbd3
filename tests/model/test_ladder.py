"""Model ladder: section law, arc (rung a), rod (rung d) and the consistent CCM reconstruction."""

import numpy as np
import pytest
from scipy.optimize._numdiff import approx_derivative
from section_reference import quad_minimiser, quad_section

from fpc_gripper.model import (ActuatorDesign, ArcSolver, CCMSolver, PRESSURE_MODELS, RodSolver,
                               SolverStatus)
from fpc_gripper.model.discretisations.ccm_geometry import (consistent_from_strain,
                                                            consistent_strain_map)
from fpc_gripper.model.section.law import (build_section_law, rib_coverage, section_minimiser,
                                           station_layout)
from fpc_gripper.model.selection import aligned_edges


def uniform_design(prestrain):
    """No ribs, channel over the whole free length: every cross-section is the same."""
    return ActuatorDesign.paper(prestrain).replace(ribs=False, Cx=0.110)


# -- section law ---------------------------------------------------------------------
@pytest.mark.parametrize('kind', ['open', 'rib', 'solid', 'mean'])
def test_section_law_matches_quad(kind):
    design = ActuatorDesign.paper(0.3)
    law = build_section_law(design, (0.0, 1.0, 0.37))
    rib = 2.0 * design.w1
    types = {'open': (0, design.t, True), 'rib': (1, design.t + rib, True),
             'solid': (3, 0.0, False), 'mean': (2, design.t + 0.37 * rib, True)}
    index, rib_width, channel = types[kind]
    rng = np.random.default_rng(index)
    for _ in range(3):
        y = rng.normal(scale=(0.1, 20.0, 0.02))
        work = 2.5 * rng.uniform(0.0, 4e5)
        energy, grad, hess = law.derivatives(y, work, index)
        ref = quad_section(design, *y, work, rib_width=rib_width, channel=channel)
        np.testing.assert_allclose(energy, ref[0], rtol=1e-11, atol=1e-12)
        np.testing.assert_allclose(grad, ref[1:], rtol=1e-10, atol=1e-10 * np.abs(ref[1:]).max())
        np.testing.assert_allclose(law.energy(y, work, index), energy, rtol=1e-14)
        scale = np.array([1e-3, 1e-1, 1e-3])
        h_fd = approx_derivative(lambda v: law.derivatives(v, work, index)[1], y,
                                 method='3-point', abs_step=scale * 1e-3)
        np.testing.assert_allclose(hess, h_fd, rtol=1e-7, atol=1e-8 * np.abs(hess).max())


def test_section_law_is_the_ccm_energy_of_a_uniform_segment():
    # A CCM segment with B' = 3 b3 + 2 d^2 = 0 has the uniform strain (b1, 2 d, c1).
    design = uniform_design(0.4)
    solver = CCMSolver(design, n_segments=3)
    law = build_section_law(design, (None,), solid=False)
    d = np.array([-12.0, 5.0, 30.0])
    y = np.stack([np.array([-0.1, 0.02, 0.05]), 2.0 * d, np.array([1e-3, -2e-3, 4e-4])], 1)
    coefficients = np.stack([y[:, 0], -2.0 * d ** 2 / 3.0, y[:, 2], d], axis=1)
    q = coefficients.copy()
    lengths = solver.segments.lengths
    q[:, 1] *= lengths ** 2
    q[:, 3] *= lengths
    for pressure in (0.0, 2e5):
        work = PRESSURE_MODELS['adiabatic'] * pressure
        total = solver._total_energy(q, pressure, [])
        np.testing.assert_allclose(total, (lengths * law.energy(y, work)).sum(), rtol=1e-12)


def test_station_layout_resolves_ribs_and_channel_end():
    design = ActuatorDesign.paper()
    breaks, types, law = station_layout(design, 'exact')
    ribs = design.transverse_ribs()
    assert breaks[0] == 0.0 and np.isclose(breaks[-1], design.free_length)   # 0.0 is set
    assert np.isclose(breaks[-2], design.channel_end) and types[-1] == law.n_types - 1
    covered = np.diff(breaks)[types == 1].sum()
    np.testing.assert_allclose(covered, np.sum(ribs[:, 1] - ribs[:, 0]))
    np.testing.assert_allclose(covered / design.channel_end, rib_coverage(design))
    _, types_avg, law_avg = station_layout(design, 'average')
    assert law_avg.n_types == 2 and list(types_avg) == [0, 1]
    with pytest.raises(ValueError, match='ribs'):
        station_layout(design, 'smeared')


# -- arc (rung a) and rod (rung d) against the section minimiser --------------------------
@pytest.mark.parametrize('prestrain, pressure, model', [
    (0.15, 0.0, 'adiabatic'), (0.40, 0.0, 'adiabatic'), (0.25, 150e3, 'isobaric')])
def test_arc_and_rod_curvature_is_kappa_over_stretch(prestrain, pressure, model):
    design = uniform_design(prestrain)
    work = PRESSURE_MODELS[model] * pressure
    eps, kappa, c1 = quad_minimiser(design, work)
    expected = -kappa / (1.0 + eps)          # SPEC sign: > 0 curling towards -Z
    law = build_section_law(design, (None,), solid=False)
    y, ok = section_minimiser(law, work)
    assert ok
    np.testing.assert_allclose(y, (eps, kappa, c1), rtol=1e-7, atol=1e-11)

    arc = ArcSolver(design, pressure_model=model).solve(pressure)
    assert arc.success, arc.message
    np.testing.assert_allclose(arc.strains[0], y, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(arc.curvature, expected, rtol=1e-7)
    assert arc.fit_rmsd < 1e-12

    rod = RodSolver(design, pressure_model=model).solve(pressure)
    assert rod.success and rod.valid, rod.message
    np.testing.assert_allclose(rod.curvature, expected, rtol=1e-7)
    np.testing.assert_allclose(rod.strains, np.tile(y, (rod.points.shape[0], 1)),
                               rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(rod.tip, arc.tip, atol=1e-12)
    # The paper's CCM turns by 2 d / (1 + b1) per reference length: curvature / (1 + eps).
    ccm = CCMSolver(design, n_segments=16, pressure_model=model).solve(pressure)
    np.testing.assert_allclose(ccm.coefficients[8, 0], eps, rtol=1e-6)
    assert abs(ccm.curvature * (1.0 + eps) - expected) < 0.01 * abs(expected) + 0.05


@pytest.mark.parametrize('force', [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)])
def test_rod_meets_the_bvp_under_tip_loads(force):
    # M(s) = dW/dkappa must equal the moment of the tip load about r(s), N = F . t, T = 0.
    design = ActuatorDesign.paper(0.25)
    solver = RodSolver(design)
    result = solver.solve(150e3, force)
    assert result.success, result.message
    layout = station_layout(design, 'exact')
    s = np.linspace(0.0, design.free_length, result.points.shape[0])
    kinds = layout[1][np.clip(np.searchsorted(layout[0], s, side='right') - 1, 0,
                              layout[1].size - 1)]
    _, grad, _ = solver.law.derivatives(result.strains, 2.5 * 150e3, kinds)
    fx, fz = force
    x, z = result.points.T
    moment = -(fx * (z[-1] - z) - fz * (x[-1] - x))
    scale = abs(grad[:, 1]).max() + 1e-3
    np.testing.assert_allclose(grad[:, 1], moment, atol=1e-9 * scale)
    np.testing.assert_allclose(grad[:, 0], fx * np.cos(result.tangent)
                               + fz * np.sin(result.tangent), atol=1e-9)
    np.testing.assert_allclose(grad[:, 2], 0.0, atol=1e-9)
    np.testing.assert_allclose(result.points[-1], result.tip)


def test_rod_discretisation_has_converged():
    design = ActuatorDesign.paper(0.40)
    fine = RodSolver(design, degree=12, max_element_length=0.003).solve(100e3, (0.5, -0.5))
    coarse = RodSolver(design, degree=6).solve(100e3, (0.5, -0.5))
    default = RodSolver(design).solve(100e3, (0.5, -0.5))
    np.testing.assert_allclose(default.tip, fine.tip, atol=1e-10)
    np.testing.assert_allclose(coarse.tip, fine.tip, atol=1e-9)


# -- CCM against the rod ----------------------------------------------------------------
def test_consistent_reconstruction_derivatives_and_round_trip():
    q = np.random.default_rng(3).normal(scale=0.1, size=(4, 4))
    qs, jac, hess3 = consistent_strain_map(q)
    np.testing.assert_allclose(consistent_from_strain(qs), q, atol=1e-15)
    for i in range(4):
        j_fd = approx_derivative(lambda v: consistent_strain_map(v[None])[0][0], q[i])
        np.testing.assert_allclose(jac[i], j_fd, rtol=1e-7, atol=1e-9)
        h_fd = approx_derivative(lambda v: consistent_strain_map(v[None])[1][0, 3], q[i])
        np.testing.assert_allclose(hess3[i], h_fd, rtol=1e-6, atol=1e-8)
    design = ActuatorDesign.paper(0.3)
    solver = CCMSolver(design, n_segments=4, reconstruction='consistent')
    loads = solver._loads((0.7, -1.3), [])
    x = np.random.default_rng(0).normal(scale=0.1, size=16)

    def gradient(v):
        return solver.derivatives(v.reshape(4, 4), 150e3, loads)[1].ravel()

    g_fd = approx_derivative(lambda v: solver._total_energy(v.reshape(4, 4), 150e3, loads), x)
    np.testing.assert_allclose(gradient(x), g_fd, rtol=1e-6, atol=1e-7 * np.abs(g_fd).max())
    hess = solver.derivatives(x.reshape(4, 4), 150e3, loads)[2]
    np.testing.assert_allclose(hess, approx_derivative(gradient, x), rtol=1e-6,
                               atol=1e-7 * np.abs(hess).max())
    assert CCMSolver(design).reconstruction == 'paper'
    with pytest.raises(ValueError, match='reconstruction'):
        CCMSolver(design, reconstruction='exact')


def test_ccm_converges_to_the_rod_up_to_the_reconstruction_difference():
    design = uniform_design(0.40)
    load = (0.5, -0.5)
    rod = RodSolver(design).solve(100e3, load)
    assert rod.success
    errors = []
    for n in (16, 32, 64):
        consistent = CCMSolver(design, n, reconstruction='consistent').solve(100e3, load)
        assert consistent.success and consistent.valid
        errors.append(np.linalg.norm(consistent.tip - rod.tip))
    # Second order: the error falls about four times per doubling.
    assert errors[1] < errors[0] / 3.0 and errors[2] < errors[1] / 3.0
    assert errors[2] < 2e-5
    paper = CCMSolver(design, 64).solve(100e3, load)
    consistent = CCMSolver(design, 64, reconstruction='consistent').solve(100e3, load)
    reconstruction = np.linalg.norm(paper.tip - consistent.tip)
    assert reconstruction > 1e-3     # a few millimetres: not a discretisation error
    np.testing.assert_allclose(np.linalg.norm(paper.tip - rod.tip), reconstruction,
                               atol=errors[2])


def test_ccm_with_edges_on_the_ribs_converges_to_the_rod():
    design = ActuatorDesign.paper(0.25)
    rod = RodSolver(design).solve(300e3, (0.0, 0.5))
    errors = [np.linalg.norm(CCMSolver(design, segment_edges=aligned_edges(design, n),
                                       reconstruction='consistent').solve(300e3, (0.0, 0.5))
                             .tip - rod.tip) for n in (22, 44, 88)]
    assert errors[1] < errors[0] / 3.0 and errors[2] < errors[1] / 3.0
    assert errors[2] < 5e-5


def test_rod_and_arc_rigidity():
    design = ActuatorDesign.paper(0.25)
    rod = RodSolver(design).rigidity(0.0)
    assert rod.success, rod.message
    np.testing.assert_allclose(rod.loaded.tip[0] - rod.unloaded.tip[0], 0.010, rtol=1e-9)
    np.testing.assert_allclose(rod.value, rod.force * rod.lever ** 3 / 0.03, rtol=1e-12)
    ccm = CCMSolver(design, segment_edges=aligned_edges(design, 44),
                    reconstruction='consistent').rigidity(0.0)
    np.testing.assert_allclose(ccm.value, rod.value, rtol=5e-3)
    arc = ArcSolver(design).rigidity(0.0, axis='z')
    assert arc.success and arc.value > 0.0


# -- API --------------------------------------------------------------------------------
@pytest.mark.parametrize('cls', [ArcSolver, RodSolver])
def test_api_fields_warm_start_and_errors(cls):
    design = ActuatorDesign.paper(0.25)
    solver = cls(design)
    cold = solver.solve(1e5, (0.2, -0.1))
    assert cold.success and cold.status is SolverStatus.SUCCESS and cold.iterations > 0
    assert cold.points.shape == (129, 2) and cold.tip.shape == (2,)
    np.testing.assert_allclose(cold.points[0], 0.0, atol=1e-15)
    assert np.isfinite(cold.curvature) and cold.fit_rmsd >= 0.0 and cold.valid
    assert cold.beta.ndim == 1 and cold.strains.shape == (129, 3)
    if cls is ArcSolver:
        assert cold.coefficients.shape == (1, 4)
    else:
        assert cold.coefficients is None
    warm = solver.solve(1.02e5, (0.2, -0.1), initial=cold)
    again = solver.solve(1.02e5, (0.2, -0.1))
    assert warm.iterations < again.iterations
    np.testing.assert_allclose(warm.tip, again.tip, atol=1e-11)
    with pytest.raises(ValueError, match='pressure'):
        solver.solve(-1.0)
    with pytest.raises(ValueError, match='tip_force'):
        solver.solve(0.0, (1.0, 2.0, 3.0))
    with pytest.raises(TypeError, match='pressure'):
        solver.solve('1e5')
    with pytest.raises(ValueError, match='initial'):
        solver.solve(0.0, initial=np.zeros((1, 4)))
    with pytest.raises(ValueError, match='pressure_model'):
        cls(design, pressure_model='isothermal')
    with pytest.raises(TypeError, match='design'):
        cls({'Lx': 0.11})


def test_adaptive_solver_makes_choose_models_choice():
    from fpc_gripper.model import AdaptiveSolver, choose_model, Scene
    design = ActuatorDesign.paper(0.25)
    solver = AdaptiveSolver(design, tolerance=0.5e-3)
    for pressure, force in [(0.0, (0.0, 0.0)), (37e3, (0.0, 0.0)), (151e3, (0.0, 0.0)),
                            (333e3, (0.0, 0.0)), (95e3, (0.0, 0.3)), (95e3, (0.2, 0.0)),
                            (450e3, (0.0, 0.0))]:
        expected = choose_model(Scene(design, pressure, force), 0.5e-3)
        got = solver.choose(pressure, force)
        assert (got.rung, got.n_segments) == (expected.rung, expected.n_segments)
        result = solver.solve(pressure, force)
        assert result.success and result.valid
