"""
Measure the Cython spike against numba on the unloaded CCM-8 solve; write the JSON.

    /work/main/.venv/bin/python bench/spike_aot/measure.py [--repeats 7] [--solves 2000]
                                                           [--no-build]

1. Builds every variant of bench/spike_aot/build.py cold (build dir removed first), in a
   subprocess each, timing the wall clock and reading the .so size.
2. Warm time per solve, median over repeats of `solves` solves at pressures 0..300 kPa, of
   (i) CCMSolver.solve (numba), (ii) engine.solves._solve_entry on the kernel data (numba),
   (iii) the Cython extension's solve_entry (each variant), (iv) ccm8_cy.py as plain
   Python (a few solves), (v) CCMSolver.solve with the engine entry swapped for the
   Cython one in this process (what the user would see). Ratios against (i), same run.
3. Agreement: status, iterations and max |x_numba - x_cython| at 51 pressures in
   [0, 400 kPa], plus paths that pressure sweep does not take (continuation, warm starts,
   high pressure) and the kernels alone (energy, gradient, blocks; the mirrored
   eigenvalue step on indefinite blocks).

Results go to bench/results/spike_aot.json.

It drives the engine's single-scene entry of its time, ``_solve_entry(data, initial, warm,
flat, ...)``; that entry now takes S scenes. Run it at commit 22e61e6 to repeat the spike.
"""

import argparse
import importlib.util
import json
import os
import pathlib
import platform
import statistics
import subprocess
import sys
import time
import warnings

# numba's run-time cache for this process (the package's build may be stale while the engine
# is being edited): kept out of the source tree.
os.environ.setdefault('NUMBA_CACHE_DIR', '/tmp/spike_aot_numba_cache')

import numpy as np  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / 'bench' / 'results' / 'spike_aot.json'
VARIANTS = ('o3', 'native', 'native-nofma')

from fpc_gripper.model import engine  # noqa: E402
from fpc_gripper.model.design import ActuatorDesign  # noqa: E402
from fpc_gripper.model.discretisations.ccm import CCMSolver  # noqa: E402
from fpc_gripper.model.engine import NewtonOptions  # noqa: E402
from fpc_gripper.model.kernels import ccm as kernels  # noqa: E402


def machine():
    model = next((line.split(':', 1)[1].strip() for line in
                  pathlib.Path('/proc/cpuinfo').read_text().splitlines()
                  if line.startswith('model name')), platform.processor())
    import Cython
    import numba
    import scipy
    return {'nproc': os.cpu_count(), 'cpu': model, 'python': platform.python_version(),
            'cython': Cython.__version__, 'numba': numba.__version__,
            'numpy': np.__version__, 'scipy': scipy.__version__,
            'gcc': subprocess.run(['gcc', '-dumpfullversion'], capture_output=True,
                                  text=True).stdout.strip()}


def build_all():
    """Cold-build every variant in a fresh interpreter; wall time and .so size."""
    out = {}
    for variant in VARIANTS:
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, str(HERE / 'build.py'), '--variant', variant,
                               '--clean'], capture_output=True, text=True, check=True)
        wall = time.perf_counter() - t0
        report = json.loads(proc.stdout.strip().splitlines()[-1])
        report['wall_s'] = wall
        out[variant] = report
        print(f"build {variant:13s} wall {wall:5.1f} s (cythonize {report['cythonize_s']:.1f} "
              f"s, C {report['compile_s']:.1f} s), .so {report['so_bytes'] / 1024:.0f} KiB")
    return out


def load(path, name='ccm8_cy'):
    """Import ccm8_cy from a given file (an extension or the .py)."""
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def so_path(variant):
    (so,) = (HERE / '_build' / variant).glob('ccm8_cy*.so')
    return so


class Case:
    """The default design's CCM-8 and the arrays the engine entry takes."""

    def __init__(self, options=None):
        self.solver = CCMSolver(ActuatorDesign.paper(prestrain=0.25), n_segments=8)
        self.data = self.solver.kernel_data(False)
        self.flat = engine.solves._flat(self.solver)
        self.opts, self.cap = engine.solves._packed(self.solver, options or self.solver._options,
                                                    self.flat.shape)
        self.nodes, self.forces = kernels.load_arrays([])

    def numba(self, pressure, initial=None):
        warm = initial is not None
        return engine.solves._solve_entry(self.data, initial if warm else self.flat, warm,
                                          self.flat, float(pressure), self.nodes,
                                          self.forces, self.opts, self.cap)

    def cython(self, module, problem, pressure, initial=None):
        warm = initial is not None
        return module.solve_entry(problem, initial if warm else self.flat, warm, self.flat,
                                  float(pressure), self.nodes, self.forces, self.opts, self.cap)


def timings(case, modules, repeats, solves, plain, plain_solves):
    """Median warm µs per solve of each variant; ratios to CCMSolver.solve, same run."""
    pressures = np.linspace(0.0, 300e3, solves)
    solver = case.solver
    problems = {name: module.Problem(case.data) for name, module in modules.items()}
    entry = engine.solves._solve_entry

    def patched(module, problem):
        def run(data, initial, warm, flat, pressure, nodes, forces, opts, cap):
            return module.solve_entry(problem, initial, warm, flat, pressure, nodes, forces,
                                      opts, cap)
        return run

    def full_solve():
        for p in pressures:
            solver.solve(pressure=p)

    def full_solve_cython():
        engine.solves._solve_entry = patched(modules['o3'], problems['o3'])
        try:
            for p in pressures:
                solver.solve(pressure=p)
        finally:
            engine.solves._solve_entry = entry

    def numba_entry():
        for p in pressures:
            case.numba(p)

    runs = {'ccmsolver_solve_numba': full_solve, 'engine_solve_entry_numba': numba_entry}
    for name, module in modules.items():
        def run(module=module, pb=problems[name]):
            for p in pressures:
                case.cython(module, pb, p)
        runs[f'cython_{name}_solve_entry'] = run
    runs['ccmsolver_solve_cython_o3'] = full_solve_cython
    for run in runs.values():
        run()                                   # warm: compile/load, first-touch memory
    samples = {name: [] for name in runs}
    names = list(runs)
    for r in range(repeats):
        # Rotate the order in each repeat so that no variant always runs first.
        for name in names[r % len(names):] + names[:r % len(names)]:
            t0 = time.perf_counter()
            runs[name]()
            samples[name].append((time.perf_counter() - t0) / solves * 1e6)
    # Plain Python: a few solves (each ~ms).
    pb = plain.Problem(case.data)
    plain_pressures = np.linspace(0.0, 300e3, plain_solves)
    samples['plain_python_py'] = []
    for _ in range(3):
        t0 = time.perf_counter()
        for p in plain_pressures:
            case.cython(plain, pb, p)
        samples['plain_python_py'].append((time.perf_counter() - t0) / plain_solves * 1e6)
    base = samples['ccmsolver_solve_numba']
    out = {}
    for name, values in samples.items():
        entry_ = {'median_us': statistics.median(values), 'min_us': min(values),
                  'samples_us': values}
        entry_['ratio_to_ccmsolver_solve'] = entry_['median_us'] / statistics.median(base)
        if len(values) == len(base):
            # Per repeat (adjacent runs), then the median: robust to drifts of the machine.
            entry_['ratio_to_ccmsolver_solve_paired'] = statistics.median(
                v / b for v, b in zip(values, base))
        out[name] = entry_
        print(f"{name:32s} {entry_['median_us']:10.2f} us/solve  "
              f"x{entry_['ratio_to_ccmsolver_solve']:.3f} of CCMSolver.solve")
    return out


def compare(a, b):
    """Agreement of two engine tuples: same status and iterations, max |dx|."""
    return {'same_status': a[1] == b[1], 'same_iterations': a[2] == b[2],
            'max_abs_dx': float(np.abs(a[0] - b[0]).max()),
            'max_rel_dx': float(np.abs(a[0] - b[0]).max() / max(np.abs(a[0]).max(), 1e-300)),
            'same_figures': all(x == y or (x != x and y != y) for x, y in zip(a[1:], b[1:]))}


def summarise(rows):
    return {'count': len(rows), 'status_mismatches': sum(not r['same_status'] for r in rows),
            'iteration_mismatches': sum(not r['same_iterations'] for r in rows),
            'figure_mismatches': sum(not r['same_figures'] for r in rows),
            'bit_identical_states': sum(r['max_abs_dx'] == 0.0 for r in rows),
            'max_abs_dx': max(r['max_abs_dx'] for r in rows),
            'max_rel_dx': max(r['max_rel_dx'] for r in rows)}


def agreement(modules):
    """Numba vs each Cython variant (and the plain .py): solves and kernels."""
    case = Case()

    def capped(iterations):
        return Case(NewtonOptions(max_iterations=iterations, gtol=case.solver.gtol,
                                  xtol=case.solver.xtol, max_step=0.5,
                                  energy_scale=case.solver.gradient_scale))
    # max_iterations = 5: Newton from flat stops short above ~300 kPa, continuation
    # succeeds; = 4: continuation fails too (CONTINUATION_FAILED).
    short = {5: capped(5), 4: capped(4)}
    sweep = np.linspace(0.0, 400e3, 51)
    out = {}
    for name, module in modules.items():
        rng = np.random.default_rng(20240611)
        pb = module.Problem(case.data)
        paths = {}
        # The requested figure: 51 pressures, Newton from flat.
        paths['sweep_0_400kPa'] = [compare(case.numba(p), case.cython(module, pb, p))
                                   for p in sweep]
        # Beyond max_pressure (the envelope reaches 2 x 400 kPa).
        paths['sweep_400_800kPa'] = [compare(case.numba(p), case.cython(module, pb, p))
                                     for p in np.linspace(400e3, 800e3, 11)]
        # Warm starts: a neighbour's state (warm succeeds), a far random state (Newton
        # from it backtracks, and may fail so the solve restarts from flat).
        rows = []
        for p in sweep[1:]:
            start = case.numba(p - 8e3)[0]
            rows.append(compare(case.numba(p, start), case.cython(module, pb, p, start)))
            for spread in (0.3, 1.0):
                far = rng.normal(0.0, spread, case.flat.shape)
                rows.append(compare(case.numba(p, far), case.cython(module, pb, p, far)))
        # A non-finite warm start: NOT_FINITE at once, then the fresh solve.
        bad = np.full(case.flat.shape, np.nan)
        rows.append(compare(case.numba(2e5, bad), case.cython(module, pb, 2e5, bad)))
        paths['warm_starts'] = rows
        statuses = set()
        for iterations, capped_case in short.items():
            pb_short = module.Problem(capped_case.data)
            rows = []
            for p in np.linspace(0.0, 800e3, 51):
                a = capped_case.numba(p)
                statuses.add(int(a[1]))
                rows.append(compare(a, capped_case.cython(module, pb_short, p)))
            paths[f'continuation_max_iterations_{iterations}'] = rows
        out[name] = {path: summarise(rows) for path, rows in paths.items()}
        out[name]['statuses_seen_capped'] = sorted(statuses)
        out[name]['kernels'] = kernel_agreement(module, pb, case, rng)
    return out


def kernel_agreement(module, pb, case, rng):
    """Energy, gradient, blocks at random states; the block step on indefinite blocks."""
    nodes, forces = case.nodes, case.forces
    worst = {'energy': 0.0, 'line_search_energy': 0.0, 'gradient': 0.0, 'blocks': 0.0,
             'step_pd': 0.0, 'step_mirrored': 0.0, 'min_eig_mirrored': 0.0}
    mirrored = 0
    for k in range(200):
        q = rng.normal(0.0, 0.2, case.flat.shape)
        p = float(rng.uniform(0.0, 800e3))
        e_n, g_n, (h_n, _, _) = kernels.ccm_derivatives(case.data, q, p, nodes, forces)
        e_c, g_c, h_c = module.derivatives(pb, q, p)
        worst['energy'] = max(worst['energy'], abs(e_n - e_c))
        worst['gradient'] = max(worst['gradient'], float(np.abs(g_n - g_c).max()))
        worst['blocks'] = max(worst['blocks'], float(np.abs(h_n - h_c).max()))
        worst['line_search_energy'] = max(worst['line_search_energy'], abs(
            kernels.ccm_energy(case.data, q, p, nodes, forces) - module.energy(pb, q, p)))
        # Symmetric blocks, half of them indefinite: the mirrored-eigenvalue branch.
        a = rng.normal(size=h_n.shape)
        hess = a + a.transpose(0, 2, 1) + (0.0 if k % 2 else 6.0) * np.eye(4)
        s_n, m_n = kernels.newton_step_blocks(g_n, hess, kernels.EIGEN_FLOOR)
        s_c, m_c = module.block_step(pb, g_n, hess)
        key = 'step_pd' if m_n == 1.0 else 'step_mirrored'
        mirrored += m_n != 1.0
        worst[key] = max(worst[key], float(np.abs(s_n - s_c).max()))
        worst['min_eig_mirrored'] = max(worst['min_eig_mirrored'], abs(m_n - m_c))
    worst['mirrored_cases'] = int(mirrored)
    worst['cases'] = 200
    return worst


def worst_path(report):
    """Largest max|dx| over the solve paths of one variant's agreement report."""
    return max(v['max_abs_dx'] for v in report.values() if isinstance(v, dict)
               and 'max_abs_dx' in v)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--repeats', type=int, default=7)
    parser.add_argument('--solves', type=int, default=2000)
    parser.add_argument('--plain-solves', type=int, default=20)
    parser.add_argument('--no-build', action='store_true', help='reuse _build/')
    args = parser.parse_args()
    warnings.simplefilter('ignore', RuntimeWarning)   # numba compiling a stale build here
    result = {'machine': machine()}
    print(result['machine'])
    if not args.no_build:
        result['build'] = build_all()
    else:
        result['build'] = {v: {'so': str(so_path(v)), 'so_bytes': so_path(v).stat().st_size}
                           for v in VARIANTS}
    modules = {variant: load(so_path(variant)) for variant in VARIANTS}
    plain = load(HERE / 'ccm8_cy.py', 'ccm8_cy_plain')
    case = Case()
    t0 = time.perf_counter()
    case.solver.solve(pressure=1e3)
    result['numba_first_solve_s'] = time.perf_counter() - t0
    result['timing'] = {'repeats': args.repeats, 'solves_per_repeat': args.solves,
                        'plain_python_solves_per_repeat': args.plain_solves,
                        'pressures_kPa': [0, 300],
                        **timings(case, modules, args.repeats, args.solves, plain,
                                  args.plain_solves)}
    result['agreement'] = agreement({**modules, 'plain_python': plain})
    for name, report in result['agreement'].items():
        sweep = report['sweep_0_400kPa']
        print(f"agreement {name:13s} sweep: {sweep['bit_identical_states']}/{sweep['count']} "
              f"bit-identical, max|dx| {sweep['max_abs_dx']:.1e}, iteration mismatches "
              f"{sweep['iteration_mismatches']}; all paths max|dx| {worst_path(report):.1e}")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=1, default=float) + '\n')
    print(f'wrote {RESULTS}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
