"""Independent equilibrium checks of any solver's result, and seeded random in-range scenes."""

import functools
import math

import numpy as np
from pcc_reference import ReferencePCCSolver
from rod_reference import ReferenceRodSolver
from scipy.optimize._numdiff import approx_derivative
from test_stability import independent_gradient

from fpc_gripper.model import ActuatorDesign, ArcSolver, CCMSolver, PCCSolver, RodSolver
from fpc_gripper.model.validation import ENVELOPE

#: Prestrains of the sweeps (designs are reused so that solvers are built once each) [-].
PRESTRAINS = (0.05, 0.10, 0.15, 0.20, 0.25, 0.30, 0.35, 0.40, 0.45, 0.50, 0.55, 0.60)
#: Largest relative gradient an independent check accepts at a reported success.
GRADIENT_TOLERANCE = 1e-7


#: Tip-force magnitude bands of `random_scenes`: (share, low [N], high [N]).
BANDS = ((0.7, 0.0, 1.0), (0.2, 1.0, 2.0), (0.1, 2.0, ENVELOPE.max_tip_force))


def random_scenes(seed, count, bands=BANDS):
    """
    Return `count` in-range scenes (design, gauge pressure [Pa], tip force [N]).

    Prestrain from `PRESTRAINS`, pressure uniform up to the envelope (twice the design's
    400 kPa), tip force in a uniform direction with a magnitude uniform in one of
    `bands` (by default [0, 1] N for 70 % of the scenes, [1, 2] N for 20 % and up to the
    envelope's 5 N for 10 %).
    """
    rng = np.random.default_rng(seed)
    shares = np.array([band[0] for band in bands])
    out = []
    for _ in range(count):
        design = _design(PRESTRAINS[rng.integers(len(PRESTRAINS))])
        pressure = rng.uniform(0.0, ENVELOPE.pressure_factor * design.max_pressure)
        low, high = bands[rng.choice(len(bands), p=shares / shares.sum())][1:]
        magnitude, angle = rng.uniform(low, high), rng.uniform(0.0, 2.0 * math.pi)
        out.append((design, float(pressure),
                    (magnitude * math.cos(angle), magnitude * math.sin(angle))))
    return out


@functools.lru_cache(maxsize=None)
def _design(prestrain):
    return ActuatorDesign.paper(prestrain)


@functools.lru_cache(maxsize=32)
def _reference(kind, design, n_segments):
    if kind == 'pcc':
        return ReferencePCCSolver(design, n_segments)
    return ReferenceRodSolver(design)


def independent_residual(model, result):
    """
    Return the relative gradient of `model`'s result, computed without the solver's own kernels.

    CCM: finite differences of the potential rebuilt from the section law and SPEC's
    kinematics (test_stability.IndependentCCM). PCC and rod: the numpy references of
    their potentials (the code before compilation). Arc: central differences of its
    potential. Relative to the solver's gradient scale.
    """
    choice = result.model_choice
    solver = model if choice is None else model.solver_for(choice.rung, choice.n_segments)
    if isinstance(solver, CCMSolver):
        return independent_gradient(solver, result)
    loads = solver.tip_loads(np.asarray(result.tip_force))
    if isinstance(solver, (PCCSolver, RodSolver)):
        kind = 'pcc' if isinstance(solver, PCCSolver) else 'rod'
        reference = _reference(kind, solver.design, solver.n_segments)
        x = reference._pack(result.state)
        grad = reference.derivatives(x, result.pressure, loads)[1]
        return float(np.abs(grad).max() / reference.gradient_scale)
    assert isinstance(solver, ArcSolver), type(solver)
    x = solver._pack(result.state)
    grad = approx_derivative(lambda v: solver.energy(v, result.pressure, loads), x,
                             method='3-point', abs_step=1e-7)
    return float(np.abs(grad).max() / solver.gradient_scale)
