"""position_at of every rung against the rung's kinematics written out independently."""

import numpy as np
import pytest
from scipy.interpolate import BarycentricInterpolator
from scipy.optimize import root
from scipy.special import roots_jacobi, roots_legendre

from fpc_gripper.model import (ActuatorDesign, AdaptiveSolver, ArcSolver, CCMSolver, PCCSolver,
                               RodSolver)

DESIGN = ActuatorDesign.paper(prestrain=0.25)
L = DESIGN.free_length
#: Arc lengths inside segments, on no edge [m].
INSIDE = np.array([0.0037, 0.0213, 0.0449, 0.0611, 0.0871])


def _rotate(theta, vector):
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * vector[..., 0] - s * vector[..., 1],
                     s * vector[..., 0] + c * vector[..., 1]], axis=-1)


@pytest.mark.parametrize('reconstruction', ['paper', 'consistent'])
def test_ccm_positions_are_the_segment_polynomials(reconstruction):
    solver = CCMSolver(DESIGN, n_segments=6, reconstruction=reconstruction)
    result = solver.solve(120e3, (0.1, 0.2))
    edges = solver.segments.edges
    np.testing.assert_allclose(result.position_at(edges), result.nodes, rtol=0, atol=1e-15)
    np.testing.assert_allclose(result.position_at(L), result.tip, rtol=0, atol=1e-15)
    # Eqs. (13) and (15) written out from the SI coefficients.
    seg = np.searchsorted(edges, INSIDE) - 1
    x = INSIDE - edges[seg]
    b1, b3, _, d = result.coefficients[seg].T
    local = np.stack([(1 + b1) * x + b3 * x ** 3, d * x ** 2], axis=1)
    want = result.nodes[seg] + _rotate(result.theta[seg], local)
    np.testing.assert_allclose(result.position_at(INSIDE), want, rtol=0, atol=1e-15)


def test_arc_positions_are_the_closed_form_arc():
    result = ArcSolver(DESIGN).solve(50e3, (0.0, 0.3))
    eps, kappa, _ = result.state
    s = np.append(INSIDE, L)
    want = (1 + eps) / kappa * np.stack([np.sin(kappa * s), 1 - np.cos(kappa * s)], axis=1)
    np.testing.assert_allclose(result.position_at(s), want, rtol=0, atol=1e-15)
    np.testing.assert_allclose(result.position_at(L), result.tip, rtol=0, atol=1e-15)


def test_pcc_positions_lie_on_the_exact_arcs():
    solver = PCCSolver(DESIGN, n_segments=24)
    result = solver.solve(200e3, (-0.2, 0.4))
    theta, eps, _ = result.state.T
    before = np.concatenate([[0.0], theta[:-1]])
    kappa = (theta - before) / solver.lengths
    # Arcs about their centres of curvature, chained from the clamp.
    chords = (1 + eps)[:, None] / kappa[:, None] * np.stack(
        [np.sin(theta) - np.sin(before), np.cos(before) - np.cos(theta)], axis=1)
    nodes = np.concatenate([[[0.0, 0.0]], np.cumsum(chords, axis=0)])
    np.testing.assert_allclose(result.position_at(solver.edges), nodes, rtol=0, atol=1e-15)
    seg = np.searchsorted(solver.edges, INSIDE) - 1
    sigma = INSIDE - solver.edges[seg]
    start, k = before[seg], kappa[seg]
    want = nodes[seg] + ((1 + eps[seg]) / k)[:, None] * np.stack(
        [np.sin(start + k * sigma) - np.sin(start), np.cos(start) - np.cos(start + k * sigma)],
        axis=1)
    np.testing.assert_allclose(result.position_at(INSIDE), want, rtol=0, atol=1e-15)
    np.testing.assert_allclose(result.position_at(L), result.tip, rtol=0, atol=1e-15)


def test_rod_positions_are_the_integral_of_its_stretched_tangent():
    # An independent quadrature: theta by barycentric interpolation through the element's
    # Gauss-Lobatto nodes (roots of a Jacobi polynomial), eps by solving the pointwise
    # equilibrium dW/d(eps, c1) = (F . t, 0) with scipy, and a 20-point Gauss-Legendre rule
    # (not the rod's 10) of (1 + eps)(cos, sin) theta over every piece from the clamp.
    rod = RodSolver(DESIGN)
    force = np.array([0.1, 0.3])
    result = rod.solve(100e3, tuple(force))
    theta = result.state[0]
    p = rod.degree
    gll = np.concatenate([[-1.0], roots_jacobi(p - 1, 1.0, 1.0)[0], [1.0]])
    work = rod.pressure_coefficient * 100e3

    def fields(s):
        e = min(int(np.searchsorted(rod.edges, s, side='right')) - 1, rod.n_elements - 1)
        lo, hi = rod.edges[e], rod.edges[e + 1]
        curve = BarycentricInterpolator(lo + 0.5 * (gll + 1) * (hi - lo),
                                        theta[e * p:e * p + p + 1])
        return e, float(curve(s)), float(curve.derivative(s))

    def integrand(s):
        e, angle, kappa = fields(s)
        along = force @ [np.cos(angle), np.sin(angle)]

        def equations(v):
            _, grad, hess = rod.law.derivatives([v[0], kappa, v[1]], work,
                                                rod.element_types[e])
            return [grad[0] - along, grad[2]], hess[np.ix_([0, 2], [0, 2])]

        sol = root(equations, [0.0, 0.0], jac=True, tol=1e-15)
        return (1.0 + sol.x[0]) * np.array([np.cos(angle), np.sin(angle)])

    nodes, weights = roots_legendre(20)
    pieces = {}

    def piece(a, b):
        if (a, b) not in pieces:
            pieces[a, b] = 0.5 * (b - a) * sum(w * integrand(a + 0.5 * (b - a) * (t + 1.0))
                                               for t, w in zip(nodes, weights))
        return pieces[a, b]

    for s in (0.0137, 0.0512, L):
        ends = [*rod.edges[rod.edges < s], s]
        want = sum(piece(a, b) for a, b in zip(ends, ends[1:]))
        np.testing.assert_allclose(result.position_at(s), want, rtol=0, atol=1e-11)
    np.testing.assert_allclose(result.position_at(rod.edges[5]), result.nodes[5], rtol=0,
                               atol=1e-15)
    np.testing.assert_allclose(result.position_at(L), result.tip, rtol=0, atol=1e-15)
    samples = np.linspace(0.0, L, rod.samples)
    np.testing.assert_allclose(result.position_at(samples), result.points, rtol=0, atol=1e-15)


def test_positions_are_vectorised_and_refuse_arc_lengths_off_the_finger():
    result = PCCSolver(DESIGN, 22).solve(0.0)
    grid = np.linspace(0.0, L, 6).reshape(2, 3)
    assert result.position_at(grid).shape == (2, 3, 2)
    assert result.position_at(0.03).shape == (2,)
    np.testing.assert_array_equal(result.position_at(0.0), [0.0, 0.0])
    for bad in (-1e-4, L + 1e-4, np.nan, [0.01, 0.2]):
        with pytest.raises(ValueError, match=r'`s` must lie in \[0, 0.09\] \[m\]'):
            result.position_at(bad)
    with pytest.raises(TypeError, match='`s` must be real numbers'):
        result.position_at('tip')


def test_adaptive_and_rigidity_results_have_positions():
    adaptive = AdaptiveSolver(DESIGN, tolerance=5e-5)
    result = adaptive.solve(80e3, (0.0, 0.2))
    np.testing.assert_allclose(result.position_at(L), result.tip, rtol=0, atol=1e-15)
    rigidity = adaptive.rigidity(30e3, 'x')
    np.testing.assert_allclose(rigidity.loaded.position_at(L), rigidity.loaded.tip, rtol=0,
                               atol=1e-15)
    assert rigidity.loaded.position_at(L)[0] == pytest.approx(
        rigidity.unloaded.tip[0] + 0.010, abs=1e-12)
