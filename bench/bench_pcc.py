"""
Accuracy and speed of the PCC rod (piecewise-constant strain) against the geometrically exact rod.

Run by hand from the repository root:

    .venv/bin/python bench/bench_pcc.py [--quick] [--skip-convergence] [--skip-compile]

Prints, and writes to bench/results/pcc.json: the largest tip error against RodSolver
over the ladder's scenes (bench_ladder.scenes: prestrain 0.15/0.25/0.40, 0-400 kPa,
unloaded and tip loads of +-0.5 and +-1 N along X and Z) for N = 16 .. 256 with the
observed order, the smallest N whose worst error is <= 0.05 mm; median solve times
for N = 24, 32, 64 (cold, and warm from the solution 1 kPa lower; unloaded and
loaded, at prestrain 0.40 / 200 kPa and for the default finger, 0.25 / 100 kPa) and of
K_x, compiled (PCCSolver) against the numpy reference of the tests
(tests/model/pcc_reference.py, the code before compilation) and RodSolver in the same
run; and the compile cost of the PCC kernels (first ever, cache cleared, and per
process with a warm cache).
"""

import argparse
from importlib import metadata
import json
import os
import pathlib
import statistics
import sys

# One BLAS thread (set before numpy loads), as the other benchmarks.
for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')

import numpy as np  # noqa: E402

_HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(_HERE))
# The numpy reference (the code before the kernels) lives with the tests.
sys.path.insert(0, str(_HERE.parent / 'tests' / 'model'))
from bench_ladder import PRESTRAINS, scenes  # noqa: E402, I100
from pcc_reference import ReferencePCCSolver  # noqa: E402
from timing import machine, median_time, numba_cache_files, run_process  # noqa: E402

from fpc_gripper.model import ActuatorDesign, RodSolver  # noqa: E402
from fpc_gripper.model.discretisations.pcc import PCCSolver  # noqa: E402
from fpc_gripper.model.kernels import pcc as pcc_kernels  # noqa: E402

RESULTS = pathlib.Path(__file__).resolve().parent / 'results' / 'pcc.json'
N_VALUES = (16, 32, 64, 128, 256)
TOLERANCE = 5e-5                     # [m]
TIMING_N = (24, 32, 64)
TIMING_SCENES = {'unloaded': (0.40, 200e3, (0.0, 0.0)), 'loaded': (0.40, 200e3, (0.0, 1.0)),
                 'default_unloaded': (0.25, 100e3, (0.0, 0.0)),
                 'default_loaded': (0.25, 100e3, (0.0, 1.0))}
#: K_x of the default finger (prestrain 0.25, 0 kPa, 10 mm along +X), as bench_solver.
RIGIDITY_SCENE = (0.25, 0.0)
#: Issue targets for the default model [s] (set for CCM8).
TARGETS = {'warm_loaded_s': 100e-6, 'cold_loaded_s': 400e-6, 'kx_s': 150e-6}
# One process that solves as a node would: unloaded and loaded, warm, K_x, a buckling
# solve (indefinite steps); every kernel runs once.
FIRST_CALLS = """
import time
t0 = time.perf_counter()
from fpc_gripper.model import ActuatorDesign
from fpc_gripper.model.discretisations.pcc import PCCSolver
t1 = time.perf_counter()
s = PCCSolver(ActuatorDesign.paper(0.25), 24)
t2 = time.perf_counter()
r = s.solve(1e5, (0.0, 1.0))
t3 = time.perf_counter()
s.solve(1e5 + 1e3, (0.0, 1.0), initial=r)
s.rigidity(0.0)
s.solve(2e5, (-20.0, 0.0))
t4 = time.perf_counter()
r = s.solve(1e5, (0.0, 1.0))
t5 = time.perf_counter()
print(t1 - t0, t3 - t2, t4 - t2, t5 - t4)
"""


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
    """
    Median solve times [s]: compiled PCC, its numpy reference and the rod, cold and warm.

    Warm starts from the solution 1 kPa lower, as a controller stepping the pressure.
    """
    out = {}
    for name, (eps0, p, f) in TIMING_SCENES.items():
        design = ActuatorDesign.paper(eps0)
        models = []
        for n in TIMING_N:
            models += [(f'pcc{n}', PCCSolver(design, n)),
                       (f'pcc{n}_numpy', ReferencePCCSolver(design, n))]
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


def rigidity_times(repeats):
    """Median K_x time [s] (a cold unloaded solve, then displacement control), as timings."""
    eps0, p = RIGIDITY_SCENE
    design = ActuatorDesign.paper(eps0)
    out = {}
    for n in TIMING_N:
        for label, solver in ((f'pcc{n}', PCCSolver(design, n)),
                              (f'pcc{n}_numpy', ReferencePCCSolver(design, n))):
            result = solver.rigidity(p)
            assert result.success, result.message
            out[label] = {'kx_s': median_time(lambda s=solver: s.rigidity(p), repeats),
                          'kx_value': result.value, 'iterations': result.iterations}
    return out


def _cache_files():
    return numba_cache_files(pcc_kernels.energy_kernel, 'pcc_kernels')


def compile_costs(warm_runs):
    """
    First-ever compile (cache cleared) and a new process with a warm cache [s].

    `first_solve_s` is the first solve of a process (kernels compiled or loaded),
    `first_calls_s` that and every other kernel's first call, `steady_solve_s` the same
    solve once all are loaded; `import_s` imports the model (numpy, scipy, numba).
    """
    removed = _cache_files()
    for path in removed:
        path.unlink()
    cold_wall, cold = run_process(FIRST_CALLS)
    written = len(_cache_files())
    warm = [run_process(FIRST_CALLS) for _ in range(warm_runs)]
    # The interpreter with numpy and scipy, without numba or the model.
    baseline = [run_process('import numpy, scipy.linalg')[0] for _ in range(warm_runs)]
    numba_import = [run_process('import numba')[0] for _ in range(warm_runs)]

    def median(k):
        return statistics.median(w[1][k] for w in warm)
    return {
        'cache_files_removed': len(removed), 'cache_files_written': written,
        'cold_process_s': cold_wall, 'cold_import_s': cold[0], 'cold_first_solve_s': cold[1],
        'cold_first_calls_s': cold[2],
        'warm_process_s': statistics.median(w[0] for w in warm), 'warm_import_s': median(0),
        'warm_first_solve_s': median(1), 'warm_first_calls_s': median(2),
        'steady_solve_s': median(3),
        'numpy_scipy_process_s': statistics.median(baseline),
        'numba_import_process_s': statistics.median(numba_import),
    }


def main(argv=None):
    """Run the study, print it and write bench/results/pcc.json."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--quick', action='store_true', help='fewer scenes and repeats')
    parser.add_argument('--skip-convergence', action='store_true',
                        help='keep the convergence study of the results file; time only')
    parser.add_argument('--skip-compile', action='store_true',
                        help='keep the numba cache; no compile costs')
    args = parser.parse_args(argv)
    if args.skip_convergence:
        stored = json.loads(RESULTS.read_text())
        convergence = stored['convergence']
        n_needed, error = stored['smallest_n']['n_segments'], stored['smallest_n']['max_error']
    else:
        convergence = tip_errors(N_VALUES, args.quick)
        n_needed, error = smallest_n(TOLERANCE, args.quick)
    print('N (asked -> used)  max tip error [m]  unloaded [m]  order  worst scene')
    for row in convergence:
        print(f"{row['requested']:4d} -> {row['n_segments']:4d}      {row['max_error']:.3e}"
              f"        {row['max_error_unloaded']:.1e}      {row.get('order', float('nan')):.2f}"
              f"   {row['worst_scene']}")
    print(f'smallest N with worst tip error <= {TOLERANCE:g} m: {n_needed} ({error:.3e} m)')
    repeats = 20 if args.quick else 200
    times = timings(repeats)
    print('scene/model                  cold [us]  warm [us]  iterations (cold, warm)  unknowns')
    for key, row in times.items():
        print(f"{key:28s} {1e6 * row['cold_s']:9.1f}  {1e6 * row['warm_s']:9.1f}   "
              f"{row['cold_iterations']:3d} {row['warm_iterations']:3d}"
              f"                 {row['unknowns']}")
    kx = rigidity_times(max(5, repeats // 4))
    print(f'K_x at prestrain {RIGIDITY_SCENE[0]}, {RIGIDITY_SCENE[1] / 1e3:g} kPa:')
    for key, row in kx.items():
        print(f"{key:12s} {1e6 * row['kx_s']:9.1f} us  K_x {row['kx_value']:.6e} N m^2  "
              f"{row['iterations']} iterations")
    default = min(TIMING_N, key=lambda n: abs(n - n_needed))
    achieved = {'n_segments': default,
                'warm_loaded_s': times[f'default_loaded/pcc{default}']['warm_s'],
                'cold_loaded_s': times[f'default_loaded/pcc{default}']['cold_s'],
                'kx_s': kx[f'pcc{default}']['kx_s']}
    print(f'targets for the default model (PCC, N = {default}): ' + ', '.join(
        f'{k} {1e6 * achieved[k]:.0f} us (target {1e6 * v:.0f})' for k, v in TARGETS.items()))
    compiled = None if args.skip_compile else compile_costs(3 if args.quick else 5)
    if compiled:
        print('compile: first ever {cold_first_calls_s:.2f} s of calls (first solve '
              '{cold_first_solve_s:.2f} s; {cold_process_s:.2f} s process); warm cache '
              '{warm_first_calls_s:.3f} s of calls (first solve {warm_first_solve_s:.4f} s, '
              'then {steady_solve_s:.6f} s), import {warm_import_s:.3f} s ({warm_process_s:.2f}'
              ' s process; numpy and scipy alone {numpy_scipy_process_s:.2f} s, numba '
              '{numba_import_process_s:.2f} s)'.format(**compiled))
    report = {
        'convergence': convergence, 'tolerance': TOLERANCE,
        'smallest_n': {'n_segments': n_needed, 'max_error': error},
        'timing_scenes': {k: [v[0], v[1], list(v[2])] for k, v in TIMING_SCENES.items()},
        'timings': times, 'rigidity_scene': list(RIGIDITY_SCENE), 'rigidity': kx,
        'targets': TARGETS, 'achieved': achieved, 'compile': compiled,
        'machine': {**machine(), 'numba': metadata.version('numba'),
                    'llvmlite': metadata.version('llvmlite')},
        'quick': args.quick,
    }
    RESULTS.write_text(json.dumps(report, indent=1) + '\n')


if __name__ == '__main__':
    main()
