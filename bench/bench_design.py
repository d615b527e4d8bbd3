"""Benchmark of design studies: sweep rows/s against a loop of single solves, Dask, figures."""

import argparse
import json
import logging
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from timing import machine  # noqa: E402

from fpc_gripper.design import figure, sweep  # noqa: E402
from fpc_gripper.design.grid import base_design, design_grid  # noqa: E402
from fpc_gripper.design.parametric import model_settings  # noqa: E402
from fpc_gripper.model import batch, selection  # noqa: E402
from fpc_gripper.model.pipeline import finger_model  # noqa: E402

RESULTS = pathlib.Path(__file__).resolve().parent / 'results' / 'design.json'
#: The issue's 4-parameter grid: 5 prestrains x 5 Cy x 5 h3a x 81 pressures = 10,125.
GRID = {'prestrain': np.linspace(0.15, 0.40, 5), 'Cy': np.linspace(0.022, 0.030, 5),
        'h3a': np.linspace(-0.0005, 0.0015, 5)}
PRESSURES = np.linspace(0.0, 400e3, 81)
#: Targets of the issue [scenes/s] on 2 cores, and per figure [s] with cached kernels.
TARGETS = {'rows_per_s': 50e3, 'rows_per_s_issue21': 30e3, 'rows_per_s_kx': 5e3,
           'figure_s': 5.0}


def _fresh():
    """Forget every built finger: each timed sweep builds its models as a user's first does."""
    finger_model.cache_clear()
    selection._arc_feature.cache_clear()


def _median(fn, repeats, cpu=None):
    """
    (median wall time [s], last result) of fn() over repeats, caches cleared before each.

    `cpu`, a list, receives the median process CPU time [s] (every thread's): on a shared
    machine it tells the work done where the wall time also tells the waiting.
    """
    samples, cpus, out = [], [], None
    for _ in range(repeats):
        _fresh()
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        samples.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    if cpu is not None:
        cpu.append(statistics.median(cpus))
    return statistics.median(samples), out


def loop_of_single_solves(model, kx):
    """
    Today's loop: every design's finger, every pressure solved alone, curvature and tip.

    The paper model is `CCMSolver(design, 8)` through the pipeline; each solve warm-starts
    from the previous pressure's result, as a hand-written loop would.
    """
    _, points = design_grid(base_design(), GRID)
    settings = model_settings(model)
    rows = []
    for point in points:
        solver = finger_model(point.design, settings)
        previous = None
        for pressure in PRESSURES:
            result = solver.solve(pressure, initial=previous)
            previous = result if result.success else None
            row = [result.curvature, *result.tip]
            if kx:
                row.append(solver.rigidity(pressure, 'x', 0.010, initial=result).value)
            rows.append(row)
    return np.array(rows)


class _Stages:
    """Wall time of what a sweep calls on its main thread, by wrapping it for one run [s]."""

    def __init__(self):
        from fpc_gripper.model import engine, selection
        self.targets = [(batch, 'finger_model', 'main thread: build models (finger_model)'),
                        (selection.AdaptiveSolver, 'choose_many', 'main thread: choose models'),
                        (engine, 'rigidity_batch', 'main thread: compiled K_x (rigidity_batch)')]
        self.spent = {}

    def _wrap(self, function, label):
        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                self.spent[label] = self.spent.get(label, 0.0) + time.perf_counter() - t0
        return timed

    def __enter__(self):
        self.saved = [(owner, name, getattr(owner, name)) for owner, name, _ in self.targets]
        for (owner, name, label), (_, _, function) in zip(self.targets, self.saved):
            setattr(owner, name, self._wrap(function, label))
        return self

    def __exit__(self, *exc):
        for owner, name, function in self.saved:
            setattr(owner, name, function)


def breakdown(model, kx, repeats):
    """
    Where a sweep's time goes: medians over `repeats` runs, caches cleared [s].

    The grid's compiled batches run on the batch threads while the main thread builds
    the next models, so their CPU is reported beside the main thread's stages, not in
    their sum: the main thread's wall by stage, what it spends waiting (wall less its
    CPU), and the CPU of the other threads (the compiled equilibria and circle fits).
    """
    runs = []
    for _ in range(repeats):
        _fresh()
        with _Stages() as stages:
            t0, c0, m0 = time.perf_counter(), time.process_time(), time.thread_time()
            sweep(GRID, PRESSURES, model=model, rigidity='x' if kx else False)
            wall = time.perf_counter() - t0
            cpu, main = time.process_time() - c0, time.thread_time() - m0
        run = dict(stages.spent)
        # The main thread's own time (its CPU) less its stages.
        run['main thread: the rest (bookkeeping, batches started, results, table)'] = \
            main - sum(stages.spent.values())
        run['main thread: waiting for the batch threads'] = wall - main
        run['total (wall)'] = wall
        run['batch threads, CPU: compiled equilibria and circle fits'] = cpu - main
        run['CPU, all threads'] = cpu
        runs.append(run)
    return {k: round(statistics.median(run[k] for run in runs), 4) for k in runs[0]}


def local_rows(repeats):
    """Sweep rows/s of the grid in this process, against the loop of single solves."""
    rows = {}
    count = PRESSURES.size * int(np.prod([len(v) for v in GRID.values()]))
    for model in ('default', 'paper'):
        for kx in (False, True):
            key = f'{model}{"_kx" if kx else ""}'
            sweep(GRID, PRESSURES, model=model, rigidity='x' if kx else False)  # warm-up
            cpu = []
            wall, frame = _median(lambda: sweep(GRID, PRESSURES, model=model,
                                                rigidity='x' if kx else False), repeats, cpu)
            loop_wall, loop = _median(lambda: loop_of_single_solves(model, kx), repeats, cpu)
            columns = ['curvature_per_m', 'tip_x_m', 'tip_z_m'] + (['kx_nm2'] if kx else [])
            deviation = float(np.nanmax(np.abs(frame[columns].to_numpy() - loop)
                                        / np.maximum(np.abs(loop), 1e-3)))
            rows[key] = {'scenes': count, 'wall_s': wall, 'rows_per_s': count / wall,
                         'loop_wall_s': loop_wall, 'loop_rows_per_s': count / loop_wall,
                         'speedup': loop_wall / wall, 'cpu_s': cpu[0], 'loop_cpu_s': cpu[1],
                         'ok_rows': int(frame['success'].sum()),
                         'max_rel_deviation_from_loop': deviation,
                         'breakdown': breakdown(model, kx, repeats)}
            print(f'{key}: {count / wall:.0f} rows/s ({wall:.2f} s, {cpu[0]:.2f} s CPU), loop '
                  f'of single solves {count / loop_wall:.0f} rows/s ({cpu[1]:.2f} s CPU), '
                  f'x{loop_wall / wall:.1f}; {rows[key]["breakdown"]}', flush=True)
    return rows


def dask_rows(repeats, local):
    """Time the grid on a 2-worker LocalCluster, with and without start-up, against local."""
    import distributed
    out = {}
    for kx in (False, True):
        key = f'default{"_kx" if kx else ""}'
        t0 = time.perf_counter()
        frame = sweep(GRID, PRESSURES, rigidity='x' if kx else False, scheduler='local:2')
        fresh = time.perf_counter() - t0
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, host='127.0.0.1',
                                      dashboard_address=':0',
                                      silence_logs=logging.CRITICAL) as cluster:
            address = cluster.scheduler_address
            sweep(GRID, PRESSURES, rigidity='x' if kx else False, scheduler=address)
            warm, again = _median(lambda: sweep(GRID, PRESSURES, rigidity='x' if kx else False,
                                                scheduler=address), repeats)
        reference = sweep(GRID, PRESSURES, rigidity='x' if kx else False)
        identical = bool(frame.equals(reference) and again.equals(reference))
        out[key] = {'wall_with_startup_s': fresh, 'wall_warm_cluster_s': warm,
                    'overhead_with_startup': fresh / local[key]['wall_s'],
                    'overhead_warm_cluster': warm / local[key]['wall_s'],
                    'rows_identical_to_local': identical}
        print(f'dask {key}: {fresh:.2f} s with cluster start-up, {warm:.2f} s on a running '
              f'cluster; local {local[key]["wall_s"]:.2f} s; identical: {identical}', flush=True)
    return out


def figures(repeats):
    """Each --figure as a fresh `fpc-design` process (kernels cached) and in this process."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for number in (4, 5, 7, 8, 9):
            cli = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                # --force: each repeat replaces the outputs of the one before.
                subprocess.run([sys.executable, '-m', 'fpc_gripper.design.cli', 'sweep',
                                '--figure', str(number), '--out', tmp, '--no-progress',
                                '--force'], check=True, capture_output=True, timeout=600)
                cli.append(time.perf_counter() - t0)
            warm, _ = _median(lambda: figure(number, tmp), repeats)
            out[str(number)] = {'cli_s': statistics.median(cli), 'in_process_s': warm}
            print(f'figure {number}: {statistics.median(cli):.2f} s as a command, '
                  f'{warm:.2f} s in a warm process', flush=True)
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--skip-dask', action='store_true')
    parser.add_argument('--skip-figures', action='store_true')
    parser.add_argument('--output', type=pathlib.Path, default=RESULTS)
    args = parser.parse_args(argv)
    import numba
    start = time.perf_counter()
    local = local_rows(args.repeats)
    dask = None if args.skip_dask else dask_rows(args.repeats, local)
    figs = {} if args.skip_figures else figures(args.repeats)
    meets = {'rows_per_s': local['default']['rows_per_s'] >= TARGETS['rows_per_s'],
             'rows_per_s_issue21': local['default']['rows_per_s']
             >= TARGETS['rows_per_s_issue21'],
             'rows_per_s_kx': local['default_kx']['rows_per_s'] >= TARGETS['rows_per_s_kx'],
             'figure_s': bool(figs) and all(f['cli_s'] <= TARGETS['figure_s']
                                            for f in figs.values())}
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps({
        'machine': machine(), 'numba_threads': numba.get_num_threads(),
        'grid': {k: list(map(float, v)) for k, v in GRID.items()},
        'pressures': [float(PRESSURES[0]), float(PRESSURES[-1]), int(PRESSURES.size)],
        'targets': TARGETS, 'meets': meets, 'local': local, 'dask': dask, 'figures': figs,
        'bench_wall_s': time.perf_counter() - start}, indent=2))
    print(f'targets met: {meets}; wrote {args.output}')


if __name__ == '__main__':
    main()
