"""Write the example calibration data set: a known finger measured by the rod, with noise."""

import argparse
import math
import pathlib

import numpy as np

from fpc_gripper.model import ActuatorDesign, Material, RodSolver
from fpc_gripper.model.section.materials import DEFAULT_EMC_COEFFICIENTS, emc_stress

#: The motion-capture pressures: 0 to 50 psi in steps of 10 psi [Pa].
MARKER_PRESSURES = tuple(6894.757 * psi for psi in (0, 10, 20, 30, 40, 50))
#: Seven markers along the free length, root to tip [m].
MARKER_S = tuple(0.010 + 0.013 * k for k in range(7))
#: The loading tests: K_x at 0 to 82.7 kPa, 10 mm of tip displacement [Pa].
LOADING_PRESSURES = (0.0, 27.6e3, 55.2e3, 82.7e3)
DISPLACEMENT = 0.010
#: The motion-capture frame: 2 degrees and (0.8, -0.6) mm off the finger's.
ROTATION = math.radians(2.0)
OFFSET = (0.8e-3, -0.6e-3)
#: Noise: marker coordinates [m], relative force, tensile stress [Pa].
MARKER_NOISE = 0.2e-3
FORCE_NOISE = 0.02
STRESS_NOISE = 5e3
#: Tensile test strains [-].
STRAINS = tuple(0.05 * k for k in range(1, 13))
SEED = 7


def truth():
    """Return the true finger: the paper's, prestrain 0.30, CL 200 MPa, FL 1.5 MPa, k_p 1.8."""
    return ActuatorDesign.paper(prestrain=0.30).replace(
        constraining_layer=Material(200e6, 200e6, 0.43),
        fluidic_layer=Material(1.5e6, 1.5e6, 0.48), pressure_work_factor=1.8)


def _write(path, header, rows):
    lines = [','.join(header)] + [','.join(f'{v:.9g}' if isinstance(v, float) else str(v)
                                           for v in row) for row in rows]
    path.write_text('\n'.join(lines) + '\n')
    return path


def write_data(out_dir):
    """Write markers.csv, loading.csv and tensile.csv of `truth` into `out_dir`."""
    out_dir = pathlib.Path(out_dir)
    rng = np.random.default_rng(SEED)
    finger = truth()
    rod = RodSolver(finger)
    c, s = math.cos(ROTATION), math.sin(ROTATION)
    rotation = np.array([[c, -s], [s, c]])
    markers = []
    for pressure in MARKER_PRESSURES:
        points = rod.solve(pressure).position_at(np.array(MARKER_S))
        seen = points @ rotation.T + np.array(OFFSET) + rng.normal(0.0, MARKER_NOISE,
                                                                   points.shape)
        markers += [(pressure, k, MARKER_S[k], x, z) for k, (x, z) in enumerate(seen)]
    loading = []
    for pressure in LOADING_PRESSURES:
        force = rod.rigidity(pressure, 'x', DISPLACEMENT).force
        loading.append((pressure, 'x', DISPLACEMENT,
                        force * (1.0 + FORCE_NOISE * rng.normal())))
    tensile = [(strain, float(emc_stress(DEFAULT_EMC_COEFFICIENTS, strain))
                + STRESS_NOISE * rng.normal()) for strain in STRAINS]
    return [_write(out_dir / 'markers.csv', ('pressure_pa', 'marker', 's_m', 'x_m', 'z_m'),
                   markers),
            _write(out_dir / 'loading.csv',
                   ('pressure_pa', 'axis', 'displacement_m', 'force_n'), loading),
            _write(out_dir / 'tensile.csv', ('strain', 'stress_pa'), tensile)]


if __name__ == '__main__':
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--out', default=pathlib.Path(__file__).resolve().parent,
                        help='directory (default: beside this script)')
    for path in write_data(parser.parse_args().out):
        print(path)
