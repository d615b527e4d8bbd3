"""The design's pressure_work_factor k_p, and pressure_model as names for 2.5 and 1."""

import numpy as np
import pytest

from fpc_gripper.model import (ActuatorDesign, AdaptiveSolver, ArcSolver, batch, CCMSolver,
                               PCCSolver, RodSolver, Scene)
from fpc_gripper.model.pipeline import finger_model, ModelSettings

DESIGN = ActuatorDesign.paper(prestrain=0.25)
#: Every rung, with the arguments that make it cheap.
RUNGS = [(CCMSolver, {'n_segments': 8}), (CCMSolver, {'n_segments': 4,
                                                      'reconstruction': 'consistent'}),
         (PCCSolver, {'n_segments': 22}), (ArcSolver, {}), (RodSolver, {})]


def state(result):
    return np.concatenate([np.ravel(part) for part in (
        result.state if isinstance(result.state, tuple) else (result.state,))])


def test_default_factor_is_the_adiabatic_2_5():
    assert DESIGN.pressure_work_factor == 2.5
    assert CCMSolver(DESIGN).pressure_coefficient == 2.5
    assert CCMSolver(DESIGN, pressure_model='isobaric').pressure_coefficient == 1.0


@pytest.mark.parametrize('cls, kwargs', RUNGS)
def test_default_design_gives_the_adiabatic_answers_exactly(cls, kwargs):
    # The default (no pressure_model: the design's 2.5) is the named adiabatic model,
    # bit for bit, loaded and unloaded.
    for force in ((0.0, 0.0), (0.1, -0.2)):
        plain = cls(DESIGN, **kwargs).solve(150e3, force)
        named = cls(DESIGN, pressure_model='adiabatic', **kwargs).solve(150e3, force)
        assert plain.success and named.success
        np.testing.assert_array_equal(state(plain), state(named))


@pytest.mark.parametrize('cls, kwargs', RUNGS)
def test_design_factor_is_used_and_an_explicit_model_wins(cls, kwargs):
    unit = DESIGN.replace(pressure_work_factor=1.0)
    isobaric = cls(DESIGN, pressure_model='isobaric', **kwargs).solve(200e3)
    np.testing.assert_array_equal(state(cls(unit, **kwargs).solve(200e3)), state(isobaric))
    np.testing.assert_array_equal(state(cls(unit, pressure_model='design', **kwargs)
                                        .solve(200e3)), state(isobaric))
    adiabatic = cls(DESIGN, **kwargs).solve(200e3)
    np.testing.assert_array_equal(
        state(cls(unit, pressure_model='adiabatic', **kwargs).solve(200e3)), state(adiabatic))


def test_only_k_p_times_pressure_matters():
    # An independent check of where k_p enters: k_p = 1.7 at P is k_p = 2.5 at 1.7 P / 2.5.
    tip = CCMSolver(DESIGN.replace(pressure_work_factor=1.7)).solve(250e3).tip
    np.testing.assert_allclose(tip, CCMSolver(DESIGN).solve(1.7 * 250e3 / 2.5).tip,
                               rtol=0, atol=1e-12)


def test_pipeline_selection_and_batch_use_the_design_factor():
    unit = DESIGN.replace(pressure_work_factor=1.0)
    assert ModelSettings().pressure_model == 'design'
    assert ModelSettings(pressure_model=None).pressure_model == 'design'
    assert Scene(unit).pressure_model == 'design'
    adaptive = finger_model(unit)
    assert isinstance(adaptive, AdaptiveSolver)
    want = AdaptiveSolver(DESIGN, tolerance=5e-5, pressure_model='isobaric').solve(
        150e3, (0.0, 0.2))
    got = adaptive.solve(150e3, (0.0, 0.2))
    assert got.model_choice == want.model_choice
    np.testing.assert_array_equal(got.tip, want.tip)
    # A batch of the two designs: each scene equals its own single solve.
    grid = batch.solve_grid([DESIGN, unit], [0.0, 150e3], [(0.0, 0.0), (0.0, 0.2)])
    for d, design in enumerate((DESIGN, unit)):
        for p, pressure in enumerate((0.0, 150e3)):
            for f, force in enumerate(((0.0, 0.0), (0.0, 0.2))):
                single = finger_model(design).solve(pressure, force)
                np.testing.assert_allclose(grid.tip[d, p, f], single.tip, rtol=0, atol=1e-12)
    assert np.abs(grid.tip[0, 1] - grid.tip[1, 1]).max() > 1e-3
    # K_x depends on k_p P only: k_p = 1 at 50 kPa is the default finger at 20 kPa.
    kx = batch.rigidity_grid([unit, DESIGN], [50e3, 20e3]).value
    assert kx[0, 0] == pytest.approx(kx[1, 1], rel=1e-9)
    assert abs(kx[0, 0] - kx[1, 0]) > 1e-3 * kx[1, 0]


@pytest.mark.parametrize('bad', ['polytropic', 2.5, ''])
def test_bad_pressure_models_are_named(bad):
    for build in (lambda: CCMSolver(DESIGN, pressure_model=bad),
                  lambda: PCCSolver(DESIGN, pressure_model=bad),
                  lambda: RodSolver(DESIGN, pressure_model=bad),
                  lambda: ModelSettings(pressure_model=bad),
                  lambda: Scene(DESIGN, pressure_model=bad),
                  lambda: AdaptiveSolver(DESIGN, pressure_model=bad)):
        with pytest.raises(ValueError, match='`pressure_model` must be one of '
                                             r"\['design', 'adiabatic', 'isobaric'\]"):
            build()
