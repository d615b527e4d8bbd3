"""Exact gradient and Hessian of the CCM potential against finite differences."""

import numpy as np
import pytest
from scipy.optimize._numdiff import approx_derivative

from fpc_gripper.model import ActuatorDesign, CCMSolver
from fpc_gripper.model.analysis import fit_circle
from fpc_gripper.model.kernels.ccm import segment_derivatives
from fpc_gripper.model.kernels.chain import load_derivatives


def _assembled(solver, pressure, loads):
    """Return energy(x), gradient(x), hessian(x) of the flattened scaled unknowns."""
    n = solver.n_segments

    def energy(x):
        return solver._total_energy(x.reshape(n, 4), pressure, loads)

    def gradient(x):
        return solver.derivatives(x.reshape(n, 4), pressure, loads)[1].ravel()

    def hessian(x):
        h = solver.derivatives(x.reshape(n, 4), pressure, loads)[2]
        if h.ndim == 3:
            dense = np.zeros((4 * n, 4 * n))
            for i in range(n):
                dense[4 * i:4 * i + 4, 4 * i:4 * i + 4] = h[i]
            return dense
        return h

    return energy, gradient, hessian


@pytest.mark.parametrize('n_segments', [1, 3, 8])
@pytest.mark.parametrize('with_loads', [False, True])
@pytest.mark.parametrize('pressure_model', ['adiabatic', 'isobaric'])
def test_gradient_and_hessian_match_finite_differences(n_segments, with_loads,
                                                       pressure_model):
    design = ActuatorDesign.paper(prestrain=0.3)
    solver = CCMSolver(design, n_segments=n_segments, pressure_model=pressure_model,
                       load_points=(0.05,) if n_segments > 2 else ())
    rng = np.random.default_rng(n_segments)
    loads = []
    if with_loads:
        loads = solver._loads((0.7, -1.3), [(0.05, -0.4, 0.9)] if n_segments > 2 else [])
    energy, gradient, hessian = _assembled(solver, 150e3, loads)
    for _ in range(3):
        x = rng.normal(scale=0.15, size=4 * n_segments)
        g = gradient(x)
        h = hessian(x)
        g_fd = approx_derivative(energy, x, method='3-point', abs_step=1e-6)
        h_fd = approx_derivative(gradient, x, method='3-point', abs_step=1e-6)
        np.testing.assert_allclose(g, g_fd, rtol=1e-6, atol=1e-7 * np.abs(g).max())
        np.testing.assert_allclose(h, h_fd, rtol=1e-6, atol=1e-7 * np.abs(h).max())
        np.testing.assert_allclose(h, h.T, rtol=0, atol=1e-12 * np.abs(h).max())


def test_load_hessian_couples_every_earlier_rotation():
    # A tip load makes the Hessian dense; a load at node 2 of 5 touches only segments 0-1.
    design = ActuatorDesign.paper()
    solver = CCMSolver(design, n_segments=5)
    q = np.random.default_rng(1).normal(scale=0.1, size=(5, 4))
    _, grad, hess = load_derivatives(q, solver.segments.lengths, [(2, np.array([0.5, 0.5]))])
    # Exact: structural zeros, entries the load never writes into the zero-filled arrays.
    assert np.all(grad[2:] == 0.0)
    assert np.all(hess[8:, :] == 0.0) and np.all(hess[:, 8:] == 0.0)
    assert np.any(hess[:4, 4:8] != 0.0)


def test_segment_energy_is_exact_quadrature():
    # The Gauss rule must integrate the quintic PEMC law exactly: a 12x6 rule agrees.
    design = ActuatorDesign.paper(prestrain=0.4)
    solver = CCMSolver(design, n_segments=2)
    seg = solver.segments
    q = np.array([[0.05, -0.02, 0.01, -0.3], [-0.1, 0.04, -0.02, 0.2]])
    energy = segment_derivatives(q, seg, 0.4, design.emc_coefficients, 0.0)[0]
    xg, wx = np.polynomial.legendre.leggauss(12)
    zg, wz = np.polynomial.legendre.leggauss(6)
    a1, a2, a3, a4 = design.emc_coefficients
    total = []
    for i, length in enumerate(seg.lengths):
        b1, b3, c1, d = q[i, 0], q[i, 1] / length ** 2, q[i, 2], q[i, 3] / length
        x = 0.5 * length * (xg + 1.0)
        z0, z1 = -design.H / 2, -design.h3
        z = z0 + 0.5 * (z1 - z0) * (zg + 1.0)
        e = b1 + (3 * b3 + 2 * d * d) * x[:, None] ** 2 - 2 * z[None, :] * d
        s = 0.4 + e
        dens = a1 * s ** 5 / 5 + a2 * s ** 4 / 4 + a3 * s ** 3 / 3 + a4 * s ** 2 / 2
        pemc = design.Ly * 0.25 * length * (z1 - z0) * (wx[:, None] * wz[None, :] * dens).sum()
        pemc += 0.5 * design.emc.Q22 * c1 ** 2 * design.Ly * length * (z1 - z0)
        total.append(pemc)
    y = np.stack([q[:, 0], 3 * q[:, 1] + 2 * q[:, 3] ** 2, q[:, 3], q[:, 2]], axis=1)
    linear = 0.5 * np.einsum('na,nab,nb->n', y, seg.stiffness, y)
    pemc_y = 0.5 * design.emc.Q22 * q[:, 2] ** 2 * design.Ly * seg.lengths * (
        design.H / 2 - design.h3)
    np.testing.assert_allclose(energy - linear + pemc_y, total, rtol=1e-12)


@pytest.mark.parametrize('radius', [0.02, 0.5, -0.07])
def test_circle_fit_recovers_exact_arcs_with_sign(radius):
    # An arc leaving the origin along +X; positive radius curls towards -Z.
    s = np.linspace(0.0, 0.09, 40)
    phi = s / radius
    pts = np.stack([radius * np.sin(phi), -radius * (1 - np.cos(phi))], axis=1)
    fit = fit_circle(pts)
    assert fit.curvature == pytest.approx(1.0 / radius, rel=1e-9)
    assert fit.rmsd < 1e-12


def test_circle_fit_is_regular_for_a_straight_line():
    pts = np.stack([np.linspace(0, 0.09, 30), np.zeros(30)], axis=1)
    fit = fit_circle(pts)
    assert abs(fit.curvature) < 1e-9
    assert fit.rmsd < 1e-12


def test_circle_fit_rmsd_is_the_orthogonal_distance():
    rng = np.random.default_rng(3)
    theta = np.linspace(0, 2.0, 200)
    r = 0.05 + rng.normal(scale=1e-4, size=theta.size)
    pts = np.stack([r * np.sin(theta), -(0.05 - r * np.cos(theta))], axis=1)
    fit = fit_circle(pts)
    dist = np.hypot(*(pts - fit.center).T) - 1.0 / abs(fit.curvature)
    assert fit.rmsd == pytest.approx(np.sqrt(np.mean(dist ** 2)), rel=1e-9)
    assert fit.curvature == pytest.approx(20.0, rel=1e-3)


def test_circle_distance_jacobian_matches_finite_differences():
    from fpc_gripper.model.analysis import _distance_jacobian, _signed_distances
    rng = np.random.default_rng(5)
    x, z = rng.normal(size=(2, 30))
    r2 = x * x + z * z
    for params in ((0.3, -0.2, 0.7), (0.0, 0.1, -1.2), (-0.8, 0.05, 2.5)):
        params = np.array(params)
        fd = approx_derivative(lambda p: _signed_distances(p, x, z, r2), params,
                               method='3-point', abs_step=1e-7)
        np.testing.assert_allclose(_distance_jacobian(params, x, z, r2), fd, rtol=1e-6,
                                   atol=1e-8)
