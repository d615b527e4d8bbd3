"""
The calibration's synthetic case: its recovery table, its speed, and docs/calibration_report.png.

Run by hand from the repository root:

    .venv/bin/python bench/bench_calibration.py [--repeats 5]

Builds the tests' synthetic measurements (tests/calibration/synthetic.py: the rod's
markers and K_x of a finger whose prestrain, moduli and k_p differ from the base design),
fits prestrain, cl_modulus, fl_modulus and pressure_work_factor, and prints and writes to
bench/results/calibration.json: truth, estimate and standard error of every parameter, the
warnings, the median wall and CPU time of the whole fit, and, in the same run, the median
time of one residual evaluation, of one exact Jacobian (sensitivities by the implicit
function theorem) and of a forward-difference Jacobian of the same residuals. The report
figure of the fit goes to docs/calibration_report.png.
"""

import argparse
import json
import os
import pathlib
import shutil
import sys
import tempfile
import time

# One BLAS thread (set before numpy loads), as the other benchmarks.
for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')

import numpy as np  # noqa: E402
from scipy.optimize._numdiff import approx_derivative  # noqa: E402

_HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(_HERE))
# The synthetic truth lives with the tests.
sys.path.insert(0, str(_HERE.parent / 'tests' / 'calibration'))
import synthetic  # noqa: E402, I100
from timing import machine, median_time  # noqa: E402

from fpc_gripper.calibration import (calibrate, FitParameters, read_loading,  # noqa: E402
                                     read_markers, write_outputs)
from fpc_gripper.calibration.fit import _Problem, FIT_SEGMENTS  # noqa: E402
from fpc_gripper.model import ActuatorDesign  # noqa: E402

RESULTS = _HERE / 'results' / 'calibration.json'
FIGURE = _HERE.parent / 'docs' / 'calibration_report.png'
FIT = ('prestrain', 'cl_modulus', 'fl_modulus', 'pressure_work_factor')


def run(repeats, figure):
    """Fit the synthetic case `repeats` times; return the figures of the benchmark."""
    base = ActuatorDesign.paper(prestrain=0.25)
    truth = synthetic.truth_design(base)
    rows, loading, clean = synthetic.measurements(truth)
    force_noise = synthetic.FORCE_NOISE * float(np.mean(clean['forces']))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        markers = read_markers(synthetic.write_csv(
            tmp / 'markers.csv', ('pressure_pa', 'marker', 's_m', 'x_m', 'z_m'), rows), base)
        loads = read_loading(synthetic.write_csv(
            tmp / 'loading.csv', ('pressure_pa', 'axis', 'displacement_m', 'force_n'),
            loading), base)

        def fit():
            return calibrate(base, markers=markers, loading=loads, fit=FIT,
                             marker_noise=synthetic.MARKER_NOISE, force_noise=force_noise)

        result = fit()
        wall, cpu = [], []
        for _ in range(repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            fit()
            wall.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        write_outputs(result, tmp / 'calibrated')
        figure.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(tmp / 'calibrated' / 'report.png', figure)
    params = FitParameters(base, FIT)
    noise = {'markers': synthetic.MARKER_NOISE, 'loading': force_noise}
    problem = _Problem(params, markers, loads, None, noise, FIT_SEGMENTS)
    u = np.concatenate([params.initial / params.scale, [0.3, 0.1, -0.1]])
    # Each evaluation at a fresh point: the problem keeps the last point's solves.
    shift = iter(np.arange(1, 10 ** 6) * 1e-9)
    residual = median_time(lambda: problem.residuals(u + next(shift)), repeats=20)
    exact = median_time(lambda: problem.jacobian(u + next(shift)), repeats=20)
    difference = median_time(lambda: approx_derivative(problem.residuals, u + next(shift),
                                                       method='2-point'), repeats=5)
    values = {'prestrain': truth.prestrain, 'cl_modulus': truth.constraining_layer.E1,
              'fl_modulus': truth.fluidic_layer.E1,
              'pressure_work_factor': truth.pressure_work_factor}
    return {
        'table': {name: {'truth': values[name], 'estimate': result.estimates[name],
                         'stderr': result.stderr[name]} for name in FIT},
        'frame': result.frame, 'frame_truth': {'rotation': synthetic.ROTATION,
                                               'offset': list(synthetic.OFFSET)},
        'warnings': result.warnings, 'nfev': result.nfev, 'njev': result.njev,
        'fit_wall_s': float(np.median(wall)), 'fit_cpu_s': float(np.median(cpu)),
        'residuals_s': residual, 'exact_jacobian_s': exact, 'difference_jacobian_s': difference,
    }


def main(argv=None):
    """Run the synthetic case, print it and write bench/results/calibration.json."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--output', type=pathlib.Path, default=RESULTS)
    parser.add_argument('--figure', type=pathlib.Path, default=FIGURE)
    args = parser.parse_args(argv)
    out = run(args.repeats, args.figure)
    print(f'{"parameter":22s} {"truth":>12s} {"estimate":>12s} {"stderr":>10s}')
    for name, row in out['table'].items():
        print(f'{name:22s} {row["truth"]:12.6g} {row["estimate"]:12.6g} {row["stderr"]:10.3g}')
    for warning in out['warnings']:
        print('warning:', warning)
    print(f'fit: {out["nfev"]} residual and {out["njev"]} Jacobian evaluations, median '
          f'{out["fit_wall_s"]:.3f} s wall, {out["fit_cpu_s"]:.3f} s CPU')
    print(f'one residual evaluation {1e3 * out["residuals_s"]:.1f} ms, exact Jacobian '
          f'{1e3 * out["exact_jacobian_s"]:.1f} ms, forward differences '
          f'{1e3 * out["difference_jacobian_s"]:.1f} ms '
          f'({out["difference_jacobian_s"] / out["exact_jacobian_s"]:.1f}x the exact one)')
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps({'machine': machine(), 'repeats': args.repeats, **out},
                                      indent=2) + '\n')
    print(f'wrote {args.output} and {args.figure}')


if __name__ == '__main__':
    main()
