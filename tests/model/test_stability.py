"""Honest convergence reports, the production path's envelope, and model selection."""

import copy
import itertools

import numpy as np
import pytest
from scipy.optimize._numdiff import approx_derivative

from fpc_gripper.model import (ActuatorDesign, AdaptiveSolver, CCMSolver, choose_model,
                               RodSolver, Scene, SolverStatus)
from fpc_gripper.model.pipeline import finger_model, ModelSettings
from fpc_gripper.model.section.law import station_layout
from fpc_gripper.model.selection import a_posteriori_error, load_error_model

_GX, _GW = np.polynomial.legendre.leggauss(6)


class IndependentCCM:
    """
    CCM potential rebuilt from the section law and SPEC's kinematics, not from energy.py.

    Each segment's energy is int W(b1 + (3 b3 + 2 d^2) x^2, 2 d, c1) dx over its
    constant-section pieces (6-point Gauss, exact for the degree-10 integrand);
    the load potential is -F . tip with the tip chained by eq. (15).
    """

    def __init__(self, solver):
        design = solver.design
        breaks, types, self.law = station_layout(design, 'exact')
        edges = solver.segments.edges
        self.lengths = np.diff(edges)
        self.work = solver.pressure_coefficient
        seg, x, w, kind = [], [], [], []
        for i, (a, b) in enumerate(zip(edges, edges[1:])):
            cuts = np.unique(np.clip(np.concatenate([[a, b], breaks]), a, b))
            for lo, hi in zip(cuts, cuts[1:]):
                if hi - lo <= 1e-15:
                    continue
                mid = 0.5 * (lo + hi)
                k = types[min(np.searchsorted(breaks, mid) - 1, types.size - 1)]
                seg.extend([i] * _GX.size)
                x.extend(lo - a + 0.5 * (hi - lo) * (_GX + 1.0))
                w.extend(0.5 * (hi - lo) * _GW)
                kind.extend([k] * _GX.size)
        self.seg, self.x, self.w, self.kind = map(np.array, (seg, x, w, kind))

    def energy(self, coefficients, pressure, force):
        b1, b3, c1, d = (coefficients[self.seg, k] for k in range(4))
        eps = b1 + (3.0 * b3 + 2.0 * d * d) * self.x ** 2
        y = np.stack([eps, 2.0 * d, c1], axis=1)
        strain = (self.w * self.law.energy(y, self.work * pressure, self.kind)).sum()
        lengths = self.lengths
        b1, b3, c1, d = coefficients.T
        beta = np.arctan2(2.0 * d * lengths, 1.0 + b1 + 3.0 * b3 * lengths ** 2)
        theta = np.concatenate([[0.0], np.cumsum(beta)[:-1]])
        u = (1.0 + b1) * lengths + b3 * lengths ** 3
        w = d * lengths ** 2
        tip = np.array([np.sum(np.cos(theta) * u - np.sin(theta) * w),
                        np.sum(np.sin(theta) * u + np.cos(theta) * w)])
        return strain - np.dot(force, tip)


def independent_gradient(solver, result):
    """Gradient in the scaled unknowns (b1, b3 L^2, c1, d L), relative to the solver's scale."""
    model = IndependentCCM(solver)
    lengths = solver.segments.lengths
    unscale = np.stack([np.ones_like(lengths), lengths ** -2, np.ones_like(lengths),
                        1.0 / lengths], axis=1)
    q = result.coefficients / unscale
    force = np.array(result.tip_force)

    def fun(v):
        return model.energy(v.reshape(-1, 4) * unscale, result.pressure, force)

    grad = approx_derivative(fun, q.ravel(), method='3-point', abs_step=1e-6)
    return np.abs(grad).max() / solver.gradient_scale


GRID = list(itertools.product(
    (0.15, 0.40), (0.0, 300e3, 500e3),
    ((0.0, 0.0), (-2.0, 0.0), (0.0, -2.0), (2.0, 0.0), (0.0, 2.0))))


@pytest.mark.parametrize('n_segments', [2, 8])
def test_ccm_success_means_converged_and_valid_is_honest(n_segments):
    seen = {'success': 0, 'invalid': 0, 'failed': 0}
    for prestrain, pressure, force in GRID:
        solver = CCMSolver(ActuatorDesign.paper(prestrain), n_segments=n_segments)
        result = solver.solve(pressure, force)
        lengths = solver.segments.lengths
        rule = np.abs(2.0 * result.coefficients[:, 3] * lengths)
        assert result.valid == bool(np.all(rule < 1.0))
        if not result.valid:
            seen['invalid'] += 1
            if result.success:
                assert 'valid=False' in result.message
        if result.success:
            seen['success'] += 1
            assert result.status is SolverStatus.SUCCESS
            assert independent_gradient(solver, result) < 1e-7, (prestrain, pressure, force)
        else:
            seen['failed'] += 1
            assert result.status is not SolverStatus.SUCCESS and result.message
    assert seen['success'] > len(GRID) // 2
    if n_segments == 2:
        assert seen['invalid'] > 0      # the grid does reach past the small-rotation rule


def test_independent_gradient_detects_an_unconverged_state():
    solver = CCMSolver(ActuatorDesign.paper(0.25), n_segments=4, max_iterations=2)
    result = solver.solve(2e5, (0.5, 0.0))
    assert not result.success
    assert independent_gradient(solver, result) > 1e-6


def test_rod_success_means_equilibrium():
    for prestrain, pressure, force in GRID[::3]:
        design = ActuatorDesign.paper(prestrain)
        solver = RodSolver(design)
        result = solver.solve(pressure, force)
        if not result.success:
            assert result.status is not SolverStatus.SUCCESS and result.message
            continue
        breaks, types, _ = station_layout(design, 'exact')
        s = np.linspace(0.0, design.free_length, result.points.shape[0])
        kinds = types[np.clip(np.searchsorted(breaks, s, side='right') - 1, 0, types.size - 1)]
        grad = solver.law.derivatives(result.strains, 2.5 * pressure, kinds)[1]
        x, z = result.points.T
        moment = -(force[0] * (z[-1] - z) - force[1] * (x[-1] - x))
        np.testing.assert_allclose(grad[:, 1], moment, atol=1e-9)
    unconverged = RodSolver(ActuatorDesign.paper(0.4), max_iterations=2).solve(4e5, (0, -1))
    assert not unconverged.success and unconverged.message


# -- production path: the finger pipeline (choice, damped Newton, refinement) -----------
ENVELOPE = list(itertools.product(
    (0.05, 0.30, 0.60), (0.0, 250e3, 500e3),
    ((0.0, 0.0), (1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0))))


def test_production_path_converges_over_the_envelope():
    for prestrain, pressure, force in ENVELOPE:
        design = ActuatorDesign.paper(prestrain)
        result = finger_model(design, ModelSettings()).solve(pressure, force)
        assert result.success and result.valid, (prestrain, pressure, force, result.message)


def test_refinement_doubles_n_until_valid():
    """A choice that breaks the small-rotation rule is refined; the result says so."""
    model = copy.deepcopy(load_error_model())
    model['ranges']['prestrain'] = [0.05, 0.7]
    for entry in model['models']:
        if (entry['rung'], entry['n_segments']) == ('ccm', 2):
            # Claim N = 2 is exact everywhere: it is chosen, and breaks the rule at 0.60.
            entry['bound'] = [[0.0] * len(row) for row in entry['bound']]
            entry['invalid'] = [[False] * len(row) for row in entry['invalid']]
            entry['cost'] = 0.0
    design = ActuatorDesign.paper(0.60)
    assert CCMSolver(design, n_segments=2).solve(0.0).valid is False
    refined = AdaptiveSolver(design, tolerance=1e-3, error_model=model).solve(0.0)
    assert refined.success and refined.valid
    assert refined.model_choice.rung == 'ccm' and refined.model_choice.n_segments > 2
    assert 'refined to N' in refined.model_choice.reason
    stuck = AdaptiveSolver(design, tolerance=1e-3, error_model=model, max_segments=2)
    result = stuck.solve(0.0)
    assert result.success and not result.valid and result.model_choice.n_segments == 2


# -- model selection ------------------------------------------------------------------
def test_choose_model_prefers_cheap_models_for_easy_scenes():
    model = load_error_model()
    easy = choose_model(Scene(ActuatorDesign.paper(0.15), 200e3), 2e-5)
    hard = choose_model(Scene(ActuatorDesign.paper(0.40), 0.0, (0.0, -1.0)), 2e-5)
    rank = {m['rung'] + str(m['n_segments']): m['cost'] for m in model['models']}
    assert easy.cost < hard.cost, (easy, hard)
    assert rank[easy.rung + str(easy.n_segments)] == easy.cost   # the JSON value, passed on
    for m in model['models']:
        # The static cost is a property of the discretisation: unknowns x iterations.
        assert m['cost'] == pytest.approx(m['unknowns'] * m['iterations'], rel=1e-12)
    outside = choose_model(Scene(ActuatorDesign.paper(0.60), 0.0), 1e-3)
    assert outside.rung == 'rod' and 'outside' in outside.reason
    with pytest.raises(ValueError, match='tolerance'):
        choose_model(Scene(ActuatorDesign.paper(0.25)), 0.0)


@pytest.mark.parametrize('prestrain, pressure, force, tolerance', [
    (0.20, 150e3, (0.0, 0.0), 3e-3), (0.30, 50e3, (0.3, 0.0), 2e-3),
    (0.35, 250e3, (0.0, -0.7), 5e-3), (0.25, 350e3, (-0.4, 0.0), 1e-3)])
def test_choose_model_bound_holds(prestrain, pressure, force, tolerance):
    design = ActuatorDesign.paper(prestrain)
    choice = choose_model(Scene(design, pressure, force), tolerance)
    assert choice.predicted_error <= tolerance
    settings = ModelSettings(rung=choice.rung, n_segments=choice.n_segments)
    result = finger_model(design, settings).solve(pressure, force)
    rod = RodSolver(design).solve(pressure, force)
    assert result.success and rod.success
    assert np.linalg.norm(result.tip - rod.tip) <= choice.predicted_error + 1e-9, choice
    if choice.rung in ('ccm', 'ccm_consistent'):
        estimate = a_posteriori_error(Scene(design, pressure, force), choice.rung,
                                      choice.n_segments)
        assert np.isfinite(estimate)
    assert finger_model(design, ModelSettings(rung='rod')).solve(pressure, force).success


def test_choose_model_never_reads_a_measured_time():
    """Scrambling the stored timings changes no choice; without static costs it refuses."""
    import random
    model = load_error_model()
    scrambled = copy.deepcopy(model)
    times = [m['time'] for m in scrambled['models']]
    random.Random(7).shuffle(times)
    for m, t in zip(scrambled['models'], times):
        m['time'] = t * 1e3
    scenes = [Scene(ActuatorDesign.paper(e), p, f) for e in (0.15, 0.25, 0.40)
              for p in (0.0, 150e3, 390e3) for f in ((0.0, 0.0), (0.0, 0.4), (-0.8, 0.0))]
    for scene in scenes:
        for tolerance in (5e-5, 5e-4, 3e-3):
            assert choose_model(scene, tolerance, model) == \
                choose_model(scene, tolerance, scrambled), (scene, tolerance)
    stripped = copy.deepcopy(model)
    for m in stripped['models']:
        del m['cost']
    with pytest.raises(ValueError, match='static costs'):
        choose_model(scenes[1], 5e-4, stripped)
