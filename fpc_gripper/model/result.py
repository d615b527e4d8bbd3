"""The one result type of the model's calls: named fields, all computed inside the call."""

import numpy as np

from .engine import SolverStatus

__all__ = ['Result', 'FINGER_FIELDS', 'finger_constants', 'finger_result', 'rung_label']


class Result:
    """
    What a solve, rigidity, contact or grid call returns: its fields, complete and read-only.

    Like scipy's `OptimizeResult`, one type serves every call, and each call documents the
    fields it fills (a finger's solve: `FINGER_FIELDS`). A field is a plain attribute
    (``result.tip``); `keys()` lists them. Every field is computed inside the call that
    returns the result; nothing is computed on a later read, and assigning or deleting a
    field raises AttributeError. Fields the call was not asked for are None.
    """

    def __setattr__(self, name, value):
        raise AttributeError(f'a Result is read-only: cannot set `{name}`')

    def __delattr__(self, name):
        raise AttributeError(f'a Result is read-only: cannot delete `{name}`')

    @classmethod
    def of(cls, fields):
        """Return the Result of a dict of fields (taken as it is: the caller builds it new)."""
        result = object.__new__(cls)
        object.__setattr__(result, '__dict__', fields)
        return result

    def keys(self):
        """Return the names of the fields."""
        return self.__dict__.keys()

    def __contains__(self, name):
        return name in self.__dict__

    def __repr__(self):
        parts = []
        for name, value in self.__dict__.items():
            if isinstance(value, np.ndarray):
                parts.append(f'{name}=<{value.dtype} array {value.shape}>')
            elif isinstance(value, (bool, int, float, str, tuple, SolverStatus)) or value is None:
                text = value.name if isinstance(value, SolverStatus) else repr(value)
                parts.append(f'{name}={text if len(text) <= 60 else text[:57] + "..."}')
        return 'Result(' + ', '.join(parts) + ')'


#: The fields of a finger's solve, by every rung (`finger_result` builds them).
FINGER_FIELDS = {
    'success': 'True only for a converged, stable equilibrium',
    'status': '`SolverStatus`; `message` explains it',
    'message': 'what happened, with the figures behind `status`',
    'iterations': 'Newton iterations, continuation steps included',
    'pressure': 'gauge pressure [Pa]',
    'tip_force': '(f0, p0) along global X and Z [N]',
    'point_loads': '(s [m], fx [N], fz [N]) at intermediate arc lengths (the CCM only)',
    'model': "the rung and N, e.g. 'pcc N=22' or 'ccm N=8' ('arc', 'rod')",
    'model_choice': "the `ModelChoice` behind an adaptive model's result, else None",
    'rung': 'the ladder rung (`selection.RUNGS`)',
    'n_segments': 'segments (1 for the arc, elements for the rod)',
    'segment_edges': 'reference arc length of every segment edge, (N + 1,) [m]',
    'state': "the discretisation's unknowns (CCM: (b1, b3 L^2, c1, d L) per segment; "
             'PCC: (theta_i, eps_i, c1_i); arc: (eps, kappa, c1); rod: (theta nodal values, '
             '(eps, c1) at its points))',
    'x': "the same in the engine's unknowns, as scipy's `x` (what a warm start takes)",
    'coefficients': '(b1 [-], b3 [1/m^2], c1 [-], d [1/m]) of every segment, (N, 4) (the PCC '
                    'and the arc: those of a CCM segment of the same uniform strain); None '
                    'for the rod (outputs "shape" and "all")',
    'tip': 'global (X, Z) of the tip, (2,) [m]',
    'valid': "every segment obeys the CCM's small-rotation rule |2 d L_i| < 1 (always True "
             'for the geometrically exact rungs)',
    'nodes': 'segment ends, (N + 1, 2) [m] (outputs "shape" and "all", as every field below '
             'but `position_at` and the last three)',
    'beta': 'rotation of every segment, (N,) [rad]',
    'theta': 'rotation at the start of every segment, (N,) [rad]',
    'energy': 'total potential [J]',
    'points': 'midplane samples, root to tip, (M, 2) [m]',
    'tangent': 'tangent angle of every sample from +X towards +Z, (M,) [rad]',
    'strains': '(eps [-], kappa [1/m], c1 [-]) at every sample, (M, 3); None for the CCM',
    'curvature': 'signed curvature of the orthogonal-distance circle through `points` '
                 '[1/m], > 0 curling towards -Z (outputs "all")',
    'fit_rmsd': "RMSD of the samples from that circle [m] (outputs 'all')",
    'position_at': 'function of reference arc lengths s [m] -> their (X, Z) [m]',
    'gradient': 'relative gradient of the last Newton iterate',
    'step': 'last Newton step [scaled units]',
    'fraction': 'fraction of the loading reached (1 unless the continuation stalled)',
}


def rung_label(rung, n_segments):
    """Label of a rung and N, e.g. 'pcc N=22'; the arc and the rod alone (they have no N)."""
    return rung if rung in ('arc', 'rod') else f'{rung} N={n_segments}'


def finger_constants(rung, n_segments, edges):
    """Return a finger's result with its discretisation's fields in (a solver copies it)."""
    template = dict.fromkeys(FINGER_FIELDS)
    template.update(model=rung_label(rung, n_segments), rung=rung, n_segments=n_segments,
                    segment_edges=edges, point_loads=())
    return template


def finger_result(outcome, message, pressure, tip_force, state, position_at, constants,
                  point_loads=(), model_choice=None):
    """
    Build a finger's solve `Result` (`FINGER_FIELDS`) from the engine's outcome and fields.

    Parameters
    ----------
    outcome : engine.NewtonOutcome
        With its `fields`, computed with the state in the same call; the arrays are the
        result's own.
    message : str
    pressure : float
        [Pa].
    tip_force : (float, float)
        [N].
    state : object
    position_at : callable
    constants : dict
        `finger_constants` of the solver (copied, not changed).
    point_loads : tuple
    model_choice : ModelChoice, optional

    """
    status = outcome.status
    f = outcome.fields
    fields = constants.copy()
    fields['success'] = status is SolverStatus.SUCCESS
    fields['status'] = status
    fields['message'] = message
    fields['iterations'] = outcome.iterations
    fields['pressure'] = pressure
    fields['tip_force'] = tip_force
    fields['state'] = state
    fields['x'] = outcome.x
    fields['tip'] = f.tip
    fields['valid'] = f.valid
    fields['position_at'] = position_at
    fields['gradient'] = outcome.gradient
    fields['step'] = outcome.step
    fields['fraction'] = outcome.fraction
    if point_loads:
        fields['point_loads'] = point_loads
    if model_choice is not None:
        fields['model_choice'] = model_choice
    if f.nodes is not None:
        fields['nodes'] = f.nodes
        fields['beta'] = f.beta
        fields['theta'] = f.theta
        fields['coefficients'] = f.coefficients
        fields['energy'] = f.energy
        fields['points'] = f.points
        fields['tangent'] = f.tangent
        fields['strains'] = f.strains
        fields['curvature'] = f.curvature
        fields['fit_rmsd'] = f.fit_rmsd
    return Result.of(fields)
