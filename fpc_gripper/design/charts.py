"""Charts and files of design studies: sweep charts, and tables written whole or not at all."""

import pathlib

import numpy as np

from fpc_gripper.io.mcap_writer import atomic_output

__all__ = ['write_table', 'save_figure', 'sweep_charts', 'pyplot']


def pyplot():
    """Return matplotlib.pyplot on the non-interactive Agg backend."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def _atomic(path, write):
    """Write `path` through `write(temporary path)`, renamed into place when complete."""
    with atomic_output(path) as tmp:
        write(tmp)
    return pathlib.Path(path)


def write_table(frame, path, fmt='csv'):
    """
    Write a DataFrame as CSV or parquet, whole or not at all.

    Parquet needs pyarrow (``pip install pyarrow``); a missing one is a ValueError that
    says so.
    """
    if fmt == 'csv':
        return _atomic(path, lambda tmp: frame.to_csv(tmp, index=False))
    if fmt == 'parquet':
        try:
            import pyarrow  # noqa: F401
        except ImportError:
            raise ValueError('parquet output needs pyarrow: pip install pyarrow') from None
        return _atomic(path, lambda tmp: frame.to_parquet(tmp, index=False))
    raise ValueError(f"`format` must be 'csv' or 'parquet', got {fmt!r}")


def save_figure(fig, path):
    """Save a matplotlib figure as PNG, whole or not at all, and close it."""
    try:
        return _atomic(path, lambda tmp: fig.savefig(tmp, format='png', dpi=120))
    finally:
        pyplot().close(fig)


def sweep_charts(frame, out_dir):
    """
    Charts of a sweep table: curvature and tip path against pressure, and K_x, K_z if any.

    One line per valid design, coloured by the first varied field (its value in the
    legend or colour bar).

    Returns
    -------
    list of pathlib.Path
        The PNG files written.

    """
    plt = pyplot()
    out_dir = pathlib.Path(out_dir)
    varied = list(frame.attrs.get('varied', []))
    key = varied[0] if varied else None
    ok = frame[frame['success']]
    designs = list(ok.groupby('design_id', sort=True))
    values = np.array([group[key].iloc[0] for _, group in designs]) if key else np.zeros(0)
    cmap = plt.get_cmap('viridis')
    span = (values.min(), values.max()) if values.size else (0.0, 1.0)
    scale = (span[1] - span[0]) or 1.0

    def colour(k):
        return cmap((values[k] - span[0]) / scale) if key else 'C0'

    panels = [('curvature_per_m', 'curvature [1/m]')]
    for name, label in (('kx_nm2', '$K_x$ [N·m²]'), ('kz_nm2', '$K_z$ [N·m²]')):
        if name in frame:
            panels.append((name, label))
    written = []
    fig, axes = plt.subplots(1, len(panels) + 1, figsize=(5.0 * (len(panels) + 1), 4.2),
                             squeeze=False)
    axes = axes[0]
    for k, (_, group) in enumerate(designs):
        for ax, (name, _) in zip(axes, panels):
            ax.plot(group['pressure_pa'] / 1e3, group[name], color=colour(k), lw=1.0)
        axes[-1].plot(group['tip_x_m'] * 1e3, group['tip_z_m'] * 1e3, color=colour(k), lw=1.0)
    for ax, (_, label) in zip(axes, panels):
        ax.set_xlabel('pressure [kPa]')
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel('tip X [mm]')
    axes[-1].set_ylabel('tip Z [mm]')
    axes[-1].set_aspect('equal', adjustable='datalim')
    axes[-1].grid(alpha=0.3)
    if key and values.size:
        mappable = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(*span))
        fig.colorbar(mappable, ax=list(axes), label=key, shrink=0.85)
    invalid = frame.loc[~frame['success'], 'design_id'].nunique()
    fig.suptitle(f'{len(designs)} designs x {frame["pressure_pa"].nunique()} pressures, '
                 f'model {frame.attrs.get("model", "?")}'
                 + (f'; {invalid} designs with failed or invalid rows' if invalid else ''))
    written.append(save_figure(fig, out_dir / 'sweep.png'))
    return written
