"""The channel cross-section FE: a clamped roof's closed form, and the band law it sets."""

import numpy as np
from numpy.testing import assert_allclose
import pytest

from fpc_gripper.model import ActuatorDesign, Material
from fpc_gripper.model.continuum.material import BiotMaterial, linear_material

pytest.importorskip('skfem')

from fpc_gripper.model.continuum import ContinuumSolver  # noqa: E402, I100
from fpc_gripper.model.continuum.fe import Strip  # noqa: E402
from fpc_gripper.model.continuum.section import ChannelSection  # noqa: E402


def test_a_pressurised_roof_bends_as_a_clamped_timoshenko_strip():
    """A roof over a void between rigid walls: w = p b^4/(384 D) + p b^2/(8 k G t)."""
    e, nu, t, b, gap, floor, wall = 1e6, 0.3, 0.5e-3, 10e-3, 1e-3, 0.5e-3, 1e-3
    law = linear_material(Material(e, e, nu), poisson=True)
    # Half the span (symmetry face y = 0); floor, wall and the roof over the wall 1e4
    # times stiffer (rigid, so the roof is built in at y = b/2); the void's ersatz 1e-9.
    width = np.array([[1e4, 1e-9, 1.0], [1e4, 1e4, 1e4]])
    gas = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
    strip = Strip([0.0, b / 2, b / 2 + wall], [0.0, floor, floor + gap, floor + gap + t],
                  np.zeros((2, 3), dtype=int), [law], width, gas, 0.25e-3,
                  support='symmetry')
    rigidity = e / (1 - nu ** 2) * t ** 3 / 12
    shear = e / (2 * (1 + nu))
    bending = b ** 4 / (384 * rigidity)
    pressure = 0.005 * t / bending          # w/t = 0.005: linear
    expected = pressure * (bending + b ** 2 / (8 * 5 / 6 * shear * t))
    out = strip.solve(pressure)
    assert out.success, out.message
    deflection = out.u[strip.vertex_dofs(0.0, floor + gap + t / 2)[1]]
    # The shear term is 3.4 % here: without it the check fails.
    assert_allclose(deflection, expected, rtol=0.01)


def test_the_band_law_grows_the_band_as_the_section_grows_the_channel():
    """Under k_p P alone, a band with `band_moduli`'s mu_z has the section's area strain."""
    design = ActuatorDesign.paper()
    work = 5e3
    fe = ContinuumSolver(design, element_size=5e-3, channel='section')
    moduli = fe.band_moduli(work)
    strains = fe.section_strains(work)
    fluidic = fe.view.laws[1]
    open_gas = design.Cy - design.t
    rib_gas = open_gas - 2 * design.w1
    for at_rib, gas in ((False, open_gas), (True, rib_gas)):
        # A band cell, its stretch along X held by a stiff fibre law: the channel's
        # cross-section is in plane strain along X.
        law = BiotMaterial((1e6 * fluidic.coefficients[0], 0.0, 0.0, 0.0), fluidic.mu,
                           fluidic.lam, 0.0, moduli[at_rib])
        band = Strip([0.0, 1e-3], [0.0, design.h3a + design.h3b], np.zeros((1, 1), int),
                     [law], np.array([[design.Ly - gas]]), np.array([[gas]]), 1e-3,
                     support='symmetry')
        out = band.solve(work)
        assert out.success, out.message
        area = band.gas_volume(out.u) / (gas * 1e-3 * (design.h3a + design.h3b)) - 1.0
        assert_allclose(area, strains[at_rib].area_strain, rtol=1e-5)
    # The section's channel grows more than the homogenised band (its roof bulges).
    assert moduli[False] < fluidic.mu and moduli[True] < fluidic.mu


def test_the_void_ersatz_does_not_carry_the_pressure():
    design = ActuatorDesign.paper()
    soft = ChannelSection(design, True, element_size=1e-3, void_stiffness=1e-8).solve(25e3)
    default = ChannelSection(design, True, element_size=1e-3).solve(25e3)
    assert_allclose(default.area_strain, soft.area_strain, rtol=1e-4)


def test_channel_section_refuses_what_it_cannot_model():
    with pytest.raises(ValueError, match='at_rib'):
        ChannelSection(ActuatorDesign.paper(ribs=False), at_rib=True)
    with pytest.raises(ValueError, match='pressure_work'):
        ChannelSection(ActuatorDesign.paper(), element_size=2e-3).solve(-1.0)
    with pytest.raises(ValueError, match='channel'):
        ContinuumSolver(ActuatorDesign.paper(), element_size=5e-3, ribs='average',
                        channel='section')
