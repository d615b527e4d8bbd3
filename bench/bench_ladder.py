"""
Speed-accuracy study of the model ladder (arc, CCM-N paper/consistent, rod).

Run by hand from the repository root:

    .venv/bin/python bench/bench_ladder.py [--quick]

Writes docs/speed_accuracy.csv (one row per scene and model), docs/speed_accuracy.png
(median over scenes of the best-of-3 solve time against the largest tip error, Pareto
front marked),
bench/results/ladder.json (the summary) and fpc_gripper/data/error_model.json (the
measured error model that `fpc_gripper.model.selection.choose_model` reads).
The reference of every error is RodSolver (geometrically exact rod, exact rib
stations, tol 1e-10).
"""

import argparse
import csv
import json
import math
import os
import pathlib
import platform
import sys
import time

# One BLAS thread (set before numpy loads): the systems are small, and threaded BLAS on a
# shared machine makes the timings (and the solves) several times slower.
for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')

import numpy as np  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fpc_gripper.model import ActuatorDesign, ArcSolver, CCMSolver, PCCSolver, RodSolver  # noqa: E402,E501
from fpc_gripper.model.selection import aligned_edges  # noqa: E402

PRESTRAINS = (0.15, 0.25, 0.40)
N_VALUES = (1, 2, 3, 4, 6, 8, 12, 16, 32)
N_ALIGNED = (22, 32, 44, 64)
N_PCC = (22, 24, 32, 48, 64)
TURNING_BINS = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0, 6.5)   # upper edges [rad]
LOAD_BINS = (0.0, 0.5, 1.0)                                        # upper edges [N]
SAFETY = 1.5
COST_NOTE = ('unknowns x median Newton iterations of the cold solves of the ladder scenes; '
             "'time' is informative only and never used to choose")
#: Upper bound on the rod's own tip error, checked by p- and h-refinement [m].
ROD_ERROR = 1e-10


def scenes(quick=False):
    """Return the list of (kind, prestrain, pressure [Pa], (f0, p0) [N])."""
    out = []
    pressures = (0.0, 200e3, 400e3) if quick else (0.0, 100e3, 200e3, 300e3, 400e3)
    for eps0 in PRESTRAINS:
        for p in pressures:
            out.append(('unloaded', eps0, p, (0.0, 0.0)))
    loads = (-1.0, 1.0) if quick else (-1.0, -0.5, 0.5, 1.0)
    for eps0 in PRESTRAINS:
        for p in (0.0, 200e3, 400e3):
            for f in loads:
                out.append(('load_x', eps0, p, (f, 0.0)))
                out.append(('load_z', eps0, p, (0.0, f)))
    return out


def models():
    """Return (rung, N, factory) of every model on the ladder, the rod reference last."""
    out = [('arc', 1, lambda d: ArcSolver(d))]
    for n in N_VALUES:
        out.append(('ccm', n, lambda d, n=n: CCMSolver(d, n_segments=n)))
    for n in N_VALUES:
        out.append(('ccm_consistent', n,
                    lambda d, n=n: CCMSolver(d, n_segments=n, reconstruction='consistent')))
    for n in N_ALIGNED:
        out.append(('ccm_aligned', n,
                    lambda d, n=n: CCMSolver(d, segment_edges=aligned_edges(d, n),
                                             reconstruction='consistent')))
    for n in N_PCC:
        out.append(('pcc', n, lambda d, n=n: PCCSolver(d, n_segments=n)))
    out.append(('rod', 0, lambda d: RodSolver(d)))
    return out


def unknowns(result):
    """Return the number of unknowns of the discretisation behind a result."""
    if hasattr(result, 'q'):
        return int(result.q.size)
    state = result.state
    if isinstance(state, tuple):
        return int(sum(np.size(part) for part in state))
    return int(np.size(state))


def static_cost(rows):
    """
    Return the static cost of every model: unknowns x median cold Newton iterations.

    Both factors are properties of the discretisation and its solver, the same on every
    machine and in every run, so the model choice never depends on a measured time.
    """
    out = {}
    for r in rows:
        out.setdefault((r['rung'], r['n']), []).append((r['unknowns'], r['iterations']))
    return {key: {'unknowns': int(v[0][0]),
                  'iterations': float(np.median([i for _, i in v])),
                  'cost': float(v[0][0] * np.median([i for _, i in v]))}
            for key, v in out.items()}


def cost_rows(quick=False):
    """Cold solves of every model on every scene: unknowns and iterations, no timing."""
    rows = []
    designs = {e: ActuatorDesign.paper(e) for e in PRESTRAINS}
    for kind, eps0, p, f in scenes(quick):
        for rung, n, factory in models():
            res = factory(designs[eps0]).solve(p, f)
            rows.append({'rung': rung, 'n': n, 'unknowns': unknowns(res),
                         'iterations': res.iterations})
    return rows


def patch_costs(path=None):
    """Write the static costs into an existing error model (no re-measurement of errors)."""
    path = ROOT / 'fpc_gripper' / 'data' / 'error_model.json' if path is None else path
    model = json.loads(path.read_text())
    costs = static_cost(cost_rows())
    for entry in model['models']:
        entry.update(costs[(entry['rung'], entry['n_segments'])])
    model['cost'] = COST_NOTE
    path.write_text(json.dumps(model, indent=1))
    return model


def timed(fn, repeats):
    """Best wall time of fn() over repeats (robust on a shared machine), and its value."""
    times, value = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        value = fn()
        times.append(time.perf_counter() - t0)
    return float(np.min(times)), value


def kx_protocol(repeats):
    """Paper's K_x protocol (delta = 10 mm along +X) per model against the rod."""
    rows = []
    # Where the lever |Z_tip| is a few mm (nearly flat finger) K_x = f |Z|^3 / (3 delta) is
    # ill-conditioned and the 10 mm push along +X may not exist: keep the paper's range.
    for eps0, p in ((0.15, 0.0), (0.15, 55.2e3), (0.25, 0.0), (0.25, 55.2e3), (0.25, 100e3)):
        design = ActuatorDesign.paper(eps0)
        ref = RodSolver(design).rigidity(p)
        for rung, n, factory in models():
            solver = factory(design)
            t, k = timed(lambda: solver.rigidity(p), repeats)
            rows.append({'kind': 'kx', 'prestrain': eps0, 'pressure': p, 'rung': rung,
                         'n': n, 'time': t, 'kx': k.value, 'kx_ref': ref.value,
                         'kx_rel_error': abs(k.value / ref.value - 1.0)
                         if k.success and ref.success else math.nan,
                         'success': k.success})
    return rows


def pareto(points):
    """Return the indices of the Pareto-optimal (time, error) points, both minimised."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def error_model(rows, summary):
    """Bounds per (rung, N): max tip error in cumulative (load, turning) bins."""
    nl, nt = len(LOAD_BINS), len(TURNING_BINS)
    out = []
    for key, entry in summary.items():
        rung, n = key
        mine = [r for r in rows if r['rung'] == rung and r['n'] == n]
        grid = np.full((nl, nt), -1.0)
        bad = np.zeros((nl, nt), dtype=bool)
        for r in mine:
            lb = int(np.searchsorted(LOAD_BINS, r['load'] * (1 - 1e-12), side='left'))
            tb = int(np.searchsorted(TURNING_BINS, r['arc_turning'], side='left'))
            tb = min(tb, nt - 1)
            ok = r['success'] and r['valid'] and math.isfinite(r['tip_error'])
            grid[lb, tb] = max(grid[lb, tb], r['tip_error'] if ok else math.inf)
            bad[lb, tb] |= not (r['success'] and r['valid'])
        # Monotone envelope: a bin's bound covers every smaller load and turning.
        cum = np.maximum.accumulate(np.maximum.accumulate(grid, axis=0), axis=1)
        cbad = np.logical_or.accumulate(np.logical_or.accumulate(bad, axis=0), axis=1)
        # No bound beyond the largest measured turning of a load class.
        has = grid >= 0.0
        reach = np.flip(np.logical_or.accumulate(np.flip(has, axis=1), axis=1), axis=1)
        reach = np.flip(np.logical_or.accumulate(np.flip(reach, axis=0), axis=0), axis=0)
        bound = [[(float(cum[i, j]) if reach[i, j] and cum[i, j] >= 0.0
                   and math.isfinite(cum[i, j]) else None) for j in range(nt)]
                 for i in range(nl)]
        out.append({'rung': rung, 'n_segments': n, 'time': entry['time_median'],
                    'unknowns': entry['unknowns'], 'iterations': entry['iterations'],
                    'cost': entry['cost'], 'bound': bound, 'invalid': cbad.tolist()})
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--quick', action='store_true', help='fewer scenes and repeats')
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--costs-only', action='store_true',
                        help='only (re)write the static costs into the shipped error model')
    args = parser.parse_args(argv)
    if args.costs_only:
        patch_costs()
        return
    repeats = 1 if args.quick else args.repeats
    start = time.perf_counter()
    rows = []
    designs = {e: ActuatorDesign.paper(e) for e in PRESTRAINS}
    for sid, (kind, eps0, p, f) in enumerate(scenes(args.quick)):
        design = designs[eps0]
        ref = RodSolver(design).solve(p, f)
        arc_turning = abs(float(ArcSolver(design).solve(p, f).beta[0]))
        for rung, n, factory in models():
            solver = factory(design)
            t, res = timed(lambda: solver.solve(p, f), repeats)
            ok = res.success and ref.success
            rows.append({
                'scene': sid, 'kind': kind, 'prestrain': eps0, 'pressure': p,
                'f0': f[0], 'p0': f[1], 'load': math.hypot(*f), 'rung': rung, 'n': n,
                'time': t, 'success': bool(res.success), 'valid': bool(res.valid),
                'unknowns': unknowns(res), 'iterations': res.iterations,
                'tip_error': float(np.linalg.norm(res.tip - ref.tip)) if ok else math.nan,
                'curvature_error': abs(res.curvature - ref.curvature) if ok else math.nan,
                'rod_turning': abs(float(ref.tangent[-1])), 'arc_turning': arc_turning,
                'rod_curvature': ref.curvature, 'curvature': res.curvature,
            })
    summary = {}
    for rung, n, _ in models():
        mine = [r for r in rows if r['rung'] == rung and r['n'] == n]
        tip = np.array([r['tip_error'] for r in mine])
        unl = np.array([r['curvature_error'] for r in mine if r['kind'] == 'unloaded'])
        summary[(rung, n)] = {
            'time_median': float(np.median([r['time'] for r in mine])),
            'tip_error_max': float(np.nanmax(tip)) if np.isfinite(tip).any() else math.nan,
            'tip_error_median': float(np.nanmedian(tip)),
            'curvature_error_max_unloaded': float(np.nanmax(unl)),
            'failed': int(sum(not r['success'] for r in mine)),
            'invalid': int(sum(r['success'] and not r['valid'] for r in mine)),
        }
    for key, cost in static_cost(rows).items():
        summary[key].update(cost)
    kx_rows = kx_protocol(repeats)
    for (rung, n), entry in summary.items():
        rel = [r['kx_rel_error'] for r in kx_rows if r['rung'] == rung and r['n'] == n]
        entry['kx_rel_error_max'] = float(np.nanmax(rel))
    elapsed = time.perf_counter() - start

    # The rod is the reference; its own error is its discretisation error, below
    # ROD_ERROR (degree and element refinement change its tip by < 1e-12 m).
    keys = list(summary)
    pts = [(summary[k]['time_median'],
            ROD_ERROR if k[0] == 'rod' else summary[k]['tip_error_max']) for k in keys]
    front = [keys[i] for i in pareto(pts)]
    for k in summary:
        summary[k]['pareto'] = k in front

    docs = ROOT / 'docs'
    docs.mkdir(exist_ok=True)
    fields = ['scene', 'kind', 'prestrain', 'pressure', 'f0', 'p0', 'load', 'rung', 'n',
              'time', 'success', 'valid', 'tip_error', 'curvature_error', 'rod_turning',
              'arc_turning', 'rod_curvature', 'curvature']
    with open(docs / 'speed_accuracy.csv', 'w', newline='') as fh:
        writer = csv.DictWriter(fh, fieldnames=fields + ['kx', 'kx_ref', 'kx_rel_error'],
                                extrasaction='ignore')
        writer.writeheader()
        for r in rows + kx_rows:
            writer.writerow(r)
    rod_time = summary[('rod', 0)]['time_median']
    result = {
        'machine': platform.platform(), 'python': platform.python_version(),
        'elapsed_s': elapsed, 'repeats': repeats, 'scenes': len(scenes(args.quick)),
        'baseline': 'rod (RodSolver, tol 1e-10) median solve time in the same run',
        'rod_time_median_s': rod_time,
        'models': [{'rung': k[0], 'n': k[1], **v, 'time_ratio_to_rod': v['time_median']
                    / rod_time} for k, v in summary.items()],
        'pareto': [{'rung': k[0], 'n': k[1], 'time_median': summary[k]['time_median'],
                    'tip_error_max': ROD_ERROR if k[0] == 'rod' else summary[k]['tip_error_max']}
                   for k in front],
    }
    (ROOT / 'bench' / 'results').mkdir(parents=True, exist_ok=True)
    (ROOT / 'bench' / 'results' / 'ladder.json').write_text(json.dumps(result, indent=1))
    model = {
        'version': 1,
        'reference': 'RodSolver, exact rib stations, tol 1e-10',
        'feature': 'turning |kappa L| of ArcSolver for the scene [rad]; tip-load magnitude [N]',
        'turning_bins': list(TURNING_BINS), 'load_bins': list(LOAD_BINS), 'safety': SAFETY,
        'ranges': {'prestrain': [min(PRESTRAINS), max(PRESTRAINS)], 'pressure': [0.0, 400e3],
                   'load': [0.0, max(LOAD_BINS)]},
        'cost': COST_NOTE,
        'models': error_model(rows, summary) + [{
            'rung': 'rod', 'n_segments': 0, 'time': rod_time, 'bound': None,
            'invalid': None,
            **{k: summary[('rod', 0)][k] for k in ('unknowns', 'iterations', 'cost')}}],
    }
    data = ROOT / 'fpc_gripper' / 'data'
    data.mkdir(exist_ok=True)
    (data / 'error_model.json').write_text(json.dumps(model, indent=1))
    plot(summary, front, docs / 'speed_accuracy.png')
    print(f'{len(rows)} solves + {len(kx_rows)} rigidities in {elapsed:.1f} s')
    print(f'{"rung":>15} {"N":>3} {"t_med [ms]":>10} {"tip max [mm]":>12} '
          f'{"kappa max [1/m]":>15} {"Kx rel":>8} {"fail":>4} {"inval":>5} pareto')
    for (rung, n), v in summary.items():
        print(f'{rung:>15} {n:>3} {1e3 * v["time_median"]:10.3f} '
              f'{1e3 * v["tip_error_max"]:12.4g} {v["curvature_error_max_unloaded"]:15.4g} '
              f'{v["kx_rel_error_max"]:8.3g} {v["failed"]:4d} {v["invalid"]:5d} '
              f'{"*" if v["pareto"] else ""}')


def plot(summary, front, path):
    """Log median time against log max tip error per model, the Pareto front joined."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7.5, 5.0))
    styles = {'arc': ('s', 'C3'), 'ccm': ('o', 'C0'), 'ccm_consistent': ('^', 'C2'),
              'ccm_aligned': ('D', 'C1'), 'pcc': ('P', 'C4'), 'rod': ('*', 'k')}
    labels = {'arc': 'arc (rung a)', 'ccm': 'CCM-N, paper reconstruction',
              'ccm_consistent': 'CCM-N, consistent reconstruction',
              'ccm_aligned': 'CCM-N, consistent, edges on rib edges',
              'pcc': 'PCC-N: exact arcs between section changes',
              'rod': 'rod (reference; own error < 1e-10 m)'}
    floor = ROD_ERROR
    for rung, (marker, color) in styles.items():
        keys = [k for k in summary if k[0] == rung]
        t = [summary[k]['time_median'] for k in keys]
        e = [max(summary[k]['tip_error_max'], floor) if rung != 'rod' else floor
             for k in keys]
        ax.loglog(t, e, marker, color=color, label=labels[rung], ms=7 if rung != 'rod' else 12)
        if rung.startswith('ccm'):
            for k, ti, ei in zip(keys, t, e):
                ax.annotate(str(k[1]), (ti, ei), textcoords='offset points', xytext=(4, 3),
                            fontsize=7, color=color)
    ft = [summary[k]['time_median'] for k in front]
    fe = [ROD_ERROR if k[0] == 'rod' else summary[k]['tip_error_max'] for k in front]
    ax.loglog(ft, fe, '-', color='0.4', lw=1, zorder=0, label='Pareto front')
    ax.loglog(ft, fe, 'o', mfc='none', mec='k', ms=12, zorder=0)
    ax.set_xlabel('median solve time [s]')
    ax.set_ylabel('largest tip-position error vs rod [m]')
    ax.set_title('Model ladder: speed vs accuracy (default finger, all scenes)')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=8, loc='lower left')
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


if __name__ == '__main__':
    main()
