"""The channel's cross-section (Y-Z plane) under pressure: the area growth of the channel."""

from dataclasses import dataclass

import numpy as np

from .body import layer_cells
from .fe import Strip
from .material import BiotMaterial, linear_material
from ..validation import ArgumentError, real_number

__all__ = ['ChannelSection', 'SectionSolution', 'section_laws']

#: Solid width of a void cell [-]: the channel's interior is a soft ersatz (the fluidic
#: layer's law at this fraction) so that the tensor mesh keeps its nodes there. Against
#: the channel's walls it is about 1e-5 of their stiffness (tests/model/
#: test_continuum_section.py holds the area's change to 1e-4 when it is 100 times smaller).
VOID_STIFFNESS = 1e-6


def section_laws(design, poisson=False):
    """
    Return the laws of the cross-section (axis 1 along Y, axis 2 along Z).

    Order: PEMC, fluidic layer, EMC, constraining layer, as `body.LAW_NAMES`. Along Y the
    EMC and the PEMC carry their fibres' Q22 (section 3: the PEMC is the regular EMC
    across X), across them (Z) E1 of the EMC, and the PEMC's a4, with nu = 0 and shear
    modulus E/2; the isotropic laminae are the side view's laws (`linear_material`). The
    prestrain acts along X only: plane strain along X leaves it out.

    Parameters
    ----------
    design : ActuatorDesign
    poisson : bool
        The fluidic and constraining layers' in-plane Poisson coupling, as the side view's.

    """
    emc = design.emc
    a4 = float(design.emc_coefficients[3])
    return (BiotMaterial((0.5 * emc.Q22, 0.0, 0.0, 0.0), 0.5 * a4, 0.0),
            linear_material(design.fluidic_layer, poisson=poisson),
            BiotMaterial((0.5 * emc.Q22, 0.0, 0.0, 0.0), emc.E1 / (2.0 * (1.0 + emc.nu)),
                         0.0),
            linear_material(design.constraining_layer, poisson=poisson))


@dataclass(frozen=True)
class SectionSolution:
    """
    Outcome of `ChannelSection.solve`.

    Attributes
    ----------
    pressure_work : float
        k_p P [Pa].
    area_strain : float
        Deformed channel area over the reference one, minus one [-].
    wall_strain : float
        Height change of the side wall's face to the channel (y = Cy/2) over the channel
        height [-]: the part of the growth that moves the layers apart.
    roof, floor : float
        Displacement along Z of the channel's ceiling and floor at the middle of the widest
        gas span [m].
    success : bool
    message : str
    u : ndarray
        Displacements [m].

    """

    pressure_work: float
    area_strain: float
    wall_strain: float
    roof: float
    floor: float
    success: bool
    message: str
    u: np.ndarray


class ChannelSection:
    """
    Half the finger's cross-section (0 <= y <= Ly/2) with the channel as a void.

    Plane strain along X (no load or strain along the finger), total Lagrangian, solved
    by the side view's FE (`fe.Strip`: the same elements, laws, gas potential and Newton
    loop). The channel (z in [-h3b, h3a], t/2 < |y| < Cy/2, less a transverse rib's
    3t/2 < |y| < 3t/2 + w1 at a rib) is a void whose gas term is -k_p P times its deformed
    area: the exact potential of a follower pressure on its roof, floor and walls. The
    roof and floor span the gas between the longitudinal rib and the side wall (or the
    transverse rib); the face y = 0 is the longitudinal rib's symmetry plane. Per unit
    length along X; the ribs' support of the roof along X is left out (plane strain), so
    between ribs the roof's bulge is an upper bound.

    Parameters
    ----------
    design : ActuatorDesign
    at_rib : bool
        The section through a transverse rib (True) or between ribs (False).
    poisson : bool
        As `ContinuumSolver`'s `poisson`.
    element_size : float
        Largest element edge [m]; 0.5 mm is within 0.5 % of the area growth at 0.25 mm.
    void_stiffness : float
        Solid width of the void's ersatz [-] (`VOID_STIFFNESS`).

    """

    def __init__(self, design, at_rib=False, poisson=False, element_size=0.5e-3,
                 void_stiffness=VOID_STIFFNESS):
        if at_rib and not design.ribs:
            raise ArgumentError('at_rib', 'True needs a design with ribs, got ribs=False')
        t, w1 = design.t, design.w1
        y = [0.0, t / 2, design.Cy / 2, design.Ly / 2]
        if design.ribs:
            y += [3 * t / 2, 3 * t / 2 + w1]
        y_breaks = np.unique(np.round(np.array(y), 12))
        z_breaks, cell_law = layer_cells(design, y_breaks)
        yc = 0.5 * (y_breaks[1:] + y_breaks[:-1])
        zc = 0.5 * (z_breaks[1:] + z_breaks[:-1])
        gas_y = (yc > t / 2) & (yc < design.Cy / 2)
        if at_rib:
            gas_y &= ~((yc > 3 * t / 2) & (yc < 3 * t / 2 + w1))
        band = (zc > -design.h3b) & (zc < design.h3a)
        void = gas_y[:, None] & band[None, :]
        # Per metre along X: solid width 1, the void's ersatz void_stiffness.
        width = np.where(void, float(void_stiffness), 1.0)
        self.design = design
        self.at_rib = bool(at_rib)
        self.strip = Strip(y_breaks, z_breaks, cell_law, section_laws(design, poisson),
                           width, void.astype(float), element_size, support='symmetry')
        self.area = float(np.sum(np.diff(y_breaks)[gas_y])) * (design.h3a + design.h3b)
        # The widest gas span's middle, and the wall's face to the channel.
        spans = [(lo, hi) for lo, hi in zip(y_breaks, y_breaks[1:])
                 if gas_y[np.searchsorted(yc, 0.5 * (lo + hi))]]
        lo, hi = max(spans, key=lambda span: span[1] - span[0])
        mid = self._vertex_near(0.5 * (lo + hi))
        self._roof = self.strip.vertex_dofs(mid, design.h3a)[1]
        self._floor = self.strip.vertex_dofs(mid, -design.h3b)[1]
        wall = design.Cy / 2
        self._wall = (self.strip.vertex_dofs(wall, design.h3a)[1],
                      self.strip.vertex_dofs(wall, -design.h3b)[1])

    def _vertex_near(self, y):
        """Return the mesh's vertex column nearest y [m]."""
        columns = np.unique(self.strip.mesh.p[0])
        return float(columns[np.argmin(np.abs(columns - y))])

    def solve(self, pressure_work):
        """
        Inflate the channel by k_p P from the stress-free state.

        Parameters
        ----------
        pressure_work : float
            k_p P [Pa], >= 0.

        Returns
        -------
        SectionSolution

        """
        pressure_work = real_number('pressure_work', pressure_work, '[Pa]')
        if pressure_work < 0.0:
            raise ArgumentError('pressure_work', f'must be >= 0 [Pa], got {pressure_work}')
        out = self.strip.solve(pressure_work)
        u = out.u
        height = self.design.h3a + self.design.h3b
        return SectionSolution(
            pressure_work=pressure_work,
            area_strain=self.strip.gas_volume(u) / self.area - 1.0,
            wall_strain=float(u[self._wall[0]] - u[self._wall[1]]) / height,
            roof=float(u[self._roof]), floor=float(u[self._floor]), success=out.success,
            message=out.message, u=u)
