"""PCC rod (piecewise-constant strain): exact derivatives, arc limits, convergence to the rod."""

import math

from helpers import fd_derivative
import numpy as np
from pcc_reference import random_state
import pytest

from fpc_gripper.model import (ActuatorDesign, ArcSolver, PCCSolver, Result, RodSolver,
                               SolverStatus)
from fpc_gripper.model.discretisations.pcc import half_angle_sinc, pcc_edges
from fpc_gripper.model.section.law import section_minimiser, station_layout

PRESTRAINS = (0.15, 0.25, 0.40)
N_VALUES = (16, 32, 64, 128, 256)


def uniform_design(prestrain):
    """No ribs, channel over the whole free length: every cross-section is the same."""
    return ActuatorDesign.paper(prestrain).replace(ribs=False, Cx=0.110)


def scenes():
    """(prestrain, pressure [Pa], tip force [N]): the ladder's unloaded and loaded scenes."""
    out = [(e, p, (0.0, 0.0)) for e in PRESTRAINS for p in (0.0, 100e3, 200e3, 300e3, 400e3)]
    for e in PRESTRAINS:
        for p in (0.0, 200e3, 400e3):
            for f in (-1.0, -0.5, 0.5, 1.0):
                out += [(e, p, (f, 0.0)), (e, p, (0.0, f))]
    return out


@pytest.fixture(scope='module')
def rod_tips():
    """RodSolver tips of every scene (converged to about 1e-10 m), solved once."""
    out = {}
    for e in PRESTRAINS:
        rod = RodSolver(ActuatorDesign.paper(e))
        for scene in scenes():
            if scene[0] == e:
                result = rod.solve(*scene[1:])
                assert result.success, result.message
                out[scene] = result.tip
    return out


# -- building blocks ------------------------------------------------------------------
def test_half_angle_sinc_is_exact_and_smooth():
    delta = np.array([0.0, 1e-9, -1e-4, 0.3, -1.7, 2.0, -2.5, 7.0, 40.0])
    s0, s1, s2 = half_angle_sinc(delta)
    h = 0.5 * delta
    with np.errstate(invalid='ignore', divide='ignore'):
        closed = np.where(h == 0.0, 1.0, np.sin(h) / h)
    np.testing.assert_allclose(s0, closed, rtol=1e-15, atol=1e-16)
    assert s0[0] == 1.0 and s1[0] == 0.0 and s2[0] == -1.0 / 12.0
    inner = delta[1:]
    for k in (1, 2):
        fd = np.array([fd_derivative(lambda v: half_angle_sinc(v)[k - 1], np.array([v]),
                                     1e-3).item() for v in inner])
        np.testing.assert_allclose(half_angle_sinc(inner)[k], fd, rtol=1e-9, atol=1e-12)
    # The series (|delta| < 2) and the closed forms (|delta| >= 2) agree where they meet.
    below, above = half_angle_sinc([2.0 - 1e-13]), half_angle_sinc([2.0])
    np.testing.assert_allclose(np.ravel(below), np.ravel(above), rtol=1e-12)


def test_edges_have_one_section_type_per_segment():
    design = ActuatorDesign.paper(0.25)
    breaks, types, _ = station_layout(design, 'exact')
    for n in (1, 22, 23, 64, 256):
        edges, kinds, _ = pcc_edges(design, n)
        assert edges.size - 1 == max(n, types.size)
        assert np.all(np.isin(breaks, edges))             # every section change is an edge
        mid = 0.5 * (edges[:-1] + edges[1:])
        np.testing.assert_array_equal(kinds, types[np.searchsorted(breaks, mid) - 1])
        lengths = np.diff(edges)
        if n >= 64:
            # As even as possible: within one interval's rounding of the mean length.
            assert lengths.max() <= 1.6 * design.free_length / n
        # Each interval cut evenly: its edges as np.linspace places them.
        counts = np.diff(np.searchsorted(edges, breaks))
        even = np.concatenate([*(np.linspace(a, b, c + 1)[:-1]
                                 for a, b, c in zip(breaks, breaks[1:], counts)), breaks[-1:]])
        np.testing.assert_allclose(edges, even, rtol=0, atol=1e-15)
    assert PCCSolver(uniform_design(0.25), 1).n_segments == 1
    assert PCCSolver(design, 8).n_segments == 22


# -- exact derivatives ---------------------------------------------------------------------
@pytest.mark.parametrize('prestrain, pressure, loads', [
    (0.15, 0.0, 'none'), (0.25, 150e3, 'tip'), (0.40, 400e3, 'tip'), (0.40, 50e3, 'inner'),
    (0.25, 300e3, 'inner')])
def test_derivatives_match_finite_differences(prestrain, pressure, loads):
    solver = PCCSolver(ActuatorDesign.paper(prestrain), n_segments=24)
    n = solver.n_segments
    x = random_state(solver, seed=int(pressure) + int(100 * prestrain))
    cases = {'none': [], 'tip': [(n, np.array([0.7, -1.3]))],
             'inner': [(n, np.array([-0.4, 0.9])), (n // 3, np.array([1.1, 0.6])),
                       (n // 2, np.array([0.0, -2.0])), (0, np.array([5.0, 5.0]))]}
    load = cases[loads]
    energy, grad, hess = solver.derivatives(x, pressure, load)
    assert energy == pytest.approx(solver.energy(x, pressure, load), rel=1e-14)
    # Fourth-order differences with h = 1e-3 (rad, or strain): truncation and round-off
    # both below 1e-12 of the largest entry; the analytic values agree to about 1e-12.
    g_fd = fd_derivative(lambda v: np.array(solver.energy(v, pressure, load)), x, 1e-3)
    np.testing.assert_allclose(grad, g_fd, rtol=0, atol=1e-10 * np.abs(grad).max())
    dense = hess.dense()
    h_fd = fd_derivative(lambda v: solver.derivatives(v, pressure, load)[1], x, 1e-3)
    np.testing.assert_allclose(dense, h_fd, rtol=0, atol=1e-10 * np.abs(dense).max())
    np.testing.assert_array_equal(dense, dense.T)
    # Banded: nothing beyond the third off-diagonal, in the FD Hessian too.
    far = np.abs(np.subtract.outer(np.arange(x.size), np.arange(x.size))) > 3
    assert np.abs(h_fd[far]).max() <= 1e-12 * np.abs(dense).max()
    for node in (n, n // 3):
        position, jac = solver.node_jacobian(x, node)
        np.testing.assert_allclose(position, solver.nodes(x)[node], rtol=0, atol=1e-16)
        j_fd = fd_derivative(lambda v: solver.nodes(v)[node], x, 1e-3)
        np.testing.assert_allclose(jac, j_fd, rtol=0, atol=1e-10 * np.abs(jac).max())


def test_step_and_linear_solve_are_the_banded_newton_systems():
    solver = PCCSolver(ActuatorDesign.paper(0.25), n_segments=24)
    x = random_state(solver, seed=1)
    _, grad, hess = solver.derivatives(x, 1e5, [(solver.tip_node, np.array([0.2, 0.1]))])
    dx, min_eig = solver.step(grad, hess)
    assert min_eig == 1.0
    np.testing.assert_allclose(hess.dense() @ dx, -grad, atol=1e-10 * np.abs(grad).max())
    rhs = np.random.default_rng(0).normal(size=x.size)
    np.testing.assert_allclose(hess.dense() @ solver.solve_linear(hess, rhs), rhs, atol=1e-9)
    # A compressive tip load far beyond the buckling load of the flat finger: indefinite.
    flat = solver.flat()
    load = [(solver.tip_node, np.array([-200.0, 0.0]))]
    _, grad, hess = solver.derivatives(flat + 1e-3, 0.0, load)
    dense = hess.dense()
    dx, min_eig = solver.step(grad, hess)
    d = np.sqrt(np.abs(dense.diagonal()))
    lam = np.linalg.eigvalsh(dense / np.outer(d, d))
    assert lam[0] < 0.0 and min_eig == pytest.approx(lam[0], rel=1e-9)
    shifted = dense + 2.0 * abs(lam[0]) * np.diag(d ** 2)
    np.testing.assert_allclose(shifted @ dx, -grad, atol=1e-6 * np.abs(grad).max())
    assert grad @ dx < 0.0                                   # the step descends
    rhs = np.random.default_rng(1).normal(size=x.size)
    np.testing.assert_allclose(dense @ solver.solve_linear(hess, rhs), rhs, atol=1e-8)


def test_solve_through_indefinite_hessians():
    # 5 N of compression (the envelope's edge) buckles the nearly flat finger: Newton from
    # flat meets indefinite Hessians (shifted steps) and still finds the rod's buckled
    # equilibrium.
    design = ActuatorDesign.paper(0.15)
    solver = PCCSolver(design, n_segments=64)
    load = [(solver.tip_node, np.array([-5.0, 0.0]))]
    _, grad, hess = solver.derivatives(solver.flat(), 200e3, load)
    seen = [solver.step(grad, hess)[1]]
    result = solver.solve(200e3, (-5.0, 0.0))
    assert result.success, result.message
    assert seen and max(seen) < 0.0
    rod = RodSolver(design).solve(200e3, (-5.0, 0.0))
    assert rod.success
    assert np.linalg.norm(result.tip - rod.tip) < 2e-5
    assert result.tip[0] < 0.0                             # buckled back past the clamp


# -- limits: the exact arc ---------------------------------------------------------------
@pytest.mark.parametrize('prestrain, pressure, force', [
    (0.15, 0.0, (0.0, 0.0)), (0.25, 200e3, (0.5, -1.0)), (0.40, 400e3, (-1.0, 0.5)),
    (0.40, 80e3, (0.0, 1.0))])
def test_one_segment_of_a_uniform_section_is_the_arc(prestrain, pressure, force):
    design = uniform_design(prestrain)
    arc = ArcSolver(design).solve(pressure, force)
    pcc = PCCSolver(design, n_segments=1).solve(pressure, force)
    assert arc.success and pcc.success, (arc.message, pcc.message)
    theta, eps, c1 = pcc.state[0]
    np.testing.assert_allclose([eps, theta / design.free_length, c1], arc.state,
                               rtol=1e-11, atol=1e-14)
    np.testing.assert_allclose(pcc.tip, arc.tip, rtol=0, atol=1e-14)
    np.testing.assert_allclose(pcc.points, arc.points, rtol=0, atol=1e-14)
    np.testing.assert_allclose(pcc.energy, arc.energy, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(pcc.coefficients, arc.coefficients, rtol=1e-11, atol=1e-14)


@pytest.mark.parametrize('prestrain, pressure', [(0.15, 0.0), (0.40, 0.0), (0.25, 300e3)])
def test_unloaded_uniform_section_is_the_exact_arc_for_every_n(prestrain, pressure):
    design = uniform_design(prestrain)
    arc = ArcSolver(design).solve(pressure)
    y, ok = section_minimiser(ArcSolver(design).law, 2.5 * pressure)
    assert ok and arc.success
    for n in (1, 2, 5, 16, 64, 256):
        pcc = PCCSolver(design, n_segments=n).solve(pressure)
        assert pcc.success, pcc.message
        np.testing.assert_allclose(pcc.strains, np.tile(y, (129, 1)), rtol=1e-8, atol=1e-12)
        np.testing.assert_allclose(pcc.tip, arc.tip, rtol=0, atol=1e-13)
        np.testing.assert_allclose(pcc.points, arc.points, rtol=0, atol=1e-13)
        np.testing.assert_allclose(pcc.curvature, arc.curvature, rtol=1e-9)


# -- convergence to the rod -------------------------------------------------------------
@pytest.fixture(scope='module')
def tip_errors(rod_tips):
    """Tip error |tip - rod tip| [m] of every scene at every N, shape (len(N_VALUES), scenes)."""
    out = []
    for n in N_VALUES:
        solvers = {e: PCCSolver(ActuatorDesign.paper(e), n_segments=n) for e in PRESTRAINS}
        row = []
        for scene, tip in rod_tips.items():
            result = solvers[scene[0]].solve(*scene[1:])
            assert result.success and result.valid, (n, scene, result.message)
            row.append(np.linalg.norm(result.tip - tip))
        out.append(row)
    return np.array(out)


def test_unloaded_pcc_is_the_rod(tip_errors, rod_tips):
    # Unloaded, the rod's strain is constant on each section: the PCC is exact for any N.
    unloaded = np.array([scene[2] == (0.0, 0.0) for scene in rod_tips])
    assert tip_errors[:, unloaded].max() < 1e-12


def test_loaded_pcc_converges_to_the_rod_at_second_order(tip_errors, rod_tips):
    loaded = np.array([scene[2] != (0.0, 0.0) for scene in rod_tips])
    worst = tip_errors[:, loaded].max(axis=1)
    counts = [PCCSolver(ActuatorDesign.paper(0.25), n).n_segments for n in N_VALUES]
    assert counts == [22, 32, 64, 128, 256]                  # N = 16 is raised to 22 intervals
    order = np.log2(worst[:-1] / worst[1:]) / np.log2(np.array(counts[1:]) / counts[:-1])
    assert np.all(np.diff(worst) < 0.0)
    # Observed order over the doublings 32 -> 64 -> 128 -> 256: second.
    assert np.all((order[1:] > 1.8) & (order[1:] < 2.3)), order
    # Worst of the scenes: below 0.05 mm from N = 32 (N = 24 suffices: docs/physics.md 11.6).
    assert worst[0] > 5e-5 > worst[1]
    assert worst[-1] < 3e-7
    # Every scene, not only the worst, converges: the error at 256 is 64 times below 32.
    assert np.all(tip_errors[-1, loaded] < tip_errors[1, loaded] / 30.0)


def test_rigidity_matches_the_rod():
    design = ActuatorDesign.paper(0.25)
    solver = PCCSolver(design, n_segments=128)
    for pressure in (0.0, 55.2e3):
        rod = RodSolver(design).rigidity(pressure)
        pcc = solver.rigidity(pressure)
        assert pcc.success and rod.success, pcc.message
        np.testing.assert_allclose(pcc.loaded.tip[0] - pcc.unloaded.tip[0], 0.010, rtol=1e-9)
        np.testing.assert_allclose(pcc.value, pcc.force * pcc.lever ** 3 / 0.03, rtol=1e-12)
        np.testing.assert_allclose(pcc.value, rod.value, rtol=5e-5)
    zrod = RodSolver(design).rigidity(0.0, axis='z')
    np.testing.assert_allclose(solver.rigidity(0.0, axis='z').value, zrod.value, rtol=1e-4)


# -- API, warm start ---------------------------------------------------------------------
@pytest.mark.parametrize('force', [(0.0, 0.0), (0.5, -0.8)])
def test_warm_start_gives_the_cold_answer(force):
    # Up to UNIQUE_LOAD (1.5 N): above it a warm start is ignored (test_envelope.py).
    solver = PCCSolver(ActuatorDesign.paper(0.40), n_segments=64)
    start = solver.solve(100e3, force)
    warm = solver.solve(101e3, force, initial=start)
    cold = solver.solve(101e3, force)
    assert warm.success and cold.success
    assert warm.iterations < cold.iterations
    np.testing.assert_allclose(warm.state, cold.state, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(warm.tip, cold.tip, rtol=1e-10)
    # A far warm start (another pressure and load) restarts as a fresh solve if needed.
    far = solver.solve(0.0, (-1.0, 0.0))
    np.testing.assert_allclose(solver.solve(101e3, force, initial=far).tip, cold.tip,
                               rtol=1e-10)


def test_result_fields_and_errors():
    design = ActuatorDesign.paper(0.25)
    solver = PCCSolver(design, n_segments=40)
    result = solver.solve(1e5, (0.2, -0.1))
    assert isinstance(result, Result) and result.status is SolverStatus.SUCCESS
    assert result.model == f'pcc N={solver.n_segments}' and result.rung == 'pcc'
    n = solver.n_segments
    assert result.state.shape == (n, 3) and result.beta.shape == (n,)
    assert result.coefficients.shape == (n, 4) and result.nodes.shape == (n + 1, 2)
    assert result.points.shape == (129, 2) and result.strains.shape == (129, 3)
    np.testing.assert_allclose(result.points[0], 0.0, atol=0)
    np.testing.assert_allclose(result.points[-1], result.tip, atol=0)
    np.testing.assert_allclose(result.nodes[-1], result.tip, atol=0)
    np.testing.assert_allclose(result.beta.sum(), result.state[-1, 0], rtol=1e-14)
    # Samples lie on the arcs: at a segment edge they are the node, and consecutive samples
    # in one segment are a chord of a circle of radius (1 + eps)/|kappa|.
    s = np.linspace(0.0, design.free_length, 129)
    at_edge = np.isclose(s[:, None], solver.edges[None, :], rtol=0, atol=1e-15)
    rows, nodes = np.nonzero(at_edge)
    np.testing.assert_allclose(result.points[rows], result.nodes[nodes], atol=1e-15)
    eps, kappa = result.strains[0, 0], result.strains[0, 1]
    step = s[1] - s[0]
    chord = np.linalg.norm(result.points[1] - result.points[0])
    radius = (1.0 + eps) / abs(kappa)
    np.testing.assert_allclose(chord, 2.0 * radius * math.sin(step * abs(kappa) / 2.0),
                               rtol=1e-12)
    assert np.isfinite(result.curvature) and result.valid and result.fit_rmsd >= 0.0
    assert result.energy == pytest.approx(
        solver.energy(solver._pack(result.state), 1e5, [(n, np.array([0.2, -0.1]))]))
    with pytest.raises(ValueError, match='initial'):
        solver.solve(0.0, initial=PCCSolver(design, n_segments=41).solve(0.0))
    with pytest.raises(ValueError, match='n_segments'):
        PCCSolver(design, n_segments=0)
    with pytest.raises(ValueError, match='pressure_model'):
        PCCSolver(design, pressure_model='isothermal')
    with pytest.raises(ValueError, match='node'):
        solver.derivatives(solver.flat(), 0.0, [(n + 1, np.array([1.0, 0.0]))])
