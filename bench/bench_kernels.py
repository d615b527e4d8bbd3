"""Benchmark of the compiled CCM kernels against their numpy originals, and their compile cost."""

import argparse
from importlib import metadata
import json
import pathlib
import statistics
import sys
import timeit

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from timing import machine, numba_cache_files, run_process  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / 'tests' / 'model'))
import ccm_reference as reference  # noqa: E402, I100 (the numpy formulas the kernels replaced)
from fpc_gripper.model import ActuatorDesign, CCMSolver  # noqa: E402, I100, I201
from fpc_gripper.model.kernels import ccm as kernels, chain, linear  # noqa: E402, I100, I201

RESULTS = pathlib.Path(__file__).resolve().parent / 'results' / 'kernels.json'
PRESTRAIN, PRESSURE, N_SEGMENTS = 0.25, 100e3, 8
LOADINGS = {'unloaded': (0.0, 0.0), 'tip_load': (0.1, 0.2)}

# One process that calls every kernel once: the cost of a fresh node with kernels.py.
FIRST_CALLS = """
import time
t0 = time.perf_counter()
import numpy as np
from fpc_gripper.model import ActuatorDesign, CCMSolver
t1 = time.perf_counter()
from fpc_gripper.model import kernels as k
t2 = time.perf_counter()
s = CCMSolver(ActuatorDesign.paper(0.25), 8)
q = np.full((8, 4), 0.01)
loads = [(8, np.array([0.1, 0.2]))]
t3 = time.perf_counter()
k.segment_energy(q, s.segments, 0.25, s.design.emc_coefficients, 1e5)
_, g, h = k.segment_derivatives(q, s.segments, 0.25, s.design.emc_coefficients, 1e5)
k.load_energy(q, s.segments.lengths, loads)
_, _, dense = k.load_derivatives(q, s.segments.lengths, loads)
k.node_positions(q, s.segments.lengths)
k.end_rotation(q)
k.consistent_strain_map(q)
k.newton_step(g, h)
k.newton_step(g, dense + np.eye(32))
k.newton_step(g, -h)
k.newton_step(g, -dense)
t4 = time.perf_counter()
print(t1 - t0, t2 - t1, t4 - t3)
"""


def per_call(fn, repeats, target=0.02):
    """Median time per call of fn [s]: timeit loops of about `target` seconds, `repeats` times."""
    timer = timeit.Timer(fn)
    number, _ = timer.autorange()
    number = max(1, int(number * target / 0.2))
    return statistics.median(timer.repeat(repeats, number)) / number


def call_times(repeats):
    """Time numpy and numba in the same run for CCM8 at 100 kPa, with and without a tip load."""
    solver = CCMSolver(ActuatorDesign.paper(prestrain=PRESTRAIN), n_segments=N_SEGMENTS)
    seg, lengths = solver.segments, solver.segments.lengths
    params = (*solver._params, solver.pressure_coefficient * PRESSURE)
    out = {}
    for name, tip in LOADINGS.items():
        result = solver.solve(PRESSURE, tip)
        assert result.success, result.message
        q, loads = result.q, list(result.point_loads)
        _, grad, hess = solver.derivatives(q, PRESSURE, loads)
        pairs = {
            'segment_energy': (lambda: reference.segment_energy(q, seg, *params),
                               lambda: kernels.segment_energy(q, seg, *params)),
            'segment_derivatives': (lambda: reference.segment_derivatives(q, seg, *params),
                                    lambda: kernels.segment_derivatives(q, seg, *params)),
            'load_energy': (lambda: reference.load_energy(q, lengths, loads),
                            lambda: chain.load_energy(q, lengths, loads)),
            'load_derivatives': (lambda: reference.load_derivatives(q, lengths, loads),
                                 lambda: chain.load_derivatives(q, lengths, loads)),
            'node_positions': (lambda: reference.node_positions(q, lengths),
                               lambda: chain.node_positions(q, lengths)),
            'consistent_strain_map': (lambda: reference.consistent_strain_map(q),
                                      lambda: chain.consistent_strain_map(q)),
            'newton_step': (lambda: reference.newton_step(grad, hess),
                            lambda: linear.newton_step(grad, hess)),
        }
        rows = {}
        for key, (numpy_fn, numba_fn) in pairs.items():
            numba_fn()  # compiled (or loaded from the cache) before the clock runs
            numpy_s, numba_s = per_call(numpy_fn, repeats), per_call(numba_fn, repeats)
            rows[key] = {'numpy_s': numpy_s, 'numba_s': numba_s, 'speedup': numpy_s / numba_s}
        rows['newton_step']['hessian'] = 'blocks (8, 4, 4)' if hess.ndim == 3 else \
            f'dense {hess.shape}'
        out[name] = rows
    return out


def _cache_files():
    return numba_cache_files(kernels.segment_energy_kernel, 'kernels')


def compile_costs(warm_runs):
    """First-ever compile (cache cleared) and a new process with a warm cache [s]."""
    removed = _cache_files()
    for path in removed:
        path.unlink()
    cold_wall, (_, cold_import, cold_calls) = run_process(FIRST_CALLS)
    written = len(_cache_files())
    warm = [run_process(FIRST_CALLS) for _ in range(warm_runs)]
    # The same process without kernels: interpreter, numpy, scipy and the model.
    baseline = [run_process('import fpc_gripper.model')[0] for _ in range(warm_runs)]
    return {
        'cache_files_removed': len(removed),
        'cache_files_written': written,
        'cold_process_s': cold_wall,
        'cold_import_s': cold_import,
        'cold_first_calls_s': cold_calls,
        'warm_process_s': statistics.median(w[0] for w in warm),
        'warm_import_s': statistics.median(w[1][1] for w in warm),
        'warm_first_calls_s': statistics.median(w[1][2] for w in warm),
        'baseline_process_s': statistics.median(baseline),
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--repeats', type=int, default=15)
    parser.add_argument('--warm-runs', type=int, default=5)
    parser.add_argument('--skip-compile', action='store_true',
                        help='keep the numba cache; time only the calls')
    parser.add_argument('--output', type=pathlib.Path, default=RESULTS)
    args = parser.parse_args(argv)
    compiled = None if args.skip_compile else compile_costs(args.warm_runs)
    calls = call_times(args.repeats)
    print(f'CCM{N_SEGMENTS}, prestrain {PRESTRAIN}, {PRESSURE / 1e3:g} kPa: median per call')
    print(f'{"":>22} {"loading":>9} {"numpy us":>9} {"numba us":>9} {"speedup":>8}')
    for loading, rows in calls.items():
        for key, row in rows.items():
            print(f'{key:>22} {loading:>9} {row["numpy_s"] * 1e6:9.2f} '
                  f'{row["numba_s"] * 1e6:9.2f} {row["speedup"]:8.1f}')
    if compiled:
        print('compile: first ever {cold_first_calls_s:.2f} s of calls ({cold_process_s:.2f} s '
              'process), warm cache {warm_first_calls_s:.3f} s of calls, import '
              '{warm_import_s:.3f} s ({warm_process_s:.2f} s process; without kernels '
              '{baseline_process_s:.2f} s)'.format(**compiled))
    report = {'machine': {**machine(), 'numba': metadata.version('numba'),
                          'llvmlite': metadata.version('llvmlite')},
              'case': {'n_segments': N_SEGMENTS, 'prestrain': PRESTRAIN,
                       'pressure_pa': PRESSURE, 'loadings': LOADINGS},
              'calls': calls, 'compile': compiled}
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(report, indent=2))
    print(f'wrote {args.output}')


if __name__ == '__main__':
    main()
