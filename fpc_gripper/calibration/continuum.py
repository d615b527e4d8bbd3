"""Fit the continuum correction to the FE reference table, taking the FE tips as measurements."""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..model.corrected import (COMPLIANCE_BOUNDS, ContinuumCorrection, CorrectedSolver,
                               FACTOR_BOUNDS, PAPER_PHYSICS)
from ..model.design import ActuatorDesign

__all__ = ['CORRECTION_NAMES', 'CORRECTION_UNITS', 'FEScene', 'fe_scenes', 'correction_tips',
           'fit_correction', 'CorrectionFit', 'rounded']

#: The fitted names, `ContinuumCorrection` field order.
CORRECTION_NAMES = ('band_stiffness', 'clamp_stiffness', 'channel_end_stiffness',
                    'shear_compliance')
CORRECTION_UNITS = {'band_stiffness': '-', 'clamp_stiffness': '-',
                    'channel_end_stiffness': '-', 'shear_compliance': '1/N'}
#: Typical size of each parameter: the fit works in value / scale.
_SCALE = np.array([1.0, 1.0, 1.0, 0.01])


@dataclass(frozen=True)
class FEScene:
    """One unpressurised FE scene: the design's prestrain, the tip force [N], the FE tip [m]."""

    prestrain: float
    tip_force: tuple
    tip: np.ndarray


def fe_scenes(table):
    """
    Return the FE table's converged unpressurised scenes (the corrected rung's data).

    Parameters
    ----------
    table : dict
        ``bench/results/continuum.json`` as read (its 'table' with 'rows').

    Raises
    ------
    ValueError
        If the table holds no such scene.

    """
    rows = table['table']['rows'] if 'table' in table else table['rows']
    out = [FEScene(float(r['prestrain']), tuple(float(f) for f in r['tip_force']),
                   np.asarray(r['tip_mm'], dtype=float) * 1e-3)
           for r in rows if r['success'] and float(r['pressure_kpa']) == 0.0]
    if not out:
        raise ValueError('`table` holds no converged unpressurised scene')
    return out


def correction_tips(correction, scenes, design=None):
    """
    Tip of the corrected rung in every scene [m], shape (K, 2).

    Parameters
    ----------
    correction : ContinuumCorrection
    scenes : sequence of FEScene
    design : ActuatorDesign, optional
        The base design (its prestrain replaced by each scene's); the paper's by default.

    """
    base = ActuatorDesign.paper() if design is None else design
    solvers = {}
    tips = np.empty((len(scenes), 2))
    for k, scene in enumerate(scenes):
        solver = solvers.get(scene.prestrain)
        if solver is None:
            solver = solvers[scene.prestrain] = CorrectedSolver(
                base.replace(prestrain=scene.prestrain), correction)
        result = solver.solve(0.0, scene.tip_force, outputs='tip')
        if not result.success:
            raise ValueError(f'`correction` {correction} has no equilibrium at prestrain '
                             f'{scene.prestrain}, tip force {scene.tip_force} N: '
                             f'{result.message}')
        tips[k] = result.tip
    return tips


@dataclass(frozen=True)
class CorrectionFit:
    """
    A fitted correction (OptimizeResult-like).

    Attributes
    ----------
    success : bool
    message : str
    correction : ContinuumCorrection
    errors : ndarray, shape (K,)
        Tip distance to the FE of every scene at the estimate [m].
    initial_errors : ndarray, shape (K,)
        The same at the start [m].
    nfev : int

    """

    success: bool
    message: str
    correction: ContinuumCorrection
    errors: np.ndarray
    initial_errors: np.ndarray
    nfev: int


def fit_correction(scenes, start=PAPER_PHYSICS, design=None, max_nfev=60):
    """
    Fit the four correction parameters to FE tips by least squares.

    `scipy.optimize.least_squares` (trust-region reflective, bounded by the parameters'
    bounds) of the tip residuals [m] over every scene. The model's derivatives in these
    parameters are not in the engine's sensitivities (`SECTION_PARAMETERS` does not hold
    them), so the Jacobian is scipy's 3-point difference of the deterministic residuals.

    Parameters
    ----------
    scenes : sequence of FEScene
    start : ContinuumCorrection
        Where the fit starts (the paper's physics by default).
    design : ActuatorDesign, optional
        The base design; the paper's by default.
    max_nfev : int

    Returns
    -------
    CorrectionFit

    """
    measured = np.array([s.tip for s in scenes])
    lower = np.array([FACTOR_BOUNDS[0]] * 3 + [COMPLIANCE_BOUNDS[0]]) / _SCALE
    upper = np.array([FACTOR_BOUNDS[1]] * 3 + [COMPLIANCE_BOUNDS[1]]) / _SCALE

    def correction(u):
        return ContinuumCorrection(*np.clip(u, lower, upper) * _SCALE)

    def residuals(u):
        return (correction_tips(correction(u), scenes, design) - measured).ravel()

    u0 = start.values / _SCALE
    initial = np.linalg.norm(correction_tips(start, scenes, design) - measured, axis=1)
    fitted = least_squares(residuals, u0, jac='3-point', bounds=(lower, upper), method='trf',
                           x_scale=1.0, xtol=1e-10, ftol=1e-12, gtol=1e-12,
                           max_nfev=int(max_nfev))
    best = correction(fitted.x)
    errors = np.linalg.norm(correction_tips(best, scenes, design) - measured, axis=1)
    return CorrectionFit(success=bool(fitted.status > 0), message=str(fitted.message),
                         correction=best, errors=errors, initial_errors=initial,
                         nfev=int(fitted.nfev))


def rounded(correction, digits=4):
    """Return a correction with every parameter to `digits` significant digits."""
    return ContinuumCorrection(*(float(f'{v:.{digits}g}') if v else 0.0
                                 for v in correction.values))
