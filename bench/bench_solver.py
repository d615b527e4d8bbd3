"""Benchmark of the CCM solver: cold solve, warm step and K_x against a naive BFGS baseline."""

import argparse
import json
import pathlib
import sys
import time

import numpy as np
from scipy.optimize import minimize

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from timing import machine, median_time  # noqa: E402

from fpc_gripper.model import ActuatorDesign, CCMSolver  # noqa: E402
from fpc_gripper.model.kinematics import node_positions, to_scaled  # noqa: E402

RESULTS = pathlib.Path(__file__).resolve().parent / 'results' / 'solver.json'
# Issue targets on a 2-core machine, CCM8 [s], and the speed-up over the baseline.
TARGETS = {'cold_s': 1e-3, 'warm_s': 0.3e-3, 'kx_s': 3e-3, 'speedup': 300.0}


def naive_solve(solver, pressure, scaled):
    """
    Minimise the same energy with scipy BFGS and finite-difference gradients, from flat.

    scaled=False works in the SI coefficients (b1, b3, c1, d) that the API exposes,
    with scipy's default gtol: what a user would write first. scaled=True hands BFGS
    the solver's own well-conditioned unknowns and a tight gtol: a generous baseline.
    Returns the result and the tip it implies.
    """
    n = solver.n_segments
    lengths = solver.segments.lengths
    if scaled:
        def unknowns(x):
            return x.reshape(n, 4)
        options = {'gtol': 1e-6 * solver.gradient_scale, 'maxiter': 20000}
    else:
        def unknowns(x):
            return to_scaled(x.reshape(n, 4), lengths)
        options = {'maxiter': 20000}

    def energy(x):
        return solver._total_energy(unknowns(x), pressure, [])

    res = minimize(energy, np.zeros(4 * n), method='BFGS', options=options)
    return res, node_positions(unknowns(res.x), lengths)[0][-1]


def run(ns, repeats):
    design = ActuatorDesign.paper(prestrain=0.25)
    rows = []
    for n in ns:
        solver = CCMSolver(design, n_segments=n)
        base = solver.solve(0.0)
        row = {
            'n_segments': n,
            'cold_iterations': base.iterations,
            'cold_s': median_time(lambda: solver.solve(0.0), repeats),
            'warm_s': median_time(lambda: solver.solve(1e3, initial=base), repeats),
            'warm_iterations': solver.solve(1e3, initial=base).iterations,
            'kx_s': median_time(lambda: solver.rigidity(0.0, 'x', 0.010), max(5, repeats // 4)),
            'kx_value': solver.rigidity(0.0, 'x', 0.010).value,
            'curvature': base.curvature,
        }
        naive_repeats = 3 if n <= 8 else 1
        for key, scaled in (('naive', False), ('naive_scaled', True)):
            times = []
            for _ in range(naive_repeats):
                t0 = time.perf_counter()
                res, tip = naive_solve(solver, 0.0, scaled)
                times.append(time.perf_counter() - t0)
            row[f'{key}_s'] = float(np.median(times))
            row[f'{key}_nfev'] = int(res.nfev)
            row[f'{key}_success'] = bool(res.success)
            row[f'{key}_tip_error_m'] = float(np.linalg.norm(tip - base.tip))
        row['speedup'] = row['naive_s'] / row['cold_s']
        row['speedup_scaled'] = row['naive_scaled_s'] / row['cold_s']
        rows.append(row)
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--repeats', type=int, default=200)
    parser.add_argument('--segments', type=int, nargs='*', default=[1, 2, 4, 8, 16])
    parser.add_argument('--output', type=pathlib.Path, default=RESULTS)
    args = parser.parse_args(argv)
    rows = run(args.segments, args.repeats)
    print(f'{"N":>3} {"cold ms":>8} {"it":>3} {"warm ms":>8} {"it":>3} {"Kx ms":>7} | '
          f'{"naive SI ms":>11} {"x":>6} {"tip err":>8} | {"naive scaled ms":>15} {"x":>5} '
          f'{"tip err":>8}')
    for r in rows:
        print(f'{r["n_segments"]:>3} {r["cold_s"] * 1e3:8.3f} {r["cold_iterations"]:>3} '
              f'{r["warm_s"] * 1e3:8.3f} {r["warm_iterations"]:>3} {r["kx_s"] * 1e3:7.3f} | '
              f'{r["naive_s"] * 1e3:11.1f} {r["speedup"]:6.0f} {r["naive_tip_error_m"]:8.1e} | '
              f'{r["naive_scaled_s"] * 1e3:15.1f} {r["speedup_scaled"]:5.0f} '
              f'{r["naive_scaled_tip_error_m"]:8.1e}')
    ccm8 = next((r for r in rows if r['n_segments'] == 8), None)
    verdict = {}
    if ccm8:
        verdict = {k: (ccm8[k] >= v if k == 'speedup' else ccm8[k] <= v)
                   for k, v in TARGETS.items()}
        print('CCM8 targets met:', verdict)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps({'machine': machine(), 'targets': TARGETS,
                                       'ccm8_meets': verdict, 'rows': rows}, indent=2))
    print(f'wrote {args.output}')


if __name__ == '__main__':
    main()
