"""Sweeps on Dask: a 2-worker LocalCluster on loopback equals the local run, even with a kill."""

import logging
import os
import signal
import sys
import threading
import time

import cloudpickle
import dask_helpers
import numpy as np
import pandas as pd
import pytest

from fpc_gripper.design import sweep
from fpc_gripper.design.grid import base_design, design_grid
from fpc_gripper.design.parametric import model_settings, solve_designs
from fpc_gripper.design.runner import run_chunks

distributed = pytest.importorskip('distributed')
# The workers import the helpers by value: they need not find tests/ on their path.
cloudpickle.register_pickle_by_value(dask_helpers)

VARY = {'prestrain': (0.15, 0.25, 0.40), 'Cy': (0.016, 0.026)}
PRESSURES = np.linspace(0.0, 300e3, 4)


@pytest.fixture(scope='module')
def cluster():
    """Two single-threaded worker processes and their scheduler, on loopback."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host='127.0.0.1', dashboard_address=':0',
                                  silence_logs=logging.CRITICAL) as local:
        with distributed.Client(local) as client:
            client.wait_for_workers(2)
            yield local.scheduler_address, client


def test_dask_rows_equal_the_local_rows(cluster):
    address, _ = cluster
    local = sweep(VARY, PRESSURES, model='paper', rigidity='x', chunk_designs=1)
    remote = sweep(VARY, PRESSURES, model='paper', rigidity='x', chunk_designs=1,
                   scheduler=address)
    # The same chunks solved by the same code: identical, not merely close.
    pd.testing.assert_frame_equal(local, remote, check_exact=True)
    assert (remote['status'] == 'invalid_design').sum() == 3 * PRESSURES.size


def test_a_killed_worker_costs_only_its_chunks(cluster, tmp_path):
    address, _ = cluster
    log = str(tmp_path / 'chunks.log')
    settings = model_settings('paper')
    _, points = design_grid(base_design(), {'prestrain': np.linspace(0.15, 0.40, 8)})
    chunks = [(log, k, 0.3, [(p.design, p.error)], PRESSURES, settings, (), 0.010)
              for k, p in enumerate(points)]
    killed = []

    def kill_one_mid_sweep():
        # Wait until a worker is inside a chunk after some chunk has finished, then kill
        # that worker's process outright.
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and not killed:
            events = dask_helpers.read_log(log)
            ended = {(k, p) for e, k, p in events if e == 'end'}
            running = [(k, p) for e, k, p in events if e == 'start' and (k, p) not in ended]
            if ended and running:
                pid = running[-1][1]
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
            time.sleep(0.02)

    watcher = threading.Thread(target=kill_one_mid_sweep)
    watcher.start()
    try:
        results = run_chunks(dask_helpers.logged_chunk, chunks, scheduler=address)
    finally:
        watcher.join()
    assert killed, 'no worker was killed mid-sweep'
    # No gaps, no duplicates: one result per chunk, in order, equal to a local solve.
    assert len(results) == len(chunks)
    for chunk, result in zip(chunks, results):
        expected = solve_designs(*chunk[3:])
        for name, column in expected.items():
            np.testing.assert_array_equal(result[name], column)
    # Only the killed worker's chunks ran twice.
    starts = {}
    for event, k, pid in dask_helpers.read_log(log):
        if event == 'start':
            starts.setdefault(k, []).append(pid)
    rerun = {k: pids for k, pids in starts.items() if len(pids) > 1}
    assert rerun, 'the killed chunk was not rerun'
    assert all(pids[0] == killed[0] for pids in rerun.values())
    assert set(starts) == set(range(len(chunks)))


def test_local_cluster_scheduler():
    # 'local:N' starts and closes its own cluster; the chunks come back in order.
    assert run_chunks(pow, [(k, 2) for k in range(6)], scheduler='local:2') == \
        [k * k for k in range(6)]


def test_without_dask_the_local_path_runs_and_says_how(monkeypatch, capsys, tmp_path):
    from fpc_gripper.design import cli, runner
    loaded = [m for m in sys.modules if m == 'dask' or m.startswith(('dask.', 'distributed'))]
    for name in loaded:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, 'dask', None)
    monkeypatch.setitem(sys.modules, 'distributed', None)
    assert not runner.dask_available()
    frame = sweep({'prestrain': (0.25,)}, [0.0], model='paper')
    assert frame['success'].all()
    with pytest.raises(ValueError, match=r"pip install 'fpc_gripper\[dask\]'"):
        sweep({'prestrain': (0.25,)}, [0.0], model='paper', scheduler='local:2')
    capsys.readouterr()
    assert cli.main(['sweep', '--vary', 'prestrain=0.25', '--pressure', '0', '--model',
                     'paper', '--no-charts', '--no-progress', '--out', str(tmp_path)]) == 0
    err = capsys.readouterr().err
    assert 'running in this process' in err and 'fpc_gripper[dask]' in err
    assert (tmp_path / 'sweep.csv').is_file()
