"""
Speed-accuracy chart of every rung against the 2-D continuum, the rod-based one beside it.

Run by hand from the repository root:

    .venv/bin/python bench/chart_continuum.py [--repeats N]

Reads the FE tips of the reference table (bench/results/continuum.json, written by
bench_continuum.py: the unpressurised scenes, the only ones the continuum is a reference
for, `model.reference.CONTINUUM_MAX_PRESSURE`), solves each scene with every rung through
`finger_model`, and times its warm solve in this run. Writes
docs/speed_accuracy_continuum.png (two panels on the same scenes: the largest tip distance
to the rod, and to the FE, against the median solve time), docs/speed_accuracy_continuum.csv
(one row per scene and rung) and bench/results/continuum_chart.json (per rung: the error
model over the table against both references, and the cost).
"""

import argparse
import csv
import json
import math
import os
import pathlib
import statistics
import sys
import time

# One BLAS thread (set before numpy loads): the systems are small.
for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')

import numpy as np  # noqa: E402

_HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(_HERE))
from timing import machine  # noqa: E402, I100

from fpc_gripper.calibration.continuum import fe_scenes  # noqa: E402
from fpc_gripper.model import ActuatorDesign  # noqa: E402
from fpc_gripper.model.pipeline import finger_model, ModelSettings  # noqa: E402
from fpc_gripper.model.reference import CONTINUUM_FLOOR  # noqa: E402

ROOT = _HERE.parent
TABLE = _HERE / 'results' / 'continuum.json'
RESULTS = _HERE / 'results' / 'continuum_chart.json'
#: The rungs charted: (label, settings). 'default' is the adaptive model at the node's
#: tolerance; 'corrected' the fast rung fitted to the FE (docs/physics.md 18.1).
MODELS = (
    ('arc', ModelSettings(rung='arc')),
    ('ccm-1', ModelSettings(rung='ccm', n_segments=1)),
    ('ccm-8 (paper)', ModelSettings(rung='ccm', n_segments=8)),
    ('ccm-16', ModelSettings(rung='ccm', n_segments=16)),
    ('ccm_consistent-8', ModelSettings(rung='ccm_consistent', n_segments=8)),
    ('pcc-22', ModelSettings(rung='pcc', n_segments=22)),
    ('pcc-32', ModelSettings(rung='pcc', n_segments=32)),
    ('default', ModelSettings()),
    ('rod', ModelSettings(rung='rod')),
    ('corrected', ModelSettings(physics='continuum')),
)


def _scenes():
    """Return the table's converged unpressurised scenes (`calibration.continuum.fe_scenes`)."""
    return fe_scenes(json.loads(TABLE.read_text()))


def _warm_time(solver, force, repeats):
    """Median over `repeats` of the best of 5 warm solves of a scene [s]."""
    start = solver.solve(pressure=0.0, tip_force=force)
    samples = []
    for _ in range(repeats):
        best = math.inf
        for _ in range(5):
            t0 = time.perf_counter()
            solver.solve(pressure=0.0, tip_force=force, initial=start, outputs='tip')
            best = min(best, time.perf_counter() - t0)
        samples.append(best)
    return statistics.median(samples)


def measure(repeats):
    """Return one row per scene and rung: tips, distances to the FE and the rod, time."""
    out = []
    designs = {}
    for scene, fe in enumerate(_scenes()):
        prestrain, force, fe_tip = fe.prestrain, fe.tip_force, fe.tip
        design = designs.setdefault(prestrain, ActuatorDesign.paper(prestrain=prestrain))
        rod_tip = finger_model(design, ModelSettings(rung='rod')).solve(
            pressure=0.0, tip_force=force).tip
        for label, settings in MODELS:
            solver = finger_model(design, settings)
            result = solver.solve(pressure=0.0, tip_force=force)
            out.append({'scene': scene, 'prestrain': prestrain, 'f0': force[0], 'p0': force[1],
                        'rung': label, 'success': bool(result.success),
                        'tip_x_mm': 1e3 * result.tip[0], 'tip_z_mm': 1e3 * result.tip[1],
                        'fe_error_mm': 1e3 * float(np.hypot(*(result.tip - fe_tip))),
                        'rod_error_mm': 1e3 * float(np.hypot(*(result.tip - rod_tip))),
                        'time_s': _warm_time(solver, force, repeats)})
    return out


def summarise(rows):
    """Return per rung: the error model against each reference and the median cost."""
    rod_time = statistics.median(r['time_s'] for r in rows if r['rung'] == 'rod')
    summary = {}
    for label, _ in MODELS:
        mine = [r for r in rows if r['rung'] == label]
        entry = {'failed': sum(not r['success'] for r in mine),
                 'time_median_us': 1e6 * statistics.median(r['time_s'] for r in mine)}
        entry['time_ratio_to_rod'] = entry['time_median_us'] * 1e-6 / rod_time
        for reference in ('fe', 'rod'):
            for kind, keep in (('unloaded', lambda r: r['f0'] == r['p0'] == 0.0),
                               ('tip_loaded', lambda r: r['f0'] or r['p0']),
                               ('all', lambda r: True)):
                errors = [r[f'{reference}_error_mm'] for r in mine if keep(r)]
                entry[f'{reference}_{kind}_max_mm'] = max(errors)
                entry[f'{reference}_{kind}_median_mm'] = statistics.median(errors)
        summary[label] = entry
    return summary


def plot(summary, path):
    """Two panels on the same scenes: largest tip error to the rod, and to the FE."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(11.0, 4.6), sharex=True)
    floor = 1e-4    # [mm], where a reference's own rung is drawn on a log axis
    for ax, reference, title in ((axes[0], 'rod', "against the rod (the ladder's reference)"),
                                 (axes[1], 'fe', 'against the 2-D continuum FE')):
        for k, (label, entry) in enumerate(summary.items()):
            error = max(entry[f'{reference}_all_max_mm'], floor)
            marker = '*' if label in ('rod', 'corrected') else 'o'
            ax.loglog(entry['time_median_us'], error, marker, ms=9 if marker == '*' else 6)
            # Staggered labels: the PCC rungs and the default sit on one another.
            ax.annotate(label, (entry['time_median_us'], error), textcoords='offset points',
                        xytext=(5, (4, -11, 14)[k % 3]), fontsize=8)
        if reference == 'fe':
            ax.axhline(1e3 * CONTINUUM_FLOOR, ls='--', lw=0.8, color='0.4')
            ax.annotate('beam floor (rod)', (ax.get_xlim()[0], 1e3 * CONTINUUM_FLOOR),
                        textcoords='offset points', xytext=(4, 3), fontsize=7, color='0.3')
        ax.set_title(title, fontsize=10)
        ax.set_xlabel('warm solve, median [µs]')
        ax.grid(True, which='both', alpha=0.3)
    axes[0].set_ylabel('largest tip error over the unpressurised table [mm]')
    fig.suptitle('Every rung on the continuum reference table (prestrain 0.15-0.40, '
                 'unloaded and 0.5 N tip loads)', fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    """Measure, then write the chart, the CSV and the summary."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--repeats', type=int, default=7, help='timed repeats per scene')
    args = parser.parse_args(argv)
    start = time.perf_counter()
    rows = measure(args.repeats)
    summary = summarise(rows)
    docs = ROOT / 'docs'
    with open(docs / 'speed_accuracy_continuum.csv', 'w', newline='') as stream:
        writer = csv.DictWriter(stream, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    plot(summary, docs / 'speed_accuracy_continuum.png')
    RESULTS.write_text(json.dumps({
        'machine': machine(), 'elapsed_s': time.perf_counter() - start,
        'repeats': args.repeats, 'scenes': len(_scenes()),
        'references': {'fe': 'ContinuumSolver, h = 1 mm, ribs exact (continuum.json table)',
                       'rod': "finger_model(ModelSettings(rung='rod'))"},
        'timing': 'median over scenes of the median over repeats of the best of 5 warm '
                  "solves (outputs='tip'), all in this run",
        'models': summary}, indent=1))
    print(f'{"rung":>17} {"t [us]":>8} {"/rod":>6} {"FE max":>8} {"FE med":>8} '
          f'{"rod max":>8} [mm]')
    for label, e in summary.items():
        print(f'{label:>17} {e["time_median_us"]:8.1f} {e["time_ratio_to_rod"]:6.3f} '
              f'{e["fe_all_max_mm"]:8.3f} {e["fe_all_median_mm"]:8.3f} '
              f'{e["rod_all_max_mm"]:8.4f}')


if __name__ == '__main__':
    main()
