"""The paper's parametric figures (Section IV, Figs. 4, 5, 7-9) with the default model overlaid."""

import pathlib

import numpy as np

from fpc_gripper.model.pipeline import finger_model, ModelSettings
from .charts import pyplot, save_figure, write_table
from .grid import base_design
from .parametric import model_settings, sweep

__all__ = ['FIGURES', 'PAPER_PRESSURES', 'figure']

#: One psi [Pa]: the paper steps pressure by 4 psi (27.6 kPa).
PSI = 6894.757293168361
#: The paper's pressure axis: 0 to 56 psi (386 kPa, its Fig. 11 'almost flat' state) in
#: 4 psi steps [Pa].
PAPER_PRESSURES = 4.0 * PSI * np.arange(15)
#: Segment counts of the convergence study (Section IV-A).
_CONVERGENCE_N = (1, 2, 3, 4, 6, 8, 12, 16)
_PRESTRAINS = (0.15, 0.25, 0.40)
#: What each figure shows. 'field' figures plot curvature (a) and K_x (b) against
#: pressure for CCM8 at the listed values, the other fields at Table II.
FIGURES = {
    4: {'title': 'Fig. 4: convergence in N at 0 kPa: (a) shapes, (b) curvature',
        'segments': _CONVERGENCE_N, 'shape_segments': (1, 2, 4, 8),
        'shape_prestrains': (0.40, 0.15)},
    5: {'title': 'Fig. 5(a): curvature against pressure for N = 1 (SRM), 4, 8, 16',
        'segments': (1, 4, 8, 16)},
    7: {'title': 'Fig. 7: prestrain (Cy 26 mm, h3a 0.9 mm), CCM8', 'field': 'prestrain',
        'values': _PRESTRAINS, 'unit': 1.0, 'label': 'prestrain {:.2f}'},
    8: {'title': 'Fig. 8: channel width Cy (prestrain 0.25, h3a 0.9 mm), CCM8', 'field': 'Cy',
        'values': (0.022, 0.024, 0.026, 0.028, 0.030), 'unit': 1e3, 'label': 'Cy {:.0f} mm'},
    9: {'title': 'Fig. 9: channel ceiling h3a (prestrain 0.25, Cy 26 mm), CCM8',
        'field': 'h3a', 'values': (-0.0005, 0.0, 0.0005, 0.0009, 0.0015), 'unit': 1e3,
        'label': 'h3a {:+.1f} mm'},
}
_PAPER = 'paper CCM{}'
_DEFAULT = 'default model'


def _ccm(n):
    return ModelSettings(tolerance=0.0, n_segments=int(n))


def _tagged(frame, curve, n_segments, panel='b'):
    frame = frame.copy()
    frame.insert(0, 'curve', curve)
    frame.insert(1, 'n_segments', n_segments)
    frame.insert(0, 'panel', panel)
    return frame


def _field_figure(spec, base, scheduler, progress):
    vary = {spec['field']: spec['values']}
    paper = sweep(vary, PAPER_PRESSURES, base, _ccm(8), rigidity='x', scheduler=scheduler,
                  progress=progress)
    default = sweep(vary, PAPER_PRESSURES, base, 'default', rigidity='x', scheduler=scheduler,
                    progress=progress)
    return [_tagged(paper, _PAPER.format(8), 8, 'ab'), _tagged(default, _DEFAULT, 0, 'ab')]


def _segments_figure(spec, base, scheduler, progress, pressures):
    vary = {'prestrain': _PRESTRAINS}
    parts = [_tagged(sweep(vary, pressures, base, _ccm(n), scheduler=scheduler,
                           progress=progress), _PAPER.format(n), n) for n in spec['segments']]
    parts.append(_tagged(sweep(vary, pressures, base, 'default', scheduler=scheduler,
                               progress=progress), _DEFAULT, 0))
    return parts


def _shapes(spec, base):
    """Fig. 4(a): midplane samples at 0 kPa, paper CCM-N and the default model."""
    import pandas as pd
    rows = []
    for prestrain in spec['shape_prestrains']:
        design = base.replace(prestrain=prestrain)
        models = [(_PAPER.format(n), n, _ccm(n)) for n in spec['shape_segments']]
        models.append((_DEFAULT, 0, model_settings('default')))
        for curve, n, settings in models:
            result = finger_model(design, settings).solve(0.0)
            points = result.points
            rows.append(pd.DataFrame({
                'panel': 'a', 'curve': curve, 'n_segments': n, 'prestrain': prestrain,
                'pressure_pa': 0.0, 'sample': np.arange(len(points)), 'x_m': points[:, 0],
                'z_m': points[:, 1], 'success': result.success}))
    return rows


def figure(number, out_dir=None, design=None, scheduler=None, progress=None):
    """
    Reproduce one of the paper's parametric figures, with the default model overlaid.

    The paper's model and protocol: CCM with N segments (CCM8 for Figs. 7-9), pressures
    from 0 in 4 psi (27.6 kPa) steps to 56 psi (386 kPa), K_x by displacement control
    with delta x = 10 mm; every other field at Table II (`design`). The default model
    (rod-accurate to 0.05 mm) is computed alike, so that the chart shows where the two
    disagree.

    Parameters
    ----------
    number : {4, 5, 7, 8, 9}
        4: convergence in N at 0 kPa (shapes and curvature for N = 1..16); 5: curvature
        against pressure for N = 1, 4, 8, 16 (panel (a); panel (b), the paper's MATLAB
        run times, is not reproduced); 7, 8, 9: curvature and K_x against pressure for
        prestrain, Cy and h3a.
    out_dir : path, optional
        Writes ``figure_<n>.png`` and ``figure_<n>.csv`` there.
    design : ActuatorDesign or path, optional
        Base design; default the paper's finger.
    scheduler, progress
        As `sweep`.

    Returns
    -------
    pandas.DataFrame
        The figure's data: the sweep columns with ``panel``, ``curve`` (``paper CCMn`` or
        ``default model``) and ``n_segments`` (0 for the default model), and for Fig. 4
        the shape samples (``x_m``, ``z_m``).

    """
    import pandas as pd
    if number not in FIGURES:
        raise ValueError(f'`figure` must be one of {sorted(FIGURES)}, got {number!r}')
    spec = FIGURES[number]
    base = base_design(design)
    if number == 4:
        parts = _segments_figure(spec, base, scheduler, progress, [0.0]) + _shapes(spec, base)
    elif number == 5:
        parts = _segments_figure(spec, base, scheduler, progress, PAPER_PRESSURES)
    else:
        parts = _field_figure(spec, base, scheduler, progress)
    frame = pd.concat(parts, ignore_index=True)
    frame.insert(0, 'figure', number)
    if out_dir is not None:
        out_dir = pathlib.Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        write_table(frame, out_dir / f'figure_{number}.csv')
        save_figure(_draw(number, spec, frame), out_dir / f'figure_{number}.png')
    return frame


#: Sweep statuses of a K where eq. 22 does not apply (`stiffness.RigidityStatus`).
_FLAGGED = ('small_lever', 'branch_change')


def _curves(frame):
    """(curve, n_segments, rows) of the paper's model first, the default model last."""
    curves = frame[['curve', 'n_segments']].drop_duplicates()
    order = sorted(curves.itertuples(index=False), key=lambda c: (c[1] == 0, c[1]))
    return [(c, n, frame[(frame['curve'] == c) & (frame['n_segments'] == n)])
            for c, n in order]


def _draw(number, spec, frame):
    plt = pyplot()
    if number == 4:
        return _draw_convergence(plt, spec, frame)
    if number == 5:
        fig, ax = plt.subplots(figsize=(6.5, 4.8), layout='constrained')
        styles = {1: ':', 4: '-.', 8: '-', 16: (0, (5, 1))}
        for k, prestrain in enumerate(sorted(frame['prestrain'].unique(), reverse=True)):
            for curve, n, rows in _curves(frame[frame['prestrain'] == prestrain]):
                ax.plot(rows['pressure_pa'] / 1e3, rows['curvature_per_m'], color=f'C{k}',
                        ls=styles.get(n, '--') if n else '--', lw=2.4 if not n else 1.2,
                        alpha=0.5 if not n else 1.0,
                        label=f'{prestrain:.2f}, {curve}')
        ax.set_xlabel('pressure [kPa]')
        ax.set_ylabel('curvature [1/m]')
        ax.axhline(0.0, color='k', lw=0.5)
        ax.legend(fontsize=7, ncol=3)
        ax.grid(alpha=0.3)
        fig.suptitle(spec['title'], fontsize=10)
        return fig
    fig, axes = plt.subplots(1, 2, figsize=(11.0, 4.6), layout='constrained')
    field, unit = spec['field'], spec['unit']
    for k, value in enumerate(spec['values']):
        rows = frame[np.isclose(frame[field], value)]
        for curve, n, part in _curves(rows):
            dashed = n == 0
            label = spec['label'].format(value * unit) + (f' ({curve})' if dashed else '')
            for ax, column in zip(axes, ('curvature_per_m', 'kx_nm2')):
                ax.plot(part['pressure_pa'] / 1e3, part[column], color=f'C{k}',
                        ls='--' if dashed else '-', marker='' if dashed else 'o', ms=3,
                        label=label if ax is axes[0] or not dashed else None)
            flagged = part[part['status'].isin(_FLAGGED)]
            axes[1].plot(flagged['pressure_pa'] / 1e3, flagged['kx_nm2'], 'x', color='k',
                         ms=6, label=None)
    if frame['status'].isin(_FLAGGED).any():
        axes[1].plot([], [], 'x', color='k', label='x: eq. 22 does not apply (small lever '
                                                   'or branch change)')
        axes[1].legend(fontsize=7)
    axes[0].set_ylabel('curvature [1/m]')
    axes[0].axhline(0.0, color='k', lw=0.5)
    axes[1].set_ylabel('$K_x$ [N·m²] ($\\delta_x$ = 10 mm)')
    for ax, tag in zip(axes, 'ab'):
        ax.set_xlabel('pressure [kPa]')
        ax.set_title(f'({tag})', fontsize=9)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(spec['title'] + '; solid: paper CCM8, dashed: default model', fontsize=10)
    return fig


def _draw_convergence(plt, spec, frame):
    fig, (shapes, kappa) = plt.subplots(1, 2, figsize=(11.0, 4.6), layout='constrained')
    samples = frame[frame['panel'] == 'a']
    styles = dict(zip(spec['shape_segments'], (':', '-.', '--', '-')))
    for k, prestrain in enumerate(spec['shape_prestrains']):
        for curve, n, rows in _curves(samples[samples['prestrain'] == prestrain]):
            shapes.plot(rows['x_m'] * 1e3, rows['z_m'] * 1e3, color=f'C{k}' if n else 'k',
                        ls=styles.get(n, '-'), lw=1.2 if n else 2.0, alpha=1.0 if n else 0.4,
                        label=f'{prestrain:.2f}, {curve}')
    shapes.set_aspect('equal', adjustable='datalim')
    shapes.set_xlabel('X [mm]')
    shapes.set_ylabel('Z [mm]')
    shapes.set_title('(a) shapes at 0 kPa', fontsize=9)
    shapes.legend(fontsize=6, ncol=2)
    table = frame[frame['panel'] == 'b']
    for k, prestrain in enumerate(sorted(table['prestrain'].unique())):
        rows = table[(table['prestrain'] == prestrain) & (table['n_segments'] > 0)]
        kappa.plot(rows['n_segments'], rows['curvature_per_m'], 'o-', color=f'C{k}',
                   label=f'prestrain {prestrain:.2f}, paper CCM-N')
        default = table[(table['prestrain'] == prestrain) & (table['n_segments'] == 0)]
        kappa.axhline(float(default['curvature_per_m'].iloc[0]), color=f'C{k}', ls='--',
                      label=f'prestrain {prestrain:.2f}, {_DEFAULT}')
    kappa.set_xscale('log', base=2)
    kappa.set_xticks(spec['segments'], [str(n) for n in spec['segments']])
    kappa.set_xlabel('segments N')
    kappa.set_ylabel('curvature at 0 kPa [1/m]')
    kappa.set_title('(b) curvature', fontsize=9)
    kappa.legend(fontsize=7)
    kappa.grid(alpha=0.3)
    fig.suptitle(spec['title'], fontsize=10)
    return fig
