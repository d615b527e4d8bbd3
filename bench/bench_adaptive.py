"""Scripted open/close/grasp session: adaptive model choice against fixed models and the rod."""

import argparse
import json
import pathlib
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from timing import machine  # noqa: E402

from fpc_gripper.model import ActuatorDesign, AdaptiveSolver, RodSolver  # noqa: E402
from fpc_gripper.model.pipeline import DEFAULT_TOLERANCE, finger_model, ModelSettings  # noqa: E402,E501

RESULTS = pathlib.Path(__file__).resolve().parent / 'results' / 'adaptive.json'


def session():
    """(phase, gauge pressure [Pa], tip force (f0, p0) [N]) of every step of the script."""
    steps = []
    for p in np.linspace(0.0, 300e3, 40):
        steps.append(('open', p, (0.0, 0.0)))
    for p in np.linspace(300e3, 95e3, 40):
        steps.append(('close', p, (0.0, 0.0)))
    for f in np.linspace(0.0, 0.5, 20):
        steps.append(('grasp', 95e3, (0.0, f)))
    for _ in range(20):
        steps.append(('hold', 95e3, (0.0, 0.5)))
    for p, f in zip(np.linspace(95e3, 300e3, 40), np.linspace(0.5, 0.0, 40)):
        steps.append(('release', p, (0.0, f)))
    return steps


def run_session(solver, steps):
    """Warm-started sweep as the model node runs it; returns (seconds, tips, labels)."""
    result = None
    tips, labels = [], []
    start = time.perf_counter()
    for _, p, f in steps:
        result = solver.solve(p, f, initial=result)
        if not result.success:
            raise RuntimeError(f'{type(solver).__name__} failed at {p} Pa, {f} N: '
                               f'{result.message}')
        tips.append(result.tip.copy())
        choice = getattr(result, 'model_choice', None)
        labels.append(f'{choice.rung} N={choice.n_segments}' if choice else '')
    return time.perf_counter() - start, np.array(tips), labels


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--tolerance', type=float, default=DEFAULT_TOLERANCE)
    parser.add_argument('--output', type=pathlib.Path, default=RESULTS)
    args = parser.parse_args(argv)
    design = ActuatorDesign.paper(prestrain=0.25)
    steps = session()
    _, reference, _ = run_session(RodSolver(design), steps)

    def fixed(rung, n):
        # finger_model shares one solver per settings; each run here builds its own.
        return finger_model.__wrapped__(design, ModelSettings(rung=rung, n_segments=n))

    methods = {
        f'adaptive (tolerance {args.tolerance * 1e3:g} mm)':
            lambda: AdaptiveSolver(design, tolerance=args.tolerance),
        'fixed CCM16 (paper)': lambda: fixed('ccm', 16),
        'fixed CCM8 (paper)': lambda: fixed('ccm', 8),
        'fixed aligned consistent CCM44': lambda: fixed('ccm_aligned', 44),
        'fixed PCC32': lambda: fixed('pcc', 32),
        'rod (reference)': lambda: RodSolver(design),
    }
    rows = []
    for name, build in methods.items():
        times = []
        for _ in range(args.repeats):
            # A fresh solver each run, so the adaptive choice cache starts empty too.
            seconds, tips, labels = run_session(build(), steps)
            times.append(seconds)
        errors = np.linalg.norm(tips - reference, axis=1)
        used = sorted(set(labels) - {''})
        rows.append({'method': name, 'session_s': statistics.median(times),
                     'per_step_ms': statistics.median(times) / len(steps) * 1e3,
                     'max_tip_error_m': float(errors.max()),
                     'models_used': used})
    base = {r['method']: r['session_s'] for r in rows}
    for r in rows:
        r['time_vs_ccm16'] = r['session_s'] / base['fixed CCM16 (paper)']
        r['time_vs_ccm44_aligned'] = r['session_s'] / base['fixed aligned consistent CCM44']
    print(f'{len(steps)} steps; tip errors against the geometrically exact rod')
    print(f'{"method":34} {"session ms":>10} {"per step ms":>11} {"vs CCM16":>8} '
          f'{"vs CCM44a":>9} {"max tip err mm":>14}  models')
    for r in rows:
        print(f'{r["method"]:34} {r["session_s"] * 1e3:10.1f} {r["per_step_ms"]:11.3f} '
              f'{r["time_vs_ccm16"]:8.2f} {r["time_vs_ccm44_aligned"]:9.2f} '
              f'{r["max_tip_error_m"] * 1e3:14.3f}  {", ".join(r["models_used"])}')
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps({'machine': machine(), 'steps': len(steps),
                                       'tolerance_m': args.tolerance, 'rows': rows}, indent=2))
    print(f'wrote {args.output}')


if __name__ == '__main__':
    main()
