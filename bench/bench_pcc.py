"""
Accuracy and speed of the PCC rod (piecewise-constant strain) against the geometrically exact rod.

Run by hand from the repository root:

    .venv/bin/python bench/bench_pcc.py [--quick]

Prints, and writes to bench/results/pcc.json: the largest tip error against RodSolver
over the ladder's scenes (bench_ladder.scenes: prestrain 0.15/0.25/0.40, 0-400 kPa,
unloaded and tip loads of +-0.5 and +-1 N along X and Z) for N = 16 .. 256 with the
observed order, the smallest N whose worst error is <= 0.05 mm, and median solve
times for N = 32, 64, 128 (cold, and warm from the solution 1 kPa lower; unloaded
and loaded) with RodSolver's in the same run.
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

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from bench_ladder import PRESTRAINS, scenes  # noqa: E402, I100
from timing import machine, median_time  # noqa: E402

from fpc_gripper.model import ActuatorDesign, RodSolver  # noqa: E402
from fpc_gripper.model.pcc import PCCSolver  # noqa: E402

RESULTS = pathlib.Path(__file__).resolve().parent / 'results' / 'pcc.json'
N_VALUES = (16, 32, 64, 128, 256)
TOLERANCE = 5e-5                     # [m]
TIMING_N = (32, 64, 128)
TIMING_SCENES = {'unloaded': (0.40, 200e3, (0.0, 0.0)), 'loaded': (0.40, 200e3, (0.0, 1.0))}


def tip_errors(n_values, quick=False):
    """Largest tip error over the scenes at every N [m], and the worst scene."""
    designs = {e: ActuatorDesign.paper(e) for e in PRESTRAINS}
    refs = {}
    for _, e, p, f in scenes(quick):
        ref = RodSolver(designs[e]).solve(p, f)
        assert ref.success, ref.message
        refs[e, p, f] = ref.tip
    out = []
    for n in n_values:
        solvers = {e: PCCSolver(designs[e], n) for e in PRESTRAINS}
        errors = {}
        for (e, p, f), tip in refs.items():
            res = solvers[e].solve(p, f)
            assert res.success, (n, e, p, f, res.message)
            errors[e, p, f] = float(np.linalg.norm(res.tip - tip))
        worst = max(errors, key=errors.get)
        unloaded = max(v for k, v in errors.items() if k[2] == (0.0, 0.0))
        out.append({'requested': n, 'n_segments': solvers[0.25].n_segments,
                    'max_error': errors[worst], 'max_error_unloaded': unloaded,
                    'worst_scene': {'prestrain': worst[0], 'pressure': worst[1],
                                    'tip_force': list(worst[2])}})
    for a, b in zip(out, out[1:]):
        b['order'] = float(np.log2(a['max_error'] / b['max_error'])
                           / np.log2(b['n_segments'] / a['n_segments']))
    return out


def smallest_n(tolerance, quick=False):
    """Smallest N whose worst tip error over the scenes is <= tolerance [m]."""
    n = 22
    while True:
        row = tip_errors((n,), quick)[0]
        if row['max_error'] <= tolerance:
            return n, row['max_error']
        n += 1


def timings(repeats):
    """Median solve times [s] of the PCC at TIMING_N and of the rod, cold and warm (+1 kPa)."""
    out = {}
    for name, (eps0, p, f) in TIMING_SCENES.items():
        design = ActuatorDesign.paper(eps0)
        models = [(f'pcc{n}', PCCSolver(design, n)) for n in TIMING_N]
        models.append(('rod', RodSolver(design)))
        for label, solver in models:
            start = solver.solve(p - 1e3, f)
            cold = solver.solve(p, f)
            warm = solver.solve(p, f, initial=start)
            out[f'{name}/{label}'] = {
                'cold_s': median_time(lambda s=solver: s.solve(p, f), repeats),
                'warm_s': median_time(lambda s=solver, w=start: s.solve(p, f, initial=w),
                                      repeats),
                'cold_iterations': cold.iterations, 'warm_iterations': warm.iterations,
                'unknowns': int(np.size(cold.state) if label != 'rod' else
                                sum(np.size(part) for part in cold.state)),
            }
    return out


def main(argv=None):
    """Run the study, print it and write bench/results/pcc.json."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--quick', action='store_true', help='fewer scenes and repeats')
    args = parser.parse_args(argv)
    convergence = tip_errors(N_VALUES, args.quick)
    print('N (asked -> used)  max tip error [m]  unloaded [m]  order  worst scene')
    for row in convergence:
        print(f"{row['requested']:4d} -> {row['n_segments']:4d}      {row['max_error']:.3e}"
              f"        {row['max_error_unloaded']:.1e}      {row.get('order', float('nan')):.2f}"
              f"   {row['worst_scene']}")
    n_needed, error = smallest_n(TOLERANCE, args.quick)
    print(f'smallest N with worst tip error <= {TOLERANCE:g} m: {n_needed} ({error:.3e} m)')
    times = timings(20 if args.quick else 200)
    print('scene/model        cold [ms]  warm [ms]  iterations (cold, warm)  unknowns')
    for key, row in times.items():
        print(f"{key:18s} {1e3 * row['cold_s']:8.3f}  {1e3 * row['warm_s']:8.3f}   "
              f"{row['cold_iterations']:3d} {row['warm_iterations']:3d}"
              f"                 {row['unknowns']}")
    RESULTS.write_text(json.dumps({
        'convergence': convergence, 'tolerance': TOLERANCE,
        'smallest_n': {'n_segments': n_needed, 'max_error': error},
        'timing_scenes': {k: [v[0], v[1], list(v[2])] for k, v in TIMING_SCENES.items()},
        'timings': times, 'machine': machine(), 'quick': args.quick,
    }, indent=1) + '\n')


if __name__ == '__main__':
    main()
