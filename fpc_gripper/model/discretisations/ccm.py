"""CCM equilibrium solver: damped Newton with warm starts, continuation and rigidity."""

import functools
import math

import numpy as np

from .ccm_geometry import material_positions, to_scaled
from .. import engine
from ..analysis import flexural_rigidity
from ..design import ActuatorDesign
from ..engine import linear_solve, linear_step, NewtonOptions, SolverStatus
from ..kernels import ccm as kernels
from ..kernels.chain import load_arrays, node_jacobian
from ..result import finger_constants, finger_result, Result
from ..section.segments import build_segments, uniform_edges
from ..validation import (arc_lengths, check_force, check_load, check_outputs,
                          check_pressure_model, integer, PRESSURE_MODELS, real_number,
                          warm_start_allowed)

__all__ = ['CCMSolver', 'SolverStatus', 'AXES', 'check_rigidity', 'rigidity_result',
           'pressure_work_factor', 'positions_at', 'CCM_RUNGS', 'RIGIDITY_FIELDS']

# The engine runs this discretisation compiled through these hooks (`engine.register`).
engine.register(kernels.CCMData, kernels.CCM_HOOKS)

#: Midplane reconstructions: the paper's, or one that converges to the rod as N grows
#: (ccm_geometry.consistent_strain_map).
RECONSTRUCTIONS = ('paper', 'consistent')
#: The rungs a CCMSolver is: its states warm-start one another where the edges agree.
CCM_RUNGS = ('ccm', 'ccm_consistent', 'ccm_aligned')
#: Largest Newton step in any scaled unknown; keeps iterates where the quintic PEMC
#: energy (unbounded below at large tension) is meaningful.
_MAX_STEP = 0.5


_MESSAGES = {
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


def positions_at(q, edges, length, s):
    """
    Midplane position of the CCM's material points at reference arc lengths `s` from the clamp.

    Exact for the CCM's kinematics: the segment polynomials of eqs. (13) and (15), as drawn
    (`ccm_geometry.material_positions`). A result's `position_at` is this function of its
    own state and edges.

    Parameters
    ----------
    q : ndarray, shape (N, 4)
        Scaled unknowns.
    edges : ndarray, shape (N + 1,)
        Segment edges [m].
    length : float
        Free length L [m].
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
    values, shape = arc_lengths('s', s, length)
    return material_positions(q, edges, values).reshape(shape + (2,))


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
    rung : {None, 'ccm', 'ccm_consistent', 'ccm_aligned'}
        The ladder rung its results report; None: by the reconstruction ('ccm_aligned' is
        the consistent CCM on `selection.aligned_edges`).

    References
    ----------
    Zhou, Headings, Dapino (2022), Section III; SPEC; docs/physics.md, sections 4-8.

    """

    def __init__(self, design, n_segments=8, pressure_model=None, segment_edges=None,
                 load_points=(), samples_per_segment=16, max_iterations=60, gtol=1e-10,
                 xtol=1e-9, reconstruction='paper', rung=None):
        if not isinstance(design, ActuatorDesign):
            raise TypeError(f'`design` must be an ActuatorDesign, got {type(design).__name__}')
        pressure_model = check_pressure_model(pressure_model)
        integer('n_segments', n_segments, 1)
        integer('samples_per_segment', samples_per_segment, 2)
        integer('max_iterations', max_iterations, 2)
        if reconstruction not in RECONSTRUCTIONS:
            raise ValueError(f'`reconstruction` must be one of {RECONSTRUCTIONS}, '
                             f'got {reconstruction!r}')
        self.reconstruction = reconstruction
        #: The ladder rung this solver is ('ccm_aligned' when `selection` aligns its edges).
        self.rung = rung or ('ccm' if reconstruction == 'paper' else 'ccm_consistent')
        if self.rung not in CCM_RUNGS:
            raise ValueError(f'`rung` must be one of {CCM_RUNGS}, got {rung!r}')
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
        # The message of a converged solve with the tolerances in: two figures per solve.
        self._converged = (f'converged: relative gradient %.1e <= {self.gtol:.0e} and last '
                           f'step %.1e <= {self.xtol:.0e}')
        # The compiled discretisations the engine runs: unloaded (block Hessian), loaded.
        self._data = {loaded: kernels.ccm_data(self.segments, design.prestrain,
                                               design.emc_coefficients,
                                               self.pressure_coefficient,
                                               reconstruction == 'consistent', loaded,
                                               self.samples_per_segment)
                      for loaded in (False, True)}
        #: What the engine runs: the compiled data, never this object.
        self.engine_problem = engine.CompiledProblem(self._data[False], self._data[True],
                                                     self.flat(), self.gradient_scale)
        self._constants = finger_constants(self.rung, self.n_segments, self.segments.edges)

    @property
    def edges(self):
        """Segment edges from 0 to the free length, (N + 1,) [m]."""
        return self.segments.edges

    # -- energy -----------------------------------------------------------
    def _total_energy(self, q, pressure, loads):
        return kernels.ccm_energy(self._data[False], np.ascontiguousarray(q, dtype=float),
                                  float(pressure), *load_arrays(loads))

    def _loads(self, tip_force, point_loads):
        """Convert a checked tip force and (s, fx, fz) point loads to (node, force) pairs."""
        loads = []
        f0, p0 = tip_force
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

    def _initial_state(self, initial):
        """Scaled warm start from a result or an (N, 4) SI array; None for a fresh solve."""
        n = self.n_segments
        if initial is None:
            return None
        if isinstance(initial, Result):
            edges = initial.segment_edges
            if initial.rung not in CCM_RUNGS or not (
                    edges is self.segments.edges or np.array_equal(edges, self.segments.edges)):
                raise ValueError('`initial` result comes from another model or segmentation; '
                                 f'expected a CCM of {n} segments with the same edges')
            return initial.x
        arr = np.asarray(initial, dtype=float)
        if arr.shape != (n, 4):
            raise ValueError(f'`initial` must be a CCM result or an ({n}, 4) array of '
                             f'(b1, b3, c1, d) in SI, got shape {arr.shape}')
        if not np.all(np.isfinite(arr)):
            raise ValueError('`initial` must be finite')
        return to_scaled(arr, self.segments.lengths)

    def solve(self, pressure=0.0, tip_force=(0.0, 0.0), initial=None, point_loads=(), *,
              outputs='all', model_choice=None):
        """
        Find the equilibrium at a gauge pressure and tip load.

        Parameters
        ----------
        pressure : float
            Gauge pressure P >= 0 [Pa].
        tip_force : (float, float)
            (f0, p0), tip force along global X and Z [N].
        initial : Result or array_like (N, 4), optional
            Warm start: a CCM result of the same edges, or (b1, b3, c1, d) in SI. Newton
            starts there, and if that does not reach a stable equilibrium the solve starts
            again from the flat state as with None. It changes the iteration count, never
            the answer.
        point_loads : sequence of (s, fx, fz)
            Extra loads at intermediate arc lengths s that are segment edges [m, N, N].
        outputs : {'all', 'shape', 'tip'}
            What the result holds besides the state (`result.FINGER_FIELDS`): 'tip' the
            chain (tip, nodes, rotations, coefficients, validity); 'shape' also the energy
            and the midplane samples; 'all' (the default) also their circle fit. Fields
            not asked for are None. All are computed in the solve's one compiled call.
        model_choice : ModelChoice, optional
            The choice that picked this model (`AdaptiveSolver` passes it), recorded in
            the result.

        Returns
        -------
        Result
            `FINGER_FIELDS`; `success` False (with a message) when Newton and continuation
            both fail: the state returned is then the last iterate and must not be used
            as truth.

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
        level = check_outputs(outputs)
        pressure, tip_force = check_load(pressure, tip_force, self.design.max_pressure)
        loads = self._loads(tip_force, point_loads)
        start = self._initial_state(initial)
        if start is not None and not warm_start_allowed(
                sum(math.hypot(*force) for _, force in loads)):
            start = None
        outcome = engine.solve(self.engine_problem, pressure, loads, self._options, start, level)
        return self._result(outcome, pressure, tip_force, tuple(point_loads), model_choice)

    def _result(self, outcome, pressure, tip_force, point_loads=(), model_choice=None,
                level=None):
        """Build the Result of an engine outcome and its fields (a solve, or a batch's scene)."""
        q = outcome.x
        fields = outcome.fields
        if outcome.status is SolverStatus.SUCCESS:
            message = self._converged % (outcome.gradient, outcome.step)
        else:
            message = _MESSAGES[outcome.status].format(
                grad=outcome.gradient, step=outcome.step, iterations=outcome.iterations,
                min_eig=outcome.min_eig, fraction=outcome.fraction)
        if outcome.status is SolverStatus.SUCCESS and not fields.valid:
            turn = np.abs(2.0 * q[:, 3])
            worst = int(np.argmax(turn))
            message += (f'; segment {worst} breaks the small-rotation rule '
                        f'|2 d L| = {turn[worst]:.3f} >= 1 (valid=False)')
        return finger_result(outcome, message, pressure, tip_force, q,
                             functools.partial(positions_at, q, self.segments.edges,
                                               self.design.free_length),
                             self._constants, point_loads, model_choice)

    # -- rigidity -----------------------------------------------------------
    def rigidity(self, pressure=0.0, axis='x', displacement=0.010, initial=None, *,
                 outputs='tip'):
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
        initial : Result or array_like, optional
            Warm start of the unloaded solve.
        outputs : {'tip', 'shape', 'all'}
            What the `unloaded` and `loaded` results hold, as `solve`'s; 'tip' (the
            default) costs least.

        Returns
        -------
        Result
            `RIGIDITY_FIELDS`: value K_x = f0 |Z_tip|^3 / (3 delta) or K_z = p0 |X_tip|^3 /
            (3 delta) [N m^2], levers in the loaded state.

        References
        ----------
        Zhou, Headings, Dapino (2022), eq. (22); docs/physics.md, section 10.

        """
        level = check_outputs(outputs)
        delta = check_rigidity(axis, displacement)
        pressure = check_load(pressure, (0.0, 0.0), self.design.max_pressure)[0]
        out = engine.rigidity(self.engine_problem, pressure, self.n_segments, AXES[axis],
                              delta, self._options, self._initial_state(initial), level)
        return rigidity_result(self, axis, delta, pressure, out, level)


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


#: The fields of a rigidity's `Result`.
RIGIDITY_FIELDS = {
    'value': 'K_x or K_z [N m^2]; NaN where not found',
    'force': 'end load that produces the displacement [N]',
    'lever': 'lever arm |Z_tip| (axis x) or |X_tip| (axis z) in the loaded state [m]',
    'axis': "'x' or 'z'",
    'displacement': 'imposed tip displacement [m]',
    'success': 'the unloaded and the displacement-controlled solves both converged',
    'message': 'what happened',
    'iterations': 'unloaded plus bordered Newton iterations',
    'unloaded': "the unloaded solve's Result",
    'loaded': "the loaded state's Result under the found force (None where the unloaded "
              'solve failed)',
    'model': "the rung and N, as the results'",
}


def rigidity_result(solver, axis, delta, pressure, out, level):
    """
    Build the Result of a displacement-controlled solve, eq. (22) (`RIGIDITY_FIELDS`).

    Parameters
    ----------
    solver : CCMSolver or ladder solver
        Builds the finger results (`_result`).
    axis : {'x', 'z'}
    delta : float
        [m].
    pressure : float
        [Pa].
    out : engine.BorderedOutcome
        `engine.rigidity`'s: the unloaded solve and the displacement control from it.
    level : int
        Of the outputs of both results (`validation.OUTPUT_LEVELS`), for a rung whose own
        code computes them.

    """
    unloaded = out.unloaded
    free = solver._result(unloaded, pressure, (0.0, 0.0), level=level)
    if not free.success:
        return _rigidity(axis, delta, math.nan, math.nan, False,
                         'unloaded solve failed: ' + free.message, free, None,
                         free.iterations)
    k = 0 if axis == 'x' else 1
    force = out.force * AXES[axis]
    tip_force = (float(force[0]), float(force[1]))
    iterations = unloaded.iterations + out.iterations
    if not out.success:
        loaded = solver._result(engine.NewtonOutcome(
            out.x, SolverStatus.CONTINUATION_FAILED, iterations, math.inf, math.inf,
            math.nan, out.fraction, out.fields), pressure, tip_force, level=level)
        return _rigidity(axis, delta, out.force, math.nan, False,
                         f'displacement control stalled at {out.fraction:.1%} of the '
                         'displacement', free, loaded, iterations)
    loaded = solver._result(engine.NewtonOutcome(out.x, SolverStatus.SUCCESS, iterations,
                                                 out.gradient, 0.0, math.nan, 1.0, out.fields),
                            pressure, tip_force, level=level)
    message = 'converged' + ('' if out.stable else
                             ' (loaded state is unstable under force control)')
    # The lever is the loaded node's position that the displacement control constrains.
    return _rigidity(axis, delta, out.force, abs(float(out.tip[1 - k])), True, message, free,
                     loaded, iterations)


def _rigidity(axis, delta, force, lever, success, message, unloaded, loaded, iterations):
    return Result.of({
        'value': flexural_rigidity(force, lever, delta) if success else math.nan,
        'force': float(force), 'lever': float(lever), 'axis': axis,
        'displacement': float(delta), 'success': bool(success), 'message': message,
        'iterations': int(iterations), 'unloaded': unloaded, 'loaded': loaded,
        'model': unloaded.model,
    })
