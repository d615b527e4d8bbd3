"""Fit the continuum correction to the FE reference table, taking the FE tips as measurements."""

import dataclasses
from dataclasses import dataclass

import numpy as np

from .fit import _ModelFailure, CalibrationStatus, least_squares_fit, solve_scene
from ..model.corrected import (COMPLIANCE_BOUNDS, ContinuumCorrection, CorrectedSolver,
                               FACTOR_BOUNDS, PAPER_PHYSICS, PARAMETERS)
from ..model.design import ActuatorDesign
from ..model.validation import integer

__all__ = ['CORRECTION_NAMES', 'CORRECTION_UNITS', 'FEScene', 'fe_scenes', 'correction_tips',
           'fit_correction', 'CorrectionFit', 'rounded']

#: The fitted names: `ContinuumCorrection`'s fields, in order.
CORRECTION_NAMES = tuple(field.name for field in dataclasses.fields(ContinuumCorrection))
CORRECTION_UNITS = {'band_stiffness': '-', 'clamp_stiffness': '-',
                    'channel_end_stiffness': '-', 'shear_compliance': '1/N'}
#: Typical size of each parameter: the fit works in value / scale.
_SCALE = np.array([1.0, 1.0, 1.0, 0.01])
#: Unit of the tip residuals [m].
_TIP_SCALE = 1e-3


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


class _CorrectionProblem:
    """
    Tip residuals r(u) over the FE scenes and their exact Jacobian, for `least_squares_fit`.

    u is the correction / `_SCALE`; r is the corrected rung's tip minus the FE's, in
    `_TIP_SCALE`. Every evaluation builds a `CorrectedSolver` per prestrain and solves
    every scene cold (`fit.solve_scene`), so r is a function of u alone. The stiffness
    factors' columns come through the engine's sensitivities (`engine.sensitivity` of the
    solver's `parameter_gradient`), as the calibration's parameters do; the shear
    compliance's is the tip's shear move per unit compliance (`CorrectedSolver.shear_tip`).
    """

    def __init__(self, scenes, design):
        self.scenes = list(scenes)
        self.base = ActuatorDesign.paper() if design is None else design
        self.measured = np.array([s.tip for s in self.scenes])
        self._memo = (None, None)
        self.nfev = self.njev = 0

    def models(self, values):
        """Return {prestrain: {'solver', 'scenes'}} at the correction's values (last kept)."""
        key = np.asarray(values, dtype=float).tobytes()
        if self._memo[0] != key:
            correction = ContinuumCorrection(*values)
            self._memo = (key, {p: {'solver': CorrectedSolver(self.base.replace(prestrain=p),
                                                              correction),
                                    'scenes': {}}
                                for p in sorted({s.prestrain for s in self.scenes})})
        return self._memo[1]

    def predict(self, values, sensitivities=False):
        """Return the tips (K, 2) [m] and, with `sensitivities`, d tip / d values (K, 2, 4)."""
        models = self.models(values)
        tips = np.empty((len(self.scenes), 2))
        slopes = np.empty((len(self.scenes), 2, len(CORRECTION_NAMES)))
        factors = [PARAMETERS.index(n) for n in CORRECTION_NAMES[:3]]
        for k, scene in enumerate(self.scenes):
            model = models[scene.prestrain]
            solved = solve_scene(model, 0.0, scene.tip_force, sensitivities)
            tips[k] = solved.result.tip
            if sensitivities:
                solver = model['solver']
                move, shear = solver.shear_tip(solved.x, scene.tip_force)
                along = solver.node_jacobian(solved.x, solver.tip_node)[1] \
                    + values[3] * shear
                slopes[k, :, :3] = along @ solved.rates[factors].T
                slopes[k, :, 3] = move
        return tips, slopes

    def residuals(self, u):
        """Tip minus FE tip of every scene, (x, z) each, in `_TIP_SCALE`."""
        self.nfev += 1
        return (self.predict(u * _SCALE)[0] - self.measured).ravel() / _TIP_SCALE

    def jacobian(self, u):
        """Exact d residuals / d u."""
        self.njev += 1
        slopes = self.predict(u * _SCALE, sensitivities=True)[1]
        return slopes.reshape(-1, len(CORRECTION_NAMES)) * _SCALE / _TIP_SCALE


def correction_tips(correction, scenes, design=None):
    """
    Tip of the corrected rung in every scene [m], shape (K, 2).

    Parameters
    ----------
    correction : ContinuumCorrection
    scenes : sequence of FEScene
    design : ActuatorDesign, optional
        The base design (its prestrain replaced by each scene's); the paper's by default.

    Raises
    ------
    ValueError
        Naming `correction` where a scene has no equilibrium.

    """
    try:
        return _CorrectionProblem(scenes, design).predict(correction.values)[0]
    except _ModelFailure as failure:
        raise ValueError(f'`correction` {correction}: {failure}') from None


@dataclass(frozen=True)
class CorrectionFit:
    """
    A fitted correction (OptimizeResult-like).

    Attributes
    ----------
    success : bool
    status : CalibrationStatus
    message : str
    correction : ContinuumCorrection
    errors : ndarray, shape (K,)
        Tip distance to the FE of every scene at the estimate [m].
    initial_errors : ndarray, shape (K,)
        The same at the start [m].
    nfev, njev : int
        Residual and (exact) Jacobian evaluations.

    """

    success: bool
    status: CalibrationStatus
    message: str
    correction: ContinuumCorrection
    errors: np.ndarray
    initial_errors: np.ndarray
    nfev: int
    njev: int


def fit_correction(scenes, start=PAPER_PHYSICS, design=None, max_nfev=60):
    """
    Fit the four correction parameters to FE tips by least squares.

    The calibration's least-squares loop (`fit.least_squares_fit`, linear loss: the FE
    is noise-free) of the tip residuals over every scene, bounded by the parameters'
    bounds, with the exact Jacobian of `_CorrectionProblem`.

    Parameters
    ----------
    scenes : sequence of FEScene
    start : ContinuumCorrection
        Where the fit starts (the paper's physics by default).
    design : ActuatorDesign, optional
        The base design; the paper's by default.
    max_nfev : int
        Largest number of residual evaluations.

    Returns
    -------
    CorrectionFit

    """
    integer('max_nfev', max_nfev, 1)
    problem = _CorrectionProblem(scenes, design)
    lower = np.array([FACTOR_BOUNDS[0]] * 3 + [COMPLIANCE_BOUNDS[0]]) / _SCALE
    upper = np.array([FACTOR_BOUNDS[1]] * 3 + [COMPLIANCE_BOUNDS[1]]) / _SCALE
    initial = np.linalg.norm(correction_tips(start, scenes, design) - problem.measured, axis=1)
    try:
        fitted = least_squares_fit(problem, start.values / _SCALE, lower, upper, 'linear',
                                   max_nfev)
    except _ModelFailure as failure:
        return CorrectionFit(False, failure.status, str(failure), start, initial * np.nan,
                             initial, problem.nfev, problem.njev)
    best = ContinuumCorrection(*np.clip(fitted.x, lower, upper) * _SCALE)
    errors = np.linalg.norm(correction_tips(best, scenes, design) - problem.measured, axis=1)
    status = CalibrationStatus.SUCCESS if fitted.status > 0 else \
        CalibrationStatus.MAX_EVALUATIONS
    return CorrectionFit(success=status is CalibrationStatus.SUCCESS, status=status,
                         message=str(fitted.message), correction=best, errors=errors,
                         initial_errors=initial, nfev=problem.nfev, njev=problem.njev)


def rounded(correction, digits=4):
    """Return a correction with every parameter to `digits` significant digits."""
    return ContinuumCorrection(*(float(f'{v:.{digits}g}') if v else 0.0
                                 for v in correction.values))
