"""
The continuum rung's reference table, its mesh convergence, and the beam rungs against it.

Run by hand from the repository root (scikit-fem installed):

    .venv/bin/python bench/bench_continuum.py [--part table|convergence|variants|all] [--quick]

Writes bench/results/continuum.json (each part its own key; a part run alone keeps the
other's stored results):
- table: the FE (ribs exact, h = 1 mm, poisson=False) over prestrain 0.15/0.25/0.40 with
  0-400 kPa unloaded, and tip loads of +-0.5 N along X and along Z at 0 and 200 kPa: tip,
  circle-fit curvature, interior curvature (x = 10-70 mm), load steps, Newton iterations,
  dofs and wall time per solve; and the tip of every beam rung in the same scene (rod,
  ribs exact; the default AdaptiveSolver at 0.05 mm; the paper's CCM8; the arc) with its
  distance to the FE tip.
- convergence: prestrain 0.25, unloaded (ribs averaged and exact) and 200 kPa (exact), at
  h = 2, 1, 0.5 mm: tip and its distance to the finest mesh; and the Poisson-coupled law
  (poisson=True) at h = 1 mm for the idealisation it stands for.
- variants: the unloaded pressure scenes of the table again with gas_model='axial' (the
  beam rungs' gas volume, no growth of the channel through the thickness) and with
  poisson=True (a nearly incompressible fluidic layer), against the rod.
- section: the channel cross-section (`continuum.section.ChannelSection`, h = 0.5 mm,
  between ribs and at a rib) under k_p P for 0-400 kPa, and the table's pressurised
  scenes with the side view's band coupled to it (channel='section', h = SECTION_SIDE_SIZE)
  against the rod and the corrected rung.
"""

import argparse
import json
import os
import pathlib
import subprocess
import sys
import time

for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')

import numpy as np  # noqa: E402

_HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(_HERE))
from timing import machine  # noqa: E402, I100

from fpc_gripper.model import (ActuatorDesign, AdaptiveSolver, ArcSolver,  # noqa: E402
                               CCMSolver, RodSolver)
from fpc_gripper.model.analysis import fit_circle  # noqa: E402
from fpc_gripper.model.continuum import ContinuumSolver  # noqa: E402
from fpc_gripper.model.corrected import CorrectedSolver  # noqa: E402

RESULTS = _HERE / 'results' / 'continuum.json'
PRESTRAINS = (0.15, 0.25, 0.40)
PRESSURES = (0.0, 100e3, 200e3, 300e3, 400e3)
LOAD_PRESSURES = (0.0, 200e3)
LOADS = ((0.5, 0.0), (-0.5, 0.0), (0.0, 0.5), (0.0, -0.5))
ELEMENT_SIZE = 1e-3
SIZES = (2e-3, 1e-3, 0.5e-3)
INTERIOR = (0.010, 0.070)     # [m] of reference arc length
#: Side-view elements of the coupled table: the channel's growth moves the tip by tens of
#: mm; 1 mm elements move it by 0.21 mm (0.25, 100 kPa; docs/physics.md, section 18.3).
SECTION_SIDE_SIZE = 2e-3


def _scenes(quick):
    out = []
    for eps0 in PRESTRAINS:
        for p in ((0.0, 400e3) if quick else PRESSURES):
            out.append((eps0, p, (0.0, 0.0)))
        for p in ((0.0,) if quick else LOAD_PRESSURES):
            for load in (LOADS[:1] if quick else LOADS):
                out.append((eps0, p, load))
    return out


def _interior_curvature(result):
    s = np.linspace(*INTERIOR, 61)
    return fit_circle(result.position_at(s)).curvature


def _rung_rows(rungs, fe_tip, pressure, load=(0.0, 0.0)):
    """Return each beam rung's tip in the scene and its distance to the FE's [mm]."""
    rows = {}
    for name, rung in rungs.items():
        beam = rung.solve(pressure=pressure, tip_force=load)
        rows[name] = {'tip_mm': (beam.tip * 1e3).tolist(),
                      'error_mm': float(np.hypot(*(beam.tip - fe_tip)) * 1e3),
                      'success': bool(beam.success)}
    return rows


def _print_row(head, row):
    """Print a scene's line: `head`, the FE's time and message, each rung's distance."""
    print(f"{head}, {row['seconds']:5.1f} s, {row['message']}; "
          + ', '.join(f"{k} {v['error_mm']:.3f}" for k, v in row['rungs'].items())
          + ' mm', flush=True)


def _fe_row(solver, pressure, load):
    start = time.perf_counter()
    r = solver.solve(pressure=pressure, tip_force=load)
    seconds = time.perf_counter() - start
    return r, {'success': bool(r.success), 'message': r.message,
               'tip_mm': (r.tip * 1e3).tolist(), 'curvature': r.curvature,
               'interior_curvature': _interior_curvature(r), 'fit_rmsd_mm': r.fit_rmsd * 1e3,
               'load_steps': int(r.load_steps), 'iterations': int(r.iterations),
               'dofs': int(r.n_dofs), 'seconds': seconds}


def variants(quick):
    """Return the pressure scenes with the two other idealisations of the channel band."""
    rows = []
    for eps0 in PRESTRAINS:
        design = ActuatorDesign.paper(prestrain=eps0)
        rod = RodSolver(design, ribs='exact')
        for name, kwargs in (('gas axial', {'gas_model': 'axial'}),
                             ('poisson', {'poisson': True})):
            fe = ContinuumSolver(design, ribs='exact', element_size=ELEMENT_SIZE, **kwargs)
            for pressure in ((400e3,) if quick else PRESSURES[1:]):
                r, row = _fe_row(fe, pressure, (0.0, 0.0))
                beam = rod.solve(pressure=pressure)
                row.update(variant=name, prestrain=eps0, pressure_kpa=pressure / 1e3,
                           rod_tip_mm=(beam.tip * 1e3).tolist(),
                           rod_error_mm=float(np.hypot(*(beam.tip - r.tip)) * 1e3))
                print(f'{name}: eps0 {eps0:.2f} P {pressure / 1e3:5.0f} kPa: FE tip '
                      f"({row['tip_mm'][0]:7.3f}, {row['tip_mm'][1]:7.3f}) mm, rod "
                      f"{row['rod_error_mm']:.3f} mm, {row['message']}", flush=True)
                rows.append(row)
    return rows


def _rungs(design):
    return {'rod': RodSolver(design, ribs='exact'),
            'default': AdaptiveSolver(design, tolerance=5e-5),
            'ccm8': CCMSolver(design, n_segments=8),
            'arc': ArcSolver(design)}


def table(quick):
    """Return the reference table's rows."""
    rows = []
    solvers = {}
    for eps0, pressure, load in _scenes(quick):
        design = ActuatorDesign.paper(prestrain=eps0)
        if eps0 not in solvers:
            solvers[eps0] = (ContinuumSolver(design, ribs='exact', element_size=ELEMENT_SIZE),
                             _rungs(design))
        fe, rungs = solvers[eps0]
        r, row = _fe_row(fe, pressure, load)
        row.update(prestrain=eps0, pressure_kpa=pressure / 1e3, tip_force=list(load))
        row['rungs'] = _rung_rows(rungs, r.tip, pressure, load)
        _print_row(f'eps0 {eps0:.2f} P {pressure / 1e3:5.0f} kPa F {load}: FE tip '
                   f"({row['tip_mm'][0]:7.3f}, {row['tip_mm'][1]:7.3f}) mm, kappa "
                   f"{row['curvature']:7.3f} 1/m", row)
        rows.append(row)
    return rows


def convergence():
    """Return the mesh-convergence rows and the Poisson-coupled comparison."""
    design = ActuatorDesign.paper(prestrain=0.25)
    cases = (('unloaded, ribs averaged', 'average', 0.0), ('unloaded, ribs exact', 'exact', 0.0),
             ('200 kPa, ribs exact', 'exact', 200e3))
    out = []
    for label, ribs, pressure in cases:
        rows = []
        for size in SIZES:
            _, row = _fe_row(ContinuumSolver(design, ribs=ribs, element_size=size), pressure,
                             (0.0, 0.0))
            row['h_mm'] = size * 1e3
            rows.append(row)
            print(f"{label}: h {size * 1e3:.2f} mm tip ({row['tip_mm'][0]:.4f}, "
                  f"{row['tip_mm'][1]:.4f}) mm, {row['dofs']} dofs, {row['seconds']:.1f} s",
                  flush=True)
        finest = np.array(rows[-1]['tip_mm'])
        for row in rows:
            row['distance_to_finest_um'] = float(np.hypot(*(np.array(row['tip_mm']) - finest))
                                                 * 1e3)
        _, poisson = _fe_row(ContinuumSolver(design, ribs=ribs, element_size=1e-3,
                                             poisson=True), pressure, (0.0, 0.0))
        print(f"{label}: poisson=True tip {poisson['tip_mm']}", flush=True)
        out.append({'case': label, 'ribs': ribs, 'pressure_kpa': pressure / 1e3, 'rows': rows,
                    'poisson_coupled_h1mm': poisson})
    return out


def section(quick):
    """Return the cross-section's area growth and the coupled side view's pressure scenes."""
    design = ActuatorDesign.paper()
    curves = []
    for at_rib in (False, True):
        cut = ContinuumSolver(design, element_size=SECTION_SIDE_SIZE, channel='section')
        for pressure in PRESSURES[1:]:
            work = design.pressure_work_factor * pressure
            start = time.perf_counter()
            sol = cut.section_strains(work)[at_rib]
            curves.append({'at_rib': at_rib, 'pressure_kpa': pressure / 1e3,
                           'pressure_work_kpa': work / 1e3, 'area_strain': sol.area_strain,
                           'wall_strain': sol.wall_strain, 'roof_mm': sol.roof * 1e3,
                           'floor_mm': sol.floor * 1e3, 'success': sol.success,
                           'message': sol.message, 'seconds': time.perf_counter() - start})
            where = 'at rib' if at_rib else 'between ribs'
            print(f'section {where} P {pressure / 1e3:.0f} '
                  f'kPa: area strain {sol.area_strain:.3f}, wall {sol.wall_strain:.3f}, '
                  f'{sol.message}', flush=True)
            if not sol.success:
                break
    rows = []
    for eps0 in PRESTRAINS:
        design = ActuatorDesign.paper(prestrain=eps0)
        fe = ContinuumSolver(design, element_size=SECTION_SIDE_SIZE, channel='section')
        rod, corrected = RodSolver(design, ribs='exact'), CorrectedSolver(design)
        for pressure in ((200e3,) if quick else PRESSURES[1:]):
            work = design.pressure_work_factor * pressure
            try:
                moduli = {str(k): v for k, v in fe.band_moduli(work).items()}
            except ValueError:
                moduli = None
            r, row = _fe_row(fe, pressure, (0.0, 0.0))
            row.update(prestrain=eps0, pressure_kpa=pressure / 1e3, band_mu_z_pa=moduli,
                       rungs=_rung_rows({'rod': rod, 'corrected': corrected}, r.tip,
                                        pressure))
            _print_row(f'coupled: eps0 {eps0:.2f} P {pressure / 1e3:5.0f} kPa: FE tip '
                       f"({row['tip_mm'][0]:7.3f}, {row['tip_mm'][1]:7.3f}) mm", row)
            rows.append(row)
    return {'curves': curves, 'rows': rows}


def main(argv=None):
    """Run the parts asked for and merge them into bench/results/continuum.json."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--part', choices=('table', 'convergence', 'variants', 'section',
                                           'all'),
                        default='all')
    parser.add_argument('--quick', action='store_true', help='a few scenes, not stored')
    args = parser.parse_args(argv)
    parts = {}
    commit = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True,
                            text=True, cwd=_HERE).stdout.strip()
    meta = {'commit': commit, 'date': time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime()),
            'machine': machine()}
    if args.part in ('table', 'all'):
        parts['table'] = {'meta': meta, 'element_size_mm': ELEMENT_SIZE * 1e3,
                          'ribs': 'exact', 'pressure_model': 'design (k_p = 2.5)',
                          'rows': table(args.quick)}
    if args.part in ('convergence', 'all') and not args.quick:
        parts['convergence'] = {'meta': meta, 'cases': convergence()}
    if args.part in ('variants', 'all'):
        parts['variants'] = {'meta': meta, 'element_size_mm': ELEMENT_SIZE * 1e3,
                             'rows': variants(args.quick)}
    if args.part in ('section', 'all'):
        parts['section'] = {'meta': meta, 'side_element_size_mm': SECTION_SIDE_SIZE * 1e3,
                            'section_element_size_mm': 0.5, 'ribs': 'exact',
                            'pressure_model': 'design (k_p = 2.5)', 'poisson': False,
                            **section(args.quick)}
    if not args.quick:
        # Read just before writing: parts run in parallel keep each other's results.
        stored = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
        stored.update(parts)
        RESULTS.write_text(json.dumps(stored, indent=1) + '\n')


if __name__ == '__main__':
    main()
