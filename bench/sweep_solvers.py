"""Seeded sweep of in-range scenes through every solver: none raises, successes converge."""

import argparse
import collections
import json
import pathlib
import statistics
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'tests' / 'model'))
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from equilibrium_checks import GRADIENT_TOLERANCE  # noqa: E402
from equilibrium_checks import independent_residual  # noqa: E402
from equilibrium_checks import random_scenes  # noqa: E402
from timing import machine  # noqa: E402

from fpc_gripper.model.pipeline import finger_model, model_label, ModelSettings  # noqa: E402

RESULTS = ROOT / 'bench' / 'results' / 'sweep_solvers.json'

#: The solvers of the sweep: the production path (default and paper settings) and each rung.
SOLVERS = {
    'adaptive (default)': lambda d: finger_model(d, ModelSettings()),
    'paper CCM8': lambda d: finger_model(d, ModelSettings(tolerance=0.0)),
    'arc': lambda d: finger_model(d, ModelSettings(rung='arc')),
    'pcc N=22': lambda d: finger_model(d, ModelSettings(rung='pcc', n_segments=22)),
    'rod': lambda d: finger_model(d, ModelSettings(rung='rod')),
}


def main():
    """Run the sweep; print a table and write bench/results/sweep_solvers.json."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--scenes', type=int, default=2000)
    parser.add_argument('--seed', type=int, default=20261202)
    args = parser.parse_args()
    scenes = random_scenes(args.seed, args.scenes)
    built = {}
    rows = {name: collections.Counter() for name in SOLVERS}
    times = {name: [] for name in SOLVERS}
    worst = dict.fromkeys(SOLVERS, 0.0)
    raised, unconverged = [], []
    for k, (design, pressure, force) in enumerate(scenes):
        for name, make in SOLVERS.items():
            key = (name, design.prestrain)
            if key not in built:
                built[key] = make(design)
            start = time.perf_counter()
            try:
                result = built[key].solve(pressure, force)
            except Exception as exc:  # noqa: BLE001 - what the sweep is looking for
                raised.append((k, name, f'{type(exc).__name__}: {exc}'))
                rows[name]['raised'] += 1
                continue
            times[name].append(time.perf_counter() - start)
            if not result.success:
                rows[name]['failed'] += 1
                continue
            rows[name]['success'] += 1
            residual = independent_residual(result)
            worst[name] = max(worst[name], residual)
            if residual > GRADIENT_TOLERANCE:
                unconverged.append((k, name, model_label(result), residual))
        if (k + 1) % 100 == 0:
            print(f'{k + 1} scenes', flush=True)
    summary = {}
    print(f'{"solver":20s} {"success":>7s} {"failed":>6s} {"raised":>6s} '
          f'{"worst residual":>14s} {"p50 ms":>7s} {"p99 ms":>7s} {"max s":>7s}')
    for name in SOLVERS:
        ts = sorted(times[name])
        summary[name] = {
            'success': rows[name]['success'], 'failed': rows[name]['failed'],
            'raised': rows[name]['raised'], 'worst_residual': worst[name],
            'p50_ms': 1e3 * statistics.median(ts), 'p99_ms': 1e3 * ts[int(0.99 * len(ts))],
            'max_s': ts[-1]}
        s = summary[name]
        print(f'{name:20s} {s["success"]:7d} {s["failed"]:6d} {s["raised"]:6d} '
              f'{s["worst_residual"]:14.2e} {s["p50_ms"]:7.2f} {s["p99_ms"]:7.2f} '
              f'{s["max_s"]:7.2f}')
    print(f'raised: {len(raised)}; successes above the residual tolerance '
          f'{GRADIENT_TOLERANCE:g}: {len(unconverged)}')
    RESULTS.write_text(json.dumps({
        'machine': machine(), 'seed': args.seed, 'scenes': args.scenes,
        'gradient_tolerance': GRADIENT_TOLERANCE, 'solvers': summary,
        'raised': raised[:50], 'unconverged': unconverged[:50]}, indent=1))
    return 1 if raised or unconverged else 0


if __name__ == '__main__':
    sys.exit(main())
