"""Parametric sweeps: designs x pressures on the batched engine, as one tidy table."""

import math

import numpy as np

from fpc_gripper.model import batch
from fpc_gripper.model.discretisations.ccm import SolverStatus
from fpc_gripper.model.pipeline import DEFAULT_N_SEGMENTS, ModelSettings
from fpc_gripper.model.stiffness import RigidityStatus
from .grid import base_design, DEFAULT_PRESSURES, design_grid
from .runner import run_chunks

__all__ = ['sweep', 'model_settings', 'settings_label', 'solve_designs',
           'MODELS', 'STATUS_OK', 'STATUS_INVALID', 'STATUS_SMALL_ROTATION', 'STATUS_RIGIDITY']

#: Model names of the command line: the default pipeline model, or the paper's CCM8.
MODELS = ('default', 'paper')
#: `status` of a row whose numbers are all good.
STATUS_OK = 'ok'
#: `status` of a row whose design fields make no valid ActuatorDesign.
STATUS_INVALID = 'invalid_design'
#: `status` of a converged CCM state that breaks the small-rotation rule |2 d L_i| < 1.
STATUS_SMALL_ROTATION = 'small_rotation'
#: `status` of a row whose equilibrium is fine but whose K_x or K_z was not found. A K
#: where eq. 22 does not apply has the `RigidityStatus` name: 'small_lever' or
#: 'branch_change' (its value is kept, beside the direct stiffness).
STATUS_RIGIDITY = 'rigidity_failed'
_SOLVER_STATUS = {int(s): s.name.lower() for s in SolverStatus}
#: Work of a local run, in scene solves, from which it is chunked for progress: about a
#: second on two cores (the default model solves some 30k sweep scenes a second). Progress
#: shows once a run has taken a second, so a shorter run goes as one batch, the fastest.
_WORK_FOR_PROGRESS = 32_000
#: Scene solves that a scene's rigidity along one axis costs, in that count.
_RIGIDITY_WORK = 8
#: Tasks of a Dask run, or steps of a progress bar, when the caller does not say.
_CHUNKS = 16


def model_settings(model='default'):
    """
    Return the settings of a model name: 'default' (the pipeline's) or 'paper' (CCM8).

    A ModelSettings passes through. Every finger is then built by
    `pipeline.finger_model(design, settings)`, as the nodes build theirs.
    """
    if isinstance(model, ModelSettings):
        return model
    if model == 'default':
        return ModelSettings()
    if model == 'paper':
        return ModelSettings(tolerance=0.0, n_segments=DEFAULT_N_SEGMENTS)
    raise ValueError(f'`model` must be one of {MODELS} or a ModelSettings, got {model!r}')


def settings_label(settings):
    """Name of a model for tables and charts: 'default (0.05 mm)' or 'paper CCM8'."""
    if settings.tolerance > 0.0:
        return f'default ({settings.tolerance * 1e3:g} mm)'
    return f'paper CCM{settings.n_segments}'


def solve_designs(designs, pressures, settings, rigidity=(), displacement=0.010):
    """
    Equilibria (and K_x, K_z) of designs x pressures: the sweep's columns, one row per scene.

    Invalid designs (None, with their message) give rows of NaN with their status. The
    valid ones are solved together on the batched engine (`batch.solve_grid`, curvature
    by the compiled circle fit; `batch.rigidity_grid` along +X and +Z), every scene cold,
    so a row does not depend on which other designs share its call. (Smaller blocks,
    which would keep `finger_model`'s cache of 32 fingers warm from one call to the next,
    measured slower: a compiled batch per design geometry costs more than a rebuild.)

    Parameters
    ----------
    designs : sequence of (ActuatorDesign or None, str)
        Design and validation message of every design.
    pressures : ndarray, shape (P,)
        [Pa].
    settings : ModelSettings
    rigidity : tuple of {'x', 'z'}
        Also K_x and/or K_z by displacement control (eq. 22).
    displacement : float
        Tip displacement of the rigidity protocol [m].

    Returns
    -------
    dict of str to ndarray
        Columns of length len(designs) * P, design-major.

    """
    n_p = pressures.size
    rows = len(designs) * n_p
    out = {'curvature_per_m': np.full(rows, np.nan), 'tip_x_m': np.full(rows, np.nan),
           'tip_z_m': np.full(rows, np.nan)}
    for axis in rigidity:
        out[f'k{axis}_nm2'] = np.full(rows, np.nan)
    for axis in rigidity:
        out[f'k{axis}_direct_n_per_m'] = np.full(rows, np.nan)
    out['success'] = np.zeros(rows, dtype=bool)
    out['status'] = np.full(rows, STATUS_INVALID, dtype=object)
    out['model'] = np.full(rows, '', dtype=object)
    out['message'] = np.full(rows, '', dtype=object)
    valid = [k for k, (design, _) in enumerate(designs) if design is not None]
    for k, (design, error) in enumerate(designs):
        if design is None:
            out['message'][k * n_p:(k + 1) * n_p] = error
    if valid:
        _solve_block(out, designs, valid, pressures, settings, rigidity, displacement)
    return out


def _solve_block(out, designs, valid, pressures, settings, rigidity, displacement):
    """Fill the rows of designs `valid` (indices into `designs`) in the columns `out`."""
    n_p = pressures.size
    grid = batch.solve_grid([designs[k][0] for k in valid], pressures, settings=settings,
                            outputs='all')
    at = (np.asarray(valid)[:, None] * n_p + np.arange(n_p)).ravel()
    success = grid.success[:, :, 0].ravel()
    status = np.array([_SOLVER_STATUS[int(c)] for c in grid.status[:, :, 0].ravel()],
                      dtype=object)
    small = success & ~grid.valid[:, :, 0].ravel()
    status[success] = STATUS_OK
    status[small] = STATUS_SMALL_ROTATION
    good = success[:, None]
    out['curvature_per_m'][at] = np.where(success, grid.curvature[:, :, 0].ravel(), np.nan)
    out['tip_x_m'][at], out['tip_z_m'][at] = np.where(good, grid.tip[:, :, 0].reshape(-1, 2),
                                                      np.nan).T
    out['success'][at] = success
    out['model'][at] = grid.models[:, :, 0].ravel()
    message = np.full(at.size, '', dtype=object)
    for j in np.flatnonzero(status != STATUS_OK):
        d, p = divmod(int(j), n_p)
        message[j] = grid.result(d, p).message
    for axis in rigidity:
        k = batch.rigidity_grid([designs[j][0] for j in valid], pressures, axis,
                                displacement, settings)
        code = k.rigidity_status.ravel()
        # A flagged K keeps its eq. 22 value beside the direct stiffness; its row says why.
        got = success & (code != int(RigidityStatus.FAILED))
        out[f'k{axis}_nm2'][at] = np.where(got, k.value.ravel(), np.nan)
        out[f'k{axis}_direct_n_per_m'][at] = np.where(got, k.direct_stiffness.ravel(), np.nan)
        for j in np.flatnonzero(success & ~k.success.ravel()):
            d, p = divmod(int(j), n_p)
            if status[j] == STATUS_OK:
                status[j] = STATUS_RIGIDITY if code[j] == int(RigidityStatus.FAILED) \
                    else RigidityStatus(code[j]).name.lower()
            message[j] = (message[j] + '; ' if message[j] else '') + \
                f'K_{axis}: {k.result(d, p).message}'
    out['status'][at] = status
    out['message'][at] = message


def _rigidity_axes(rigidity):
    if rigidity is True:
        return ('x', 'z')
    if rigidity is False or rigidity is None:
        return ()
    if rigidity in ('x', 'z'):
        return (rigidity,)
    raise ValueError(f"`rigidity` must be a bool, 'x' or 'z', got {rigidity!r}")


def sweep(vary=None, pressures=None, design=None, model='default', rigidity=False,
          displacement=0.010, scale_w1=False, scheduler=None, chunk_designs=None,
          progress=None):
    """
    Sweep designs x pressures: one row per scene, as a tidy pandas DataFrame.

    Parameters
    ----------
    vary : mapping of str to sequence of float, optional
        ActuatorDesign field -> values, e.g. ``{'prestrain': [0.15, 0.25, 0.40],
        'Cy': [0.022, 0.026]}``; every combination, the last field fastest (SI units).
    pressures : array_like, optional
        Gauge pressures [Pa]; default 0 to 400 kPa every 5 kPa.
    design : ActuatorDesign or path, optional
        Base design, or its YAML file (`ActuatorDesign.from_yaml`); default the paper's
        finger at prestrain 0.25.
    model : {'default', 'paper'} or ModelSettings
        'default': the pipeline's default model (rod-accurate to 0.05 mm); 'paper': the
        paper's CCM8. Every finger is `pipeline.finger_model(design, settings)`.
    rigidity : bool or {'x', 'z'}
        Add K_x and K_z (eq. 22, displacement control along +X and +Z); 'x' or 'z': that
        one alone.
    displacement : float
        Their tip displacement delta [m] (the paper's protocol: 10 mm).
    scale_w1 : bool
        Scale the rib width w1 with Cy where Cy varies (see `grid.design_grid`).
    scheduler : str, optional
        None: this process (compiled loops on every core). ``'local:N'`` or
        ``'tcp://host:port'``: Dask (`runner.run_chunks`; needs ``fpc_gripper[dask]``).
    chunk_designs : int, optional
        Designs per task. Default: about 16 tasks on Dask, or for progress in a run long
        enough to show it (about a second: 32k scenes, a rigidity axis counting as 8),
        else one batch of every design. Any chunking gives the same rows.
    progress : bool, optional
        Progress bar on stderr for runs over a second (default: when it is a terminal).

    Returns
    -------
    pandas.DataFrame
        Columns: ``design_id``, every varied field under its ActuatorDesign name,
        ``pressure_pa``, ``curvature_per_m``, ``tip_x_m``, ``tip_z_m``, (``kx_nm2``,
        ``kz_nm2``, then ``kx_direct_n_per_m``, ``kz_direct_n_per_m``, dF/d delta of the
        displacement control, with `rigidity`), ``success``, ``status`` ('ok',
        'invalid_design', a SolverStatus name, 'small_rotation', 'rigidity_failed',
        'small_lever' or 'branch_change'), ``model`` (the
        rung and N of the scene) and ``message`` (why, where status is not 'ok').
        Numbers are NaN where the solve failed or the design is invalid. ``attrs``
        holds the base design and the settings.

    Raises
    ------
    ValueError, TypeError
        On unknown fields, non-finite values, bad pressures, models or schedulers.

    """
    import pandas as pd
    base = base_design(design)
    settings = model_settings(model)
    pressures = batch.check_pressures(DEFAULT_PRESSURES if pressures is None else pressures)
    if isinstance(displacement, bool) or not (isinstance(displacement, (int, float))
                                              and math.isfinite(displacement)
                                              and displacement > 0.0):
        raise ValueError(f'`displacement` must be finite and > 0 [m], got {displacement!r}')
    axes = _rigidity_axes(rigidity)
    columns, points = design_grid(base, vary, scale_w1)
    if chunk_designs is None:
        # One batch is fastest (designs of one discretisation and options share compiled
        # loops, and a batch's last compiled loops leave a core idle); tasks for Dask and
        # for progress, of runs long enough to show any. No chunking changes a row.
        work = len(points) * pressures.size * (1 + _RIGIDITY_WORK * len(axes))
        whole = scheduler is None and (progress is False or work < _WORK_FOR_PROGRESS)
        size = len(points) if whole else max(1, math.ceil(len(points) / _CHUNKS))
    else:
        size = int(chunk_designs)
    if size < 1:
        raise ValueError(f'`chunk_designs` must be >= 1, got {chunk_designs!r}')
    entries = [(p.design, p.error) for p in points]
    chunks = [(entries[k:k + size], pressures, settings, axes, float(displacement))
              for k in range(0, len(entries), size)]
    parts = run_chunks(solve_designs, chunks, [len(c[0]) * pressures.size for c in chunks],
                       scheduler, progress, unit='scene')
    n_p = pressures.size
    table = {'design_id': np.repeat(np.arange(len(points)), n_p)}
    for name in columns:
        table[name] = np.repeat([p.values[name] for p in points], n_p)
    table['pressure_pa'] = np.tile(pressures, len(points))
    for name in parts[0]:
        table[name] = np.concatenate([part[name] for part in parts])
    frame = pd.DataFrame(table)
    frame.attrs.update(base_design=base.to_dict(), model=settings_label(settings),
                       settings=vars(settings).copy(), varied=columns)
    return frame
