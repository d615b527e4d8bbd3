"""
Build the compiled engine at install: ``python -m fpc_gripper.model.build``.

scripts/setup.sh, ``pip install`` and ``colcon build`` (through setup.py) run this once;
nodes, tools and tests then load the code read-only (`compiled`). The parts
(`build_parts`) run the front ends on small scenes, which compiles every entry for the
argument types it meets in use; two processes share them, each writing a directory of
its own, and the directories are merged into the build, which is replaced whole only
when every part succeeded. A last pass runs every part again in a fresh process and
fails if anything had to compile there.
"""

import argparse
import contextlib
import os
import pathlib
import selectors
import shutil
import subprocess
import sys
import tempfile
import time
import typing

__all__ = ['PARTS', 'build', 'main']

_PACKAGE_ROOT = pathlib.Path(__file__).resolve().parents[2]


# -- the parts: each runs one front end on a small scene -----------------------------------
def _design(prestrain=0.25):
    from fpc_gripper.model import ActuatorDesign
    return ActuatorDesign.paper(prestrain=prestrain)


def _outputs(result):
    """Call a result's `position_at` (its kinematics run from Python)."""
    position_at = getattr(result, 'position_at', None)
    if position_at is not None:
        position_at(0.045)


def _engine_calls(solver, force):
    """Run the engine's Newton and sensitivity, and the discretisation's hooks, from Python."""
    from fpc_gripper.model import engine
    from fpc_gripper.model.kernels.chain import load_arrays
    tip_loads = getattr(solver, 'tip_loads', None)
    loads = tip_loads(force) if tip_loads else solver._loads(force, ())
    problem = solver.engine_problem
    for load in ([], loads):
        out = engine.solve(problem, 5.0e4, load, solver._options)
        engine.newton(problem, out.x, 5.0e4, load, solver._options)
        if hasattr(solver, 'parameter_gradient'):
            engine.sensitivity(problem, out.x, 5.0e4, load,
                               solver.parameter_gradient(out.x, 5.0e4, load))
        # The interface the engine's loops take, called from Python (the interpreted loop
        # and the hooks' own tests do): the methods, then the compiled hooks themselves.
        x = out.x + 0.01
        _, grad, hess = solver.derivatives(x, 5.0e4, load)
        solver.energy(x, 5.0e4, load)
        solver.step(grad, hess)
        solver.node_jacobian(x, loads[0][0])
        if hasattr(solver, 'solve_linear'):
            solver.solve_linear(hess, grad)
        problem.energy(x, 5.0e4, load)
        problem.step(grad, problem.derivatives(x, 5.0e4, load)[2])
        data = problem.data[bool(load)]
        hooks = engine.hooks_of(type(data))
        nodes, forces = load_arrays(load)
        _, grad, hess = hooks['derivatives'](data, x, 5.0e4, nodes, forces)
        hooks['energy'](data, x, 5.0e4, nodes, forces)
        hooks['step'](data, grad, hess)
        hooks['solve_linear'](data, hess, grad)
        hooks['node_jacobian'](data, x, loads[0][0])
        for samples in (False, True):
            hooks['outputs'](data, x, 5.0e4, nodes, forces, samples)


def _circle_fit():
    """Run the circle fit's pieces on a sampled arc, as its own tests call them."""
    import numpy as np
    from fpc_gripper.model import analysis
    angle = np.linspace(0.0, 1.0, 17)
    x, z = np.sin(angle) / 20.0, (np.cos(angle) - 1.0) / 20.0
    params = np.array([10.0, 0.0, 0.1])
    analysis._signed_distances(params, x, z, x * x + z * z)
    analysis._distance_jacobian(params, x, z, x * x + z * z)
    analysis.fit_circle(np.column_stack([x, z]))


def _scenes(solver):
    """Solve cold, warm and loaded, with every output, both rigidities and the engine calls."""
    free = solver.solve(pressure=1.0e5)
    _outputs(free)
    _outputs(solver.solve(pressure=1.01e5, initial=free, outputs='tip'))
    _outputs(solver.solve(pressure=1.0e5, tip_force=(0.05, -0.05)))
    solver.rigidity(pressure=5.0e4, axis='x')
    solver.rigidity(pressure=5.0e4, axis='z', initial=free, outputs='all')
    _engine_calls(solver, (0.05, -0.05))


def _ccm():
    from fpc_gripper.model import CCMSolver
    _scenes(CCMSolver(_design(), n_segments=8))
    _scenes(CCMSolver(_design(), n_segments=8, reconstruction='consistent'))
    loaded = CCMSolver(_design(), n_segments=8, load_points=(0.045,))
    _outputs(loaded.solve(pressure=5.0e4, point_loads=[(0.045, 0.0, -0.05)]))
    _circle_fit()


def _pcc():
    from fpc_gripper.model import PCCSolver
    _scenes(PCCSolver(_design(), n_segments=22))
    _corrected()


def _corrected():
    """Run the corrected rung's shear move: every output level, `position_at`, `shear_tip`."""
    from fpc_gripper.model.corrected import CorrectedSolver, shear_displacements
    solver = CorrectedSolver(_design())
    for outputs in ('tip', 'shape', 'all'):
        result = solver.solve(pressure=1.0e5, tip_force=(0.05, -0.05), outputs=outputs)
        _outputs(result)
        result.position_at([0.01, 0.045])
    solver.shear_tip(result.x, (0.05, -0.05))
    shear_displacements(result.x[2::3], solver.lengths, [1], [0.001], (0.05, -0.05), 1.0)


def _adaptive():
    from fpc_gripper.model.pipeline import finger_model
    solver = finger_model(_design())
    for pressure in (0.0, 1.0e5, 3.0e5):
        _outputs(solver.solve(pressure=pressure))
        _outputs(solver.solve(pressure=pressure, tip_force=(0.1, -0.2)))
    solver.rigidity(pressure=5.0e4, axis='x')
    solver.rigidity(pressure=5.0e4, axis='z')


def _ladder():
    import numpy as np
    from fpc_gripper.model import ArcSolver, RodSolver
    from fpc_gripper.model import engine
    from fpc_gripper.model.discretisations import rod
    from fpc_gripper.model.kernels import rod as rod_kernels
    for solver in (ArcSolver(_design()), RodSolver(_design())):
        _outputs(solver.solve(pressure=1.0e5))
        _outputs(solver.solve(pressure=1.0e5, tip_force=(0.05, -0.05)))
        solver.rigidity(pressure=5.0e4, axis='x')
        solver.rigidity(pressure=5.0e4, axis='z')
    # The rod's pointwise (eps, c1) problem of its outputs, energy included (the line
    # search of its Newton calls it only when a full step fails).
    state = engine.solve(solver.engine_problem, 1.0e5, [], solver._options).x
    _, kap, along, start = rod_kernels.sample_fields_kernel(
        state, solver._xq.size, *solver._sample_at[1:5], np.zeros(2))
    local = rod._PointwiseLocal(solver, kap, along, solver._sample_at[4], 1.0e5)
    local.energy(start, 1.0e5, [])
    local.derivatives(start, 1.0e5, [])


def _contact():
    from fpc_gripper.model.contact import Circle, contact_path, point_gaps, solve_contact
    from fpc_gripper.model.pipeline import contact_model
    solver = contact_model(_design())
    disk = Circle(center=(0.04, -0.06), radius=0.02)
    result = solve_contact(solver, 1.0e5, [disk])
    _outputs(result)
    point_gaps(solver, solver.flat(), [disk])
    contact_path(solver, [0.5e5, 1.0e5], [disk], mu=0.5)


def _grids():
    from fpc_gripper.model import batch
    from fpc_gripper.model.pipeline import ModelSettings
    designs = [_design(), _design(0.15)]
    pressures = [0.0, 1.0e5, 2.0e5]
    for settings in (ModelSettings(), ModelSettings(tolerance=0.0)):
        for forces in (((0.0, 0.0),), ((0.0, 0.0), (0.05, -0.05))):
            grid = batch.solve_grid(designs, pressures, tip_forces=forces, settings=settings,
                                    outputs='all')
            grid.result(0, 1, len(forces) - 1)
        for axis in ('x', 'z'):
            batch.rigidity_grid(designs, pressures, axis=axis, settings=settings).result(0, 1)


class Part(typing.NamedTuple):
    """One part of the build: what it runs, what it costs, how hard LLVM optimises it."""

    run: typing.Callable[[], None]
    #: Seconds it compiles for with the other worker busy, measured in its lane (ccm: 1 s
    #: after grids, about 30 alone): the cost deals them on other than 2 workers.
    seconds: float
    #: LLVM's optimisation level (numba's NUMBA_OPT). Level 1 compiles in 0.6x the time of
    #: numba's default 3 and runs the solves, rigidities and batches as fast (within 1 %,
    #: the same bits); the contact solve alone is 6 % slower at 1, so it keeps 3.
    opt: int


PARTS = {
    'ccm': Part(_ccm, 1, 1), 'contact': Part(_contact, 39, 3), 'grids': Part(_grids, 56, 1),
    'pcc': Part(_pcc, 7, 1), 'ladder': Part(_ladder, 13, 1), 'adaptive': Part(_adaptive, 1, 1),
}


def _run_parts(names, out=sys.stdout):
    for name in names:
        start = time.perf_counter()
        # numba rereads NUMBA_* at every compile (`config.reload_config`).
        os.environ['NUMBA_OPT'] = str(PARTS[name].opt)
        PARTS[name].run()
        print(f'done {name} {time.perf_counter() - start:.1f}', file=out, flush=True)


# -- what the workers optimise ---------------------------------------------------------------
def _kept_functions():
    """Return the qualified names of the functions whose code the build keeps."""
    import importlib
    import pkgutil
    from numba.core.registry import CPUDispatcher
    from fpc_gripper import model
    from fpc_gripper.model import compiled
    names = {func.__qualname__ for func in compiled._ADOPTED}
    for package in ('kernels', 'engine', 'discretisations'):
        path = [str(pathlib.Path(model.__file__).parent / package)]
        for info in pkgutil.walk_packages(path, f'fpc_gripper.model.{package}.'):
            for value in vars(importlib.import_module(info.name)).values():
                if isinstance(value, CPUDispatcher) and isinstance(value._cache, compiled._Cache):
                    names.add(value.py_func.__qualname__)
    return names


def _optimise_kept_code_only():
    """
    Have numba optimise and emit machine code only for the functions the build keeps.

    numba finalises every function it compiles: it links in the finished code of every
    function it calls, runs LLVM's module passes over the whole and emits machine code. A
    helper called only from compiled code (the engine's `register_jitable` loops, numba's
    own internals) is so optimised and emitted once for itself and again inside each
    function above it: a call chain costs its depth times its size (numba's PR #9566 shows
    the same). The build keeps only `compiled.jit`'s functions, the ones Python calls; a
    helper's code runs only inside them, optimised with theirs. So a helper is left as
    lowered (numba's function passes) and never emitted: the build takes half the time.
    The kept code is optimised by the same passes at the same level, and no pass LLVM
    runs without fast-math changes a float, so the answers are the same
    (docs/engine_build.md). A kept function missed here fails the build, when numba
    stores it.

    This reaches into numba's codegen (0.68); with another numba the build runs as numba does.
    """
    from numba.core import codegen, cpu
    library_class = codegen.CPUCodeLibrary
    needed = ('_optimize_final_module', '_finalize_final_module', '_finalize_dynamic_globals',
              '_verify_declare_only_symbols', '_finalized')
    if not all(hasattr(library_class, name) for name in needed) \
            or not hasattr(cpu.CPUContext, 'get_executable'):
        return
    from numba import _dynfunc
    kept = _kept_functions()
    optimise, finalise = library_class._optimize_final_module, library_class._finalize_final_module
    executable = cpu.CPUContext.get_executable

    def optimize_final_module(library):
        if library.name in kept:
            optimise(library)

    def finalize_final_module(library):
        if library.name in kept:
            finalise(library)
            return
        library._finalize_dynamic_globals()
        library._verify_declare_only_symbols()
        library._finalized = True

    def get_executable(context, library, fndesc, env):
        if library.name in kept:
            return executable(context, library, fndesc, env)
        # Never called: only compiled code calls a helper, and it links the helper's code.
        return _dynfunc.make_function(fndesc.lookup_module(), fndesc.qualname.split('.')[-1],
                                      'linked only', 0, env, (library,))

    library_class._optimize_final_module = optimize_final_module
    library_class._finalize_final_module = finalize_final_module
    cpu.CPUContext.get_executable = get_executable


# -- the driver --------------------------------------------------------------------------------
def _spawn(args, env_extra, cwd):
    from fpc_gripper.model import compiled
    env = {k: v for k, v in os.environ.items() if k not in (compiled.BUILD_ENV,
                                                            'NUMBA_DISABLE_JIT')}
    # The machine code generator keeps the level the process starts with: the highest.
    env.update(env_extra, NUMBA_OPT='3')
    return subprocess.Popen([sys.executable, '-m', 'fpc_gripper.model.build', *args],
                            cwd=cwd, env=env, stdout=subprocess.PIPE, text=True)


#: The two workers' parts on 2 cores, by measurement: parts in one process share what they
#: compile (grids compiles most of ccm, adaptive and the arc), which dealing by cost alone
#: cannot see. Measured: 46 s and 70 s per worker this way (75 s in all, 2.0 min of CPU); with
#: the ladder beside contact 69 s and 61 s (73 s in all, 2.3 min of CPU).
TWO_LANES = (('contact', 'pcc'), ('grids', 'ccm', 'adaptive', 'ladder'))


def _split(names, jobs):
    """Deal the parts to `jobs` workers, the costliest first to the least loaded."""
    if jobs == 2 and sorted(names) == sorted(sum(TWO_LANES, ())):
        return [list(lane) for lane in TWO_LANES]
    groups = [[] for _ in range(jobs)]
    loads = [0.0] * jobs
    for name in sorted(names, key=lambda n: -PARTS[n].seconds):
        k = loads.index(min(loads))
        groups[k].append(name)
        loads[k] += PARTS[name].seconds
    return [group for group in groups if group]


def _merge(workers, into):
    """Merge the workers' indexes and data into `into`; return the distinct signatures."""
    from numba.core.caching import IndexDataCacheFile
    from fpc_gripper.model import compiled
    stamp = compiled.sources_stamp()
    merged = set()
    for directory in workers:
        for index in sorted(pathlib.Path(directory).glob('*.nbi')):
            base = index.name[:-len('.nbi')]
            source = IndexDataCacheFile(str(directory), base, stamp)
            target = IndexDataCacheFile(str(into), base, stamp)
            for key, name in source._load_index().items():
                target.save(key, source._load_data(name))
                merged.add((base, key))
    return len(merged)


def build(jobs=2, log=sys.stderr):
    """
    Build the engine into `compiled.BUILD_DIR`, replacing any earlier build only on success.

    Returns the wall time [s]; raises RuntimeError when a part fails or compiles again.
    """
    from fpc_gripper.model import compiled
    start = time.perf_counter()
    final = compiled.BUILD_DIR
    names = list(PARTS)
    groups = _split(names, max(1, int(jobs)))
    estimate = max(sum(PARTS[n].seconds for n in group) for group in groups) + 15
    print(f'fpc_gripper: building the compiled engine into {final} ({len(names)} parts, '
          f'{len(groups)} processes; about {estimate / 60:.1f} min on free cores)', file=log,
          flush=True)
    final.parent.mkdir(parents=True, exist_ok=True)
    for stale in final.parent.glob('.build-*'):
        shutil.rmtree(stale, ignore_errors=True)      # an interrupted build's
    with tempfile.TemporaryDirectory(prefix='.build-', dir=final.parent) as work:
        work = pathlib.Path(work)
        dirs = [work / f'worker{k}' for k in range(len(groups))]
        procs = [_spawn(['--parts', ','.join(group)], {compiled.BUILD_ENV: str(d)},
                        _PACKAGE_ROOT) for group, d in zip(groups, dirs)]
        done = 0
        with contextlib.ExitStack() as stack:
            for proc in procs:
                stack.callback(proc.wait)
            for line in _interleave(procs):
                if line.startswith('done '):
                    done += 1
                    _, name, seconds = line.split()
                    print(f'  [{done}/{len(names)}] {name:<10} {float(seconds):6.1f} s '
                          f'({time.perf_counter() - start:.0f} s in all)', file=log,
                          flush=True)
        failed = [proc.returncode for proc in procs if proc.returncode]
        if failed or done != len(names):
            raise RuntimeError(f'engine build failed (worker exit codes {failed}): the '
                               f'earlier build, if any, is left as it was')
        staging = work / 'compiled'
        staging.mkdir()
        count = _merge(dirs, staging)
        compiled.write_manifest(staging, built=time.strftime('%Y-%m-%d %H:%M:%S'),
                                signatures=count, parts=names)
        restore = _swap(staging, final)
        check = _spawn(['--verify'], {}, _PACKAGE_ROOT)
        out, _ = check.communicate()
        if check.returncode:
            shutil.rmtree(final, ignore_errors=True)
            restore()
            raise RuntimeError(f'engine build incomplete: {out.strip()}')
    wall = time.perf_counter() - start
    print(f'fpc_gripper: engine built, {count} compiled signatures, {wall:.0f} s; '
          f'{out.strip()}', file=log, flush=True)
    return wall


def _swap(staging, final):
    """Put `staging` in place of `final`; return a callable that restores the old build."""
    old = final.with_name(final.name + '.old')
    shutil.rmtree(old, ignore_errors=True)
    if final.exists():
        final.rename(old)
    staging.rename(final)

    def restore():
        if old.exists():
            old.rename(final)
    return restore


def _interleave(procs):
    """Yield the lines of several processes' stdout as they come."""
    selector = selectors.DefaultSelector()
    for proc in procs:
        selector.register(proc.stdout, selectors.EVENT_READ)
    open_count = len(procs)
    while open_count:
        for key, _ in selector.select():
            line = key.fileobj.readline()
            if not line:
                selector.unregister(key.fileobj)
                open_count -= 1
            else:
                yield line.strip()


def _verify():
    """Run every part with the build in place; exit 1 naming whatever compiled."""
    from numba.core import event
    from fpc_gripper.model import compiled
    if not compiled.USABLE:
        print(f'build not usable: {compiled.REASON}')
        return 1
    compiles = []

    class Listener(event.Listener):
        def on_start(self, ev):
            func = ev.data['dispatcher'].py_func
            if func.__module__.startswith('fpc_gripper') or func in compiled._ADOPTED:
                compiles.append(f'{func.__module__}.{func.__qualname__}{ev.data["args"]}')

        def on_end(self, ev):
            pass

    start = time.perf_counter()
    with event.install_listener('numba:compile', Listener()):
        _run_parts(list(PARTS), out=open(os.devnull, 'w'))
    if compiles:
        print(f'{len(compiles)} compiled at run time: ' + '; '.join(compiles[:5]))
        return 1
    print(f'verified: every part ran in {time.perf_counter() - start:.1f} s, nothing compiled')
    return 0


def main(argv=None):
    """Command line: build (default), or one worker's parts, or the verification."""
    parser = argparse.ArgumentParser(prog='python -m fpc_gripper.model.build',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--jobs', type=int, default=min(2, os.cpu_count() or 1),
                        help='processes that compile (default: 2, or 1 on one core)')
    parser.add_argument('--if-stale', action='store_true',
                        help='do nothing when the build is already these sources on this '
                             'machine')
    parser.add_argument('--parts', help=argparse.SUPPRESS)
    parser.add_argument('--verify', action='store_true', help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.parts:
        _optimise_kept_code_only()
        _run_parts(args.parts.split(','))
        return 0
    if args.verify:
        return _verify()
    if args.if_stale:
        from fpc_gripper.model import compiled
        usable, reason = compiled.build_status()
        if usable:
            print(f'fpc_gripper: compiled engine is current ({reason})', file=sys.stderr)
            return 0
    try:
        build(args.jobs)
    except RuntimeError as exc:
        print(f'fpc_gripper: {exc}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
