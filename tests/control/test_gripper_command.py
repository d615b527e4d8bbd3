"""GripperCommand goals on the control law without ROS: acceptance, reach, stall, cancel."""

import math

from control_sim import Loop, PALM_RADIUS
import numpy as np
import pytest

from fpc_gripper.control.controller import (ControllerConfig, GoalStatus, GripperControlLaw,
                                            Mode)
from fpc_gripper.control.geometry import PalmGeometry
from fpc_gripper.control.gripper_command import check_goal, CommandGoal, Outcome
from fpc_gripper.control.inverse import InverseModel
from fpc_gripper.control.virtual_object import VirtualObject
from fpc_gripper.grasp import make_object
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.model import ActuatorDesign

DESIGN = ActuatorDesign.paper(prestrain=0.25)
THIRDS = (0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0)


@pytest.fixture(scope='module')
def model():
    return InverseModel(DESIGN, PALM_RADIUS, 400.0e3)


def make_loop(model, obj=None, **changes):
    law = GripperControlLaw([model] * 3, PalmGeometry(PALM_RADIUS, THIRDS),
                            ControllerConfig().replace(**changes))
    if obj is None:
        return Loop(law)
    virtual = VirtualObject(obj, load_gripper_config())
    return Loop(law, tip_force=lambda i, p: virtual.contact(i, p).force)


def run_goal(loop, goal, seconds):
    """Step the loop until the goal ends; return its result (None if it did not end)."""
    for _ in range(round(seconds / loop.period)):
        out = loop.run(loop.period)
        result = goal.update(out, loop.clock.now)
        if result is not None:
            return result
    return None


def test_goals_outside_the_range_are_refused_naming_the_argument(model):
    law = make_loop(model).law
    low, high = law.aperture_range()
    assert check_goal(law, 0.5 * (low + high), 0.0) == ''
    for position, effort, words in ((high + 1e-3, 0.0, ('position', 'mm')),
                                    (low - 1e-3, 0.0, ('position', 'mm')),
                                    (math.nan, 0.0, ('position',)),
                                    (0.08, -1.0, ('max_effort', 'N')),
                                    (0.08, math.inf, ('max_effort', 'N'))):
        reason = check_goal(law, position, effort)
        assert all(word in reason for word in words), reason
        with pytest.raises(ValueError, match=words[0]):
            CommandGoal(law, position, effort, 0.0)
    assert law.mode is Mode.IDLE            # a refused goal leaves the law alone


def test_a_free_goal_is_reached(model):
    loop = make_loop(model)
    goal = CommandGoal(loop.law, 0.090, 0.0, loop.clock.now)
    result = run_goal(loop, goal, 5.0)
    assert result.outcome is Outcome.SUCCEEDED and result.reached_goal
    assert not result.stalled and result.effort == 0.0
    assert result.position == pytest.approx(0.090, abs=loop.law.config.goal_tolerance_m)


@pytest.mark.parametrize('effort', [0.9, 1.5])
def test_an_object_stalls_the_goal_at_max_effort(model, effort):
    obj = make_object('cylinder', 0.040)
    loop = make_loop(model, obj)
    assert run_goal(loop, CommandGoal(loop.law, 0.100, 0.0, loop.clock.now), 5.0).reached_goal
    goal = CommandGoal(loop.law, 0.020, effort, loop.clock.now)
    result = run_goal(loop, goal, 10.0)
    assert result.outcome is Outcome.SUCCEEDED and result.stalled
    assert not result.reached_goal
    # Independent: what the object takes at the regulator's true pressures.
    virtual = VirtualObject(obj, load_gripper_config())
    normal = sum(virtual.contact(i, loop.regulator.true_pressure(i)).normal_force
                 for i in range(3))
    assert normal == pytest.approx(effort, rel=0.05)
    assert result.effort == pytest.approx(effort, rel=0.05)
    assert result.position > 0.035          # held open by the 40 mm cylinder


def test_without_a_limit_an_object_stalls_the_goal_at_the_timeout(model):
    loop = make_loop(model, make_object('cylinder', 0.040), stall_timeout_s=2.0)
    assert run_goal(loop, CommandGoal(loop.law, 0.100, 0.0, loop.clock.now), 5.0).reached_goal
    goal = CommandGoal(loop.law, 0.020, 0.0, loop.clock.now)
    start = loop.clock.now
    result = run_goal(loop, goal, 5.0)
    assert result.outcome is Outcome.SUCCEEDED and result.stalled
    assert loop.clock.now - start == pytest.approx(2.0, abs=2 * loop.period)
    assert result.effort > 0.1 and result.position > 0.035


def test_a_free_goal_that_never_comes_is_aborted(model):
    loop = make_loop(model, stall_timeout_s=1.0)
    loop.stuck_pressure = 0.0
    result = run_goal(loop, CommandGoal(loop.law, 0.100, 0.0, loop.clock.now), 3.0)
    assert result.outcome is Outcome.ABORTED and not result.stalled
    assert 'stalled' in result.message


def test_cancel_holds_every_command_from_the_next_step(model):
    loop = make_loop(model)
    goal = CommandGoal(loop.law, 0.120, 0.0, loop.clock.now)
    out = loop.run(0.2)
    assert goal.update(out, loop.clock.now) is None
    before = loop.commands()[-2:]
    assert np.all(np.abs(before[1] - before[0]) > 0.0)      # still moving
    result = goal.cancel(out, loop.clock.now)
    assert result.outcome is Outcome.CANCELED
    held = loop.commands()[-1]
    out = loop.run(0.5)
    assert out.mode is Mode.HOLD and out.status is GoalStatus.NONE
    # Exact: held commands are the stored doubles, unchanged.
    assert np.array_equal(loop.commands()[-25:], np.tile(held, (25, 1)))


def test_hold_before_any_command_commands_nothing(model):
    loop = make_loop(model)
    loop.law.hold(loop.clock.now)
    out = loop.run(0.1)
    assert out.mode is Mode.HOLD and out.commands is None
