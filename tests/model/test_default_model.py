"""The default finger model lands within its tolerance of the converged rod, scene by scene."""

import itertools

import numpy as np
import pytest

from fpc_gripper.model import ActuatorDesign, AdaptiveSolver, RodSolver
from fpc_gripper.model.pipeline import DEFAULT_TOLERANCE, finger_model, ModelSettings

PRESTRAINS = (0.15, 0.25, 0.40)


def ladder_scenes():
    """The 87 scenes of bench/bench_ladder.py: unloaded, and tip loads along X and Z."""
    out = [(e, p, (0.0, 0.0)) for e in PRESTRAINS for p in (0.0, 100e3, 200e3, 300e3, 400e3)]
    for e, p, f in itertools.product(PRESTRAINS, (0.0, 200e3, 400e3), (-1.0, -0.5, 0.5, 1.0)):
        out += [(e, p, (f, 0.0)), (e, p, (0.0, f))]
    return out


def other_scenes():
    """Scenes off the ladder's grid: other prestrains, pressures, loads and channel widths."""
    rng = np.random.default_rng(20261201)
    out = []
    for _ in range(24):
        prestrain = float(rng.uniform(0.15, 0.40))
        pressure = float(rng.uniform(0.0, 400e3))
        angle = float(rng.uniform(0.0, 2.0 * np.pi))
        load = float(rng.uniform(0.0, 1.0)) if rng.random() < 0.8 else 0.0
        width = (0.024, 0.026, 0.028)[int(rng.integers(3))]
        out.append((prestrain, pressure, (load * np.cos(angle), load * np.sin(angle)), width))
    return out


@pytest.fixture(scope='module')
def designs():
    cache = {}

    def get(prestrain, width=None):
        key = (prestrain, width)
        if key not in cache:
            design = ActuatorDesign.paper(prestrain=prestrain)
            cache[key] = design if width is None else design.replace(Cy=width)
        return cache[key]
    return get


def test_the_default_tolerance_is_rod_accuracy():
    assert DEFAULT_TOLERANCE == 5e-5            # SPEC: model_node runs 0.05 mm by default
    assert isinstance(finger_model(ActuatorDesign.paper(0.25), ModelSettings()), AdaptiveSolver)


@pytest.mark.parametrize('prestrain, pressure, force', ladder_scenes())
def test_default_model_meets_its_tolerance_on_the_ladder(designs, prestrain, pressure, force):
    design = designs(prestrain)
    result = finger_model(design, ModelSettings()).solve(pressure, force)
    rod = RodSolver(design).solve(pressure, force)
    assert result.success and rod.success, (result.message, rod.message)
    assert np.linalg.norm(result.tip - rod.tip) <= DEFAULT_TOLERANCE, result.model_choice


@pytest.mark.parametrize('prestrain, pressure, force, width', other_scenes())
def test_default_model_meets_its_tolerance_off_the_ladder(designs, prestrain, pressure,
                                                          force, width):
    design = designs(prestrain, width)
    result = finger_model(design, ModelSettings()).solve(pressure, force)
    rod = RodSolver(design).solve(pressure, force)
    assert result.success and rod.success, (result.message, rod.message)
    assert np.linalg.norm(result.tip - rod.tip) <= DEFAULT_TOLERANCE, result.model_choice


@pytest.mark.parametrize('shape', ['smooth', 'flat-ends', 'steps'])
def test_the_feature_table_evaluates_as_scipy_does(shape):
    # The unloaded feature table's cubic (`selection._pchip`, evaluated by `_Cubic` in plain
    # floats) gives scipy's PCHIP bits at random points, at every breakpoint and at both
    # ends: through a turn of the slope, flat pieces, and ends where the one-sided estimate
    # is clipped to 0 or to 3 times the end slope.
    from scipy.interpolate import PchipInterpolator

    from fpc_gripper.model.selection import _Cubic, _pchip
    grid = np.linspace(0.0, 6e5, 121)
    values = {'smooth': np.sin(grid / 1.7e5) * 2.0 + grid * 1e-6,
              'flat-ends': np.clip(np.sin(grid / 1.1e5), -0.6, 0.8),
              'steps': np.round(np.sin(grid / 0.9e5) * 3.0) + np.cos(grid / 4e4)}[shape]
    reference = PchipInterpolator(grid, values)
    np.testing.assert_allclose(_pchip(grid, values).c, reference.c, rtol=1e-15, atol=0)
    cubic = _Cubic(_pchip(grid, values))
    points = np.concatenate([np.random.default_rng(7).uniform(0.0, 6e5, 5000), grid])
    np.testing.assert_array_equal([cubic(float(p)) for p in points], reference(points))


@pytest.mark.parametrize('tolerance', [5e-5, 1e-3, 2e-2])
def test_many_choices_are_each_scene_chosen_alone(tolerance):
    # `choose_many` (the grids' path: the feature table read at once, cells binned at
    # once) against `choose` scene by scene on fresh solvers, inside and outside the error
    # model's ranges: past its pressures and loads, and prestrains below and above it.
    pressures = np.linspace(0.0, 800e3, 81)
    forces = [(0.0, 0.0), (0.3, -0.2), (0.0, -2.0), (1.2, 0.9), (-4.0, 2.0)]
    scenes = [(float(p), f) for p in pressures for f in forces]
    models = set()
    for prestrain in (0.1, 0.15, 0.3, 0.45):
        design = ActuatorDesign.paper(prestrain).replace(Cy=0.026)
        many = AdaptiveSolver(design, tolerance).choose_many(*zip(*scenes))
        alone = AdaptiveSolver(design, tolerance)
        assert many == [alone.choose(p, f) for p, f in scenes]
        models |= {(c.rung, c.n_segments) for c in many}
    assert len(models) >= 2 and ('rod', 0) in models, models
