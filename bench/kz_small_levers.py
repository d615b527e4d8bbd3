"""
K_z of the paper's finger at prestrain 0.40 against pressure, where eq. 22 holds and not.

Run by hand from the repository root:

    .venv/bin/python bench/kz_small_levers.py

Writes docs/kz_small_levers.csv and docs/kz_small_levers.png: eq. 22's K_z = F |X_tip|^3 /
(3 delta) and the direct stiffness dF/d delta of the displacement control (delta = 10 mm
along +Z), 0 to 150 kPa every 2.5 kPa, for the default model and the paper's CCM8
(`batch.rigidity_grid`), with every scene's `RigidityStatus`; the chart shades the
pressures where eq. 22 does not apply (a lever shorter than delta, or a loaded state off
the unloaded branch).
"""

import pathlib

import numpy as np

from fpc_gripper.model import ActuatorDesign, batch
from fpc_gripper.model.pipeline import ModelSettings
from fpc_gripper.model.stiffness import RigidityStatus

ROOT = pathlib.Path(__file__).resolve().parents[1]
PRESSURES = np.arange(0.0, 150e3 + 1.0, 2.5e3)
MODELS = {'default model': ModelSettings(), 'paper CCM8': ModelSettings(tolerance=0.0)}
_SHADE = {RigidityStatus.SMALL_LEVER: ('tab:orange', 'lever < delta'),
          RigidityStatus.BRANCH_CHANGE: ('tab:red', 'loaded state off its branch')}


def compute():
    """Return {model: rigidity grid Result} of the design at PRESSURES."""
    design = ActuatorDesign.paper(prestrain=0.40)
    return {name: batch.rigidity_grid(design, PRESSURES, 'z', 0.010, settings)
            for name, settings in MODELS.items()}


def write_csv(grids, path):
    """Write one row per model and pressure."""
    lines = ['model,pressure_pa,kz_nm2,force_n,lever_m,direct_n_per_m,status']
    for name, k in grids.items():
        for j, p in enumerate(PRESSURES):
            lines.append(f'{name},{p:.6g},{k.value[0, j]:.6g},{k.force[0, j]:.6g},'
                         f'{k.lever[0, j]:.6g},{k.direct_stiffness[0, j]:.6g},'
                         f'{RigidityStatus(k.rigidity_status[0, j]).name.lower()}')
    path.write_text('\n'.join(lines) + '\n')


def plot(grids, path):
    """Chart K_z (log) and dF/d delta against pressure, flagged pressures shaded."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharex=True, layout='constrained')
    kpa = PRESSURES / 1e3
    step = (kpa[1] - kpa[0]) / 2
    for col, (name, k) in enumerate(grids.items()):
        status = k.rigidity_status[0]
        for ax in axes[:, col]:
            for code, (colour, label) in _SHADE.items():
                first = True
                for j in np.flatnonzero(status == int(code)):
                    ax.axvspan(kpa[j] - step, kpa[j] + step, color=colour, alpha=0.18, lw=0,
                               label=label if first else None)
                    first = False
            ax.grid(alpha=0.3)
        axes[0, col].semilogy(kpa, k.value[0], 'k.-', ms=3, label='eq. 22: F |X|³ / (3δ)')
        axes[0, col].axhline(1e-5, color='grey', ls=':', lw=1)
        axes[0, col].set_title(f'{name}, prestrain 0.40, δ = 10 mm along +Z')
        axes[0, col].set_ylabel('$K_z$ [N·m²]')
        axes[1, col].plot(kpa, k.direct_stiffness[0], 'b.-', ms=3, label='dF/dδ')
        axes[1, col].set_ylabel('direct stiffness dF/dδ [N/m]')
        axes[1, col].set_xlabel('pressure [kPa]')
        axes[0, col].legend(fontsize=7, loc='lower right')
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main():
    """Compute, write the CSV and the chart, print the flagged pressures."""
    grids = compute()
    write_csv(grids, ROOT / 'docs' / 'kz_small_levers.csv')
    plot(grids, ROOT / 'docs' / 'kz_small_levers.png')
    for name, k in grids.items():
        for code in (RigidityStatus.SMALL_LEVER, RigidityStatus.BRANCH_CHANGE):
            flagged = PRESSURES[k.rigidity_status[0] == int(code)] / 1e3
            spans = f'{flagged.min():g}-{flagged.max():g} kPa ({flagged.size})' \
                if flagged.size else 'none'
            print(f'{name}: {code.name.lower()}: {spans}')


if __name__ == '__main__':
    main()
