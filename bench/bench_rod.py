"""
Speed of the compiled rod (RodSolver) against its numpy reference, in the same run.

Run by hand from the repository root:

    .venv/bin/python bench/bench_rod.py [--repeats 50]

Prints, and writes to bench/results/rod.json: median solve times of RodSolver and of
the numpy reference of the tests (tests/model/rod_reference.py, the code before
compilation) on bench_solver's loaded scene (default finger, 100 kPa, p0 = 0.3 N) and
at 55.2 kPa with f0 = 0.3 N, cold (from flat) and warm (from the solution 1 kPa lower),
with the Newton iterations, the largest tip and sample deviation between the two, and
K_x at 0 kPa; the issue's target is a loaded cold solve in 1 ms.
"""

import argparse
import json
import os
import pathlib
import sys

# One BLAS thread (set before numpy loads), as the other benchmarks.
for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')

import numpy as np  # noqa: E402

_HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(_HERE))
# The numpy reference (the code before the kernels) lives with the tests.
sys.path.insert(0, str(_HERE.parent / 'tests' / 'model'))
from rod_reference import ReferenceRodSolver  # noqa: E402, I100
from timing import machine, median_time  # noqa: E402

from fpc_gripper.model import ActuatorDesign, RodSolver  # noqa: E402

RESULTS = _HERE / 'results' / 'rod.json'
#: bench_solver's loaded scene, and the brief's: (pressure [Pa], tip force [N]).
SCENES = {'loaded (bench_solver)': (100e3, (0.0, 0.3)), 'loaded f0': (55.2e3, (0.3, 0.0))}
TARGET_S = 1e-3


def run(repeats):
    """Time both implementations on every scene, interleaved in one process."""
    design = ActuatorDesign.paper(prestrain=0.25)
    solvers = {'compiled': RodSolver(design), 'numpy': ReferenceRodSolver(design)}
    rows = {}
    for name, (pressure, force) in SCENES.items():
        row = {'pressure_pa': pressure, 'tip_force_n': list(force)}
        results = {}
        for key, solver in solvers.items():
            cold = solver.solve(pressure, force)
            warm = solver.solve(pressure + 1e3, force, initial=solver.solve(pressure, force))
            base = solver.solve(pressure, force)
            results[key] = cold
            row[key] = {
                'cold_s': median_time(lambda: solver.solve(pressure, force), repeats),
                'warm_s': median_time(
                    lambda: solver.solve(pressure + 1e3, force, initial=base), repeats),
                'cold_iterations': cold.iterations, 'warm_iterations': warm.iterations,
                'success': bool(cold.success and warm.success),
                'tip_m': cold.tip.tolist(),
            }
        got, want = results['compiled'], results['numpy']
        row['tip_deviation_m'] = float(np.abs(got.tip - want.tip).max())
        row['points_deviation_m'] = float(np.abs(got.points - want.points).max())
        row['speedup_cold'] = row['numpy']['cold_s'] / row['compiled']['cold_s']
        rows[name] = row
    kx = {}
    for key, solver in solvers.items():
        result = solver.rigidity(0.0)
        kx[key] = {'kx_s': median_time(lambda: solver.rigidity(0.0), max(5, repeats // 4)),
                   'kx_value': result.value, 'iterations': result.iterations}
    return rows, kx


def main(argv=None):
    """Run the comparison, print it and write bench/results/rod.json."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--repeats', type=int, default=50)
    parser.add_argument('--output', type=pathlib.Path, default=RESULTS)
    args = parser.parse_args(argv)
    rows, kx = run(args.repeats)
    print('scene                    impl       cold [ms]  warm [ms]  iterations (cold, warm)')
    for name, row in rows.items():
        for key in ('numpy', 'compiled'):
            r = row[key]
            print(f'{name:24s} {key:9s} {1e3 * r["cold_s"]:9.3f}  {1e3 * r["warm_s"]:9.3f}'
                  f'   {r["cold_iterations"]:3d} {r["warm_iterations"]:3d}')
        print(f'{"":24s} speed-up {row["speedup_cold"]:.1f}x, tip deviation '
              f'{row["tip_deviation_m"]:.1e} m, samples {row["points_deviation_m"]:.1e} m')
    for key, r in kx.items():
        print(f'K_x {key:9s} {1e3 * r["kx_s"]:.3f} ms  {r["kx_value"]:.9e} N m^2  '
              f'{r["iterations"]} iterations')
    cold = rows['loaded (bench_solver)']['compiled']['cold_s']
    met = cold <= TARGET_S
    print(f'target: loaded cold solve <= {1e3 * TARGET_S:g} ms: {1e3 * cold:.3f} ms, '
          f'{"met" if met else "not met"}')
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps({'machine': machine(), 'repeats': args.repeats,
                                       'scenes': rows, 'kx': kx, 'target_s': TARGET_S,
                                       'target_met': met}, indent=2) + '\n')


if __name__ == '__main__':
    main()
