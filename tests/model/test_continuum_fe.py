"""The continuum FE: its law's exact derivatives, and closed forms it must reproduce."""

import numpy as np
from numpy.testing import assert_allclose
import pytest
from scipy.linalg import polar

from fpc_gripper.model import ActuatorDesign, Material
from fpc_gripper.model.continuum.material import (biot_response, BiotMaterial,
                                                  linear_material, pemc_material,
                                                  stretch_response, volume_response)

pytest.importorskip('skfem')

from fpc_gripper.model.continuum.fe import Strip  # noqa: E402, I100

LAWS = {
    'linear': linear_material(Material(1.2e6, 1.2e6, 0.48), eigenstrain=0.01),
    'decoupled': linear_material(Material(263e6, 263e6, 0.43), poisson=False),
    'pemc': pemc_material(ActuatorDesign.paper().emc_coefficients, 0.25),
    # The channel band's effective law: its through-thickness mu_z apart from its shear.
    'band': BiotMaterial((7.8e5, 0.0, 0.0, 0.0), 4.05e5, 1.0e5, 0.0, mu_z=5.0e4),
}


def _params(law):
    return law.params


def _deformation(angle, seed):
    """A displacement gradient: a rotation by `angle` of a random stretch-and-shear."""
    rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    stretch = np.eye(2) + 0.15 * np.random.default_rng(seed).standard_normal((2, 2))
    return rotation @ stretch - np.eye(2)


@pytest.mark.parametrize('name', ['decoupled', 'band'])
@pytest.mark.parametrize('angle', [0.0, 1.3, 3.0, -2.4])
def test_the_biot_strain_is_the_polar_stretch(angle, name):
    grad = _deformation(angle, 1)
    law = LAWS[name]
    psi = biot_response(grad, _params(law))[0]
    _, stretch = polar(np.eye(2) + grad)
    e = stretch - np.eye(2)
    mu_z = law.mu if law.mu_z is None else law.mu_z
    expected = law.coefficients[0] * e[0, 0] ** 2 + mu_z * e[1, 1] ** 2 \
        + 2 * law.mu * e[0, 1] ** 2 + 0.5 * law.lam * (e[0, 0] + e[1, 1]) ** 2
    assert_allclose(psi, expected, rtol=1e-12)


@pytest.mark.parametrize('name', sorted(LAWS))
@pytest.mark.parametrize('angle', [0.2, 2.9, -1.7])
def test_stress_and_tangent_against_finite_differences(name, angle):
    grad = _deformation(angle, 2)
    params = _params(LAWS[name])
    _, stress, tangent = biot_response(grad, params)
    h = 1e-6
    scale = np.abs(tangent).max()
    for i in range(2):
        for j in range(2):
            up, down = grad.copy(), grad.copy()
            up[i, j] += h
            down[i, j] -= h
            psi_up, stress_up, _ = biot_response(up, params)
            psi_down, stress_down, _ = biot_response(down, params)
            assert_allclose((psi_up - psi_down) / (2 * h), stress[i, j], atol=1e-8 * scale)
            assert_allclose((stress_up - stress_down) / (2 * h), tangent[:, :, i, j],
                            atol=1e-7 * scale)
    assert_allclose(tangent, tangent.transpose(2, 3, 0, 1), atol=1e-12 * scale)


def test_a_rigid_rotation_is_stress_free():
    angle = 2.0
    rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    for name in ('linear', 'decoupled'):
        law = LAWS[name]
        params = _params(law)
        params[6] = 0.0
        psi, stress, _ = biot_response(rotation - np.eye(2), params)
        assert abs(psi) < 1e-9 * law.mu and np.abs(stress).max() < 1e-9 * law.mu


@pytest.mark.parametrize('response', [volume_response, stretch_response])
def test_gas_volume_derivatives(response):
    grad = _deformation(0.7, 4)
    value, first, second = response(grad)
    if response is volume_response:
        assert_allclose(value, np.linalg.det(np.eye(2) + grad))
    else:
        assert_allclose(value, np.linalg.norm((np.eye(2) + grad)[:, 0]))
    h = 1e-6
    for i in range(2):
        for k in range(2):
            up, down = grad.copy(), grad.copy()
            up[i, k] += h
            down[i, k] -= h
            assert_allclose((response(up)[0] - response(down)[0]) / (2 * h), first[i, k],
                            atol=1e-8)
            assert_allclose((response(up)[1] - response(down)[1]) / (2 * h), second[:, :, i, k],
                            atol=1e-8)


def _strip(element_size=1e-3, **kwargs):
    """A two-layer strip with a channel band: PEMC below, an elastomer band with gas above."""
    laws = [LAWS['pemc'], linear_material(Material(1.2e6, 1.2e6, 0.48)),
            linear_material(Material(263e6, 263e6, 0.43), poisson=False)]
    cell_law = np.array([[0, 1, 2], [0, 1, 2]])
    gas = np.array([[0.0, 0.02, 0.0], [0.0, 0.0, 0.0]])
    return Strip([0.0, 4e-3, 6e-3], [-2e-3, 0.0, 1e-3, 1.4e-3], cell_law, laws,
                 0.03 - gas, gas, element_size, **kwargs)


@pytest.mark.parametrize('gas_model', ['area', 'axial'])
def test_the_total_potential_has_the_exact_gradient_and_hessian(gas_model):
    strip = _strip(gas_model=gas_model)
    rng = np.random.default_rng(5)
    u = 2e-4 * rng.standard_normal(strip.n_dofs)
    loads = dict(level=0.8, pressure_work=2.5e5, tip_force=(0.3, -0.2))
    energy, grad, hess = strip.derivatives(u, **loads)
    assert_allclose(energy, strip.energy(u, **loads), rtol=1e-14)
    for seed in range(3):
        v = 1e-9 * np.random.default_rng(seed).standard_normal(strip.n_dofs)
        de = (strip.energy(u + v, **loads) - strip.energy(u - v, **loads)) / 2
        assert_allclose(de, grad @ v, rtol=1e-7)
        dg = (strip.derivatives(u + v, **loads)[1] - strip.derivatives(u - v, **loads)[1]) / 2
        assert_allclose(dg, hess @ v, atol=1e-7 * np.abs(hess @ v).max())
    assert abs(hess - hess.T).max() < 1e-9 * abs(hess).max()


def _timoshenko_bimetal(t1, t2, e1, e2, mismatch):
    """Curvature of a free bimetal strip [1/m] (Timoshenko 1925), moduli already reduced."""
    m, n, h = t1 / t2, e1 / e2, t1 + t2
    denominator = 3 * (1 + m) ** 2 + (1 + m * n) * (m ** 2 + 1 / (m * n))
    return 6 * mismatch * (1 + m) ** 2 / (h * denominator)


@pytest.mark.parametrize('e_bottom, e_top, t_bottom, t_top', [
    (1e6, 200e6, 1e-3, 1e-3),          # the stiffness contrast of EMC against the CL
    (1.2e6, 1.2e6, 1.5e-3, 0.5e-3),
    (5e6, 1e6, 0.6e-3, 1.4e-3),
])
def test_bimetal_strip_curls_as_timoshenko_says(e_bottom, e_top, t_bottom, t_top):
    nu, mismatch, half_length = 0.3, 2e-4, 30e-3
    # The bottom layer shrinks by `mismatch`; x = 0 is the strip's plane of symmetry.
    laws = [linear_material(Material(e_bottom, e_bottom, nu), -mismatch),
            linear_material(Material(e_top, e_top, nu))]
    strip = Strip([0.0, half_length], [-t_bottom, 0.0, t_top], np.array([[0, 1]]), laws,
                  np.ones((1, 2)), np.zeros((1, 2)), 1e-3, support='symmetry')
    out = strip.solve()
    assert out.success, out.message
    x, dofs = strip.line_dofs(0.0)
    inner = x < half_length / 2       # away from the free end's boundary layer
    big_x, big_z = x + out.u[dofs[0]], out.u[dofs[1]]
    curvature = -2 * np.polyfit(big_x[inner], big_z[inner], 2)[0]
    reduced = 1 - nu ** 2             # plane strain: E' = E / (1 - nu^2)
    expected = _timoshenko_bimetal(t_bottom, t_top, e_bottom / reduced, e_top / reduced,
                                   mismatch)
    assert_allclose(curvature, expected, rtol=1e-3)


def test_cantilever_tip_deflection_is_euler_bernoulli_plus_shear():
    # Timoshenko & Goodier, section 21: the exact plane-stress field of an end-loaded
    # cantilever whose root's vertical element is held; plane strain by E' = E/(1 - nu^2),
    # nu' = nu/(1 - nu). Its root displacement is prescribed, the tip traction is parabolic.
    young, nu, length, depth, force = 1e6, 0.3, 10e-3, 2e-3, 2e-3
    e_p, nu_p = young / (1 - nu ** 2), nu / (1 - nu)
    shear = young / (2 * (1 + nu))
    c = depth / 2
    inertia = depth ** 3 / 12           # per unit width (the strip's width is 1 m)
    c1 = force * c ** 2 / (2 * inertia * shear)

    def root(x, z):
        ux = nu_p * force * z ** 3 / (6 * e_p * inertia) - force * z ** 3 / (
            6 * inertia * shear) + (force * c ** 2 / (2 * inertia * shear) - c1) * z
        uz = nu_p * force * length * z ** 2 / (2 * e_p * inertia)
        return ux, uz

    law = [linear_material(Material(young, young, nu))]
    strip = Strip([0.0, length], [-c, 0.0, c], np.zeros((1, 2), int), law, np.ones((1, 2)),
                  np.zeros((1, 2)), 0.5e-3, support=root,
                  tip_profile=lambda z: 1.5 / depth * (1 - (z / c) ** 2))
    out = strip.solve(tip_force=(0.0, force))
    assert out.success, out.message
    deflection = out.u[strip.vertex_dofs(length, 0.0)[1]]
    bending = force * length ** 3 / (3 * e_p * inertia)
    expected = bending + 1.5 * force * length / (shear * depth)
    assert expected > 1.02 * bending    # the shear term matters at L/h = 5
    assert_allclose(deflection, expected, rtol=1e-3)


@pytest.mark.parametrize('gas_model', ['axial', 'area'])
def test_the_gas_potential_is_minus_pressure_times_the_deformed_gas_volume(gas_model):
    # A gas band between two solid layers. Under a uniform stretch eps of everything and a
    # uniform through-thickness strain e of the band alone, the gas volume is g h L (1 + eps)
    # by the beam rungs' measure ('axial') and g h L (1 + eps)(1 + e) by area ('area').
    solid = linear_material(Material(263e6, 263e6, 0.0), poisson=False)
    length, h_band, t_layer, gas_width, p_work = 10e-3, 1e-3, 0.5e-3, 0.02, 2e5
    strip = Strip([0.0, length], [-h_band / 2 - t_layer, -h_band / 2, 0.0, h_band / 2,
                                  h_band / 2 + t_layer], np.zeros((1, 4), int), [solid],
                  np.full((1, 4), 0.01), np.array([[0.0, gas_width, gas_width, 0.0]]), 1e-3,
                  gas_model=gas_model)
    eps, e = 0.03, -0.2
    x, z = strip.basis.doflocs
    u = np.where(np.arange(strip.n_dofs) % 2 == 0, eps * x,
                 e * np.clip(z, -h_band / 2, h_band / 2))
    assert set(np.unique(strip.basis.nodal_dofs[0] % 2)) == {0}    # u_x, u_z interleaved
    gas = strip.energy(u, pressure_work=p_work) - strip.energy(u)
    volume = gas_width * h_band * length * (1 + eps) * ((1 + e) if gas_model == 'area' else 1)
    assert_allclose(gas, -p_work * volume, rtol=1e-12)
