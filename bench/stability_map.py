"""
Stability map of the CCM solution methods over prestrain x pressure x tip load.

Run by hand from the repository root:

    .venv/bin/python bench/stability_map.py [--n-segments 4 8]

Methods, all on the same CCM-N potential (paper reconstruction) from the flat state:
plain Newton (full steps, no damping), damped Newton (the solver's line search
and step cap, no continuation), Newton with continuation (CCMSolver.solve, the
default), and scipy.optimize.minimize(method='BFGS') with the exact gradient.
Every point is classified as converged (stationary, stable, valid),
invalid (converged, but a segment breaks the small-rotation rule), unstable
(stationary but the Hessian is not positive definite), or failed, and compared
with RodSolver. Writes docs/stability_map.png, docs/stability_map.csv and
bench/results/stability_map.json.
"""

import argparse
import csv
import json
import math
import os
import pathlib
import sys
import time

for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')

import numpy as np  # noqa: E402
from scipy.optimize import minimize  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fpc_gripper.model import ActuatorDesign, CCMSolver, engine, RodSolver  # noqa: E402
from fpc_gripper.model.discretisations.ccm import SolverStatus  # noqa: E402
from fpc_gripper.model.discretisations.ccm_geometry import node_positions  # noqa: E402

PRESTRAINS = (0.05, 0.15, 0.25, 0.40, 0.60)
PRESSURES = (0.0, 100e3, 200e3, 300e3, 400e3, 500e3)
FORCES = (-2.0, -1.0, 0.0, 1.0, 2.0)
METHODS = ('plain_newton', 'damped_newton', 'continuation', 'scipy_bfgs')
#: BFGS stops on an absolute gradient; a point counts as converged when the relative
#: gradient is below this (the Newton methods reach the solver's gtol = 1e-10).
BFGS_RELATIVE_GTOL = 1e-8
#: Tip distance from the continuation result beyond which a method has found another
#: equilibrium of the same CCM potential [m].
BRANCH_GAP = 1e-6


def load_cases():
    """(axis, (f0, p0)) of every load: none, then -2..2 N along X and along Z."""
    out = [('none', (0.0, 0.0))]
    for f in FORCES:
        if f:
            out.append(('x', (f, 0.0)))
    for f in FORCES:
        if f:
            out.append(('z', (0.0, f)))
    return out


def _classify(solver, q, converged, pressure, loads):
    """Return (status, valid, relative gradient) of a final state."""
    _, grad, hess = solver.derivatives(q, pressure, loads)
    rel = float(np.abs(grad).max()) / solver.gradient_scale
    valid = bool(np.all(np.abs(2.0 * q[:, 3]) < 1.0))
    if not converged or not np.isfinite(rel):
        return 'failed', valid, rel
    if hess.ndim == 3:
        n = q.shape[0]
        dense = np.zeros((4 * n, 4 * n))
        for i in range(n):
            dense[4 * i:4 * i + 4, 4 * i:4 * i + 4] = hess[i]
        hess = dense
    try:
        np.linalg.cholesky(hess)
    except np.linalg.LinAlgError:
        return 'unstable', valid, rel
    return ('converged' if valid else 'invalid'), valid, rel


def plain_newton(solver, pressure, loads):
    """Full Newton steps from the flat state, no damping and no step cap."""
    q = np.zeros((solver.n_segments, 4))
    for it in range(1, solver.max_iterations + 1):
        _, grad, hess = solver.derivatives(q, pressure, loads)
        rel = float(np.abs(grad).max()) / solver.gradient_scale
        if not np.isfinite(rel):
            return q, False, it
        try:
            if hess.ndim == 3:
                step = -np.linalg.solve(hess, grad[:, :, None])[:, :, 0]
            else:
                step = -np.linalg.solve(hess, grad.ravel()).reshape(grad.shape)
        except np.linalg.LinAlgError:
            return q, False, it
        q = q + step
        if rel <= solver.gtol and float(np.abs(step).max()) <= solver.xtol:
            return q, True, it
        if not np.all(np.isfinite(q)) or np.abs(q).max() > 1e3:
            return q, False, it
    return q, False, solver.max_iterations


def damped_newton(solver, pressure, loads):
    """Run the engine's damped Newton from the flat state, without continuation."""
    out = engine.newton(solver.engine_problem, solver.flat(), pressure, loads, solver._options)
    return out.x, out.status in (SolverStatus.SUCCESS, SolverStatus.UNSTABLE), out.iterations


def continuation(solver, pressure, force):
    """CCMSolver.solve: damped Newton, then continuation in pressure and load."""
    result = solver.solve(pressure, force)
    return result.q, result.status in (SolverStatus.SUCCESS, SolverStatus.UNSTABLE), \
        result.iterations


def scipy_bfgs(solver, pressure, loads):
    """scipy.optimize.minimize(BFGS) on the same energy with the exact gradient."""
    n = solver.n_segments
    scale = solver.gradient_scale

    def fun(x):
        energy, grad, _ = solver.derivatives(x.reshape(n, 4), pressure, loads)
        return energy / scale, grad.ravel() / scale

    with np.errstate(all='ignore'):
        res = minimize(fun, np.zeros(4 * n), jac=True, method='BFGS',
                       options={'gtol': BFGS_RELATIVE_GTOL, 'maxiter': 5000})
    q = res.x.reshape(n, 4)
    _, grad, _ = solver.derivatives(q, pressure, loads)
    rel = float(np.abs(grad).max()) / scale
    return q, bool(np.isfinite(rel) and rel <= BFGS_RELATIVE_GTOL), int(res.nit)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--n-segments', type=int, nargs='+', default=[4, 8])
    args = parser.parse_args(argv)
    start = time.perf_counter()
    rows = []
    for n_seg, eps0 in ((n, e) for n in args.n_segments for e in PRESTRAINS):
        design = ActuatorDesign.paper(eps0)
        solver = CCMSolver(design, n_segments=n_seg)
        rod_solver = RodSolver(design)
        for pressure in PRESSURES:
            for axis, force in load_cases():
                rod = rod_solver.solve(pressure, force)
                loads = solver._loads(force, ())
                reference_tip = None
                for method in ('continuation',) + tuple(m for m in METHODS
                                                        if m != 'continuation'):
                    t0 = time.perf_counter()
                    if method == 'plain_newton':
                        q, ok, its = plain_newton(solver, pressure, loads)
                    elif method == 'damped_newton':
                        q, ok, its = damped_newton(solver, pressure, loads)
                    elif method == 'continuation':
                        q, ok, its = continuation(solver, pressure, force)
                    else:
                        q, ok, its = scipy_bfgs(solver, pressure, loads)
                    elapsed = time.perf_counter() - t0
                    status, valid, rel = _classify(solver, q, ok, pressure, loads)
                    tip_error, branch = math.nan, False
                    if status != 'failed' and np.all(np.isfinite(q)):
                        tip = node_positions(q, solver.segments.lengths)[0][-1]
                        if rod.success:
                            tip_error = float(np.linalg.norm(tip - rod.tip))
                        if method == 'continuation':
                            reference_tip = tip
                        elif reference_tip is not None:
                            branch = bool(np.linalg.norm(tip - reference_tip) > BRANCH_GAP)
                    rows.append({'n_segments': n_seg, 'prestrain': eps0,
                                 'pressure': pressure, 'axis': axis,
                                 'f0': force[0], 'p0': force[1], 'method': method,
                                 'status': status, 'valid': valid, 'iterations': its,
                                 'relative_gradient': rel, 'time': elapsed,
                                 'tip_error': tip_error,
                                 'other_branch': branch,
                                 'rod_success': rod.success})
    elapsed = time.perf_counter() - start
    docs = ROOT / 'docs'
    with open(docs / 'stability_map.csv', 'w', newline='') as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    summary = {}
    rows.sort(key=lambda r: (r['n_segments'], METHODS.index(r['method'])))
    for n_seg in args.n_segments:
        for method in METHODS:
            mine = [r for r in rows if r['method'] == method and r['n_segments'] == n_seg]
            counts = {s: sum(r['status'] == s for r in mine)
                      for s in ('converged', 'invalid', 'unstable', 'failed')}
            errs = [r['tip_error'] for r in mine if r['status'] == 'converged'
                    and math.isfinite(r['tip_error'])]
            summary[f'{method}/N{n_seg}'] = {
                'points': len(mine), **counts,
                'fraction_converged': counts['converged'] / len(mine),
                'fraction_stationary': (counts['converged'] + counts['invalid']) / len(mine),
                'other_equilibrium': sum(r['other_branch'] for r in mine),
                'median_iterations': float(np.median([r['iterations'] for r in mine])),
                'median_time_s': float(np.median([r['time'] for r in mine])),
                'median_tip_error_m': float(np.median(errs)) if errs else math.nan,
            }
    out = {'n_segments': args.n_segments, 'grid': {
        'prestrain': PRESTRAINS, 'pressure_pa': PRESSURES, 'force_n': FORCES},
        'rod_failed': sum(not r['rod_success'] for r in rows)
        // (len(METHODS) * len(args.n_segments)),
        'elapsed_s': elapsed, 'summary': summary}
    (ROOT / 'bench' / 'results').mkdir(parents=True, exist_ok=True)
    (ROOT / 'bench' / 'results' / 'stability_map.json').write_text(json.dumps(out, indent=1))
    plot(rows, docs / 'stability_map.png', args.n_segments)
    print(f'{len(rows)} solves in {elapsed:.1f} s; rod failed at {out["rod_failed"]} points')
    for method, s in summary.items():
        print(f'{method:>17}: converged {s["converged"]:3d} invalid {s["invalid"]:3d} '
              f'unstable {s["unstable"]:3d} failed {s["failed"]:3d} of {s["points"]} '
              f'({s["fraction_converged"]:.0%}), other equilibrium {s["other_equilibrium"]}, '
              f'median its {s["median_iterations"]:.0f}, '
              f'median tip error {1e3 * s["median_tip_error_m"]:.3g} mm')


def plot(rows, path, n_values):
    """Panels methods x N: load case (rows) against prestrain x pressure (columns)."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib.colors import ListedColormap
    import matplotlib.pyplot as plt
    codes = {'converged': 0, 'invalid': 1, 'unstable': 2, 'failed': 3}
    cmap = ListedColormap(['#4daf4a', '#ffbf00', '#984ea3', '#e41a1c'])
    cases = load_cases()
    fig, axes = plt.subplots(len(METHODS), len(n_values), figsize=(7 * len(n_values), 10.5),
                             sharex=True, sharey=True, squeeze=False)
    for col, n_seg in enumerate(n_values):
        for ax, method in zip(axes[:, col], METHODS):
            grid = np.full((len(cases), len(PRESTRAINS) * len(PRESSURES)), np.nan)
            branch = np.zeros_like(grid, dtype=bool)
            for r in rows:
                if r['method'] != method or r['n_segments'] != n_seg:
                    continue
                i = cases.index((r['axis'], (r['f0'], r['p0'])))
                j = PRESTRAINS.index(r['prestrain']) * len(PRESSURES) + \
                    PRESSURES.index(r['pressure'])
                grid[i, j] = codes[r['status']]
                branch[i, j] = r['other_branch']
            ax.imshow(grid, cmap=cmap, vmin=-0.5, vmax=3.5, aspect='auto',
                      interpolation='none')
            yy, xx = np.nonzero(branch)
            ax.plot(xx, yy, 'kx', ms=4)
            ax.set_yticks(range(len(cases)))
            ax.set_yticklabels([('0' if a == 'none' else f'{a.upper()} {f[0] + f[1]:+g} N')
                                for a, f in cases], fontsize=7)
            for k in range(1, len(PRESTRAINS)):
                ax.axvline(k * len(PRESSURES) - 0.5, color='k', lw=0.8)
            ax.set_title(f'CCM{n_seg}, {method.replace("_", " ")}: '
                         f'{np.mean(grid == 0):.0%} converged', fontsize=9)
        ticks = np.arange(len(PRESTRAINS) * len(PRESSURES))
        axes[-1, col].set_xticks(ticks)
        axes[-1, col].set_xticklabels([f'{int(p / 1e3)}' for _ in PRESTRAINS
                                       for p in PRESSURES], fontsize=5)
        axes[-1, col].set_xlabel('pressure [kPa], blocks of prestrain '
                                 + ', '.join(f'{e:g}' for e in PRESTRAINS), fontsize=8)
    handles = [plt.Rectangle((0, 0), 1, 1, color=cmap(k)) for k in range(4)]
    fig.legend(handles + [plt.Line2D([], [], ls='', marker='x', color='k')],
               list(codes) + ['other equilibrium than continuation'], loc='lower center',
               ncol=5, fontsize=8)
    fig.suptitle('CCM solution methods from the flat state (paper reconstruction)',
                 fontsize=11)
    fig.tight_layout(rect=(0, 0.03, 1, 0.98))
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == '__main__':
    main()
