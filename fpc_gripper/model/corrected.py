"""The continuum-corrected fast rung: the PCC rod with effective parameters fitted to the FE."""

from dataclasses import dataclass
import functools

import numpy as np

from .discretisations.pcc import material_jacobian, PCCSolver
from .engine import ALL, Fields, SHAPE
from .kernels.shear import shear_moves, shear_outputs
from .section.law import (_add_linear, _box_moments, SECTION_PARAMETERS, SectionLaw,
                          station_layout)
from .section.segments import interval_of, share_segments
from .validation import arc_lengths, real_number

__all__ = ['ContinuumCorrection', 'CorrectedSolver', 'PAPER_PHYSICS', 'CONTINUUM_FIT',
           'CLAMP_ZONE', 'CHANNEL_END_ZONE', 'CORRECTED_SEGMENTS', 'corrected_layout',
           'shear_displacements', 'sheared_positions_at', 'PARAMETERS']

#: Length of the clamp zone from the clamp edge [m]: the Saint-Venant zone where the
#: clamped face holds the PEMC's shortening (the FE's first 2-5 mm, docs/physics.md 18.1).
CLAMP_ZONE = 3.0e-3
#: Length of the channel-end zone, ending at the channel end [m]: the channel's last
#: millimetres, held by the solid tip beyond it.
CHANNEL_END_ZONE = 4.0e-3
#: Segments of the corrected rung's PCC: the calibration's discretisation (FIT_SEGMENTS).
CORRECTED_SEGMENTS = 32
#: Column of a segment's angle in the engine's unknowns (eps, c1, theta) per segment.
_THETA = 2
#: No points, as the shear kernels take them (a tip-only move).
_NO_SEGMENTS = np.zeros(0, dtype=np.int64)
_NO_OFFSETS = np.zeros(0)
_NO_POINTS = np.zeros((0, 2))
#: Parameters of `CorrectedSolver.parameter_gradient`: `SECTION_PARAMETERS`, then the
#: stiffness factors (the shear compliance acts after the solve: `CorrectedSolver.shear_tip`).
PARAMETERS = SECTION_PARAMETERS + ('band_stiffness', 'clamp_stiffness',
                                   'channel_end_stiffness')
#: Bounds of each stiffness factor [-] and of the shear compliance [1/N].
FACTOR_BOUNDS = (0.05, 20.0)
COMPLIANCE_BOUNDS = (0.0, 1.0)


@dataclass(frozen=True)
class ContinuumCorrection:
    """
    Effective parameters that bring the plane-section rod to the 2-D continuum.

    Parameters
    ----------
    band_stiffness : float
        Factor on the stiffness of the fluidic layer's band beside the channel (its solid
        between the channel's floor and ceiling, z in [-h3b, h3a], in every channel
        section) [-]. Below 1: in 2-D the soft band between ribs shears and carries less
        than the section law's plane sections say.
    clamp_stiffness : float
        Factor on the whole linear section stiffness over the first `CLAMP_ZONE` [-].
        Above 1: the clamped face holds the PEMC's shortening there, so the finger curls
        less near the clamp than the section law says.
    channel_end_stiffness : float
        Factor on the linear section stiffness over the channel's last `CHANNEL_END_ZONE`
        [-]. Above 1: the solid tip stiffens the channel's end beyond its own section.
    shear_compliance : float
        1 / (k G A) of the section [1/N]: the shear strain V / (k G A) of the soft layers
        under a shear force V, which plane sections leave out (Timoshenko). It moves every
        point by the integral of gamma n along the arc (first order in the compliance).

    """

    band_stiffness: float = 1.0
    clamp_stiffness: float = 1.0
    channel_end_stiffness: float = 1.0
    shear_compliance: float = 0.0

    def __post_init__(self):
        for name, unit, (low, high) in (('band_stiffness', '[-]', FACTOR_BOUNDS),
                                        ('clamp_stiffness', '[-]', FACTOR_BOUNDS),
                                        ('channel_end_stiffness', '[-]', FACTOR_BOUNDS),
                                        ('shear_compliance', '[1/N]', COMPLIANCE_BOUNDS)):
            value = real_number(name, getattr(self, name), unit)
            if not low <= value <= high:
                raise ValueError(f'`{name}` must be in [{low}, {high}] {unit}, got {value}')
            object.__setattr__(self, name, value)

    @property
    def values(self):
        """Return the four parameters as an array, field order."""
        return np.array([self.band_stiffness, self.clamp_stiffness,
                         self.channel_end_stiffness, self.shear_compliance])


#: No correction: the paper's plane-section physics (the corrected rung is then the PCC).
PAPER_PHYSICS = ContinuumCorrection()
#: Fitted to the FE table's 15 unpressurised scenes (bench/results/continuum.json) by
#: bench/fit_continuum.py; its result, with the per-scene errors, is
#: bench/results/continuum_fit.json. Numbers, not a fit at import (STYLE: constants).
CONTINUUM_FIT = ContinuumCorrection(band_stiffness=0.7217, clamp_stiffness=1.300,
                                    channel_end_stiffness=3.892, shear_compliance=0.01742)


def _band_stiffness(design, gas_width):
    """Return K of the fluidic band beside a channel of gas width [m] (3, 3)."""
    k = np.zeros((3, 3))
    _add_linear(k, _box_moments(-design.h3b, design.h3a, design.Ly - gas_width),
                design.fluidic_layer, 1.0)
    return k


def corrected_layout(design, correction):
    """
    Section layout of the corrected rung: `station_layout` with the effective stiffnesses.

    Every type's K is linear in each stiffness factor: a channel type's is K0 + (b - 1) B
    (B the band's, `_band_stiffness`), its copy in a zone f (K0 + (b - 1) B).

    Parameters
    ----------
    design : ActuatorDesign
    correction : ContinuumCorrection

    Returns
    -------
    breaks : ndarray, shape (K + 1,)
        Interval ends, the zone edges among them [m].
    types : ndarray of int, shape (K,)
    law : SectionLaw
        The paper's types with the band factor, then the zones' scaled copies (with their
        `modulus_directions`).
    directions : ndarray, shape (3, S, 3, 3)
        dK / d(band, clamp, channel-end factor) of every type [N, N m, N m^2].

    """
    breaks, types, law = station_layout(design, ribs='exact')
    fl_modulus = design.fluidic_layer.E1
    base, band, moduli = [], [], []
    for j in range(law.n_types):
        b = np.zeros((3, 3)) if j == law.n_types - 1 else \
            _band_stiffness(design, law.gas[j, 0] / (design.h3a + design.h3b))
        base.append(law.stiffness[j] + (correction.band_stiffness - 1.0) * b)
        band.append(b)
        # The band is fluidic layer: linear in its E1 (E2 / E1 and nu held).
        moduli.append(law.modulus_directions[:, j]
                      + np.array([np.zeros((3, 3)), (correction.band_stiffness - 1.0) * b
                                  / fl_modulus]))
    stiffness, gas, labels = list(base), list(law.gas), list(law.labels)
    directions = [[b, np.zeros((3, 3)), np.zeros((3, 3))] for b in band]
    end = design.channel_end
    zones = [((0.0, min(CLAMP_ZONE, end)), correction.clamp_stiffness, 'clamp zone', 1),
             ((max(end - CHANNEL_END_ZONE, min(CLAMP_ZONE, end)), end),
              correction.channel_end_stiffness, 'channel-end zone', 2)]
    # A zone edge within 1 um of a section change is that change: no sliver intervals.
    cuts = list(breaks)
    for (lo, hi), _, _, _ in zones:
        for edge in (lo, hi):
            if np.min(np.abs(np.asarray(cuts) - edge)) > 1e-6:
                cuts.append(edge)
    cuts = np.array(sorted(cuts))
    middle = 0.5 * (cuts[:-1] + cuts[1:])
    new_types = types[interval_of(breaks, middle)]
    copies = {}
    for (lo, hi), factor, label, row in zones:
        inside = (middle > lo) & (middle < hi)
        for k in np.flatnonzero(inside):
            j = int(new_types[k])
            key = (label, j)
            if key not in copies:
                copies[key] = len(stiffness)
                stiffness.append(base[j] * factor)
                moduli.append(moduli[j] * factor)
                gas.append(gas[j])
                labels.append(f'{labels[j]}, {label}')
                direction = [band[j] * factor, np.zeros((3, 3)), np.zeros((3, 3))]
                direction[row] = base[j]
                directions.append(direction)
            new_types[k] = copies[key]
    law = SectionLaw(stiffness=np.array(stiffness), gas=np.array(gas), pemc_z=law.pemc_z,
                     pemc_weights=law.pemc_weights, prestrain=law.prestrain, emc=law.emc,
                     labels=tuple(labels), modulus_directions=np.stack(moduli, axis=1))
    return cuts, np.asarray(new_types, dtype=int), law, \
        np.array(directions).transpose(1, 0, 2, 3)


def _moment_rates(a, b, length):
    """
    Return d/da and d/db of the part moments (xx, xz, zz), each shape (3, ...) [m/rad].

    The part moments are int n n^T ds over an arc part from angle a to b
    (`kernels.shear._part_moments`, `shear_displacements`).

    With p = a + b, d = b - a and s(d) = sin(d) / d: c = (l / 2) cos(p) s(d) gives
    dc/da = (l / 2)(-sin p s - cos p s'), dc/db = (l / 2)(-sin p s + cos p s'), and
    xz = -(l / 2) sin(p) s the same way; s'(d) = (cos d - s) / d, by its series near 0.
    """
    d = b - a
    small = np.abs(d) < 1e-2
    safe = np.where(small, 1.0, d)
    sinc = np.where(small, 1.0 - d * d / 6.0 + d ** 4 / 120.0, np.sin(safe) / safe)
    slope = np.where(small, -d / 3.0 + d ** 3 / 30.0 - d ** 5 / 840.0,
                     (np.cos(safe) - np.sin(safe) / safe) / safe)
    half = 0.5 * length
    cp, sp = np.cos(a + b) * half, np.sin(a + b) * half
    dc_da, dc_db = -sp * sinc - cp * slope, -sp * sinc + cp * slope
    dxz_da, dxz_db = -(cp * sinc - sp * slope), -(cp * sinc + sp * slope)
    return np.stack([-dc_da, dxz_da, dc_da]), np.stack([-dc_db, dxz_db, dc_db])


def shear_displacements(theta, lengths, segment, offset, force, compliance):
    """
    Move of material points by the shear strain of a tip force (first order) [m].

    The shear force at arc length s is V = F . n(s), n the normal of the tangent at angle
    phi(s) (from +X towards +Z); the shear strain V / (k G A) moves the section along n,
    so a point at s moves by c int_0^s n n^T ds F, with phi linear in each PCC segment:
    int n n^T ds = (l / 2) (I - [[C, S], [S, -C]]), (C, S) = (cos, sin)(a + b) sinc(b - a)
    over a segment part of reference length l from angle a to b (compiled:
    `kernels.shear.shear_moves`).

    Parameters
    ----------
    theta : ndarray, shape (N,)
        End angle of every segment (the first starts at 0) [rad].
    lengths : ndarray, shape (N,)
        Reference lengths [m].
    segment, offset : ndarray, shape (M,)
        Segment of every point and its arc length into it [m].
    force : ndarray, shape (2,)
        Tip force (f0, p0) [N].
    compliance : float
        1 / (k G A) [1/N].

    Returns
    -------
    ndarray, shape (M, 2)

    """
    theta = np.asarray(theta, dtype=float)
    # The kernel reads the angles from the engine's unknowns (eps, c1, theta) per segment.
    x = np.zeros(3 * theta.size)
    x[_THETA::3] = theta
    return shear_moves(x, np.ascontiguousarray(lengths, dtype=float),
                       np.ascontiguousarray(segment, dtype=np.int64),
                       np.ascontiguousarray(offset, dtype=float), float(force[0]),
                       float(force[1]), float(compliance))[1]


def sheared_positions_at(x, edges, force, compliance, s):
    """
    Midplane position of the corrected rung's material points at arc lengths `s` [m].

    The PCC's (`pcc.positions_at`) plus the shear move of the tip force (as
    `shear_displacements`); a result's `position_at` is this function of its own state.

    Parameters
    ----------
    x : ndarray, shape (3 N,)
        Engine unknowns.
    edges : ndarray, shape (N + 1,)
        Segment edges [m].
    force : (float, float)
        Tip force (f0, p0) [N].
    compliance : float
        1 / (k G A) [1/N].
    s : float or array_like
        Reference arc length from the clamp edge, in [0, L] [m].

    Returns
    -------
    ndarray, shape s.shape + (2,)
        Global (X, Z) [m].

    """
    values, shape = arc_lengths('s', s, edges[-1])
    lengths = np.diff(edges)
    seg = interval_of(edges, values)
    moves = shear_moves(x, lengths, seg.astype(np.int64),
                        np.minimum(values - edges[seg], lengths[seg]), force[0], force[1],
                        compliance)[1]
    return (material_jacobian(x, edges, values)[0] + moves).reshape(shape + (2,))


class CorrectedSolver(PCCSolver):
    """
    The fast rung corrected to the 2-D continuum: the PCC on a corrected section layout.

    The PCC rod (`PCCSolver`, its compiled kernels unchanged) on `corrected_layout`, with
    the shear displacements of the tip force (compiled, `kernels.shear`) added to the tip,
    nodes, samples and `position_at`. With `PAPER_PHYSICS` it is the paper's PCC. Fitted to
    the unpressurised FE scenes only: under pressure the FE is no reference
    (docs/physics.md, section 18).

    Parameters
    ----------
    design : ActuatorDesign
    correction : ContinuumCorrection
        Default `CONTINUUM_FIT`.
    n_segments : int
        Segments of the PCC (`CORRECTED_SEGMENTS`, the fit's).
    pressure_model : {None, 'adiabatic', 'isobaric'}

    """

    def __init__(self, design, correction=CONTINUUM_FIT, n_segments=CORRECTED_SEGMENTS,
                 pressure_model=None, **options):
        if not isinstance(correction, ContinuumCorrection):
            raise TypeError(f'`correction` must be a ContinuumCorrection, '
                            f'got {type(correction).__name__}')
        self.correction = correction
        super().__init__(design, n_segments, pressure_model, **options)
        self._constants['model'] = f'pcc N={self.n_segments}, continuum-corrected'

    def _layout(self, design, n_segments):
        """Return `corrected_layout`'s intervals cut into about `n_segments` segments."""
        breaks, types, law, self._factor_directions = corrected_layout(design,
                                                                       self.correction)
        counts = share_segments(np.diff(breaks), max(int(n_segments), types.size))
        edges = np.concatenate([*(np.linspace(a, b, c + 1)[:-1]
                                  for a, b, c in zip(breaks, breaks[1:], counts)),
                                breaks[-1:]])
        return edges, np.repeat(types, counts), law

    def parameter_gradient(self, x, pressure, loads):
        """
        Differentiate the gradient in the engine unknowns by `PARAMETERS`, exactly.

        `SECTION_PARAMETERS` as `PCCSolver.parameter_gradient`, then the three stiffness
        factors: K is linear in each (`corrected_layout`'s directions D), so the section's
        gradient moves by D y, mapped to the unknowns as the section law's rates are.

        Returns
        -------
        ndarray, shape (11, 3 N)
            [J per unit of each parameter].

        """
        paper = super().parameter_gradient(x, pressure, loads)
        rates = np.einsum('fnij,nj->fni', self._factor_directions[:, self.segment_types],
                          self._section_strains(x))
        return np.concatenate([paper, self._to_unknowns(rates)])

    def shear_tip(self, x, force):
        """
        Return the tip's shear move per unit compliance M(x) F [m N] and d(M F)/dx, (2, 3 N).

        The tip moves by c M F, M = int_0^L n n^T ds (`shear_displacements`): linear in
        the compliance c, and through the segments' angles in the unknowns.
        """
        force = np.asarray(force, dtype=float)
        x = np.ascontiguousarray(x, dtype=float)
        move = shear_moves(x, self.lengths, _NO_SEGMENTS, _NO_OFFSETS, float(force[0]),
                           float(force[1]), 1.0)[0][-1]
        theta = x[_THETA::3]
        start = np.concatenate([[0.0], theta[:-1]])
        d_start, d_end = _moment_rates(start, theta, self.lengths)
        d_end[:, :-1] += d_start[:, 1:]
        jac = np.zeros((2, theta.size * 3))
        jac[0, _THETA::3] = d_end[0] * force[0] + d_end[1] * force[1]
        jac[1, _THETA::3] = d_end[1] * force[0] + d_end[2] * force[1]
        return move, jac

    def _sheared(self, force):
        """Whether a tip force (f0, p0) [N] moves the points: `moves_after_solve` of it."""
        return self.moves_after_solve(force[0] != 0.0 or force[1] != 0.0)

    def moves_after_solve(self, loaded):
        """
        Whether a solve, loaded or not, moves the engine's state afterwards (`batch`).

        The shear move of a tip load: a compiled batch row does not carry it, so
        `batch.solve_grid` solves those scenes singly, and `rigidity_grid` refuses with
        `rigidity`.
        """
        return bool(loaded) and self.correction.shear_compliance != 0.0

    def _fields_level(self, level, force):
        """
        Return the level the engine computes a solve's outputs to (`RungSolver.solve`).

        With a shear move the circle is fitted to the moved samples (`_result`), so the
        engine stops at the samples rather than fit the rod's, which would be dropped.
        """
        return SHAPE if level >= ALL and self._sheared(force) else level

    def _result(self, outcome, pressure, tip_force, point_loads=(), model_choice=None,
                level=ALL):
        if self._sheared(tip_force):
            f = outcome.fields
            if f is None:
                f = self._python_fields(outcome.x, pressure, tip_force, level)
            # The rod's tip and the load moving it, in the kernel's order after the samples.
            load = (float(tip_force[0]), float(tip_force[1]),
                    self.correction.shear_compliance, f.tip)
            if f.nodes is None:
                f = f._replace(tip=shear_outputs(outcome.x, self.lengths, _NO_SEGMENTS,
                                                 _NO_OFFSETS, *load, _NO_POINTS, _NO_POINTS,
                                                 False)[0])
            else:
                # One compiled pass: the moves of the tip, nodes and samples, and the
                # circle of the moved samples where it was asked for ('all').
                fit = level >= ALL
                tip, nodes, points, curvature, rmsd = shear_outputs(
                    outcome.x, self.lengths, self._sample_segment, self._sample_offset, *load,
                    f.nodes, f.points, fit)
                f = Fields(tip, f.energy, f.valid, curvature if fit else None,
                           rmsd if fit else None, nodes, f.beta, f.theta, f.coefficients,
                           points, f.tangent, f.strains)
            outcome = outcome._replace(fields=f)
        return super()._result(outcome, pressure, tip_force, point_loads, model_choice,
                               level=level)

    def _positions(self, x, pressure, force):
        """Return the `position_at` of a result: `sheared_positions_at` under a shear move."""
        if not self._sheared(force):
            return super()._positions(x, pressure, force)
        return functools.partial(sheared_positions_at, x, self.edges,
                                 (float(force[0]), float(force[1])),
                                 self.correction.shear_compliance)

    def rigidity(self, *args, **kwargs):
        """
        `PCCSolver.rigidity` without a shear compliance; refuse with one.

        The bordered displacement control does not carry the shear correction.
        """
        # The control solves a loaded state: refused where that state would move after.
        if not self.moves_after_solve(True):
            return super().rigidity(*args, **kwargs)
        raise NotImplementedError('CorrectedSolver.rigidity: the bordered displacement '
                                  'control does not include the shear correction; use '
                                  'solve() with a tip force')
