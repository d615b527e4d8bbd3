"""The engine's statuses, Newton options and the outcomes its loops return."""

from dataclasses import dataclass
import enum
import math
import typing

import numpy as np


class SolverStatus(enum.IntEnum):
    """Outcome of a solve; only SUCCESS has success=True."""

    SUCCESS = 0
    MAX_ITERATIONS = 1
    LINE_SEARCH_FAILED = 2
    NOT_FINITE = 3
    UNSTABLE = 4
    CONTINUATION_FAILED = 5


# The loops below compare plain ints: numba compiles them as constants.
_SUCCESS = int(SolverStatus.SUCCESS)
_MAX_ITERATIONS = int(SolverStatus.MAX_ITERATIONS)
_LINE_SEARCH_FAILED = int(SolverStatus.LINE_SEARCH_FAILED)
_NOT_FINITE = int(SolverStatus.NOT_FINITE)
_UNSTABLE = int(SolverStatus.UNSTABLE)
_CONTINUATION_FAILED = int(SolverStatus.CONTINUATION_FAILED)


@dataclass(frozen=True)
class NewtonOptions:
    """
    Tolerances and safeguards of the damped Newton, in a discretisation's scaled unknowns.

    Attributes
    ----------
    max_iterations : int
        Newton iterations per (sub)solve.
    gtol : float
        Largest max|gradient| / gradient_scale at convergence (inf: not checked).
    xtol : float
        Largest final Newton step, max|dx| [scaled units].
    max_step : float or ndarray
        Cap on each component of a step (broadcast to the unknowns): Newton stays local,
        where the quintic PEMC energy (unbounded below at large tension) is meaningful.
    flat_slope : float
        Near the solution the energy change is below round-off: a full step is taken
        when -slope <= flat_slope * (|E| + energy_scale).
    energy_scale : float
        Energy scale of that test [J].
    armijo : float
        Sufficient-decrease constant of the backtracking line search.

    """

    max_iterations: int = 60
    gtol: float = math.inf
    xtol: float = 1e-9
    max_step: object = 0.5
    flat_slope: float = 1e-13
    energy_scale: float = 1.0
    armijo: float = 1e-4

    def packed(self, gradient_scale, shape):
        """Return the options as the loops take them: a tuple and the step cap of `shape`."""
        cap = np.ascontiguousarray(np.broadcast_to(np.asarray(self.max_step, dtype=float),
                                                   shape))
        return (int(self.max_iterations), float(self.gtol), float(self.xtol),
                float(self.flat_slope), float(self.energy_scale), float(self.armijo),
                float(gradient_scale)), cap


class NewtonOutcome(typing.NamedTuple):
    """State and figures of one Newton run (internal: solvers build their results from it)."""

    x: np.ndarray
    status: SolverStatus
    iterations: int
    gradient: float
    step: float
    min_eig: float = math.nan
    fraction: float = 1.0
    #: The state's outputs (`Fields`), computed with it; None where the problem runs
    #: interpreted (its own code computes them) or none were asked for.
    fields: object = None


class Fields(typing.NamedTuple):
    """
    The outputs of a state, computed with it in one compiled call (internal: results).

    Below the call's level (`solves.OUTPUTS`) the fields it does not reach are None, as
    coefficients and strains are where the discretisation has none.
    """

    tip: np.ndarray
    energy: object
    valid: bool
    curvature: object
    fit_rmsd: object
    nodes: object
    beta: object
    theta: object
    coefficients: object
    points: object
    tangent: object
    strains: object


#: SolverStatus by code, without the enum's own lookup on every solve.
_STATUS = tuple(SolverStatus)


@dataclass(frozen=True)
class BorderedOutcome:
    """Loaded state of a displacement-controlled solve (internal)."""

    x: np.ndarray
    force: float
    success: bool
    iterations: int
    fraction: float
    stable: bool
    gradient: float
    #: Position of the loaded node in the loaded state [m], shape (2,).
    tip: np.ndarray
    #: The unloaded solve it started from (`engine.rigidity` makes it).
    unloaded: NewtonOutcome = None
    #: The loaded state's outputs under the found force, as `NewtonOutcome.fields`.
    fields: object = None
