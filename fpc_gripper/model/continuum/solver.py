"""`ContinuumSolver`: a design's side view solved by the FE, returned as a finger `Result`."""

import numpy as np

from .body import side_view
from .fe import Strip, StripSolution
from .material import BiotMaterial
from .section import ChannelSection
from ..analysis import fit_circle
from ..engine import SolverStatus
from ..result import FINGER_FIELDS, Result
from ..validation import (ArgumentError, check_pressure_model, PRESSURE_MODELS, real_number,
                          real_pair)

__all__ = ['ContinuumSolver']


class ContinuumSolver:
    """
    The continuum rung: a 2-D plane-strain, total-Lagrangian finite-strain FE of the finger.

    Offline and slow (seconds to a minute per solve): the accuracy reference of the beam
    rungs, not a model for the node. Idealisations (docs/physics.md, section 18): plane
    strain across the width; every lamina with its Q11 along X and, by default, no X-Z
    Poisson coupling (`poisson`), shear modulus E1/(2 (1 + nu)); the PEMC with the
    project's stress law along X and E = a4, nu = 0 across it; hyperelastic
    in the Biot strain, so that a fibre's strain is its stretch minus one as in the section
    law; the channel homogenised across the width (`body.side_view`); the gas potential
    -k_p P V with V the gas width times the band's deformed area; the clamp face x = 0
    fixed; the tip force a dead load spread evenly over the tip face.

    Parameters
    ----------
    design : ActuatorDesign
    ribs : {'exact', 'average'}
        Discrete transverse ribs, or ribs smeared at their coverage.
    element_size : float
        Largest element edge [m], in (0, 5e-3].
    pressure_model : {None, 'design', 'adiabatic', 'isobaric'}
        k_p as the beam rungs take it.
    poisson : bool
        The linear laminae's X-Z Poisson coupling (`material.linear_material`). False (the
        default) keeps their thickness in pure bending, as the section law does; True is
        the isotropic plane-strain law, whose thinning moves the unloaded tip by ~3 mm.
    gas_model : {'area', 'axial'}
        'area': the gas volume is the gas width times the channel band's deformed area, the
        exact potential of a follower pressure on its walls. 'axial': the beam rungs'
        volume, the band's X-fibre stretch, without the channel's growth through the
        thickness (`fe.Strip`).
    channel : {'band', 'section'}
        'band' (the default): the homogenised band's through-thickness law is the fluidic
        layer's. 'section': under pressure, the band's through-thickness stiffness `mu_z`
        is set per scene so that, under k_p P alone, the band's area grows as the channel
        cross-section's (`section.ChannelSection`, a void with its roof, floor and walls):
        between ribs as the section between ribs, at a rib as the section through it
        (`band_moduli`). Needs ribs='exact' and gas_model='area'; unpressurised it is
        'band'.

    """

    def __init__(self, design, ribs='exact', element_size=1e-3, pressure_model=None,
                 poisson=False, gas_model='area', channel='band'):
        size = real_number('element_size', element_size, '[m]')
        if not 0.0 < size <= 5e-3:
            raise ArgumentError('element_size', f'must be in (0, 0.005] [m], got {size}')
        if channel not in ('band', 'section'):
            raise ArgumentError('channel', f"must be 'band' or 'section', got {channel!r}")
        if channel == 'section' and (ribs != 'exact' or gas_model != 'area'):
            raise ArgumentError('channel', "'section' needs ribs='exact' and "
                                f"gas_model='area', got {ribs!r} and {gas_model!r}")
        name = check_pressure_model(pressure_model)
        self.design = design
        self.pressure_work_factor = design.pressure_work_factor if name == 'design' \
            else PRESSURE_MODELS[name]
        self.view = side_view(design, ribs, poisson)
        self.ribs = ribs
        self.element_size = size
        self.channel = channel
        self.poisson = bool(poisson)
        self.strip = Strip(self.view.x_breaks, self.view.z_breaks, self.view.cell_law,
                           self.view.laws, self.view.width, self.view.gas_width, size,
                           gas_model=gas_model)
        self._x, self._mid = self.strip.line_dofs(0.0)
        self._tip = self.strip.vertex_dofs(design.free_length, 0.0)
        self._sections = {}
        self.model = f'continuum h={size * 1e3:.3g} mm, ribs {ribs}, gas {gas_model}' \
            + (', channel section' if channel == 'section' else '')

    def section_strains(self, pressure_work):
        """
        Area strain of the channel cross-section between ribs and at a rib under k_p P.

        Parameters
        ----------
        pressure_work : float
            k_p P [Pa].

        Returns
        -------
        dict
            {False: SectionSolution between ribs, True: at a rib (designs with ribs)}.

        """
        key = float(pressure_work)
        if key not in self._sections:
            kinds = (False, True) if self.design.ribs else (False,)
            self._sections[key] = {
                at_rib: ChannelSection(self.design, at_rib, self.poisson).solve(key)
                for at_rib in kinds}
        return self._sections[key]

    def band_moduli(self, pressure_work):
        """
        Return the band's effective through-thickness stiffness mu_z [Pa], between ribs, at a rib.

        Under k_p P alone (no stretch along X) the band of solid width w and gas width g
        carries (2 mu_z + lam) w e = k_p P g, and its area strain is e; mu_z makes e the
        cross-section's area strain a: mu_z = (k_p P g / (w a) - lam) / 2, the secant
        stiffness of the channel's growth at that pressure.

        Returns
        -------
        dict
            {at_rib: mu_z}; raises ValueError if a section has no equilibrium there.

        """
        band = self.view.gas_width > 0.0
        fluidic = self.view.laws[1]
        out = {}
        for at_rib, sol in self.section_strains(pressure_work).items():
            if not sol.success:
                where = 'at a rib' if at_rib else 'between ribs'
                raise ValueError(f'the channel cross-section ({where}) has no equilibrium '
                                 f'at k_p P = {pressure_work:g} [Pa]: {sol.message}')
            cells = band & (self.view.at_rib[:, None] == at_rib)
            g = float(self.view.gas_width[cells][0])
            w = float(self.view.width[cells][0])
            out[at_rib] = 0.5 * (pressure_work * g / (w * sol.area_strain) - fluidic.lam)
        return out

    def _coupled_strip(self, pressure_work):
        """Return the side view with the band's mu_z from the cross-sections (a new Strip)."""
        moduli = self.band_moduli(pressure_work)
        laws = list(self.view.laws)
        cell_law = self.view.cell_law.copy()
        band = self.view.gas_width > 0.0
        fluidic = laws[1]
        for at_rib, mu_z in moduli.items():
            laws.append(BiotMaterial(fluidic.coefficients, fluidic.mu, fluidic.lam,
                                     fluidic.eigenstrain, mu_z))
            cell_law[band & (self.view.at_rib[:, None] == at_rib)] = len(laws) - 1
        return Strip(self.view.x_breaks, self.view.z_breaks, cell_law, laws, self.view.width,
                     self.view.gas_width, self.element_size)

    def solve(self, pressure=0.0, tip_force=(0.0, 0.0)):
        """
        Solve one scene from the flat, stress-free state by load stepping.

        Parameters
        ----------
        pressure : float
            Gauge pressure in [0, max_pressure] [Pa].
        tip_force : (float, float)
            (f0, p0) along global X and Z [N], spread over the tip face.

        Returns
        -------
        Result
            `FINGER_FIELDS` (tip and points at the midplane; nodes at the midplane's
            element-column edges; strains, coefficients, beta and theta None), plus
            `n_dofs` and `load_steps`.

        """
        pressure = real_number('pressure', pressure, '[Pa]')
        if not 0.0 <= pressure <= self.design.max_pressure:
            raise ArgumentError('pressure', f'must be in [0, {self.design.max_pressure:g}] '
                                            f'[Pa], got {pressure}')
        tip_force = real_pair('tip_force', tip_force, '[N]')
        work = self.pressure_work_factor * pressure
        strip, out = self.strip, None
        if self.channel == 'section' and work > 0.0:
            try:
                strip = self._coupled_strip(work)
            except ValueError as exc:
                # No band law to solve with: the flat state, failed, with the reason.
                out = StripSolution(np.zeros(strip.n_dofs), False, str(exc), 0, 0, 0.0)
        if out is None:
            out = strip.solve(work, tip_force)
        u = out.u
        points = np.stack([self._x + u[self._mid[0]], u[self._mid[1]]], axis=1)
        tip = np.array([self.design.free_length + u[self._tip[0]], u[self._tip[1]]])
        fit = fit_circle(points)
        x_ref = self._x.copy()

        def position_at(s):
            s = np.asarray(s, dtype=float)
            return np.stack([np.interp(s, x_ref, points[:, 0]),
                             np.interp(s, x_ref, points[:, 1])], axis=-1)

        columns = np.unique(self.strip.mesh.p[0])
        fields = dict.fromkeys(FINGER_FIELDS)
        status = SolverStatus.SUCCESS if out.success else SolverStatus.CONTINUATION_FAILED
        fields.update(
            success=out.success, status=status, message=out.message, iterations=out.iterations,
            pressure=pressure, tip_force=tip_force, point_loads=(), model=self.model,
            rung='continuum', n_segments=columns.size - 1, segment_edges=columns, state=u,
            x=u, tip=tip, valid=True, nodes=position_at(columns), energy=strip.energy(
                u, out.fraction, work, tip_force),
            points=points, curvature=fit.curvature, fit_rmsd=fit.rmsd,
            position_at=position_at, fraction=out.fraction, n_dofs=self.strip.n_dofs,
            load_steps=out.steps)
        return Result.of(fields)
