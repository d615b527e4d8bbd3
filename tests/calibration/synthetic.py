"""Synthetic measurements of a finger from the rod (the accuracy reference), with known truth."""

import math

import numpy as np

from fpc_gripper.model import ActuatorDesign, Material, RodSolver

#: The paper's motion-capture pressures: 0 to 50 psi in steps of 10 psi [Pa].
MARKER_PRESSURES = tuple(6894.757 * psi for psi in (0, 10, 20, 30, 40, 50))
#: Seven markers along the free length, root to tip [m].
MARKER_S = tuple(0.010 + 0.013 * k for k in range(7))
#: The paper's loading protocol: K_x at 0 to 82.7 kPa in steps of 4 psi [Pa].
LOADING_PRESSURES = (0.0, 27.6e3, 55.2e3, 82.7e3)
#: The motion-capture frame: 2 degrees and 1 mm off the finger's.
ROTATION = math.radians(2.0)
OFFSET = (0.8e-3, -0.6e-3)
MARKER_NOISE = 0.2e-3
FORCE_NOISE = 0.02     # relative


def truth_design(base=None):
    """Return the true finger: prestrain and both moduli 20-25 % off the base, k_p = 1.8."""
    base = ActuatorDesign.paper(prestrain=0.25) if base is None else base
    return base.replace(prestrain=0.30, constraining_layer=Material(200e6, 200e6, 0.43),
                        fluidic_layer=Material(1.5e6, 1.5e6, 0.48), pressure_work_factor=1.8)


def measurements(truth, seed=7):
    """
    Marker rows and loading rows of the true finger, with noise.

    Returns
    -------
    markers : list of (pressure, marker, s, x, z)
        In the motion-capture frame [Pa, -, m, m, m].
    loading : list of (pressure, axis, displacement, force)
    clean : dict
        The noise-free marker positions in the finger frame, (F, 7, 2) [m], and forces [N].

    """
    rng = np.random.default_rng(seed)
    rod = RodSolver(truth)
    c, s = math.cos(ROTATION), math.sin(ROTATION)
    rotation = np.array([[c, -s], [s, c]])
    rows, clean = [], []
    for pressure in MARKER_PRESSURES:
        result = rod.solve(pressure)
        assert result.success
        points = result.position_at(np.array(MARKER_S))
        clean.append(points)
        seen = points @ rotation.T + np.array(OFFSET)
        seen = seen + rng.normal(0.0, MARKER_NOISE, seen.shape)
        for k, (x, z) in enumerate(seen):
            rows.append((pressure, k, MARKER_S[k], x, z))
    loading, forces = [], []
    for pressure in LOADING_PRESSURES:
        result = rod.rigidity(pressure, 'x', 0.010)
        assert result.success
        forces.append(result.force)
        loading.append((pressure, 'x', 0.010,
                        result.force * (1.0 + FORCE_NOISE * rng.normal())))
    return rows, loading, {'markers': np.array(clean), 'forces': np.array(forces)}


def write_csv(path, header, rows):
    """Write rows under a header, floats with repr (exact)."""
    lines = [','.join(header)] + [','.join(repr(float(v)) if isinstance(v, float) else str(v)
                                           for v in row) for row in rows]
    path.write_text('\n'.join(lines) + '\n')
    return path
