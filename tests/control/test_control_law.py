"""Control law without ROS: limits, anti-windup, goals, safe state, closed-loop responses."""

import math

from control_sim import fresh_solver, independent_rho, Loop, PALM_RADIUS
import numpy as np
import pytest

from fpc_gripper.control.controller import (ControllerConfig, FingerMeasurement, FingerPhase,
                                            GoalStatus, GripperControlLaw, Level, Mode)
from fpc_gripper.control.geometry import PalmGeometry
from fpc_gripper.control.inverse import InverseModel
from fpc_gripper.control.virtual_object import VirtualObject
from fpc_gripper.grasp import FingerGrasp, make_object
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.model import ActuatorDesign

DESIGN = ActuatorDesign.paper(prestrain=0.25)
THIRDS = (0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0)
#: Settling time claimed for an aperture step of up to 120 mm in simulation [s].
SETTLING_S = 1.5


@pytest.fixture(scope='module')
def model():
    return InverseModel(DESIGN, PALM_RADIUS, 400.0e3)


@pytest.fixture(scope='module')
def solver():
    return fresh_solver(DESIGN)


def make_law(model, **changes):
    return GripperControlLaw([model] * 3, PalmGeometry(PALM_RADIUS, THIRDS),
                             ControllerConfig().replace(**changes))


def measured(pressure, now, force=0.0):
    return [FingerMeasurement(pressure, now, (0.0, force))] * 3


def test_idle_commands_nothing(model):
    law = make_law(model)
    out = law.step(1.0, measured(100.0e3, 1.0))
    assert out.commands is None and out.mode is Mode.IDLE
    assert out.aperture == pytest.approx(2.0 * model.rho(100.0e3), abs=2e-5)


@pytest.mark.parametrize('changes, word', [
    ({'max_pressure': -1.0}, 'max_pressure'), ({'slew_rate_pa_s': 0.0}, 'slew_rate_pa_s'),
    ({'kp': -0.1}, 'kp'), ({'safe_state': 'explode'}, 'safe_state'),
    ({'goal_tolerance_m': math.inf}, 'goal_tolerance_m'), ({'bogus': 1.0}, 'bogus'),
])
def test_config_is_validated(changes, word):
    with pytest.raises(ValueError, match=word):
        ControllerConfig().replace(**changes)


def test_goal_arguments_are_validated(model):
    law = make_law(model)
    with pytest.raises(ValueError, match='aperture'):
        law.set_aperture(-0.01, 0.0)
    with pytest.raises(ValueError, match='force'):
        law.set_grasp_force(0.0, 0.0)
    low, high = law.aperture_range()
    assert law.set_aperture(1.0, 0.0) == pytest.approx(high)
    assert law.set_aperture(0.0, 0.0) == pytest.approx(low)


def test_slew_limit_and_range_hold_on_every_step(model):
    rate, limit = 250.0e3, 300.0e3
    law = make_law(model, slew_rate_pa_s=rate, max_pressure=limit, kp=20.0, ki=50.0)
    loop = Loop(law)
    for aperture in (0.17, 0.005, 0.12):   # 0.17 m needs more than the 300 kPa allowed
        law.set_aperture(aperture, loop.clock.now)
        loop.run(1.5)
    commands = loop.commands()
    steps = np.abs(np.diff(commands, axis=0))
    assert steps.max() <= rate * loop.period * (1 + 1e-9)
    assert commands.max() <= limit and commands.min() >= 0.0
    assert commands.max() == pytest.approx(limit)          # the limit was actually hit


def _recover_from_saturation(model, anti_windup):
    """Saturate the command for 3 s with a stuck reading, free it, watch the aperture."""
    law = make_law(model, anti_windup=anti_windup, max_pressure=350.0e3)
    loop = Loop(law)
    loop.stuck_pressure = 0.0
    law.set_aperture(0.120, loop.clock.now)
    loop.run(3.0)
    assert loop.commands()[-1] == pytest.approx(350.0e3)    # saturated at the limit
    wound = law._fingers[0].integral
    loop.stuck_pressure = None
    start = len(loop.log)
    loop.run(3.0)
    aperture = np.array([row['out'].aperture for row in loop.log[start:]])
    t = loop.times(start) - loop.times(start)[0]
    outside = np.nonzero(np.abs(aperture - 0.120) > 1e-3)[0]
    return (t[outside[-1] + 1] if outside.size < t.size else math.inf), wound


def test_anti_windup_holds_the_integrator_and_speeds_the_recovery(model):
    settle, wound = _recover_from_saturation(model, anti_windup=True)
    settle_free, wound_free = _recover_from_saturation(model, anti_windup=False)
    assert abs(wound) < 1.0e3                  # held while the error pushed into the limit
    assert wound_free == pytest.approx(350.0e3)   # without it: wound up to its own clamp
    assert settle < SETTLING_S
    assert settle_free == math.inf             # still far off after 3 s


def test_aperture_step_settles_without_overshoot(model, solver):
    law = make_law(model)
    loop = Loop(law)
    law.set_aperture(0.040, loop.clock.now)
    loop.run(2.0)
    for target in (0.120, 0.060):
        start = len(loop.log)
        initial = loop.log[-1]['out'].aperture
        law.set_aperture(target, loop.clock.now)
        loop.run(3.0)
        # Independent aperture: the raw solver at the regulator's true pressure.
        aperture = 2.0 * independent_rho(solver, loop.series('true', start)[:, 0])
        t = loop.times(start) - loop.times(start)[0]
        outside = np.nonzero(np.abs(aperture - target) > 1e-3)[0]
        settle = t[outside[-1] + 1] if outside.size else 0.0
        overshoot = max(0.0, (aperture - target).max() if target > initial
                        else (target - aperture).max()) / abs(target - initial)
        assert settle < SETTLING_S
        assert overshoot < 0.10
        assert loop.log[-1]['out'].status is GoalStatus.REACHED


def test_tip_force_step_is_rejected(model, solver):
    law = make_law(model)
    force = [0.0]
    loop = Loop(law, tip_force=lambda i, p: (0.0, force[0]))
    law.set_aperture(0.080, loop.clock.now)
    loop.run(2.5)
    force[0] = 0.15
    start = len(loop.log)
    loop.run(3.0)
    pressures = loop.series('true', start)[:, 0]
    aperture = 2.0 * independent_rho(solver, pressures, [(0.0, 0.15)] * len(pressures))
    assert np.abs(aperture - 0.080).max() > 2e-3            # the step did push the tip out
    t = loop.times(start) - loop.times(start)[0]
    assert np.all(np.abs(aperture[t > SETTLING_S] - 0.080) < 1e-3)


@pytest.mark.parametrize('kind, known', [('cylinder', True), ('sphere', True),
                                         ('cylinder', False)])
def test_grasp_reaches_the_total_normal_force(model, kind, known):
    """The law regulates the sum of the normal forces; the plant is the contact model."""
    config = load_gripper_config()
    obj = make_object(kind, 0.040 if kind == 'cylinder' else 0.050)
    virtual = VirtualObject(obj, config)
    grasps = [FingerGrasp(f.design, obj.section(f.mount_angle, config.palm_radius),
                          config.max_pressure) for f in config.fingers] if known else None
    law = GripperControlLaw([model] * 3, PalmGeometry(PALM_RADIUS, THIRDS),
                            ControllerConfig(), grasps)
    loop = Loop(law, tip_force=lambda i, p: virtual.contact(i, p).force)
    law.set_aperture(0.120, loop.clock.now)
    loop.run(2.0)
    law.set_grasp_force(1.2, loop.clock.now)
    out = loop.run(6.0)
    assert out.status is GoalStatus.REACHED, out.message
    assert all(f.phase is FingerPhase.CONTACT for f in out.fingers)
    # Independent: the normal forces the object takes at the regulator's true pressures.
    forces = [virtual.contact(i, loop.regulator.true_pressure(i)).normal_force
              for i in range(3)]
    np.testing.assert_allclose(forces, 0.4, rtol=0.03)
    assert sum(forces) == pytest.approx(1.2, rel=0.03)


def test_stalled_when_the_pressure_never_comes(model):
    law = make_law(model, stall_timeout_s=1.0)
    loop = Loop(law)
    loop.stuck_pressure = 0.0
    law.set_aperture(0.100, loop.clock.now)
    out = loop.run(0.9)
    assert out.status is GoalStatus.ACTIVE
    out = loop.run(0.3)
    assert out.status is GoalStatus.STALLED and out.level is Level.WARN


@pytest.mark.parametrize('safe_state', ['vent', 'hold'])
def test_lost_feedback_enters_the_safe_state(model, safe_state):
    law = make_law(model, feedback_timeout_s=0.3, safe_state=safe_state)
    loop = Loop(law)
    law.set_aperture(0.100, loop.clock.now)
    loop.run(1.0)
    loop.freeze_feedback = True            # readings stop arriving (their stamps age)
    out = loop.run(0.26)
    assert out.mode is Mode.APERTURE
    out = loop.run(0.1)
    last = [row['out'].commands for row in loop.log if row['out'].mode is Mode.APERTURE][-1]
    assert out.mode is Mode.SAFE and out.status is GoalStatus.FAULT
    assert out.level is Level.ERROR and 'feedback lost' in out.message
    expected = (0.0,) * 3 if safe_state == 'vent' else last
    assert out.commands == pytest.approx(expected)
    # Fresh readings alone do not leave the safe state; a new goal does.
    loop.freeze_feedback = False
    assert loop.run(0.2).mode is Mode.SAFE
    law.set_aperture(0.100, loop.clock.now)
    assert loop.run(0.1).mode is Mode.APERTURE


def test_no_reading_at_all_is_lost_feedback(model):
    law = make_law(model, feedback_timeout_s=0.2)
    law.set_aperture(0.1, 0.0)
    assert law.step(0.1, [FingerMeasurement()] * 3).mode is Mode.APERTURE
    out = law.step(0.3, [FingerMeasurement()] * 3)
    assert out.mode is Mode.SAFE and out.commands == (0.0, 0.0, 0.0)


class FailingModel:
    """A real InverseModel whose pressure_for_rho raises while `failing` is set."""

    def __init__(self, model):
        self.model = model
        self.failing = False

    def pressure_for_rho(self, *args, **kwargs):
        if self.failing:
            raise ValueError('f(a) and f(b) must have different signs')
        return self.model.pressure_for_rho(*args, **kwargs)

    def __getattr__(self, name):
        return getattr(self.model, name)


def test_an_exception_in_a_step_holds_the_last_commands(model):
    """A model error becomes an ERROR output with the last good commands, and then recovers."""
    failing = FailingModel(model)
    law = make_law(failing)
    law.set_aperture(0.080, 0.0)
    good = None
    for k in range(1, 6):
        good = law.step(0.02 * k, measured(120.0e3, 0.02 * k))
    assert good.commands is not None and good.level is Level.OK
    state = [(f.command, f.integral, f.phase) for f in law._fingers]
    failing.failing = True
    out = law.step(0.12, measured(121.0e3, 0.12))
    assert out.level is Level.ERROR and 'model error' in out.message
    assert 'different signs' in out.message
    assert out.commands == good.commands              # held exactly: the values are copied
    assert [(f.command, f.integral, f.phase) for f in law._fingers] == state   # step undone
    assert out.mode is Mode.APERTURE                  # the goal is kept
    failing.failing = False
    after = law.step(0.14, measured(121.0e3, 0.14))
    assert after.level is Level.OK and after.commands is not None
