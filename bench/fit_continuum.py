"""
Refit the continuum-corrected rung to the stored FE table, and time it against the default.

Run by hand from the repository root:

    .venv/bin/python bench/fit_continuum.py

Reads bench/results/continuum.json (the FE table; no FE is run), fits the four
`ContinuumCorrection` parameters from the paper's physics (`calibration.continuum`), and
writes bench/results/continuum_fit.json: the fitted values, the tip distance to the FE of
every unpressurised scene before (the rod, from the table) and after (the corrected rung,
fitted and the stored `CONTINUUM_FIT`), the largest per prestrain, and the median warm cost
per solve of the corrected rung and of the default model measured in the same run.
`model/corrected.py` stores the fitted values as numbers.
"""

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
from timing import machine, median_time  # noqa: E402, I100

from fpc_gripper.calibration.continuum import (CORRECTION_NAMES,  # noqa: E402
                                               correction_tips, fe_scenes, fit_correction)
from fpc_gripper.model import ActuatorDesign  # noqa: E402
from fpc_gripper.model.corrected import CONTINUUM_FIT  # noqa: E402
from fpc_gripper.model.pipeline import finger_model, ModelSettings  # noqa: E402

TABLE = _HERE / 'results' / 'continuum.json'
RESULTS = _HERE / 'results' / 'continuum_fit.json'


def _timing():
    """Median warm cost per solve [us] of the default model and the corrected rung."""
    out = {}
    scenes = [(0.0, (0.0, 0.0)), (0.0, (0.5, 0.0)), (0.0, (0.0, -0.5)), (200e3, (0.0, 0.0))]
    for prestrain in (0.15, 0.25, 0.40):
        design = ActuatorDesign.paper(prestrain=prestrain)
        for name, settings in (('default', ModelSettings()),
                               ('corrected', ModelSettings(physics='continuum'))):
            solver = finger_model(design, settings)
            for pressure, force in scenes:
                start = solver.solve(pressure, force)
                # Warm: from the scene next to it, as the node's stream of commands.
                nearby = (force[0] + 0.01, force[1])

                for outputs in ('all', 'tip'):
                    def run(solver=solver, pressure=pressure, nearby=nearby, start=start,
                            outputs=outputs):
                        solver.solve(pressure, nearby, initial=start, outputs=outputs)

                    out.setdefault(f'{name} outputs={outputs}', []).append(
                        median_time(run, repeats=200) * 1e6)
    return {name: {'median_us': float(np.median(v)), 'per_scene_us': v}
            for name, v in out.items()}


def main():
    table = json.loads(TABLE.read_text())
    scenes = fe_scenes(table)
    fit = fit_correction(scenes)
    measured = np.array([s.tip for s in scenes])
    stored = np.linalg.norm(correction_tips(CONTINUUM_FIT, scenes) - measured, axis=1)
    rows = [r for r in table['table']['rows'] if r['success'] and r['pressure_kpa'] == 0.0]
    rod = np.array([r['rungs']['rod']['error_mm'] for r in rows]) * 1e-3
    per_scene = [{'prestrain': s.prestrain, 'tip_force': list(s.tip_force),
                  'fe_tip_mm': (s.tip * 1e3).tolist(), 'rod_error_mm': float(r * 1e3),
                  'fitted_error_mm': float(f * 1e3), 'stored_error_mm': float(c * 1e3)}
                 for s, r, f, c in zip(scenes, rod, fit.errors, stored)]
    summary = {}
    for prestrain in sorted({s.prestrain for s in scenes}):
        for kind, pick in (('unloaded', lambda s: not any(s.tip_force)),
                           ('tip_loaded', lambda s: any(s.tip_force))):
            k = [i for i, s in enumerate(scenes) if s.prestrain == prestrain and pick(s)]
            summary[f'{prestrain:.2f} {kind}'] = {
                'rod_max_mm': float(rod[k].max() * 1e3),
                'corrected_max_mm': float(stored[k].max() * 1e3)}
    commit = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True,
                            text=True, check=False).stdout.strip()
    out = {'meta': {'commit': commit, 'date': time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime()),
                    'machine': machine(), 'table_commit': table['table']['meta']['commit']},
           'fit': {'success': fit.success, 'message': fit.message, 'nfev': fit.nfev,
                   'njev': fit.njev, 'jacobian': 'exact (engine.sensitivity, shear_tip)',
                   'start': 'paper physics (1, 1, 1, 0)',
                   'parameters': dict(zip(CORRECTION_NAMES,
                                          fit.correction.values.tolist())),
                   'max_error_mm': float(fit.errors.max() * 1e3),
                   'rms_error_mm': float(np.sqrt(np.mean(fit.errors ** 2)) * 1e3)},
           'stored': {'parameters': dict(zip(CORRECTION_NAMES, CONTINUUM_FIT.values.tolist())),
                      'max_error_mm': float(stored.max() * 1e3)},
           'rod_max_error_mm': float(rod.max() * 1e3),
           'per_prestrain': summary, 'scenes': per_scene, 'cost': _timing()}
    RESULTS.write_text(json.dumps(out, indent=1) + '\n')
    print(json.dumps({k: out[k] for k in ('fit', 'stored', 'per_prestrain', 'cost')},
                     indent=1))


if __name__ == '__main__':
    main()
