"""The ``fpc-grasp`` command: grasp and holding force of an object against grasp pressure."""

import argparse
import csv
import math
import sys

from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.io.mcap_writer import atomic_output
from fpc_gripper.model.pipeline import ModelSettings
from fpc_gripper.progress import Progress
from fpc_gripper.ranges import RANGE_HELP
from fpc_gripper.tools import add_version, JobFailed, OutputDir, run

from .grasp import GraspSettings, pressure_range, simulate_grasp
from .objects import make_object, OBJECTS

__all__ = ['build_parser', 'main', 'plot_sweeps', 'write_csv', 'CSV_COLUMNS']

#: Columns of grasp.csv, in order.
CSV_COLUMNS = ('pressure_pa', 'grasp_force_n', 'holding_force_n', 'fingers_in_contact',
               'success', 'status')


def write_csv(sweep, path):
    """Write a GraspSweep's rows to `path` (atomically): the columns of CSV_COLUMNS."""
    columns = sweep.columns()
    with atomic_output(path) as tmp:
        with open(tmp, 'w', newline='') as stream:
            writer = csv.writer(stream)
            writer.writerow(CSV_COLUMNS)
            for row in zip(*(columns[c] for c in CSV_COLUMNS)):
                writer.writerow([f'{v:.10g}' if isinstance(v, float) else v for v in row])


def plot_sweeps(sweeps, labels, path, title=''):
    """
    Chart grasp force and holding force against grasp pressure, one colour per sweep.

    Parameters
    ----------
    sweeps : sequence of GraspSweep
    labels : sequence of str
    path : path-like
        PNG to write (atomically).
    title : str

    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5))
    for k, (sweep, label) in enumerate(zip(sweeps, labels)):
        colour = f'C{k}'
        pts = sorted(sweep.points, key=lambda p: p.pressure)
        kpa = [p.pressure * 1e-3 for p in pts]
        ax.plot(kpa, [p.grasp_force for p in pts], '-', color=colour, marker='o', ms=3,
                label=f'{label}: grasp force')
        ax.plot(kpa, [p.holding_force for p in pts], '--', color=colour, marker='s', ms=3,
                label=f'{label}: holding force (mu = {sweep.mu:g})')
        failed = [p for p in pts if not p.success]
        if failed:
            ax.plot([p.pressure * 1e-3 for p in failed], [0.0] * len(failed), 'x',
                    color=colour, label=f'{label}: not completed')
        best = sweep.best
        if best is not None and best.holding_force > 0.0:
            ax.annotate(f'best {best.pressure * 1e-3:.0f} kPa',
                        (best.pressure * 1e-3, best.holding_force), textcoords='offset points',
                        xytext=(6, 6), fontsize=8, color=colour)
    ax.set_xlabel('grasp pressure [kPa gauge]')
    ax.set_ylabel('force [N]')
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title or 'three-finger grasp')
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=100, format='png')
    plt.close(fig)


_EPILOG = f"""\
example:
  fpc-grasp --object cylinder --diameter 0.040 --mu 0.5 --pressure 0:300e3:10e3 --out DIR

{RANGE_HELP}"""


def build_parser():
    """Return the argument parser of ``fpc-grasp``."""
    parser = argparse.ArgumentParser(
        prog='fpc-grasp', description='Grasp an object with the gripper over a range of grasp '
        'pressures: grasp force, holding force along the palm axis, best pressure.',
        formatter_class=argparse.RawDescriptionHelpFormatter, epilog=_EPILOG)
    parser.add_argument('--object', required=True, choices=OBJECTS,
                        help='cylinder: coaxial with the palm axis; sphere: centred on it; '
                             'box: D x D section, lying across the palm')
    parser.add_argument('--diameter', required=True, type=float, help='object size D [m]')
    parser.add_argument('--mu', required=True, type=float, help='Coulomb coefficient [-]')
    parser.add_argument('--pressure', required=True,
                        help='grasp pressures [Pa gauge]: a,b,c, start:stop:step or '
                             'start:stop/count (see below)')
    parser.add_argument('--out', required=True, help='output directory (grasp.csv, grasp.png)')
    parser.add_argument('--force', action='store_true',
                        help='replace the outputs of an earlier run in --out')
    parser.add_argument('--height', type=float, default=0.0,
                        help="height of the object's lowest point above the palm [m] "
                             '(default 0: resting on it)')
    parser.add_argument('--gripper-config', default=None, help='gripper YAML (default: the '
                        "paper's three fingers)")
    parser.add_argument('--open-pressure', type=float, default=None,
                        help='pressure the gripper opens to before the object is placed [Pa] '
                             '(default: the config max_pressure)')
    parser.add_argument('--tolerance', type=float, default=ModelSettings().tolerance,
                        help='finger model tolerance [m] (sets the contact model)')
    parser.add_argument('--pull-step', type=float, default=GraspSettings().pull_step,
                        help='pull-out step [m]')
    parser.add_argument('--no-progress', dest='progress', action='store_false', default=None,
                        help='no progress on stderr (default: a bar on a terminal, a line '
                             'every few seconds otherwise, once a run takes a second)')
    return add_version(parser)


def _prepare(args):
    """Check every input and --out; return the job (the sweep and its files)."""
    out = OutputDir(args.out, args.force).check()
    pressures = pressure_range(args.pressure, '`pressure`')
    if not (0.0 <= args.height < float('inf')):
        raise ValueError(f'`height` must be >= 0 [m] (the object rests on or above the '
                         f'palm), got {args.height}')
    obj = make_object(args.object, args.diameter, args.height)
    config = load_gripper_config(args.gripper_config)
    settings = GraspSettings(open_pressure=args.open_pressure, pull_step=args.pull_step,
                             model=ModelSettings(tolerance=args.tolerance))
    open_pressure = config.max_pressure if args.open_pressure is None else args.open_pressure
    if pressures.max() > open_pressure:
        raise ValueError(f'`pressure` must be <= the open pressure {open_pressure:g} [Pa] '
                         f'(--open-pressure, default the config max_pressure), got '
                         f'{args.pressure!r}')
    if not (args.mu >= 0.0 and math.isfinite(args.mu)):
        raise ValueError(f'`mu` must be finite and >= 0 [-], got {args.mu}')

    def job():
        with Progress(len(config.fingers) + len(pressures), 'step', 'fpc-grasp',
                      show=args.progress) as progress:
            sweep = simulate_grasp(config, obj, pressures, args.mu, settings, progress)
        best = sweep.best
        usable = best is not None and math.isfinite(best.holding_force)
        reason = None if usable else _why(sweep)
        with out:
            write_csv(sweep, out.file('grasp.csv'))
            label = f'{args.object} D = {args.diameter * 1e3:g} mm'
            plot_sweeps([sweep], [label], out.file('grasp.png'),
                        title=f'{label}, mu = {args.mu:g}, open at '
                              f'{sweep.open_pressure * 1e-3:.0f} kPa')
            out.commit(failed=reason)
        _print(sweep, out)
        if reason is not None:
            raise JobFailed(f'{reason}; {out.path} holds the failed rows and FAILED.txt')
        return 0
    return job


def _why(sweep):
    """Say why no grasp pressure gave a result: the first row's status and message."""
    first = sweep.points[0]
    return (f'no grasp pressure was simulated to the end ({first.status.name}: '
            f'{first.message})')


def _print(sweep, out):
    print(f'{"pressure[kPa]":>13} {"grasp[N]":>9} {"holding[N]":>10} {"fingers":>7}  status')
    for p in sweep.points:
        print(f'{p.pressure * 1e-3:13.1f} {p.grasp_force:9.4f} {p.holding_force:10.4f} '
              f'{p.fingers_in_contact:7d}  {p.status.name}')
    best = sweep.best
    if best is not None and math.isfinite(best.holding_force):
        if best.holding_force <= 0.0:
            print('no grasp pressure holds the object')
        else:
            print(f'best grasp pressure {best.pressure * 1e-3:.1f} kPa: holding force '
                  f'{best.holding_force:.4f} N (grasp force {best.grasp_force:.4f} N)')
    print(f'wrote {out.path / "grasp.csv"} and {out.path / "grasp.png"}')
    if out.replaced:
        print(out.replaced_note())


def main(argv=None):
    """
    Run ``fpc-grasp``.

    Returns
    -------
    int
        The exit status of `fpc_gripper.tools.EXIT_CODES`: 1 when no grasp pressure was
        simulated to the end.

    """
    return run(build_parser(), _prepare, argv)


if __name__ == '__main__':
    sys.exit(main())
