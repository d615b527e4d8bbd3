"""What every rung beyond the CCM shares: its solve, rigidity and results."""

import math

import numpy as np

from .ccm import AXES, check_rigidity, pressure_work_factor, rigidity_result
from .. import engine
from ..design import ActuatorDesign
from ..engine import SolverStatus
from ..kernels.circle import circle_fit
from ..result import finger_result, Result
from ..validation import (check_load, check_outputs, check_pressure_model, integer,
                          OUTPUT_LEVELS, warm_start_allowed)

__all__ = ['RungSolver', 'check_common', 'set_common']

_MESSAGES = {
    SolverStatus.MAX_ITERATIONS: 'not converged after {iterations} Newton iterations '
                                 '(last step {step:.1e})',
    SolverStatus.LINE_SEARCH_FAILED: 'line search found no decrease (last step {step:.1e}); '
                                     'the equilibrium may not exist nearby',
    SolverStatus.NOT_FINITE: 'energy or gradient became non-finite',
    SolverStatus.UNSTABLE: 'converged to an unstable equilibrium (Hessian not positive '
                           'definite)',
    SolverStatus.CONTINUATION_FAILED: 'continuation in pressure and load stalled at '
                                      '{fraction:.1%} of the requested loading',
}
#: The level of every result a rigidity builds for an interpreted rung (the rod).
_ALL = OUTPUT_LEVELS['all']


def check_common(design, pressure_model, samples):
    if not isinstance(design, ActuatorDesign):
        raise TypeError(f'`design` must be an ActuatorDesign, got {type(design).__name__}')
    check_pressure_model(pressure_model)
    integer('samples', samples, 3)


def set_common(solver, design, pressure_model, tol, samples, max_iterations):
    """Check and store the settings every non-CCM rung has."""
    check_common(design, pressure_model, samples)
    solver.design = design
    solver.pressure_model = check_pressure_model(pressure_model)
    solver.pressure_coefficient = pressure_work_factor(design, pressure_model)
    solver.tol = float(tol)
    solver.samples = int(samples)
    solver.max_iterations = int(max_iterations)
    solver.length = design.free_length


class RungSolver:
    """
    Shared solve and rigidity of the non-CCM rungs: discretisations of the one engine.

    A subclass provides `_constants` (`result.finger_constants`, at its construction),
    `_pack`/`_unpack` between its state and the engine's flat
    unknowns, `_flat_state`, `energy`, `derivatives`, `step`, `solve_linear`,
    `node_jacobian`, `gradient_scale`, `_options`, `edges` and `_positions` (its result's
    `position_at`), and a compiled `engine_problem` or `_outputs` (the output fields of a
    state by name, for one run interpreted); the Newton loop, the warm-start rule,
    continuation and displacement control are the engine's.
    """

    @property
    def tip_node(self):
        """Index of the tip node, where these rungs take their load."""
        return self.n_segments

    def flat(self):
        """Return the flat, unstrained state as engine unknowns."""
        return self._pack(self._flat_state())

    def unknowns(self, result):
        """Return the engine unknowns of a result of this solver (for `engine` functions)."""
        return self._pack(result.state)

    def tip_loads(self, force):
        """Return the engine loads of a tip force (F_X, F_Z) [N]: none when it is zero."""
        f0, f1 = force
        # Compared as floats, not through an array reduction: this is on every solve.
        if f0 == 0.0 and f1 == 0.0:
            return []
        return [(self.tip_node, np.array((f0, f1), dtype=float))]

    def _force(self, loads):
        """Total tip force (F_X, F_Z) [N] of engine loads (these rungs load the tip only)."""
        force = np.zeros(2)
        for node, value in loads:
            if node != self.tip_node:
                raise ValueError(f'{type(self).__name__} takes a load at the tip only, got '
                                 f'one at node {node}')
            force = force + np.asarray(value, dtype=float)
        return force

    def _warm_start(self, initial):
        """Engine unknowns of a warm start: a result of the same discretisation, or None."""
        if initial is None:
            return None
        if isinstance(initial, Result) and initial.rung == self.rung and (
                initial.segment_edges is self.edges
                or np.array_equal(initial.segment_edges, self.edges)):
            x = initial.x
            if x.shape == self.engine_problem.flat().shape:
                return x
        raise ValueError(f'`initial` must be None or a result of a {type(self).__name__} with '
                         'the same discretisation')

    def solve(self, pressure=0.0, tip_force=(0.0, 0.0), initial=None, *, outputs='all',
              model_choice=None):
        """
        Find the equilibrium at a gauge pressure and tip load.

        Parameters
        ----------
        pressure : float
            Gauge pressure P >= 0 [Pa].
        tip_force : (float, float)
            (f0, p0), tip force along global X and Z [N].
        initial : Result, optional
            Warm start, a result of the same discretisation: Newton starts there, and if
            that does not reach a stable equilibrium the solve starts again from the flat,
            unstrained state as with None. It changes the iteration count, never the
            answer; it is ignored above `validation.UNIQUE_LOAD` of tip load.
        outputs : {'all', 'shape', 'tip'}
            What the result holds besides the state, as `CCMSolver.solve`'s.
        model_choice : ModelChoice, optional
            The choice that picked this model, recorded in the result.

        Returns
        -------
        Result
            `result.FINGER_FIELDS`; `success` False (with a message) when Newton and
            continuation both fail.

        """
        level = check_outputs(outputs)
        pressure, force = check_load(pressure, tip_force, self.design.max_pressure)
        start = self._warm_start(initial)
        # Beyond UNIQUE_LOAD a warm start could pick another stable branch: start cold.
        if start is not None and not warm_start_allowed(math.hypot(*force)):
            start = None
        loads = self.tip_loads(force)
        outcome = engine.solve(self.engine_problem, pressure, loads, self._options, start,
                               self._fields_level(level, force))
        return self._result(outcome, pressure, force, model_choice=model_choice, level=level)

    def _fields_level(self, level, force):
        """Return the level the engine computes a solve's outputs to: the one asked for."""
        return level

    def _result(self, outcome, pressure, tip_force, point_loads=(), model_choice=None,
                level=_ALL):
        """Build the Result of an engine outcome and its fields (a solve, or a batch's scene)."""
        tip_force = (float(tip_force[0]), float(tip_force[1]))
        fields = outcome.fields
        if fields is None:
            fields = self._python_fields(outcome.x, pressure, tip_force, level)
        if outcome.status is SolverStatus.SUCCESS:
            message = f'converged: last Newton step {outcome.step:.1e} <= {self.tol:.0e}'
        else:
            message = _MESSAGES[outcome.status].format(step=outcome.step,
                                                       iterations=outcome.iterations,
                                                       fraction=outcome.fraction)
        if outcome.fields is None:
            outcome = outcome._replace(fields=fields)
        return finger_result(outcome, message, pressure, tip_force, self._unpack(outcome.x),
                             self._positions(outcome.x, pressure, tip_force), self._constants,
                             (), model_choice)

    def _python_fields(self, x, pressure, force, level):
        """
        Return the `engine.Fields` of a state an outcome came without (run interpreted).

        A compiled rung's (a test may run its loops interpreted) from its outputs hook; the
        rod's from its `_outputs` (a dict).
        """
        force = np.asarray(force, dtype=float)
        if isinstance(self.engine_problem, engine.CompiledProblem):
            loads = [(self.tip_node, force[None])] if force.any() else []
            return engine.outputs(self.engine_problem, np.asarray(x)[None], [pressure], loads,
                                  level)[0]
        if level < OUTPUT_LEVELS['shape']:
            tip = np.asarray(self.node_jacobian(x, self.tip_node)[0], dtype=float)
            return engine.Fields(tip, None, True, None, None, None, None, None, None, None,
                                 None, None)
        out = self._outputs(self._unpack(x), pressure, force)
        tip = np.asarray(out['tip'], dtype=float)
        curvature = rmsd = None
        if level >= _ALL:
            curvature, rmsd = (float(v) for v in circle_fit(
                np.ascontiguousarray(out['points'], dtype=float))[:2])
        beta = np.asarray(out['beta'], dtype=float)
        coefficients = out['coefficients']
        return engine.Fields(
            tip, float(out['energy']), True, curvature, rmsd, out['nodes'], beta,
            np.concatenate([[0.0], np.cumsum(beta[:-1])]),
            coefficients, out['points'], out['tangent'], out['strains'])

    def rigidity(self, pressure=0.0, axis='x', displacement=0.010, initial=None, *,
                 outputs='tip'):
        """
        Flexural rigidity at fixed pressure by displacement control, eq. (22).

        The engine's bordered system finds the tip force along +X (or +Z) whose
        equilibrium moves the tip by `displacement` along that axis; see
        `CCMSolver.rigidity` for the parameters.

        Returns
        -------
        Result
            `ccm.RIGIDITY_FIELDS`: K_x = f0 |Z_tip|^3 / (3 delta) or K_z = p0 |X_tip|^3 /
            (3 delta) [N m^2].

        """
        level = check_outputs(outputs)
        delta = check_rigidity(axis, displacement)
        pressure = check_load(pressure, (0.0, 0.0), self.design.max_pressure)[0]
        out = engine.rigidity(self.engine_problem, pressure, self.tip_node, AXES[axis], delta,
                              self._options, self._warm_start(initial), level)
        return rigidity_result(self, axis, delta, pressure, out, level)
