"""CCM equilibrium solver: damped Newton with warm starts, continuation and rigidity."""

import functools
import math

import numpy as np

from .ccm_geometry import (from_scaled, material_positions, midplane_samples, node_positions,
                           to_scaled)
from .. import engine
from ..analysis import CircleFitted, flexural_rigidity
from ..design import ActuatorDesign
from ..engine import linear_solve, linear_step, NewtonOptions, SolverStatus
from ..kernels import ccm as kernels
from ..kernels.chain import load_arrays, node_jacobian
from ..section.segments import build_segments, uniform_edges
from ..validation import (arc_lengths, check_force, check_load, check_pressure_model,
                          PRESSURE_MODELS, real_number, warm_start_allowed)

__all__ = ['CCMSolver', 'CCMResult', 'RigidityResult', 'SolverStatus', 'AXES', 'check_rigidity',
           'rigidity_result', 'pressure_work_factor']

# The engine runs this discretisation compiled through these hooks (`engine.register`).
engine.register(kernels.CCMData, kernels.CCM_HOOKS)

#: Midplane reconstructions: the paper's, or one that converges to the rod as N grows
#: (ccm_geometry.consistent_strain_map).
RECONSTRUCTIONS = ('paper', 'consistent')
#: Largest Newton step in any scaled unknown; keeps iterates where the quintic PEMC
#: energy (unbounded below at large tension) is meaningful.
_MAX_STEP = 0.5


_MESSAGES = {
    SolverStatus.SUCCESS: 'converged: relative gradient {grad:.1e} <= {gtol:.0e} and last step '
                          '{step:.1e} <= {xtol:.0e}',
    SolverStatus.MAX_ITERATIONS: 'not converged after {iterations} Newton iterations '
                                 '(relative gradient {grad:.1e})',
    SolverStatus.LINE_SEARCH_FAILED: 'line search found no decrease (relative gradient '
                                     '{grad:.1e}); the equilibrium may not exist nearby',
    SolverStatus.NOT_FINITE: 'energy or gradient became non-finite',
    SolverStatus.UNSTABLE: 'converged to an unstable equilibrium (Hessian not positive '
                           'definite, smallest eigenvalue {min_eig:.2e})',
    SolverStatus.CONTINUATION_FAILED: 'continuation in pressure and load stalled at '
                                      '{fraction:.1%} of the requested loading',
}


def pressure_work_factor(design, pressure_model=None):
    """
    Return k_p of Pi_P = -k_p P V for a design and a solver's pressure model [-].

    A solver built with an explicit pressure model uses that model's k_p; without one
    (None or 'design') it uses the design's `pressure_work_factor` (SPEC "Pressure work").
    """
    name = check_pressure_model(pressure_model)
    return design.pressure_work_factor if name == 'design' else PRESSURE_MODELS[name]


class ResultPositions:
    """Mixin of a solver result: `position_at`, through the solver's `material_points`."""

    def position_at(self, s):
        """
        Midplane position of the material point at reference arc length `s` from the clamp.

        Exact for the result's own kinematics (the CCM's segment polynomials, the arcs of
        the PCC and the arc rung, the extensible rod's integral of (1 + eps)(cos, sin)
        theta).

        Parameters
        ----------
        s : float or array_like
            Reference (undeformed) arc length from the clamp edge, in [0, L] [m].

        Returns
        -------
        ndarray, shape s.shape + (2,)
            Global (X, Z) [m].

        Raises
        ------
        ValueError, TypeError
            Where `s` is not a real number in [0, L].

        References
        ----------
        docs/physics.md, section 13.

        """
        values, shape = arc_lengths('s', s, self.solver.design.free_length)
        return self.solver.material_points(self, values).reshape(shape + (2,))


class CCMResult(ResultPositions, CircleFitted):
    """
    Equilibrium of one finger, with OptimizeResult-like fields.

    Attributes
    ----------
    success : bool
        True only for a converged, stable equilibrium.
    status : SolverStatus
        Outcome code; `message` explains it.
    message : str
    iterations : int
        Newton iterations, continuation steps included.
    coefficients : ndarray, shape (N, 4)
        (b1 [-], b3 [1/m^2], c1 [-], d [1/m]) of each segment.
    points : ndarray, shape (M, 2)
        Global (X, Z) midplane samples [m].
    tangent : ndarray, shape (M,)
        Tangent angle of each sample from +X towards +Z [rad].
    tip : ndarray, shape (2,)
        Global (X, Z) of the tip [m].
    nodes : ndarray, shape (N + 1, 2)
        Segment nodes [m].
    beta : ndarray, shape (N,)
        End rotations [rad].
    valid : bool
        Every segment obeys the small-rotation rule |2 d L_i| < 1.
    curvature, fit_rmsd : float
        Signed curvature of the least-squares circle [1/m] and its RMSD [m].
    pressure : float
        Gauge pressure [Pa].
    tip_force : tuple of float
        (f0, p0) [N].
    energy : float
        Total potential [J].

    """

    def __init__(self, solver, q, status, iterations, gradient, step, pressure, loads,
                 tip_force, min_eig=float('nan'), fraction=1.0):
        self.solver = solver
        self.q = q
        self.status = status if type(status) is SolverStatus else SolverStatus(status)
        self.success = self.status is SolverStatus.SUCCESS
        self.iterations = int(iterations)
        self.gradient_norm = float(gradient)
        self.last_step = float(step)
        self.pressure = float(pressure)
        self.tip_force = (float(tip_force[0]), float(tip_force[1]))
        self.point_loads = tuple(loads)
        # Derived fields are built on first use: a controller polling tips pays for
        # neither the message nor the coefficients it does not read.
        self._figures = (gradient, step, iterations, min_eig, fraction)

    @property
    def _message_args(self):
        grad, step, iterations, min_eig, fraction = self._figures
        return dict(grad=grad, gtol=self.solver.gtol, step=step, xtol=self.solver.xtol,
                    iterations=iterations, min_eig=min_eig, fraction=fraction)

    @functools.cached_property
    def rotation_measure(self):
        """|2 d L_i| of every segment, shape (N,): the small-rotation rule wants < 1."""
        return np.abs(2.0 * self.q[:, 3])

    @functools.cached_property
    def valid(self):
        """Every segment obeys the small-rotation rule |2 d L_i| < 1."""
        return bool(self.small_rotations(self.q))

    @staticmethod
    def small_rotations(q):
        """Whether states q (..., N, 4) obey |2 d L_i| < 1 in every segment, shape (...)."""
        return np.all(np.abs(2.0 * q[..., 3]) < 1.0, axis=-1)

    @functools.cached_property
    def message(self):
        """What happened, with the figures behind `status`."""
        text = _MESSAGES[self.status].format(**self._message_args)
        if self.success and not self.valid:
            worst = int(np.argmax(self.rotation_measure))
            text += (f'; segment {worst} breaks the small-rotation rule '
                     f'|2 d L| = {self.rotation_measure[worst]:.3f} >= 1 (valid=False)')
        return text

    @functools.cached_property
    def coefficients(self):
        """(b1 [-], b3 [1/m^2], c1 [-], d [1/m]) of each segment, shape (N, 4)."""
        return from_scaled(self.q, self.solver.segments.lengths)

    @functools.cached_property
    def _chain(self):
        return node_positions(self.q, self.solver.segments.lengths)

    @property
    def nodes(self):
        """Segment nodes O_1..O_{N+1}, shape (N + 1, 2) [m]."""
        return self._chain[0]

    @property
    def theta(self):
        """Node angles theta_i, shape (N,) [rad]."""
        return self._chain[1]

    @property
    def beta(self):
        """End rotations beta_i, shape (N,) [rad]."""
        return self._chain[2]

    @property
    def tip(self):
        """Global (X, Z) of the tip, shape (2,) [m]."""
        return self._chain[0][-1]

    @functools.cached_property
    def _samples(self):
        return midplane_samples(self.q, self.solver.segments.lengths,
                                self.solver.samples_per_segment)

    @property
    def points(self):
        """Global (X, Z) midplane samples, m per segment then the tip, shape (M, 2) [m]."""
        return self._samples[0]

    @property
    def tangent(self):
        """Tangent angle of each sample from +X towards +Z, shape (M,) [rad]."""
        return self._samples[1]

    @property
    def x(self):
        """Alias of `coefficients` flattened, as in scipy's OptimizeResult."""
        return self.coefficients.ravel()

    @functools.cached_property
    def energy(self):
        """Total potential at this state [J]."""
        return self.solver._total_energy(self.q, self.pressure, self.point_loads)

    def __repr__(self):
        return (f'CCMResult(success={self.success}, status={self.status.name}, '
                f'iterations={self.iterations}, tip={self.tip.round(6).tolist()}, '
                f'valid={self.valid})')


class RigidityResult:
    """
    Flexural rigidity by displacement control, eq. (22).

    Attributes
    ----------
    value : float
        K_x or K_z [N m^2].
    force : float
        End load that produces the displacement [N].
    lever : float
        Lever arm |Z_tip| (axis x) or |X_tip| (axis z) in the loaded state [m].
    displacement : float
        Imposed tip displacement [m].
    success, message : bool, str
    unloaded, loaded : CCMResult

    """

    def __init__(self, axis, displacement, force, lever, success, message, unloaded, loaded,
                 iterations):
        self.axis = axis
        self.displacement = float(displacement)
        self.force = float(force)
        self.lever = float(lever)
        self.value = flexural_rigidity(force, lever, displacement) if success else float('nan')
        self.success = bool(success)
        self.message = message
        self.unloaded = unloaded
        self.loaded = loaded
        self.iterations = int(iterations)

    def __repr__(self):
        return (f'RigidityResult(axis={self.axis!r}, value={self.value:.6g}, '
                f'force={self.force:.6g}, lever={self.lever:.6g}, success={self.success})')


class CCMSolver:
    """
    Chained composite model of one finger.

    Parameters
    ----------
    design : ActuatorDesign
        The finger.
    n_segments : int
        Number N of segments of equal length (split at load points if any).
    pressure_model : {None, 'design', 'adiabatic', 'isobaric'}
        k_p = 1/(gamma - 1) (the paper's eq. 20) or 1 (a regulated source); None or
        'design' (the default): the design's `pressure_work_factor`.
    segment_edges : array_like, optional
        Explicit edges from 0 to the free length [m]; overrides `n_segments`.
    load_points : sequence of float
        Arc lengths of intermediate point loads [m]; each becomes a segment edge.
    samples_per_segment : int
        Midplane samples m per segment.
    max_iterations : int
        Newton iterations per (sub)solve.
    gtol : float
        Gradient tolerance relative to the axial stiffness of a segment.
    xtol : float
        Largest final Newton step in the scaled unknowns.
    reconstruction : {'paper', 'consistent'}
        'paper' (default, SPEC) or 'consistent': segment chords and end rotations
        that converge to the rod's as N grows (deformed curvature kappa / (1 + eps));
        see `ccm_geometry.consistent_strain_map`. With 'consistent', `coefficients`
        hold the reconstruction coefficients; map them with that function to get
        the strain's (b1, b3, c1, d).

    References
    ----------
    Zhou, Headings, Dapino (2022), Section III; SPEC; docs/physics.md, sections 4-8.

    """

    def __init__(self, design, n_segments=8, pressure_model=None, segment_edges=None,
                 load_points=(), samples_per_segment=16, max_iterations=60, gtol=1e-10,
                 xtol=1e-9, reconstruction='paper'):
        if not isinstance(design, ActuatorDesign):
            raise TypeError(f'`design` must be an ActuatorDesign, got {type(design).__name__}')
        pressure_model = check_pressure_model(pressure_model)
        if isinstance(n_segments, bool) or not isinstance(n_segments, (int, np.integer)) \
                or n_segments < 1:
            raise ValueError(f'`n_segments` must be an integer >= 1, got {n_segments!r}')
        for name, value in (('samples_per_segment', samples_per_segment),
                            ('max_iterations', max_iterations)):
            if not isinstance(value, (int, np.integer)) or value < 2:
                raise ValueError(f'`{name}` must be an integer >= 2, got {value!r}')
        if reconstruction not in RECONSTRUCTIONS:
            raise ValueError(f'`reconstruction` must be one of {RECONSTRUCTIONS}, '
                             f'got {reconstruction!r}')
        self.reconstruction = reconstruction
        #: The ladder rung this solver is ('ccm_aligned' when `selection` aligns its edges).
        self.rung = 'ccm' if reconstruction == 'paper' else 'ccm_consistent'
        self.design = design
        self.pressure_model = pressure_model
        self.pressure_coefficient = pressure_work_factor(design, pressure_model)
        length = design.free_length
        self.load_points = tuple(real_number('load_points', s, '[m]') for s in load_points)
        for s in self.load_points:
            if not 0.0 < s <= length:
                raise ValueError(f'`load_points` must lie in (0, {length}] [m], got {s}')
        if segment_edges is None:
            edges = uniform_edges(length, int(n_segments), self.load_points)
        else:
            edges = np.asarray(segment_edges, dtype=float)
        self.segments = build_segments(design, edges)
        for s in self.load_points:
            if np.min(np.abs(self.segments.edges - s)) > 1e-12:
                raise ValueError(f'load point {s} [m] is not a segment edge')
        self.n_segments = self.segments.n
        self.samples_per_segment = int(samples_per_segment)
        self.max_iterations = int(max_iterations)
        self.gtol = float(gtol)
        self.xtol = float(xtol)
        # Axial stiffness of the stiffest segment [J]: the scale of gradients in q.
        self.gradient_scale = float(self.segments.stiffness[:, 0, 0].max())
        self._options = NewtonOptions(max_iterations=self.max_iterations, gtol=self.gtol,
                                      xtol=self.xtol, max_step=_MAX_STEP,
                                      energy_scale=self.gradient_scale)
        # The compiled discretisations the engine runs: unloaded (block Hessian), loaded.
        self._data = {loaded: kernels.ccm_data(self.segments, design.prestrain,
                                               design.emc_coefficients,
                                               self.pressure_coefficient,
                                               reconstruction == 'consistent', loaded)
                      for loaded in (False, True)}
        #: What the engine runs: the compiled data, never this object.
        self.engine_problem = engine.CompiledProblem(self._data[False], self._data[True],
                                                     self.flat(), self.gradient_scale)

    # -- energy -----------------------------------------------------------
    def _total_energy(self, q, pressure, loads):
        return kernels.ccm_energy(self._data[False], np.ascontiguousarray(q, dtype=float),
                                  float(pressure), *load_arrays(loads))

    def _loads(self, tip_force, point_loads):
        """Convert the tip force and (s, fx, fz) point loads to (node index, force) pairs."""
        loads = []
        f0 = real_number('tip_force[0]', tip_force[0], '[N]')
        p0 = real_number('tip_force[1]', tip_force[1], '[N]')
        if f0 or p0:
            loads.append((self.n_segments, np.array([f0, p0])))
        for item in point_loads:
            if len(item) != 3:
                raise ValueError(f'`point_loads` items must be (s [m], fx [N], fz [N]), '
                                 f'got {item!r}')
            s, fx, fz = (real_number('point_loads', v, '[m, N]') for v in item)
            check_force('point_loads', (fx, fz))
            node = int(np.argmin(np.abs(self.segments.edges - s)))
            if abs(self.segments.edges[node] - s) > 1e-12 or node == 0:
                raise ValueError(f'point load at s = {s} [m] needs a segment edge there; '
                                 'pass it in `load_points` when building the solver')
            if fx or fz:
                loads.append((node, np.array([fx, fz])))
        return loads

    # -- the discretisation's side of the engine ----------------------------------------
    def flat(self):
        """Return the flat, unstrained state in the scaled unknowns, shape (N, 4)."""
        return np.zeros((self.n_segments, 4))

    def energy(self, q, pressure, loads):
        """Total potential [J] at scaled unknowns `q`."""
        return self._total_energy(q, pressure, loads)

    def derivatives(self, q, pressure, loads):
        """Energy [J], gradient (N, 4) and Hessian ((N, 4, 4) blocks, or dense when loaded)."""
        data = self._data[bool(loads)]
        energy, grad, hess = kernels.ccm_derivatives(
            data, np.ascontiguousarray(q, dtype=float), float(pressure),
            *load_arrays(loads))
        return energy, grad, hess[0][0] if loads else hess[0]

    def step(self, grad, hess):
        """Compute the Newton step, shape (N, 4), and the smallest eigenvalue (1.0 if PD)."""
        return linear_step(grad, hess)

    solve_linear = staticmethod(linear_solve)

    def node_jacobian(self, q, node):
        """Position of a node [m] and its derivatives in the scaled unknowns, (2, N, 4)."""
        return node_jacobian(q, self.segments.lengths, node)

    def material_points(self, result, s):
        """(X, Z) [m] of the material points at reference arc lengths s (K,) of a result."""
        return material_positions(result.q, self.segments.edges, s)

    def _initial_state(self, initial):
        """Scaled warm start from a result or an (N, 4) SI array; None for a fresh solve."""
        n = self.n_segments
        if initial is None:
            return None
        if isinstance(initial, CCMResult):
            if initial.solver is not self and not np.array_equal(
                    initial.solver.segments.edges, self.segments.edges):
                raise ValueError('`initial` result comes from a different segmentation; '
                                 f'expected {n} segments with the same edges')
            return initial.q.copy()
        arr = np.asarray(initial, dtype=float)
        if arr.shape != (n, 4):
            raise ValueError(f'`initial` must be a CCMResult or an ({n}, 4) array of '
                             f'(b1, b3, c1, d) in SI, got shape {arr.shape}')
        if not np.all(np.isfinite(arr)):
            raise ValueError('`initial` must be finite')
        return to_scaled(arr, self.segments.lengths)

    def solve(self, pressure=0.0, tip_force=(0.0, 0.0), initial=None, point_loads=()):
        """
        Find the equilibrium at a gauge pressure and tip load.

        Parameters
        ----------
        pressure : float
            Gauge pressure P >= 0 [Pa].
        tip_force : (float, float)
            (f0, p0), tip force along global X and Z [N].
        initial : CCMResult or array_like (N, 4), optional
            Warm start: Newton starts there, and if that does not reach a stable
            equilibrium the solve starts again from the flat state as with None. It
            changes the iteration count, never the answer.
        point_loads : sequence of (s, fx, fz)
            Extra loads at intermediate arc lengths s that are segment edges [m, N, N].

        Returns
        -------
        CCMResult
            `success` False (with a message) when Newton and continuation both fail;
            the state returned is then the last iterate and must not be used as truth.

        Raises
        ------
        ValueError, TypeError
            On non-finite or negative pressure, malformed loads or initial state, and on
            loads outside the model's envelope (`validation.ENVELOPE`: gauge pressure up
            to twice `design.max_pressure`, tip and point loads up to 5 N each).

        Notes
        -----
        With more than `validation.UNIQUE_LOAD` of load in all, `initial` is ignored: there
        a load can hold the finger on more than one stable branch, and the answer must not
        depend on what was solved before.

        References
        ----------
        Zhou, Headings, Dapino (2022), eq. (21); docs/physics.md, section 8.

        """
        pressure, tip_force = check_load(pressure, tip_force, self.design.max_pressure)
        loads = self._loads(tip_force, point_loads)
        start = self._initial_state(initial)
        if not warm_start_allowed(sum(math.hypot(*force) for _, force in loads)):
            start = None
        out = engine.solve(self.engine_problem, pressure, loads, self._options, start)
        return self._result(out.x, out.status, out.iterations, out.gradient, out.step,
                            out.min_eig, out.fraction, pressure, loads, tip_force)

    def _result(self, x, status, iterations, gradient, step, min_eig, fraction, pressure, loads,
                tip_force):
        """Build the result of an engine solve (a single one or a batch's scene)."""
        return CCMResult(self, x, status, iterations, gradient, step, pressure, loads,
                         tip_force, min_eig, fraction)

    # -- rigidity -----------------------------------------------------------
    def rigidity(self, pressure=0.0, axis='x', displacement=0.010, initial=None):
        """
        Flexural rigidity at fixed pressure by displacement control, eq. (22).

        Solves the unloaded state, then the tip force along +X (or +Z) whose
        loaded equilibrium moves the tip by `displacement` along that axis,
        by Newton on the bordered (Lagrange-multiplier) system.

        Parameters
        ----------
        pressure : float
            Gauge pressure [Pa].
        axis : {'x', 'z'}
            Load and displacement direction.
        displacement : float
            Tip displacement delta > 0 [m].
        initial : CCMResult or array_like, optional
            Warm start of the unloaded solve.

        Returns
        -------
        RigidityResult
            K_x = f0 |Z_tip|^3 / (3 delta) or K_z = p0 |X_tip|^3 / (3 delta), levers
            in the loaded state [N m^2].

        References
        ----------
        Zhou, Headings, Dapino (2022), eq. (22); docs/physics.md, section 10.

        """
        delta = check_rigidity(axis, displacement)
        unloaded = self.solve(pressure, (0.0, 0.0), initial=initial)
        if not unloaded.success:
            return rigidity_result(self, axis, delta, pressure, unloaded)
        out = engine.rigidity(self.engine_problem, unloaded.q, pressure, self.n_segments,
                              AXES[axis], delta, self._options)
        return rigidity_result(self, axis, delta, pressure, unloaded, out)


#: Unit load and displacement direction of each rigidity axis.
AXES = {'x': np.array([1.0, 0.0]), 'z': np.array([0.0, 1.0])}


def check_rigidity(axis, displacement):
    """Check a rigidity request; return the displacement delta > 0 [m] as a float."""
    if axis not in AXES:
        raise ValueError(f"`axis` must be 'x' or 'z', got {axis!r}")
    delta = real_number('displacement', displacement, '[m]')
    if delta <= 0.0:
        raise ValueError(f'`displacement` must be > 0 [m], got {delta}')
    return delta


def rigidity_result(solver, axis, delta, pressure, unloaded, out=None):
    """
    Build the RigidityResult of a displacement-controlled solve, eq. (22).

    Parameters
    ----------
    solver : CCMSolver or ladder solver
        Builds the loaded state's result (`_result`).
    axis : {'x', 'z'}
    delta : float
        [m].
    pressure : float
        [Pa].
    unloaded : result
        The unloaded solve; a failed one gives a failed RigidityResult.
    out : engine.BorderedOutcome, optional
        The displacement control from `unloaded` (None when that failed).

    """
    if not unloaded.success:
        return RigidityResult(axis, delta, math.nan, math.nan, False,
                              'unloaded solve failed: ' + unloaded.message, unloaded, None,
                              unloaded.iterations)
    k = 0 if axis == 'x' else 1
    direction = AXES[axis]
    iterations = unloaded.iterations + out.iterations
    force = out.force * direction
    loads = [(solver.n_segments, force)]
    if not out.success:
        loaded = solver._result(out.x, SolverStatus.CONTINUATION_FAILED, iterations, math.inf,
                                math.inf, math.nan, out.fraction, pressure, loads, tuple(force))
        return RigidityResult(axis, delta, out.force, math.nan, False,
                              f'displacement control stalled at {out.fraction:.1%} '
                              'of the displacement', unloaded, loaded, iterations)
    loaded = solver._result(out.x, SolverStatus.SUCCESS, iterations, out.gradient, 0.0,
                            math.nan, 1.0, pressure, loads, tuple(force))
    message = 'converged' + ('' if out.stable else
                             ' (loaded state is unstable under force control)')
    # The lever is the loaded node's position that the displacement control constrains.
    return RigidityResult(axis, delta, out.force, abs(float(out.tip[1 - k])), True, message,
                          unloaded, loaded, iterations)
