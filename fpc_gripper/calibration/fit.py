"""The calibration fit: residuals, exact Jacobians by the implicit function theorem, statistics."""

from dataclasses import dataclass, field
import enum
import math

import numpy as np
from scipy.optimize import least_squares

from .data import (DataError, LoadingData, MarkerData, read_loading, read_markers, read_tensile,
                   TensileData)
from .parameters import FitParameters
from ..model import engine
from ..model.design import ActuatorDesign
from ..model.discretisations.ccm import AXES
from ..model.pipeline import finger_model, ModelSettings
from ..model.section.materials import emc_stress
from ..model.validation import integer

__all__ = ['calibrate', 'pcc_model', 'CalibrationResult', 'CalibrationStatus', 'FIT_SEGMENTS',
           'DEFAULT_FIT', 'IDENTIFIABLE_RSE', 'least_squares_fit', 'solve_scene']

#: Segments of the PCC the fit uses for every scene and every parameter value: one fixed
#: discretisation, so that the objective is smooth and deterministic. Unloaded, the PCC
#: equals the rod for any N; under tip loads PCC32 is within 18 um of it on the ladder's
#: scenes (docs/physics.md, section 11.6).
FIT_SEGMENTS = 32
#: Parameters fitted when the caller names none.
DEFAULT_FIT = ('prestrain', 'cl_modulus', 'pressure_work_factor')
#: A parameter whose standard error exceeds this fraction of its estimate is reported as
#: not identifiable from the data.
IDENTIFIABLE_RSE = 0.25
#: Typical size of the frame rotation [rad] and offset [m]: the fit works in these units.
_FRAME_SCALE = np.array([0.1, 1e-2, 1e-2])
_FRAME_LABELS = ('frame_rotation', 'frame_offset_x', 'frame_offset_z')
#: Singular values of the column-normalised Jacobian below this times the largest span
#: directions the data do not see at all.
_RCOND = 1e-12
#: Residual RMS (in units of the stated noise) above which the noise or the model is off.
_NOISE_WARNING = 2.0


class CalibrationStatus(enum.IntEnum):
    """Outcome of a calibration; only SUCCESS has success=True."""

    SUCCESS = 0
    MAX_EVALUATIONS = 1
    MODEL_FAILED = 2
    INVALID_DESIGN = 3


class _ModelFailure(Exception):
    """The model has no equilibrium (or no valid design) at trial parameters."""

    def __init__(self, status, message):
        super().__init__(message)
        self.status = status


@dataclass
class CalibrationResult:
    """
    A calibrated design with its uncertainties (OptimizeResult-like).

    Attributes
    ----------
    success : bool
        The fit converged to a valid design.
    status : CalibrationStatus
    message : str
    design : ActuatorDesign or None
        The base design with the estimates (None when they make no valid design).
    estimates, stderr : dict
        Keyed by the fitted names (`FIT_NAMES`): a float, or a list of four for ``emc``
        [the design field's unit]; stderr inf where the data do not see a parameter.
    correlation : ndarray, shape (n, n)
        Correlation of every fitted component, `labels` order (frame nuisances last).
    labels : list of str
        Names of the components: 'prestrain', ..., 'emc[0]'..'emc[3]', then the frame's.
    residuals : dict
        Model minus measurement at the estimate: 'markers' (K, 2) [m] in the motion-capture
        frame, 'loading' (L,) [N], 'tensile' (T,) [Pa]; only the datasets given.
    residual_rms : dict
        RMS of each dataset's residuals [m, N, Pa].
    warnings : list of str
        Parameters the data cannot identify, noise that looks wrong, data not used.
    frame : dict
        The motion-capture frame: 'rotation' [rad], 'offset' (x, z) [m], and their
        'rotation_stderr', 'offset_stderr'; measured = R(rotation) model + offset.
    condition_number : float
        Of the Jacobian with unit-norm columns (scale-free) at the estimate.
    nfev, njev : int
        Residual and Jacobian evaluations.
    settings : dict
        Fitted names, noises [m, N, Pa], loss, the fit's model.

    """

    success: bool
    status: CalibrationStatus
    message: str
    design: object
    estimates: dict
    stderr: dict
    correlation: np.ndarray
    labels: list
    residuals: dict
    residual_rms: dict
    warnings: list
    frame: dict
    condition_number: float
    nfev: int
    njev: int
    settings: dict
    data: dict = field(default_factory=dict, repr=False)

    def report(self):
        """Return the content of report.json (plain JSON types, SI units)."""
        def plain(value):
            if isinstance(value, dict):
                return {k: plain(v) for k, v in value.items()}
            if isinstance(value, (list, tuple, np.ndarray)):
                return [plain(v) for v in value]
            if isinstance(value, (float, np.floating)):
                return float(value) if math.isfinite(value) else None
            return value

        return plain({
            'success': bool(self.success), 'status': self.status.name,
            'message': self.message, 'warnings': list(self.warnings),
            'estimates': self.estimates, 'stderr': self.stderr,
            'correlation': {'names': self.labels, 'matrix': self.correlation},
            'residual_rms': self.residual_rms, 'frame': self.frame,
            'condition_number': self.condition_number, 'settings': self.settings,
        })


@dataclass
class _Scene:
    """
    The model's answer to one measurement scene at one theta, with its sensitivities.

    `rates` is d x / d SECTION_PARAMETERS (8, unknowns) of a force-controlled scene, or
    d force / d SECTION_PARAMETERS (8,) of a displacement-controlled one.
    """

    result: object
    x: np.ndarray
    loads: list
    rates: np.ndarray = None


def solve_scene(model, pressure, force, sensitivities):
    """
    Solve one force-controlled scene cold, and with `sensitivities` differentiate it.

    Parameters
    ----------
    model : dict
        {'solver': the fit's solver, 'scenes': its solved scenes by key} (memo).
    pressure : float
        [Pa].
    force : array_like, shape (2,)
        Tip force [N].
    sensitivities : bool
        Also d x / d parameters (the solver's `parameter_gradient` rows) by the implicit
        function theorem (`engine.sensitivity`).

    Returns
    -------
    _Scene

    Raises
    ------
    _ModelFailure
        Where the solver finds no equilibrium.

    """
    solver = model['solver']
    key = ('solve', pressure, float(force[0]), float(force[1]))
    scene = model['scenes'].get(key)
    if scene is None:
        result = solver.solve(pressure, force, outputs='tip')
        if not result.success:
            raise _ModelFailure(CalibrationStatus.MODEL_FAILED,
                                f'no equilibrium at {pressure:g} Pa, tip force '
                                f'{tuple(force)} N: {result.message}')
        scene = model['scenes'][key] = _Scene(result, solver.unknowns(result),
                                              solver.tip_loads(force))
    if sensitivities and scene.rates is None:
        scene.rates = engine.sensitivity(
            solver.engine_problem, scene.x, pressure, scene.loads,
            solver.parameter_gradient(scene.x, pressure, scene.loads))[0]
    return scene


def least_squares_fit(problem, u0, lower, upper, loss, max_nfev):
    """
    Run the calibration's one least-squares loop on a problem's residuals and exact Jacobian.

    `scipy.optimize.least_squares`, trust-region reflective, bounded, with the tolerances
    every fit uses.

    Parameters
    ----------
    problem : object
        With ``residuals(u)`` and ``jacobian(u)`` (exact).
    u0, lower, upper : ndarray
        Start and bounds, in the problem's scaled units.
    loss : {'linear', 'soft_l1'}
        'soft_l1' at one stated noise for measurements; 'linear' for noise-free data.
    max_nfev : int
        Largest number of residual evaluations.

    Returns
    -------
    scipy.optimize.OptimizeResult

    """
    return least_squares(problem.residuals, u0, jac=problem.jacobian, bounds=(lower, upper),
                         method='trf', loss=loss, f_scale=1.0, x_scale=1.0, xtol=1e-10,
                         ftol=1e-10, gtol=1e-10, max_nfev=int(max_nfev))


def pcc_model(design, n_segments):
    """Return the finger the fit models: the PCC with `n_segments`, from the finger pipeline."""
    return finger_model(design, ModelSettings(rung='pcc', n_segments=n_segments))


class _Problem:
    """
    Residuals r(u) and their exact Jacobian for `least_squares`.

    u is theta / scale, then the frame (rotation, offset) / its scale. Every evaluation
    builds the fit's model for theta (a PCCSolver of the design, FIT_SEGMENTS segments)
    and solves every scene cold, so r is a function of u alone.
    """

    def __init__(self, params, markers, loading, tensile, noise, n_segments):
        self.params = params
        self.markers, self.loading, self.tensile = markers, loading, tensile
        self.noise = noise
        self.n_segments = n_segments
        self.frames = markers is not None
        self.scale = np.concatenate([params.scale, _FRAME_SCALE if self.frames else []])
        self._memo = (None, None)
        self.nfev = self.njev = 0

    # -- the model at theta ---------------------------------------------------------------
    def theta(self, u):
        return u[:len(self.params)] * self.params.scale

    def frame(self, u):
        return u[len(self.params):] * _FRAME_SCALE if self.frames else np.zeros(3)

    def model(self, theta):
        """Return the fit's PCC solver at theta and its solved scenes (the last theta's kept)."""
        key = theta.tobytes()
        if self._memo[0] != key:
            try:
                design = self.params.design(theta)
            except ValueError as exc:
                raise _ModelFailure(CalibrationStatus.INVALID_DESIGN,
                                    f'the parameters {self.params.split(theta)} make no '
                                    f'valid design: {exc}') from None
            self._memo = (key, {'solver': pcc_model(design, self.n_segments), 'scenes': {}})
        return self._memo[1]

    def _rigidity(self, model, pressure, axis, displacement, sensitivities):
        """Displacement-controlled force (and d force / d section parameters), cold."""
        solver = model['solver']
        key = ('rigidity', pressure, axis, displacement)
        scene = model['scenes'].get(key)
        if scene is None:
            result = solver.rigidity(pressure, axis, displacement)
            if not result.success:
                raise _ModelFailure(CalibrationStatus.MODEL_FAILED,
                                    f'no displacement-controlled state at {pressure:g} Pa, '
                                    f'axis {axis}, {displacement:g} m: {result.message}')
            scene = model['scenes'][key] = _Scene(result, solver.unknowns(result.loaded),
                                                  [(solver.tip_node,
                                                    result.force * AXES[axis])])
        if sensitivities and scene.rates is None:
            # The target e . tip(unloaded) + delta moves with the unloaded state.
            free = solve_scene(model, pressure, (0.0, 0.0), True)
            tip = solver.tip_node
            direction = AXES[axis]
            along = np.tensordot(direction, solver.node_jacobian(free.x, tip)[1], axes=1)
            scene.rates = engine.sensitivity(
                solver.engine_problem, scene.x, pressure, scene.loads,
                solver.parameter_gradient(scene.x, pressure, scene.loads),
                control=(tip, direction, free.rates @ along))[1]
        return scene

    # -- predictions ----------------------------------------------------------------------
    def predict(self, theta, sensitivities=False):
        """
        Model values of every measurement at theta, and their derivatives in theta.

        Returns a dict: 'markers' (K, 2) finger-frame positions [m], 'loading' (L,) [N],
        'tensile' (T,) [Pa]; with `sensitivities`, the same keys + '_d' with a last axis
        of size len(theta).
        """
        # Tensile stresses alone need no model (nor a valid design) until the end.
        model = self.model(theta) if self.markers is not None or self.loading is not None \
            else None
        rows = self.params.rows
        out = {}
        if self.markers is not None:
            data = self.markers
            points = np.empty((data.s.size, 2))
            slopes = np.empty((data.s.size, 2, rows.size))
            for f in range(data.pressure.size):
                scene = solve_scene(model, float(data.pressure[f]), data.tip_force[f],
                                    sensitivities)
                where = np.flatnonzero(data.frame == f)
                points[where], jac = model['solver'].material_jacobian(scene.x, data.s[where])
                if sensitivities:
                    slopes[where] = jac @ scene.rates[rows].T
            out['markers'] = points
            if sensitivities:
                out['markers_d'] = slopes
        if self.loading is not None:
            data = self.loading
            forces = np.empty(data.force.size)
            slopes = np.empty((data.force.size, rows.size))
            for k in range(forces.size):
                scene = self._rigidity(model, float(data.pressure[k]), data.axis[k],
                                       float(data.displacement[k]), sensitivities)
                forces[k] = scene.result.force
                if sensitivities:
                    slopes[k] = scene.rates[rows]
            out['loading'] = forces
            if sensitivities:
                out['loading_d'] = slopes
        if self.tensile is not None:
            emc = self.params.split(theta)['emc']
            strain = self.tensile.strain
            out['tensile'] = emc_stress(emc, strain)
            if sensitivities:
                slopes = np.zeros((strain.size, rows.size))
                first = self.params.labels.index('emc[0]')
                slopes[:, first:first + 4] = strain[:, None] ** np.arange(4, 0, -1)[None, :]
                out['tensile_d'] = slopes
        return out

    # -- residuals and Jacobian in u ---------------------------------------------------------
    def _mapped(self, u, points):
        rotation, ox, oz = self.frame(u)
        c, s = math.cos(rotation), math.sin(rotation)
        mapped = np.stack([c * points[:, 0] - s * points[:, 1] + ox,
                           s * points[:, 0] + c * points[:, 1] + oz], axis=1)
        return mapped, np.array([[c, -s], [s, c]]), np.array([[-s, -c], [c, -s]])

    def physical(self, u, predicted):
        """Model minus measurement of every dataset [m, N, Pa]."""
        out = {}
        if self.markers is not None:
            out['markers'] = self._mapped(u, predicted['markers'])[0] - self.markers.xz
        if self.loading is not None:
            out['loading'] = predicted['loading'] - self.loading.force
        if self.tensile is not None:
            out['tensile'] = predicted['tensile'] - self.tensile.stress
        return out

    def residuals(self, u):
        """Residuals in units of the stated noise, markers (x, z) first, then forces, stresses."""
        self.nfev += 1
        parts = self.physical(u, self.predict(self.theta(u)))
        return np.concatenate([parts[name].ravel() / self.noise[name] for name in parts])

    def jacobian(self, u):
        """Exact d residuals / d u (sensitivities by the implicit function theorem)."""
        self.njev += 1
        theta = self.theta(u)
        predicted = self.predict(theta, sensitivities=True)
        blocks = []
        n = len(self.params)
        if self.markers is not None:
            points = predicted['markers']
            _, rotation, turn = self._mapped(u, points)
            block = np.zeros((points.shape[0], 2, u.size))
            block[:, :, :n] = np.einsum('ij,kjp->kip', rotation, predicted['markers_d'])
            block[:, :, n] = points @ turn.T
            block[:, 0, n + 1] = 1.0
            block[:, 1, n + 2] = 1.0
            blocks.append(block.reshape(-1, u.size) / self.noise['markers'])
        for name in ('loading', 'tensile'):
            if name in predicted:
                block = np.zeros((predicted[name].size, u.size))
                block[:, :n] = predicted[name + '_d']
                blocks.append(block / self.noise[name])
        return np.concatenate(blocks) * self.scale[None, :]


def _initial_frame(problem, u):
    """Rotation and offset that best align the base model's markers with the measured ones."""
    points = problem.predict(problem.theta(u))['markers']
    measured = problem.markers.xz
    pc, mc = points - points.mean(axis=0), measured - measured.mean(axis=0)
    rotation = math.atan2(np.sum(pc[:, 0] * mc[:, 1] - pc[:, 1] * mc[:, 0]),
                          np.sum(pc * mc))
    c, s = math.cos(rotation), math.sin(rotation)
    offset = measured.mean(axis=0) - np.array([[c, -s], [s, c]]) @ points.mean(axis=0)
    return np.array([rotation, *offset]) / _FRAME_SCALE


def _covariance(jac, z):
    """
    Covariance of the estimate (in u) of a soft_l1 M-estimator, and the condition number.

    The asymptotic covariance of Huber (Robust Statistics, 1981; statsmodels' RLM 'H1')
    K^2 [sum psi^2 / (m - n)] / [mean psi']^2 (J^T J)^-1 with psi(z) = z / sqrt(1 + z^2),
    K = 1 + (n / m) var(psi') / mean(psi')^2: the scale comes from the residuals, so a
    misstated noise does not bias the standard errors, and outliers (psi bounded) do not
    inflate them. Directions the Jacobian does not see get infinite variance.
    """
    m, n = jac.shape
    norms = np.linalg.norm(jac, axis=0)
    norms = np.where(norms > 0.0, norms, 1.0)
    _, sing, vt = np.linalg.svd(jac / norms, full_matrices=False)
    condition = float(sing[0] / sing[-1]) if sing[-1] > 0.0 else math.inf
    seen = sing > _RCOND * sing[0]
    inverse = (vt[seen].T / sing[seen] ** 2) @ vt[seen]
    cov = inverse / np.outer(norms, norms)
    blind = np.abs(vt[~seen]).max(axis=0) > 1e-6 if (~seen).any() else np.zeros(n, bool)
    psi = z / np.sqrt(1.0 + z * z)
    dpsi = (1.0 + z * z) ** -1.5
    mean = dpsi.mean()
    factor = (1.0 + n / m * dpsi.var() / mean ** 2) ** 2
    scale = np.sum(psi ** 2) / (m - n) if m > n else math.inf
    cov = cov * factor * scale / mean ** 2
    cov[blind, :] = np.nan
    cov[:, blind] = np.nan
    cov[blind, blind] = np.inf
    return cov, condition


def _law_rse(prestrain, values, cov):
    """Largest relative standard error of the PEMC stress over its working strains [-]."""
    strain = np.linspace(0.5 * prestrain, prestrain + 0.1, 9)
    basis = strain[:, None] ** np.arange(4, 0, -1)[None, :]
    se = np.sqrt(np.maximum(np.einsum('ka,ab,kb->k', basis, cov, basis), 0.0))
    return float(np.max(se / np.abs(basis @ values)))


def _identifiability(params, theta, cov, labels):
    """Warnings naming every fitted parameter whose relative standard error is too large."""
    warnings = []
    sd = np.sqrt(np.diag(cov))
    start = 0
    for name, size in zip(params.names, params.sizes):
        part = slice(start, start + size)
        start += size
        if size == 1:
            rse = sd[part][0] / abs(theta[part][0]) if theta[part][0] else math.inf
            what = (f'standard error {sd[part][0]:.3g} is {rse:.0%} of the estimate '
                    f'{theta[part][0]:.4g}')
        else:
            block = cov[part, part]
            prestrain = params.split(theta).get('prestrain', params.base.prestrain)
            rse = _law_rse(prestrain, theta[part], block) if np.all(np.isfinite(block)) \
                else math.inf
            what = f'the PEMC stress it gives is uncertain by up to {rse:.0%}'
        if rse <= IDENTIFIABLE_RSE:
            continue
        index = [k for k in range(len(labels)) if not labels[k].startswith(name)]
        own = [k for k in range(len(labels)) if labels[k].startswith(name)]
        partner = ''
        with np.errstate(invalid='ignore', divide='ignore'):
            corr = cov / np.outer(sd, sd)
        if index and np.all(np.isfinite(corr[np.ix_(own, index)])):
            k = index[int(np.argmax(np.abs(corr[np.ix_(own, index)]).max(axis=0)))]
            partner = (f'; most correlated with {labels[k]} '
                       f'({np.abs(corr[np.ix_(own, [k])]).max():.3f})')
        warnings.append(f'{name} is not identifiable from these data ({what}{partner}); '
                        'fix it at the base design or add data that constrain it')
    return warnings


def _as(kind, reader, value, design):
    if value is None or isinstance(value, kind):
        if value is not None:
            value.check(design)
        return value
    if str(value).endswith('.mcap'):
        raise DataError(f'{value}: read MCAP markers with read_markers_mcap(path, marker_s, '
                        'markers_topic, pressure_topic) and pass the MarkerData')
    return reader(value, design)


def _positive(name, value, unit):
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f'`{name}` must be finite and > 0 {unit}, got {value}')
    return value


def calibrate(design, markers=None, loading=None, tensile=None, fit=DEFAULT_FIT,
              marker_noise=0.3e-3, force_noise=0.02, stress_noise=5.0e3,
              n_segments=FIT_SEGMENTS, max_nfev=100):
    """
    Fit a finger design to its measurements.

    Robust weighted least squares (`scipy.optimize.least_squares`, trust-region
    reflective, soft_l1 loss at one stated noise) of marker positions (with the
    motion-capture frame's rotation and offset, always fitted), loading-test forces and
    tensile stresses, each divided by its stated noise. The model is one fixed
    discretisation for every scene and parameter value, the PCC with `n_segments`
    (`FIT_SEGMENTS`), solved cold, so the objective is a smooth, deterministic function of
    the parameters. Its Jacobian is exact: the equilibria's sensitivities by the implicit
    function theorem on the engine's Hessian (`engine.sensitivity`), the loading tests'
    through their bordered displacement-control system.

    Parameters
    ----------
    design : ActuatorDesign or path
        The base design (or its YAML); what is not fitted stays as it is.
    markers : MarkerData or path, optional
        markers.csv (`read_markers`) or `read_markers_mcap`'s data.
    loading : LoadingData or path, optional
        loading.csv (`read_loading`).
    tensile : TensileData or path, optional
        tensile.csv (`read_tensile`); it constrains ``emc``.
    fit : sequence of str or str
        Names of `FIT_NAMES` ('a,b' text accepted).
    marker_noise, force_noise, stress_noise : float
        Standard deviation of each marker coordinate [m], force [N] and stress [Pa].
    n_segments : int
        Segments of the fit's PCC.
    max_nfev : int
        Largest number of residual evaluations.

    Returns
    -------
    CalibrationResult

    Raises
    ------
    DataError
        On bad data, naming the file and row.
    ValueError, TypeError
        On bad arguments.

    References
    ----------
    docs/physics.md, section 14; Zhou, Headings, Dapino (2022), Section VI.

    """
    if not isinstance(design, ActuatorDesign):
        design = ActuatorDesign.from_yaml(design)
    params = FitParameters(design, fit)
    markers = _as(MarkerData, read_markers, markers, design)
    loading = _as(LoadingData, read_loading, loading, design)
    tensile = _as(TensileData, read_tensile, tensile, design)
    if markers is None and loading is None and tensile is None:
        raise ValueError('`calibrate` needs data: markers, loading or tensile')
    noise = {'markers': _positive('marker_noise', marker_noise, '[m]'),
             'loading': _positive('force_noise', force_noise, '[N]'),
             'tensile': _positive('stress_noise', stress_noise, '[Pa]')}
    warnings = []
    if tensile is not None and 'emc' not in params.names:
        warnings.append(f'{tensile.source}: tensile data unused: `emc` is not fitted')
        tensile = None
    if 'emc' in params.names and tensile is None:
        warnings.append('`emc` is fitted without tensile data: only the shapes and forces '
                        'constrain the PEMC law')
    integer('n_segments', n_segments, 1)
    integer('max_nfev', max_nfev, 1)
    problem = _Problem(params, markers, loading, tensile, noise, int(n_segments))
    settings = {'fit': list(params.names), 'noise': noise, 'loss': 'soft_l1',
                'model': f'pcc N={n_segments}', 'n_segments': int(n_segments)}
    data = {'markers': markers, 'loading': loading, 'tensile': tensile}
    lower, upper = params.bounds()
    u0 = np.concatenate([params.initial / params.scale, np.zeros(3 if problem.frames else 0)])
    lb = np.concatenate([lower / params.scale, np.full(u0.size - len(params), -np.inf)])
    ub = np.concatenate([upper / params.scale, np.full(u0.size - len(params), np.inf)])
    u0[:len(params)] = np.clip(u0[:len(params)], lb[:len(params)], ub[:len(params)])
    try:
        if problem.frames:
            u0[len(params):] = _initial_frame(problem, u0)
        fitted = least_squares_fit(problem, u0, lb, ub, 'soft_l1', max_nfev)
        u = fitted.x
        jac = problem.jacobian(u)
        predicted = problem.predict(problem.theta(u))
    except _ModelFailure as failure:
        return _failed(failure.status, str(failure), params, problem, warnings, settings, data)
    return _finish(params, problem, u, jac, predicted, fitted, warnings, settings, data)


def _failed(status, message, params, problem, warnings, settings, data):
    nan = {name: (math.nan if size == 1 else [math.nan] * 4)
           for name, size in zip(params.names, params.sizes)}
    labels = params.labels + (list(_FRAME_LABELS) if problem.frames else [])
    return CalibrationResult(False, status, message, None, nan, dict(nan),
                             np.full((len(labels), len(labels)), np.nan), labels, {}, {},
                             warnings, {}, math.nan, problem.nfev, problem.njev, settings, data)


def _finish(params, problem, u, jac, predicted, fitted, warnings, settings, data):
    """Statistics, warnings and the design at the estimate."""
    n = len(params)
    labels = params.labels + (list(_FRAME_LABELS) if problem.frames else [])
    residuals = problem.physical(u, predicted)
    z = np.concatenate([residuals[k].ravel() / problem.noise[k] for k in residuals])
    cov_u, condition = _covariance(jac, z)
    cov = cov_u * np.outer(problem.scale, problem.scale)
    theta = problem.theta(u)
    estimate = np.concatenate([theta, problem.frame(u) if problem.frames else []])
    sd = np.sqrt(np.diag(cov))
    with np.errstate(invalid='ignore', divide='ignore'):
        correlation = cov / np.outer(sd, sd)
    warnings = warnings + _identifiability(params, estimate, cov, labels)
    rms = {k: float(np.sqrt(np.mean(v ** 2))) for k, v in residuals.items()}
    for name, value in rms.items():
        if value > _NOISE_WARNING * problem.noise[name]:
            warnings.append(f'{name} residual RMS {value:.3g} is '
                            f'{value / problem.noise[name]:.1f} times the stated noise '
                            f'{problem.noise[name]:.3g}: the noise or the model is off')
    frame = {}
    if problem.frames:
        frame = {'rotation': float(estimate[n]), 'offset': estimate[n + 1:].tolist(),
                 'rotation_stderr': float(sd[n]), 'offset_stderr': sd[n + 1:].tolist()}
    status = CalibrationStatus.SUCCESS if fitted.status > 0 else \
        CalibrationStatus.MAX_EVALUATIONS
    message = fitted.message
    design = None
    try:
        design = params.design(theta)
    except ValueError as exc:
        status = CalibrationStatus.INVALID_DESIGN
        message = f'the estimates make no valid design: {exc}'
    return CalibrationResult(
        success=status is CalibrationStatus.SUCCESS, status=status, message=message,
        design=design, estimates=params.split(theta), stderr=params.split(sd[:n]),
        correlation=correlation, labels=labels, residuals=residuals, residual_rms=rms,
        warnings=warnings, frame=frame, condition_number=condition, nfev=problem.nfev,
        njev=problem.njev, settings=settings, data=data)
