"""Benchmark of the solvers: CCM-N, the default model and the rod, against naive BFGS."""

import argparse
import json
import pathlib
import sys
import time

import numba
import numpy as np
from scipy.optimize import minimize

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from timing import machine, median_time  # noqa: E402

from fpc_gripper.model import ActuatorDesign, batch, CCMSolver, RodSolver  # noqa: E402
from fpc_gripper.model.discretisations.ccm_geometry import node_positions, to_scaled  # noqa: E402
from fpc_gripper.model.pipeline import finger_model, ModelSettings  # noqa: E402

RESULTS = pathlib.Path(__file__).resolve().parent / 'results' / 'solver.json'
# Targets on a 2-core machine [s] (issue 21, "no speed lost": CCM8 warm 20 us, K_x 110 us,
# default loaded 40 us; the cold ones from "One equilibrium engine"), and the speed-up of
# CCM8 (cold) over the naive baseline measured in the same run.
TARGETS = {'cold_s': 60e-6, 'warm_s': 20e-6, 'kx_s': 110e-6, 'speedup': 5000.0}
DEFAULT_TARGETS = {'loaded_warm_s': 40e-6, 'loaded_cold_s': 400e-6, 'rod_s': 1e-3}
#: The loaded scene of the default-model rows: default finger, 100 kPa, p0 = 0.3 N.
LOADED = (100e3, (0.0, 0.3))
#: Batched throughput targets [solves/s] on 2 cores.
BATCH_TARGETS = {'ccm8_unloaded': 100e3, 'default_loaded': 20e3, 'kx_ccm8': 10e3}
#: Designs of the batches: the paper finger at ten prestrains.
BATCH_PRESTRAINS = np.linspace(0.15, 0.40, 10)


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
            # The targets time a result with the state and tip (outputs 'tip'); '_all' adds
            # the samples, energy and circle fit (outputs 'all', the default).
            'cold_s': median_time(lambda: solver.solve(0.0, outputs='tip'), repeats),
            'warm_s': median_time(lambda: solver.solve(1e3, initial=base, outputs='tip'),
                                  repeats),
            'warm_all_s': median_time(lambda: solver.solve(1e3, initial=base), repeats),
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


def run_default(repeats):
    """Median times of the default model (the finger pipeline) and of the rod."""
    design = ActuatorDesign.paper(prestrain=0.25)
    model = finger_model(design, ModelSettings())
    pressure, force = LOADED
    loaded = model.solve(pressure, force)
    unloaded = model.solve(pressure)
    rod = RodSolver(design)
    return {
        'scene': {'pressure_pa': pressure, 'tip_force_n': list(force)},
        'model': f'{loaded.model_choice.rung} N={loaded.model_choice.n_segments}',
        'loaded_cold_s': median_time(lambda: model.solve(pressure, force, outputs='tip'),
                                     repeats),
        'loaded_warm_s': median_time(
            lambda: model.solve(pressure + 1e3, force, initial=loaded, outputs='tip'), repeats),
        'loaded_warm_all_s': median_time(
            lambda: model.solve(pressure + 1e3, force, initial=loaded), repeats),
        'unloaded_cold_s': median_time(lambda: model.solve(pressure, outputs='tip'), repeats),
        'unloaded_warm_s': median_time(
            lambda: model.solve(pressure + 1e3, initial=unloaded, outputs='tip'), repeats),
        'kx_s': median_time(lambda: model.rigidity(0.0, 'x', 0.010), max(5, repeats // 4)),
        'rod_s': median_time(lambda: rod.solve(pressure, force, outputs='tip'),
                             max(5, repeats // 20)),
        'tip_error_m': float(np.linalg.norm(loaded.tip - rod.solve(pressure, force).tip)),
    }


def _batches():
    """Return the batched workloads: name -> (callable, scenes)."""
    designs = [ActuatorDesign.paper(prestrain=float(e)) for e in BATCH_PRESTRAINS]
    paper = ModelSettings(tolerance=0.0)
    unloaded = np.linspace(0.0, 300e3, 2000)
    loaded = np.linspace(0.0, 300e3, 500)
    kx = np.linspace(0.0, 80e3, 500)
    d = len(designs)
    return {
        'ccm8_unloaded': (lambda: batch.solve_grid(designs, unloaded, settings=paper),
                          d * unloaded.size),
        'default_loaded': (lambda: batch.solve_grid(designs, loaded, [LOADED[1]]),
                           d * loaded.size),
        'kx_ccm8': (lambda: batch.rigidity_grid(designs, kx, settings=paper), d * kx.size),
        'kx_default': (lambda: batch.rigidity_grid(designs, kx), d * kx.size),
    }


def _batch_equals_single(grid, settings, samples=60):
    """Return the largest relative tip deviation of batched scenes from single solves."""
    rng = np.random.default_rng(0)
    worst = 0.0
    for flat in rng.choice(grid.success.size, size=min(samples, grid.success.size),
                           replace=False):
        d, p, f = np.unravel_index(flat, grid.shape)
        single = finger_model(grid.designs[d], settings).solve(
            float(grid.pressures[p]), tuple(grid.tip_forces[f]))
        worst = max(worst, float(np.abs(grid.tip[d, p, f] - single.tip).max()
                                 / np.abs(single.tip).max()))
    return worst


def run_batch(repeats):
    """Measure the median throughput of the batched entry point on both cores and on one."""
    out = {'threads': numba.get_num_threads(), 'rows': {}}
    workloads = _batches()
    for name, (fn, scenes) in workloads.items():
        grid = fn()
        row = {'scenes': scenes, 'success': float(np.mean(grid.success))}
        row['wall_s'] = median_time(fn, repeats, warmup=1)
        row['per_s'] = scenes / row['wall_s']
        threads = numba.get_num_threads()
        numba.set_num_threads(1)
        try:
            row['one_thread_per_s'] = scenes / median_time(fn, max(1, repeats // 2), warmup=0)
        finally:
            numba.set_num_threads(threads)
        out['rows'][name] = row
    paper = ModelSettings(tolerance=0.0)
    designs = [ActuatorDesign.paper(prestrain=float(e)) for e in BATCH_PRESTRAINS]
    out['equal_single_rel'] = {
        'ccm8_unloaded': _batch_equals_single(
            batch.solve_grid(designs, np.linspace(0.0, 300e3, 40), settings=paper), paper),
        'default_loaded': _batch_equals_single(
            batch.solve_grid(designs, np.linspace(0.0, 300e3, 40),
                             [(0.0, 0.0), LOADED[1], (0.3, 0.0)]),
            ModelSettings()),
    }
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--repeats', type=int, default=200)
    parser.add_argument('--segments', type=int, nargs='*', default=[1, 2, 4, 8, 16])
    parser.add_argument('--batch-repeats', type=int, default=5)
    parser.add_argument('--output', type=pathlib.Path, default=RESULTS)
    args = parser.parse_args(argv)
    rows = run(args.segments, args.repeats)
    default = run_default(args.repeats)
    batches = run_batch(args.batch_repeats)
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
    print(f"default model ({default['model']}) at {LOADED[0]:g} Pa, tip force {LOADED[1]} N: "
          f"loaded cold {default['loaded_cold_s'] * 1e6:.0f} us, warm "
          f"{default['loaded_warm_s'] * 1e6:.0f} us; unloaded cold "
          f"{default['unloaded_cold_s'] * 1e6:.0f} us, warm "
          f"{default['unloaded_warm_s'] * 1e6:.0f} us; K_x {default['kx_s'] * 1e6:.0f} us; "
          f"rod {default['rod_s'] * 1e3:.2f} ms; tip vs rod {default['tip_error_m'] * 1e6:.1f} um")
    default_verdict = {k: default[k] <= v for k, v in DEFAULT_TARGETS.items()}
    print('default-model targets met:', default_verdict)
    print()
    print('| what | median | target | met |')
    print('|---|---|---|---|')
    if ccm8:
        for key, label in (('warm_s', "CCM8 warm step (+1 kPa), outputs 'tip'"),
                           ('cold_s', "CCM8 cold, outputs 'tip'"), ('kx_s', 'CCM8 K_x')):
            print(f'| {label} | {ccm8[key] * 1e6:.0f} µs | ≤ {TARGETS[key] * 1e6:.0f} µs | '
                  f'{"yes" if verdict[key] else "no"} |')
        print(f"| CCM8 warm step, outputs 'all' (samples, energy, circle fit) | "
              f"{ccm8['warm_all_s'] * 1e6:.0f} µs | — | — |")
    for key, label in (('loaded_warm_s', "default model, loaded, warm, outputs 'tip'"),
                       ('loaded_cold_s', "default model, loaded, cold, outputs 'tip'"),
                       ('rod_s', "`RodSolver`, loaded, outputs 'tip'")):
        print(f'| {label} | {default[key] * 1e6:.0f} µs | ≤ {DEFAULT_TARGETS[key] * 1e6:.0f} µs '
              f'| {"yes" if default_verdict[key] else "no"} |')
    print(f"| default model, loaded, warm, outputs 'all' | "
          f"{default['loaded_warm_all_s'] * 1e6:.0f} µs | — | — |")
    if ccm8:
        print(f'| CCM8 cold against naive BFGS (SI unknowns), same run | {ccm8["speedup"]:.0f}× '
              f'| ≥ {TARGETS["speedup"]:.0f}× | {"yes" if verdict["speedup"] else "no"} |')
    batch_verdict = {}
    for key, label in (('ccm8_unloaded', 'batched throughput, unloaded CCM8'),
                       ('default_loaded', 'batched throughput, default model, loaded'),
                       ('kx_ccm8', 'batched throughput, K_x (CCM8)'),
                       ('kx_default', 'batched throughput, K_x (default model)')):
        row = batches['rows'][key]
        target = BATCH_TARGETS.get(key)
        batch_verdict[key] = None if target is None else row['per_s'] >= target
        print(f'| {label} | {row["per_s"] / 1e3:.1f}k/s ({row["one_thread_per_s"] / 1e3:.1f}k/s '
              f'on 1 thread) | {"≥ %.0fk/s" % (target / 1e3) if target else "—"} | '
              f'{"—" if target is None else ("yes" if batch_verdict[key] else "no")} |')
    print('batched = single, largest relative tip deviation:', batches['equal_single_rel'])
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps({'machine': machine(), 'targets': TARGETS,
                                       'ccm8_meets': verdict, 'rows': rows,
                                       'default_targets': DEFAULT_TARGETS,
                                       'default': default,
                                       'default_meets': default_verdict,
                                       'batch_targets': BATCH_TARGETS, 'batch': batches,
                                       'batch_meets': batch_verdict}, indent=2))
    print(f'wrote {args.output}')


if __name__ == '__main__':
    main()
