"""Where eq. 22's rigidity breaks: a short lever, a loaded state off its branch, and dF/dδ."""

import enum
import math

import numpy as np

from . import engine
from .discretisations.ccm import AXES
from .result import Result

__all__ = ['RigidityStatus', 'RIGIDITY_CHECK_FIELDS', 'checked_rigidity', 'classify',
           'direct_stiffness', 'UNSTABLE_NOTE']

#: What `rigidity_result` appends to the message of a loaded state that is unstable under
#: force control (the loaded state is on another branch than the unloaded one).
UNSTABLE_NOTE = 'unstable under force control'


class RigidityStatus(enum.IntEnum):
    """How far eq. 22's K = F l^3 / (3 delta) describes the finger at one pressure."""

    #: Eq. 22 applies: a lever longer than the displacement, a stable loaded state.
    OK = 0
    #: No displacement-controlled state was found (or the unloaded solve failed).
    FAILED = 1
    #: The lever is shorter than the imposed displacement: the finger is curled until its
    #: tip stands nearly over (K_z) or level with (K_x) the clamp, and F l^3 / (3 delta)
    #: is no cantilever's rigidity (it goes to 0 with the lever while F does not).
    SMALL_LEVER = 2
    #: The loaded state is unstable under force control: displacement control followed the
    #: path past a limit point, onto another branch than the unloaded state's (a force-
    #: controlled test would snap), so K jumps between neighbouring pressures.
    BRANCH_CHANGE = 3


_MESSAGES = {
    RigidityStatus.SMALL_LEVER: 'eq. 22 does not apply: lever {lever:.4g} m is shorter than '
                                'the displacement {delta:.4g} m (K = F l^3 / (3 delta) '
                                'vanishes with the lever); use direct_stiffness',
    RigidityStatus.BRANCH_CHANGE: 'eq. 22 does not apply: the loaded state left the unloaded '
                                  "state's branch (unstable under force control: a "
                                  'force-controlled test snaps); use direct_stiffness',
}

#: The fields `checked_rigidity` adds to a rigidity Result (`ccm.RIGIDITY_FIELDS`).
RIGIDITY_CHECK_FIELDS = {
    'rigidity_status': '`RigidityStatus`: OK, FAILED, SMALL_LEVER or BRANCH_CHANGE; '
                       '`success` is True only for OK',
    'direct_stiffness': 'dF/d delta of the displacement-control path at the imposed '
                        'displacement [N/m] (NaN where no loaded state was found)',
}


def classify(success, lever, displacement, unstable):
    """
    Return the RigidityStatus of one displacement-controlled solve.

    Parameters
    ----------
    success : bool
        The unloaded and the displacement-controlled solves converged.
    lever : float
        Lever arm in the loaded state [m].
    displacement : float
        Imposed displacement delta [m].
    unstable : bool
        The loaded state is unstable under force control.

    """
    if not success:
        return RigidityStatus.FAILED
    if abs(lever) < displacement:
        return RigidityStatus.SMALL_LEVER
    if unstable:
        return RigidityStatus.BRANCH_CHANGE
    return RigidityStatus.OK


def _tip_node(solver):
    node = getattr(solver, 'tip_node', None)
    return solver.n_segments if node is None else node


def direct_stiffness(solver, x, pressure, force, axis):
    """
    Return dF/d delta of the displacement-control path at a loaded state [N/m].

    The implicit function theorem on the bordered system (`engine.sensitivity` with the
    displacement itself as the parameter): dF/d delta = 1 / (grad c . H^-1 grad c), H the
    loaded potential's Hessian, c = e . O_tip. Unlike eq. 22 it needs no lever.

    Parameters
    ----------
    solver : the rung that solved it (CCMSolver or a ladder solver)
    x : ndarray
        The loaded state in the engine's unknowns (`Result.x`).
    pressure : float
        [Pa].
    force : float
        The displacement control's force along the axis [N].
    axis : {'x', 'z'}

    """
    node = _tip_node(solver)
    direction = AXES[axis]
    x = np.asarray(x, dtype=float)
    try:
        _, dforce = engine.sensitivity(solver.engine_problem, x, float(pressure),
                                       [(node, float(force) * direction)],
                                       np.zeros((1,) + x.shape),
                                       control=(node, direction, np.ones(1)))
    except (ValueError, np.linalg.LinAlgError, ArithmeticError):
        return math.nan
    return float(dforce[0])


def checked_rigidity(solver, result):
    """
    Return a rigidity Result with its `RigidityStatus` and direct stiffness.

    A small lever or a branch change keeps `value` (what eq. 22 gives) but sets
    `success` False, with a message that says why; `RIGIDITY_CHECK_FIELDS` are added.

    Parameters
    ----------
    solver : the rung that computed `result`
    result : Result
        Of ``solver.rigidity`` (`ccm.RIGIDITY_FIELDS`).

    """
    fields = dict(result.__dict__)
    unstable = UNSTABLE_NOTE in result.message
    status = classify(result.success, result.lever, result.displacement, unstable)
    stiffness = math.nan
    if result.loaded is not None and result.loaded.x is not None \
            and math.isfinite(result.force) and status is not RigidityStatus.FAILED:
        stiffness = direct_stiffness(solver, result.loaded.x, result.loaded.pressure,
                                     result.force, result.axis)
    if status in _MESSAGES:
        fields['success'] = False
        fields['message'] = _MESSAGES[status].format(lever=result.lever,
                                                     delta=result.displacement)
    fields.update(rigidity_status=status, direct_stiffness=stiffness)
    return Result.of(fields)
