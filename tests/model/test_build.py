"""The compiled engine built at install: current, relocatable, read-only, and honest when stale."""

import json
import os
import pathlib
import shutil
import subprocess
import sys

import numpy as np
import pytest

from fpc_gripper.model import ActuatorDesign, CCMSolver, compiled
from fpc_gripper.model.pipeline import finger_model

PACKAGE = pathlib.Path(compiled.__file__).resolve().parents[1]

#: Solves a few scenes through the front ends and prints them with the compile count.
PROBE = r"""
import json
from numba.core import event
compiles = []
class Listener(event.Listener):
    def on_start(self, ev):
        compiles.append(ev.data['dispatcher'].py_func.__qualname__)
    def on_end(self, ev):
        pass
event.register('numba:compile', Listener())
from fpc_gripper.model import ActuatorDesign, batch, CCMSolver, compiled
from fpc_gripper.model.pipeline import finger_model
design = ActuatorDesign.paper(prestrain=0.25)
ccm = CCMSolver(design, n_segments=8).solve(pressure=1.0e5)
default = finger_model(design).solve(pressure=1.0e5, tip_force=(0.1, -0.2))
k = CCMSolver(design, n_segments=8).rigidity(pressure=0.0, axis='x')
# A batch hands its entry a numba typed list: numba's own list helpers come from the build.
grid = batch.solve_grid([design, ActuatorDesign.paper(prestrain=0.3)], [0.0, 1.0e5])
print(json.dumps({'usable': compiled.USABLE, 'reason': compiled.REASON,
                  'ccm': ccm.coefficients.tolist(), 'default_tip': default.tip.tolist(),
                  'k': k.value, 'grid_tip': grid.tip.tolist(), 'compiles': compiles}))
"""


def _reference():
    design = ActuatorDesign.paper(prestrain=0.25)
    return {'ccm': CCMSolver(design, n_segments=8).solve(pressure=1.0e5).coefficients,
            'default_tip': finger_model(design).solve(pressure=1.0e5,
                                                      tip_force=(0.1, -0.2)).tip,
            'k': CCMSolver(design, n_segments=8).rigidity(pressure=0.0, axis='x').value,
            # Each scene alone, through the single-scene front end (not the batch).
            'grid_tip': [[finger_model(d).solve(pressure=p).tip for p in (0.0, 1.0e5)]
                         for d in (design, ActuatorDesign.paper(prestrain=0.3))]}


def _copy_package(tmp_path):
    """The installed package as colcon or a container image copies it: new paths, mtimes."""
    root = tmp_path / 'site'
    shutil.copytree(PACKAGE, root / 'fpc_gripper',
                    ignore=shutil.ignore_patterns('__pycache__', 'compiled.old', '.build-*'))
    return root


def _run(root, read_only, home, extra_env=None):
    env = {k: v for k, v in os.environ.items()
           if not k.startswith('NUMBA_') and k not in ('PYTHONPATH', compiled.BUILD_ENV)}
    env.update(HOME=str(home), XDG_CACHE_HOME=str(home / '.cache'), PYTHONPATH=str(root),
               FPC_ENGINE_STRICT='1', **(extra_env or {}))
    command = [sys.executable, '-c', PROBE]
    if read_only:
        mount = (f'mount --bind {root} {root} && mount -o remount,bind,ro {root} && '
                 f'exec "$@"')
        command = ['unshare', '-m', 'sh', '-c', mount, 'sh', *command]
    return subprocess.run(command, cwd=home, env=env, capture_output=True, text=True,
                          timeout=600)


def test_the_build_is_this_checkouts():
    # scripts/setup.sh built it; without it every first solve compiles for minutes.
    usable, reason = compiled.build_status()
    assert usable, reason
    assert compiled.USABLE and 'built' in compiled.REASON


@pytest.mark.parametrize('key, value', [('sources', '0' * 64), ('numba', '0.1.0'),
                                        ('python', '2.7'), ('machine', ['x', 'y', 'z'])])
def test_build_status_names_what_differs(tmp_path, key, value):
    manifest = json.loads((compiled.BUILD_DIR / 'manifest.json').read_text())
    manifest[key] = value
    (tmp_path / 'manifest.json').write_text(json.dumps(manifest))
    usable, reason = compiled.build_status(tmp_path)
    assert not usable
    assert repr(value) in reason


def test_no_build_is_not_usable(tmp_path):
    usable, reason = compiled.build_status(tmp_path)
    assert not usable and 'no build' in reason


@pytest.mark.skipif(shutil.which('unshare') is None or os.geteuid() != 0,
                    reason='a read-only bind mount needs unshare as root')
def test_a_read_only_copy_with_an_empty_home_loads_and_compiles_nothing(tmp_path):
    # The scenario: a colcon install tree mounted read-only, HOME an empty folder.
    root = _copy_package(tmp_path)
    home = tmp_path / 'home'
    home.mkdir()
    done = _run(root, read_only=True, home=home)
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert out['usable'], out['reason']
    assert out['compiles'] == []
    reference = _reference()
    np.testing.assert_allclose(out['ccm'], reference['ccm'], rtol=0, atol=1e-12)
    np.testing.assert_allclose(out['default_tip'], reference['default_tip'], rtol=0,
                               atol=1e-12)
    np.testing.assert_allclose(out['k'], reference['k'], rtol=1e-12)
    np.testing.assert_allclose(np.squeeze(out['grid_tip'], axis=2), reference['grid_tip'],
                               rtol=0, atol=1e-9)
    assert not any(home.rglob('*.nbi')), 'numba wrote a cache into the empty HOME'


def test_an_edited_source_makes_the_build_stale_and_strict_mode_refuses(tmp_path):
    # A copy whose kernels differ by a comment: the build no longer matches, and with
    # FPC_ENGINE_STRICT (as in this suite) the first solve refuses to compile, naming it.
    root = _copy_package(tmp_path)
    kernel = root / 'fpc_gripper' / 'model' / 'kernels' / 'ccm.py'
    kernel.write_text(kernel.read_text() + '# edited\n')
    home = tmp_path / 'home'
    home.mkdir()
    done = _run(root, read_only=False, home=home)
    assert done.returncode != 0
    assert 'is not in the compiled engine' in done.stderr
    assert 'built for sources' in done.stderr and 'FPC_ENGINE_STRICT' in done.stderr


def test_a_batch_is_the_same_on_one_thread_and_on_every_core():
    # over_cores splits a batch into chunks, one thread each: no scene depends on another
    # but its chain's, and a chunk starts only where a chain does (else that scene would
    # start cold: more iterations).
    import numba
    from fpc_gripper.model import batch
    from fpc_gripper.model.pipeline import ModelSettings
    designs = [ActuatorDesign.paper(prestrain=e) for e in (0.15, 0.25, 0.40)]
    pressures = np.linspace(0.0, 3.0e5, 13)
    grids = []
    threads = numba.get_num_threads()
    for count in (1, threads):
        numba.set_num_threads(count)
        try:
            for settings in (ModelSettings(), ModelSettings(tolerance=0.0)):
                grid = batch.solve_grid(designs, pressures, settings=settings, outputs='all')
                kx = batch.rigidity_grid(designs, pressures[:4], axis='x', settings=settings)
                grids.append((grid.curvature, kx.result(2, 3).value, grid.iterations))
        finally:
            numba.set_num_threads(threads)
    for one, every in zip(grids[:2], grids[2:]):
        np.testing.assert_allclose(one[0], every[0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(one[1], every[1], rtol=1e-12)
        np.testing.assert_array_equal(one[2], every[2])
        assert np.isfinite(one[0]).all()


def test_batches_started_without_waiting_keep_to_numbas_thread_count():
    # over_cores(wait=False) hands its chunks to the pool of numba's thread count: lowered
    # to one, at most one pool thread runs them (and the waiter the chunks not yet started),
    # whatever pools earlier batches started.
    import threading
    import time

    import numba
    seen = set()

    def run(lo, hi):
        seen.add(threading.get_ident())
        time.sleep(0.005)
        return np.arange(lo, hi)
    compiled.over_cores(run, 64)                      # every core's pool, first
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        seen.clear()
        pending = [compiled.over_cores(run, 64, wait=False) for _ in range(6)]
        parts = [collect() for collect in pending]
    finally:
        numba.set_num_threads(threads)
    assert all(np.array_equal(part, np.arange(64)) for part in parts)
    assert len(seen - {threading.get_ident()}) == 1


def test_the_build_optimises_exactly_the_functions_it_stores():
    """The workers leave linked-only helpers unoptimised: every stored function is kept."""
    from fpc_gripper.model import build
    kept = build._kept_functions()
    # numba names each stored function's index '<module tail>.<qualname>-<line>.py<ver>.nbi'.
    stored = {path.name.split('-')[0].split('.', 1)[1]
              for path in compiled.BUILD_DIR.glob('*.nbi')}
    assert stored and stored <= kept, sorted(stored - kept)
    assert {'_solve_entry', '_rigidity_entry', '_contact_entry'} <= kept
    # The engine's register_jitable loops are linked into the entries, never stored.
    assert not {'_contact_settle', '_constrained_newton', '_newton'} & kept
