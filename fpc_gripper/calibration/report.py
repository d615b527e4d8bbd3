"""What a calibration writes: the design YAML, a gripper config, report.json and report.png."""

import json
import math
import pathlib

import numpy as np
import yaml

from .fit import pcc_model
from ..io.config import default_gripper_config_path, load_gripper_config
from ..io.mcap_writer import atomic_output
from ..model.analysis import fit_circle, flexural_rigidity

__all__ = ['write_outputs', 'plot_report']

#: Pressures of the modelled K_x, K_z curves when no loading test sets the range [Pa].
_RIGIDITY_TOP = 100e3


def write_outputs(result, out_dir):
    """
    Write a calibration's files into `out_dir` (created if missing).

    ``report.json`` (`CalibrationResult.report`) and ``report.png`` (`plot_report`)
    always; for a successful fit also ``actuator.yaml`` (`ActuatorDesign.to_yaml`) and
    ``gripper.yaml``, the package's default gripper with that actuator on every finger, for
    ``model_node --ros-args -p gripper_config:=<out_dir>/gripper.yaml``. Each file is
    written to a temporary name and moved into place when complete.

    Returns
    -------
    dict
        File kind to path.

    """
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    # A failed fit's estimates stay in report.json: no file of it may look deployable.
    if result.success and result.design is not None:
        paths['actuator'] = out / 'actuator.yaml'
        with atomic_output(paths['actuator']) as tmp:
            result.design.to_yaml(tmp)
        paths['gripper'] = out / 'gripper.yaml'
        with atomic_output(paths['gripper']) as tmp:
            tmp.write_text(_gripper_yaml(paths['actuator'].name))
    paths['report'] = out / 'report.json'
    with atomic_output(paths['report']) as tmp:
        tmp.write_text(json.dumps(result.report(), indent=2) + '\n')
    paths['plot'] = plot_report(result, out / 'report.png')
    return paths


def _gripper_yaml(actuator):
    """Return the default gripper config's palm, limits and fingers with `actuator` on each."""
    base = load_gripper_config(default_gripper_config_path())
    data = {
        'actuator': actuator, 'palm_radius': base.palm_radius,
        'atmospheric_pressure': base.atmospheric_pressure, 'max_pressure': base.max_pressure,
        'fingers': [{'name': f.name, 'mount_angle': f.mount_angle} for f in base.fingers],
    }
    return ('# Gripper of calibrated fingers (fpc-calibrate), SI units (m, rad, Pa)\n'
            + yaml.safe_dump(data, sort_keys=False))


def _finger_frame(result):
    """Return the measured markers in the finger frame: R^T (measured - offset) [m]."""
    rotation = result.frame['rotation']
    c, s = math.cos(rotation), math.sin(rotation)
    shifted = result.data['markers'].xz - np.array(result.frame['offset'])
    return shifted @ np.array([[c, -s], [s, c]])


def plot_report(result, path, size=(1500, 1100), dpi=100):
    """
    Draw the calibration's figure into a PNG file.

    Four panels: measured markers (in the finger frame, through the fitted motion-capture
    frame) against the modelled midplanes at every pressure; curvature against pressure,
    from the paper-style least-squares circles through the measured and the modelled
    markers, and of the whole modelled midplane; K_x and K_z against pressure, modelled
    and from the measured forces (with the model's loaded levers, eq. 22); and every
    residual in units of its stated noise.

    Returns
    -------
    pathlib.Path

    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi)
    axes = fig.subplots(2, 2)
    title = 'calibrated' if result.success else f'FAILED ({result.status.name})'
    fig.suptitle(f'fpc-calibrate: {title}, model {result.settings["model"]}\n'
                 + ', '.join(_estimate_text(result, n) for n in result.estimates),
                 fontsize='medium')
    solver = pcc_model(result.design, result.settings['n_segments']) \
        if result.design is not None else None
    frames = _frames(result, solver)
    _plot_shapes(_axes(axes[0, 0], 'shapes: measured markers and model', 'X [mm]', 'Z [mm]'),
                 result, frames)
    _plot_curvature(_axes(axes[0, 1], 'curvature of least-squares circles',
                          'pressure [kPa]', 'curvature [1/m]'), result, frames)
    _plot_rigidity(_axes(axes[1, 0], 'flexural rigidity, eq. (22)', 'pressure [kPa]',
                         'K [N m²]'), result, solver)
    _plot_residuals(_axes(axes[1, 1], 'residuals / stated noise', 'measurement',
                          'residual [noise]'), result)
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    path = pathlib.Path(path)
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format='png')
    return path


def _axes(ax, title, xlabel, ylabel):
    ax.set_title(title)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    return ax


def _estimate_text(result, name):
    value, error = result.estimates[name], result.stderr[name]
    if isinstance(value, list):
        return f'{name} fitted'
    return f'{name} {value:.4g} ± {error:.2g}'


def _frames(result, solver):
    """Return (marker rows, modelled result) of every marker frame by pressure; [] if none."""
    markers = result.data.get('markers')
    if markers is None or solver is None:
        return []
    seen = _finger_frame(result)
    out = []
    for f in np.argsort(markers.pressure, kind='stable'):
        where = np.flatnonzero(markers.frame == f)
        where = where[np.argsort(markers.s[where])]
        model = solver.solve(float(markers.pressure[f]), markers.tip_force[f])
        out.append((float(markers.pressure[f]), markers.s[where], seen[where],
                    model if model.success else None))
    return out


def _plot_shapes(ax, result, frames):
    if not frames:
        ax.text(0.5, 0.5, 'no marker data' if result.data.get('markers') is None
                else 'no valid design', ha='center', transform=ax.transAxes)
        return
    import matplotlib
    cmap = matplotlib.colormaps['viridis']
    top = max(max(pressure for pressure, *_ in frames), 1.0)
    for pressure, _, seen, model in frames:
        color = cmap(pressure / top)
        if model is not None:
            ax.plot(1e3 * model.points[:, 0], 1e3 * model.points[:, 1], '-', color=color,
                    lw=1.2)
        ax.plot(1e3 * seen[:, 0], 1e3 * seen[:, 1], 'o', color=color, ms=4,
                label=f'{pressure / 1e3:.0f} kPa')
    ax.set_aspect('equal', adjustable='datalim')
    ax.legend(fontsize='small', ncol=2)


def _circle(points):
    return fit_circle(points).curvature if len(points) >= 3 else math.nan


def _plot_curvature(ax, result, frames):
    rows = [(pressure / 1e3, _circle(seen), _circle(model.position_at(s)), model.curvature)
            for pressure, s, seen, model in frames if model is not None]
    if rows:
        p, measured, at_markers, whole = np.array(rows).T
        ax.plot(p, measured, 'ko', label='measured markers')
        ax.plot(p, at_markers, 'C0.-', label='model at the markers')
        ax.plot(p, whole, 'C1--', label='model midplane')
        ax.legend(fontsize='small')


def _plot_rigidity(ax, result, solver):
    if solver is None:
        return
    loading = result.data.get('loading')
    top = _RIGIDITY_TOP if loading is None else max(float(loading.pressure.max()), 1.0)
    grid = np.linspace(0.0, top, 9)
    for axis, color in (('x', 'C0'), ('z', 'C3')):
        values = [solver.rigidity(p, axis).value for p in grid]
        ax.plot(grid / 1e3, values, '-', color=color, label=f'model K_{axis}')
        if loading is None:
            continue
        points = []
        for k in np.flatnonzero(np.array(loading.axis) == axis):
            model = solver.rigidity(float(loading.pressure[k]), axis,
                                    float(loading.displacement[k]))
            if model.success:
                points.append((loading.pressure[k] / 1e3, flexural_rigidity(
                    loading.force[k], model.lever, loading.displacement[k])))
        if points:
            ax.plot(*np.array(points).T, 'o', color=color, label=f'measured K_{axis}')
    ax.legend(fontsize='small')


def _plot_residuals(ax, result):
    start = 0
    noise = result.settings['noise']
    for name, values in result.residuals.items():
        if name == 'markers':
            for k, axis in enumerate('xz'):
                z = values[:, k] / noise[name]
                ax.plot(start + np.arange(z.size), z, '.', label=f'marker {axis}')
            start += values.shape[0]
        else:
            z = values / noise[name]
            ax.plot(start + np.arange(z.size), z, 's', label=name)
            start += z.size
    for level, style in ((1.0, ':'), (3.0, '--')):
        ax.axhline(level, color='0.5', ls=style, lw=0.8)
        ax.axhline(-level, color='0.5', ls=style, lw=0.8)
    if result.residuals:
        ax.legend(fontsize='small')
