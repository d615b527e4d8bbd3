"""Rung a: the finger as one arc of uniform strain."""

import functools

import numpy as np

from .rung import RungSolver, set_common
from ..engine import CompiledProblem, linear_solve, NewtonOptions, register
from ..kernels import arc as arc_kernels
from ..kernels.chain import load_arrays
from ..kernels.pcc_section import half_angle_sinc_kernel, section_arrays
from ..result import finger_constants
from ..section.law import station_layout
from ..validation import arc_lengths

__all__ = ['ArcSolver', 'positions_at']

# The engine runs this discretisation compiled through these hooks (`engine.register`).
register(arc_kernels.ArcData, arc_kernels.ARC_HOOKS)

#: Gauss rule on [0, 1] for the arc integrals int_0^1 (cos, sin)(phi t) t^k dt; exact to
#: round-off for |phi| up to about 40 rad (several full turns).
_ARC_X, _ARC_WX = np.polynomial.legendre.leggauss(48)
_ARC_T, _ARC_W = 0.5 * (_ARC_X + 1.0), 0.5 * _ARC_WX


class ArcSolver(RungSolver):
    """
    Rung a: the finger as one arc of uniform strain (eps, kappa, c1).

    Minimises L W_mean(eps, kappa, c1) - F . tip(eps, kappa) with W_mean the
    length-weighted mean section law (channel with ribs, channel-free tip), and
    tip = (1 + eps) L int_0^1 (cos, sin)(kappa L t) dt. Without a tip load and for
    a uniform section this is exact: the rod's solution is an arc. With loads or
    a non-uniform section it is the one-element constant-strain Ritz solution.

    Parameters
    ----------
    design : ActuatorDesign
        The finger.
    pressure_model : {None, 'design', 'adiabatic', 'isobaric'}
        k_p = 1/(gamma - 1) or 1 (SPEC "Pressure work"); None or 'design' (the
        default): the design's `pressure_work_factor`.
    tol : float
        Largest final Newton step in (eps, kappa L, c1) [-].
    samples : int
        Midplane samples M, root to tip.
    max_iterations : int
        Newton iterations per (sub)solve.

    References
    ----------
    docs/physics.md, sections 11.2 and 11.3.

    """

    rung = 'arc'

    def __init__(self, design, pressure_model=None, tol=1e-12, samples=129,
                 max_iterations=60):
        set_common(self, design, pressure_model, tol, samples, max_iterations)
        self.n_segments = 1
        breaks, types, law = station_layout(design, ribs='average')
        self.law = law.mean(np.bincount(types, np.diff(breaks), minlength=law.n_types))
        self.length = design.free_length
        self._scale = np.array([1.0, self.length, 1.0])
        # Axial stiffness of the finger [J]: the scale of gradients in (eps, kappa L, c1).
        self.gradient_scale = float(self.law.stiffness[:, 0, 0].max()) * self.length
        self._options = NewtonOptions(max_iterations=self.max_iterations, xtol=self.tol,
                                      max_step=0.5, flat_slope=1e-14, energy_scale=1e-6)
        self.edges = np.array([0.0, self.length])
        self._data = arc_kernels.ArcData(*section_arrays(self.law, np.zeros(1, dtype=int)),
                                         float(self.pressure_coefficient), float(self.length),
                                         self._scale, _ARC_T, _ARC_W, self.samples)
        #: What the engine runs: the compiled data, never this object.
        self.engine_problem = CompiledProblem(self._data, self._data, self.flat(),
                                              self.gradient_scale)
        self._constants = finger_constants(self.rung, self.n_segments, self.edges)

    def _flat_state(self):
        return np.zeros(3)

    # -- the discretisation's side of the engine: unknowns (eps, kappa L, c1) ----------
    def _pack(self, y):
        return np.asarray(y, dtype=float) * self._scale

    def _unpack(self, x):
        return x / self._scale

    def derivatives(self, x, pressure, loads):
        """Energy [J], gradient and Hessian in the scaled unknowns (eps, kappa L, c1)."""
        return arc_kernels.arc_derivatives(self._data, np.ascontiguousarray(x, dtype=float),
                                           float(pressure), *self._load_arrays(loads))

    def energy(self, x, pressure, loads):
        """Total potential [J] at scaled unknowns `x`."""
        return self.derivatives(x, pressure, loads)[0]

    def step(self, grad, hess):
        """Newton step of the 3 x 3 system (eigenvalues mirrored where indefinite)."""
        return arc_kernels.arc_step(self._data, np.ascontiguousarray(grad, dtype=float),
                                    np.ascontiguousarray(hess, dtype=float))

    solve_linear = staticmethod(linear_solve)

    def node_jacobian(self, x, node):
        """Tip position [m] and its derivatives in the scaled unknowns, (2, 3)."""
        if node != self.tip_node:
            raise ValueError(f'ArcSolver has nodes 0 and 1 (the tip), got {node}')
        return arc_kernels.arc_node_jacobian(self._data, np.ascontiguousarray(x, dtype=float),
                                             int(node))

    def _load_arrays(self, loads):
        force = self._force(loads)
        return (np.array([self.tip_node], dtype=np.int64), force.reshape(1, 2)) \
            if force.any() else load_arrays([])

    def turning(self, y):
        """Return the turning kappa L [rad] of the arc of state y = (eps, kappa, c1)."""
        return y[1] * self.length

    def _positions(self, x, pressure, force):
        """Return the `position_at` of a result at scaled unknowns `x`."""
        y = self._unpack(x)
        return functools.partial(positions_at, float(y[0]), float(y[1]), self.length)


def positions_at(eps, kappa, length, s):
    """
    Midplane position of the arc's material points at reference arc lengths `s` [m].

    The point at s is (1 + eps) s S(kappa s) along (cos, sin)(kappa s / 2), exactly on the
    arc; a result's `position_at` is this function of its own strains.

    Parameters
    ----------
    eps, kappa : float
        Axial strain [-] and curvature per reference length [1/m].
    length : float
        Free length L [m].
    s : float or array_like
        Reference arc length from the clamp edge, in [0, L] [m].

    Returns
    -------
    ndarray, shape s.shape + (2,)
        Global (X, Z) [m].

    """
    values, shape = arc_lengths('s', s, length)
    turn = np.ascontiguousarray(kappa * values)
    chord = (1.0 + eps) * values * half_angle_sinc_kernel(turn, 0)[0]
    points = np.stack([chord * np.cos(0.5 * turn), chord * np.sin(0.5 * turn)], axis=1)
    return points.reshape(shape + (2,))
