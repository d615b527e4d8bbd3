"""The continuum-corrected fast rung: the PCC rod with effective parameters fitted to the FE."""

from dataclasses import dataclass

import numpy as np

from .discretisations.pcc import PCCSolver
from .kernels.circle import circle_fit
from .result import Result
from .section.law import (_add_linear, _box_moments, SECTION_PARAMETERS, SectionLaw,
                          station_layout)
from .section.segments import share_segments
from .validation import real_number

__all__ = ['ContinuumCorrection', 'CorrectedSolver', 'PAPER_PHYSICS', 'CONTINUUM_FIT',
           'CLAMP_ZONE', 'CHANNEL_END_ZONE', 'CORRECTED_SEGMENTS', 'corrected_layout',
           'shear_displacements', 'PARAMETERS']

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
    new_types = types[np.clip(np.searchsorted(breaks, middle, side='right') - 1, 0,
                              types.size - 1)]
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


def _moments(a, b, length):
    """Return int n n^T ds as (xx, xz, zz), shape (3, ...), over parts from angle a to b [m]."""
    d = b - a
    # sin(d) / d loses no digits as d -> 0; only d = 0 itself needs a stand-in (sinc 1).
    d = np.where(d == 0.0, 1e-300, d)
    half = 0.5 * length
    sinc = np.sin(d) / d * half
    p = a + b
    c = np.cos(p) * sinc
    out = np.empty((3,) + c.shape, dtype=c.dtype)
    np.subtract(half, c, out=out[0])
    np.multiply(np.sin(p), -sinc, out=out[1])
    np.add(half, c, out=out[2])
    return out


def _moment_rates(a, b, length):
    """
    Return d/da and d/db of `_moments` (xx, xz, zz), each shape (3, ...) [m/rad].

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
    over a segment part of reference length l from angle a to b.

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
    lengths = np.asarray(lengths, dtype=float)
    segment = np.asarray(segment)
    offset = np.asarray(offset, dtype=float)
    start = np.empty_like(theta)
    start[0] = 0.0
    start[1:] = theta[:-1]
    whole = np.zeros((3, theta.size + 1))
    np.cumsum(_moments(start, theta, lengths), axis=1, out=whole[:, 1:])
    a = start[segment]
    xx, xz, zz = whole[:, segment] + _moments(
        a, a + (theta[segment] - a) * (offset / lengths[segment]), offset)
    out = np.empty((segment.size, 2))
    out[:, 0] = xx * force[0] + xz * force[1]
    out[:, 1] = xz * force[0] + zz * force[1]
    return compliance * out


class CorrectedSolver(PCCSolver):
    """
    The fast rung corrected to the 2-D continuum: the PCC on a corrected section layout.

    The PCC rod (`PCCSolver`, its compiled kernels unchanged) on `corrected_layout`, with
    the shear displacements of the tip force added to the tip, nodes, samples and
    `position_at`. With `PAPER_PHYSICS` it is the paper's PCC. Fitted to the unpressurised
    FE scenes only: under pressure the FE is no reference (docs/physics.md, section 18).

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
        # For the shear move: the samples' fraction of their segment, and the lengths of
        # the parts it integrates over (the segments, then the samples' partial segments).
        self._sample_fraction = self._sample_offset / self.lengths[self._sample_segment]
        self._moment_lengths = np.concatenate((self.lengths, self._sample_offset))
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
        theta = np.asarray(x, dtype=float)[_THETA::3]
        start = np.concatenate([[0.0], theta[:-1]])
        xx, xz, zz = _moments(start, theta, self.lengths).sum(axis=1)
        move = np.array([xx * force[0] + xz * force[1], xz * force[0] + zz * force[1]])
        d_start, d_end = _moment_rates(start, theta, self.lengths)
        d_end[:, :-1] += d_start[:, 1:]
        jac = np.zeros((2, theta.size * 3))
        jac[0, _THETA::3] = d_end[0] * force[0] + d_end[1] * force[1]
        jac[1, _THETA::3] = d_end[1] * force[0] + d_end[2] * force[1]
        return move, jac

    def _result(self, outcome, pressure, tip_force, point_loads=(), model_choice=None,
                **level):
        result = super()._result(outcome, pressure, tip_force, point_loads, model_choice,
                                 **level)
        force = np.asarray(result.tip_force, dtype=float)
        compliance = self.correction.shear_compliance
        if compliance == 0.0 or not force.any():
            return result
        fields = dict(result.__dict__)
        theta = result.x[_THETA::3]
        edges, lengths, n = self.edges, self.lengths, self.n_segments
        # F^T as the map from (xx, xz, zz) to the move, times the compliance.
        mix = compliance * np.array([[force[0], force[1], 0.0], [0.0, force[0], force[1]]])
        if result.nodes is None:
            fields['tip'] = result.tip + mix @ _moments(
                np.concatenate(([0.0], theta[:-1])), theta, lengths).sum(axis=1)
        else:
            # One pass over the segments and the samples' partial segments together.
            seg, rho = self._sample_segment, self._sample_fraction
            start = np.zeros(n + seg.size)
            start[1:n] = theta[:-1]
            begin = start[seg]
            start[n:] = begin
            end = np.concatenate((theta, begin + (theta[seg] - begin) * rho))
            parts = _moments(start, end, self._moment_lengths)
            whole = np.zeros((3, n + 1 + seg.size))
            np.cumsum(parts[:, :n], axis=1, out=whole[:, 1:n + 1])
            whole[:, n + 1:] = whole[:, seg] + parts[:, n:]
            moves = mix @ whole
            fields['tip'] = result.tip + moves[:, n]
            fields['nodes'] = result.nodes + moves[:, :n + 1].T
            fields['points'] = result.points + moves[:, n + 1:].T
            if result.curvature is not None:
                # The circle of the moved samples; only where the fit was asked for ('all').
                fields['curvature'], fields['fit_rmsd'] = (
                    float(v) for v in circle_fit(fields['points'])[:2])
        base = result.position_at

        def position_at(s):
            s_arr = np.asarray(s, dtype=float)
            seg = np.clip(np.searchsorted(edges, s_arr, side='right') - 1, 0, n - 1)
            moved = shear_displacements(
                theta, lengths, np.atleast_1d(seg),
                np.atleast_1d(np.minimum(s_arr - edges[seg], lengths[seg])), force, compliance)
            return np.asarray(base(s)) + (moved[0] if s_arr.ndim == 0 else moved)

        fields['position_at'] = position_at
        return Result.of(fields)

    def rigidity(self, *args, **kwargs):
        """Refuse: the displacement control does not carry the shear correction."""
        raise NotImplementedError('CorrectedSolver.rigidity: the bordered displacement '
                                  'control does not include the shear correction; use '
                                  'solve() with a tip force')
