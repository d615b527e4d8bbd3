"""What every rung beyond the CCM shares: its result type and its solve and rigidity."""

import functools
import math

import numpy as np

from .ccm import AXES, check_rigidity, pressure_work_factor, ResultPositions, rigidity_result
from .. import engine
from ..analysis import CircleFitted
from ..design import ActuatorDesign
from ..engine import SolverStatus
from ..validation import check_load, check_pressure_model, warm_start_allowed

__all__ = ['LadderResult', 'ArcResult', 'RodResult', 'RungSolver', 'check_common',
           'set_common']

_MESSAGES = {
    SolverStatus.SUCCESS: 'converged: last Newton step {step:.1e} <= {tol:.0e}',
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


class LadderResult(ResultPositions, CircleFitted):
    """
    Equilibrium of one finger from a ladder rung, with the fields of `CCMResult`.

    Attributes
    ----------
    success : bool
        True only for a converged, stable equilibrium.
    status : SolverStatus
    message : str
    iterations : int
        Newton iterations, continuation steps included.
    coefficients : ndarray, shape (N, 4) or None
        Arc: the CCM coefficients (b1, b3, c1, d) of one segment with the same
        uniform strain (b1 = eps, d = kappa/2, b3 = -2 d^2/3, SI). Rod: None
        (it has no polynomial segments); see `strains`.
    points : ndarray, shape (M, 2)
        Global (X, Z) midplane samples at evenly spaced reference arc length,
        the root first and the tip last [m].
    tangent : ndarray, shape (M,)
        Tangent angle theta of every sample from +X towards +Z [rad].
    strains : ndarray, shape (M, 3)
        (eps [-], kappa [1/m], c1 [-]) at every sample; kappa = d theta/d s per
        reference length, the deformed curvature is kappa / (1 + eps).
    tip : ndarray, shape (2,)
        Global (X, Z) of the tip [m].
    beta : ndarray, shape (N,)
        Rotation of every element (arc: N = 1, the whole arc) [rad].
    valid : bool
        Always True: these rungs are geometrically exact and have no
        small-rotation rule.
    curvature, fit_rmsd : float
        Signed curvature of the least-squares circle [1/m] and its RMSD [m].
    pressure : float
        Gauge pressure [Pa].
    tip_force : tuple of float
        (f0, p0) [N].
    energy : float
        Total potential [J].

    """

    def __init__(self, solver, state, status, iterations, step, pressure, tip_force,
                 fraction=1.0):
        self.solver = solver
        self.state = state
        self.status = SolverStatus(status)
        self.success = self.status is SolverStatus.SUCCESS
        self.iterations = int(iterations)
        self.last_step = float(step)
        self.pressure = float(pressure)
        self.tip_force = (float(tip_force[0]), float(tip_force[1]))
        self.valid = True
        self._figures = (step, iterations, fraction)

    @functools.cached_property
    def message(self):
        """What happened, with the figures behind `status`."""
        step, iterations, fraction = self._figures
        return _MESSAGES[self.status].format(step=step, tol=self.solver.tol,
                                             iterations=iterations, fraction=fraction)

    # The outputs are built on first use: a caller reading the tip pays for the samples only
    # when it reads them.
    @functools.cached_property
    def _out(self):
        return self.solver._outputs(self.state, self.pressure, np.array(self.tip_force))

    points = property(lambda self: self._out['points'],
                      doc='Global (X, Z) midplane samples, root first, tip last [m].')
    tangent = property(lambda self: self._out['tangent'],
                       doc='Tangent angle theta of every sample from +X towards +Z [rad].')
    strains = property(lambda self: self._out['strains'],
                       doc='(eps [-], kappa [1/m], c1 [-]) at every sample.')
    tip = property(lambda self: self._out['tip'], doc='Global (X, Z) of the tip [m].')
    beta = property(lambda self: self._out['beta'],
                    doc='Rotation of every element [rad].')
    coefficients = property(lambda self: self._out['coefficients'],
                            doc='CCM coefficients (b1, b3, c1, d) of every segment, or None.')
    nodes = property(lambda self: self._out['nodes'], doc='Segment ends [m].')
    energy = property(lambda self: self._out['energy'], doc='Total potential [J].')

    def __repr__(self):
        return (f'{type(self).__name__}(success={self.success}, status={self.status.name}, '
                f'iterations={self.iterations}, tip={self.tip.round(6).tolist()})')


class ArcResult(LadderResult):
    """Result of `ArcSolver`; `state` is (eps, kappa, c1)."""


class RodResult(LadderResult):
    """Result of `RodSolver`; `state` is (theta nodal values, (eps, c1) at quadrature points)."""


def check_common(design, pressure_model, samples):
    if not isinstance(design, ActuatorDesign):
        raise TypeError(f'`design` must be an ActuatorDesign, got {type(design).__name__}')
    check_pressure_model(pressure_model)
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 3:
        raise ValueError(f'`samples` must be an integer >= 3, got {samples!r}')


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

    A subclass provides `_pack`/`_unpack` between its state and the engine's flat
    unknowns, `_flat_state`, `energy`, `derivatives`, `step`, `solve_linear`,
    `node_jacobian`, `gradient_scale` and `_options`; the Newton loop, the warm-start
    rule, continuation and displacement control are the engine's.
    """

    _result_type = LadderResult

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
        force = np.asarray(force, dtype=float)
        return [(self.tip_node, force)] if force.any() else []

    def _force(self, loads):
        """Total tip force (F_X, F_Z) [N] of engine loads (these rungs load the tip only)."""
        force = np.zeros(2)
        for node, value in loads:
            if node != self.tip_node:
                raise ValueError(f'{type(self).__name__} takes a load at the tip only, got '
                                 f'one at node {node}')
            force = force + np.asarray(value, dtype=float)
        return force

    def solve(self, pressure=0.0, tip_force=(0.0, 0.0), initial=None):
        """
        Find the equilibrium at a gauge pressure and tip load.

        Parameters
        ----------
        pressure : float
            Gauge pressure P >= 0 [Pa].
        tip_force : (float, float)
            (f0, p0), tip force along global X and Z [N].
        initial : result of this solver, optional
            Warm start: Newton starts there, and if that does not reach a stable
            equilibrium the solve starts again from the flat, unstrained state as
            with None. It changes the iteration count, never the answer; it is ignored
            above `validation.UNIQUE_LOAD` of tip load.

        Returns
        -------
        LadderResult
            `success` False (with a message) when Newton and continuation both fail.

        """
        pressure, force = check_load(pressure, tip_force, self.design.max_pressure)
        force = np.array(force)
        if initial is not None and not (isinstance(initial, self._result_type) and (
                initial.solver is self or initial.solver._compatible(self))):
            raise ValueError(f'`initial` must be None or a {self._result_type.__name__} of a '
                             'solver with the same discretisation')
        # Beyond UNIQUE_LOAD a warm start could pick another stable branch: start cold.
        warm = initial is not None and warm_start_allowed(math.hypot(*force))
        x0 = self._pack(initial.state) if warm else None
        loads = self.tip_loads(force)
        out = engine.solve(self.engine_problem, pressure, loads, self._options, x0)
        return self._result(out.x, out.status, out.iterations, out.gradient, out.step,
                            out.min_eig, out.fraction, pressure, loads, force)

    def _result(self, x, status, iterations, gradient, step, min_eig, fraction, pressure, loads,
                tip_force):
        """Build the result of an engine solve (a single one or a batch's scene)."""
        return self._result_type(self, self._unpack(x), status, iterations, step, pressure,
                                 np.asarray(tip_force, dtype=float), fraction=fraction)

    def rigidity(self, pressure=0.0, axis='x', displacement=0.010, initial=None):
        """
        Flexural rigidity at fixed pressure by displacement control, eq. (22).

        The engine's bordered system finds the tip force along +X (or +Z) whose
        equilibrium moves the tip by `displacement` along that axis.

        Returns
        -------
        RigidityResult
            K_x = f0 |Z_tip|^3 / (3 delta) or K_z = p0 |X_tip|^3 / (3 delta) [N m^2].

        """
        delta = check_rigidity(axis, displacement)
        unloaded = self.solve(pressure, (0.0, 0.0), initial=initial)
        if not unloaded.success:
            return rigidity_result(self, axis, delta, pressure, unloaded)
        out = engine.rigidity(self.engine_problem, self._pack(unloaded.state), pressure,
                              self.tip_node, AXES[axis], delta, self._options)
        return rigidity_result(self, axis, delta, pressure, unloaded, out)
