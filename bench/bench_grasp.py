"""
Grasps of the paper's gripper, and what contact costs per scene.

Run by hand from the repository root:

    .venv/bin/python bench/bench_grasp.py [--quick]

Prints, and writes to bench/results/grasp.json, docs/grasp_forces.png and a grasp.csv per
object (docs/grasp_<object>.csv): the
grasp force and holding force (mu = 0.5) against grasp pressure (0-300 kPa every 10 kPa)
for a 40 mm cylinder coaxial with the palm axis and a 50 mm sphere, both resting on the
palm, with the best grasp pressure; and the median time of a warm contact solve per
scene (from the solution 1 kPa higher, as the node's warm steps) against the same finger
and pressure solved without contact, in the same run, for the default contact model.
"""

import argparse
import json
import os
import pathlib
import sys
import time

for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')

import numpy as np  # noqa: E402

_HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(_HERE))
from timing import machine, median_time  # noqa: E402, I100

from fpc_gripper.grasp import make_object, simulate_grasp  # noqa: E402, I100
from fpc_gripper.grasp.cli import plot_sweeps, write_csv  # noqa: E402
from fpc_gripper.io.config import load_gripper_config  # noqa: E402
from fpc_gripper.model.contact import solve_contact  # noqa: E402
from fpc_gripper.model.pipeline import contact_model  # noqa: E402

_ROOT = _HERE.parent
OBJECTS = (('cylinder', 0.040, '40 mm cylinder'), ('sphere', 0.050, '50 mm sphere'))
#: Scenes of the timing: object, pressure [Pa] and finger (every one in contact).
SCENES = (('cylinder', 0.040, 100e3, 0), ('cylinder', 0.040, 0.0, 0),
          ('sphere', 0.050, 30e3, 0), ('sphere', 0.050, 0.0, 0), ('box', 0.040, 40e3, 1),
          ('box', 0.040, 0.0, 1))


def sweeps(config, pressures, mu):
    """Return the GraspSweep of every object, and the wall time of each [s]."""
    out = []
    for kind, size, label in OBJECTS:
        start = time.perf_counter()
        sweep = simulate_grasp(config, make_object(kind, size), pressures, mu)
        out.append((label, sweep, time.perf_counter() - start))
    return out


def scene_times(config, repeats):
    """Median warm solve per scene, with contact and without, in this run [s]."""
    rows = []
    for kind, size, pressure, index in SCENES:
        finger = config.fingers[index]
        solver = contact_model(finger.design)
        section = make_object(kind, size).section(finger.mount_angle, config.palm_radius)
        start = solve_contact(solver, pressure + 1e3, section)
        result = solve_contact(solver, pressure, section, initial=start)
        free_start = solver.solve(pressure + 1e3)
        contact = median_time(lambda: solve_contact(solver, pressure, section,
                                                    initial=start), repeats)
        free = median_time(lambda: solver.solve(pressure, initial=free_start), repeats)
        rows.append({'object': kind, 'diameter_m': size, 'pressure_pa': pressure,
                     'finger': index,
                     'points_in_contact': int(result.in_contact.sum()),
                     'normal_force_n': result.normal_force_total,
                     'warm_contact_s': contact, 'warm_free_s': free, 'ratio': contact / free})
        print(f'{kind:9s} {pressure * 1e-3:6.0f} kPa finger {index}: '
              f'{int(result.in_contact.sum()):2d} points in contact, warm contact '
              f'{contact * 1e6:7.0f} us, free {free * 1e6:5.0f} us, x{contact / free:.1f}')
    return rows


def main():
    """Run the benchmark and write its results and chart."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--quick', action='store_true', help='30 kPa steps, fewer repeats')
    args = parser.parse_args()
    config = load_gripper_config()
    step = 30e3 if args.quick else 10e3
    pressures = np.arange(0.0, 300e3 + 1.0, step)
    mu = 0.5
    results = sweeps(config, pressures, mu)
    table = {}
    for label, sweep, wall in results:
        best = sweep.best
        print(f'{label}: {len(sweep.points)} grasp pressures in {wall:.1f} s; best '
              f'{best.pressure * 1e-3:.0f} kPa, holding {best.holding_force:.3f} N, grasp '
              f'{best.grasp_force:.3f} N')
        table[label] = {'wall_s': wall, 'best_pressure_pa': best.pressure,
                        'best_holding_force_n': best.holding_force,
                        'rows': sweep.columns()}
        write_csv(sweep, _ROOT / 'docs' / f'grasp_{label.replace(" ", "_")}.csv')
    plot_sweeps([r[1] for r in results], [r[0] for r in results],
                _ROOT / 'docs' / 'grasp_forces.png',
                title=f"paper's gripper (prestrain 0.25), objects resting on the palm, "
                      f'mu = {mu:g}')
    scenes = scene_times(config, 20 if args.quick else 200)
    out = {'machine': machine(), 'mu': mu, 'sweeps': table, 'scenes': scenes}
    path = _HERE / 'results' / 'grasp.json'
    path.write_text(json.dumps(out, indent=1))
    print(f'wrote {path} and docs/grasp_forces.png')


if __name__ == '__main__':
    main()
