"""What the gripper controller reports, without ROS: status values, its schedule, the contacts."""

import math
import types

import pytest

from fpc_gripper.control.controller import ControlOutput
from fpc_gripper.control.controller import FingerOutput
from fpc_gripper.control.controller import FingerPhase
from fpc_gripper.control.controller import GoalStatus
from fpc_gripper.control.controller import Level
from fpc_gripper.control.controller import Mode
from fpc_gripper.control.controller_status import contact_states
from fpc_gripper.control.controller_status import ContactDisplay
from fpc_gripper.control.controller_status import controller_status
from fpc_gripper.control.controller_status import StatusSchedule
from fpc_gripper.control.inputs import ControllerInputs
from fpc_gripper.services.input_limits import Rejection
from fpc_gripper.services.logs import MAX_LOG_CHARS
from fpc_gripper.services.logs import Severity

NAMES = ('finger_0', 'finger_1', 'finger_2')


def inputs():
    """ControllerInputs of three fingers (a rejection needs no law)."""
    return ControllerInputs(types.SimpleNamespace(models=(None,) * 3), NAMES)


def output(mode=Mode.APERTURE, status=GoalStatus.ACTIVE, level=Level.OK, message='tracking',
           forces=(0.1, 0.2, 0.3)):
    fingers = tuple(FingerOutput(command=1.0e5 + i, feedforward=9.0e4, error=0.0,
                                 integral=0.0, rho=0.05, phase=FingerPhase.FREE,
                                 saturated=i == 2, contact_force=f)
                    for i, f in enumerate(forces))
    return ControlOutput(time=1.0, mode=mode, status=status, level=level, message=message,
                         commands=None, aperture=0.1, aperture_target=0.08,
                         force_target=math.nan, fingers=fingers)


def test_the_status_holds_every_key_of_the_controller_state():
    status = controller_status(output(), NAMES, inputs())
    assert status.level is Level.OK and status.message == 'tracking'
    values = status.values
    assert values['mode'] == 'aperture' and values['goal_status'] == 'active'
    assert float(values['aperture_target_m']) == pytest.approx(0.08)
    assert float(values['normal_force_n']) == pytest.approx(0.6, abs=1e-4)
    assert values['force_target_n'] == 'nan'
    for i, name in enumerate(NAMES):
        assert float(values[f'{name}/command_pa']) == pytest.approx(1.0e5 + i, abs=0.05)
        assert values[f'{name}/phase'] == 'free'
        assert values[f'{name}/saturated'] == str(i == 2)
    assert values['rejected_inputs'] == '0' and values['last_rejection'] == 'none'
    assert values['lost_messages'] == '0'
    assert list(values)[-3:] == ['rejected_inputs', 'lost_messages', 'last_rejection']


def test_a_rejected_input_makes_the_status_warn_and_says_why():
    heard = inputs()
    heard.reject('aperture_command', Rejection.NOT_FINITE, 'got nan')
    status = controller_status(output(), NAMES, heard)
    assert status.level is Level.WARN
    assert status.message.startswith('tracking; rejected aperture_command (not finite)')
    assert status.values['rejected_inputs'] == '1'
    # An ERROR of the law stays an ERROR.
    assert controller_status(output(level=Level.ERROR), NAMES, heard).level is Level.ERROR


def test_the_status_message_is_bounded():
    status = controller_status(output(message='x' * 5000), NAMES, inputs())
    assert len(status.message) < MAX_LOG_CHARS + 50


def update(schedule, now, **changes):
    out = output(**changes)
    return schedule.update(out, controller_status(out, NAMES, inputs()), now)


def test_the_status_is_logged_at_a_change_at_the_severity_of_its_level():
    schedule = StatusSchedule(period_s=1.0)
    # A goal still active is not worth a line, but it is sent.
    assert update(schedule, 0.0) == (None, True)
    assert update(schedule, 0.1) == (None, False)
    assert update(schedule, 0.2, status=GoalStatus.REACHED) == (Severity.INFO, True)
    assert update(schedule, 0.3, status=GoalStatus.STALLED, level=Level.WARN) \
        == (Severity.WARN, True)
    assert update(schedule, 0.4, mode=Mode.SAFE, status=GoalStatus.FAULT,
                  level=Level.ERROR) == (Severity.ERROR, True)
    assert update(schedule, 0.5, mode=Mode.SAFE, status=GoalStatus.FAULT,
                  level=Level.ERROR) == (None, False)


def test_an_unchanged_status_is_sent_once_a_period():
    schedule = StatusSchedule(period_s=1.0)
    sent = [update(schedule, 0.25 * k)[1] for k in range(9)]
    assert sent == [True, False, False, False, True, False, False, False, True]


class Law:
    """A law whose contact model fails for finger 1 and finds no contact for finger 2."""

    def contact(self, index, pressure):
        if index == 1:
            raise RuntimeError('contact model did not converge')
        if index == 2:
            raise ArithmeticError('no contact state')
        return ('state', pressure)


def test_contact_states_are_none_where_the_contact_model_has_none():
    measurements = [types.SimpleNamespace(pressure=p) for p in (1.0e5, 2.0e5, 3.0e5)]
    assert contact_states(Law(), measurements) == [('state', 1.0e5), None, None]


def test_contacts_are_shown_at_most_once_a_period_and_cleared_once():
    display = ContactDisplay(3, period_s=0.1)
    assert display.due(0.0)
    assert not display.show(0.0, [None, None, None])
    assert display.due(0.01)
    assert display.show(0.01, ['a', None, None])
    assert display.shown == [True, False, False]
    assert not display.due(0.08) and display.due(0.15)
    # The contact ended: one more display clears it, then nothing until the next.
    assert display.show(0.15, [None, None, None])
    assert display.shown == [False, False, False]
    assert not display.show(0.3, [None, None, None])


def test_a_clock_stepping_back_does_not_silence_the_status_or_the_contacts():
    # A simulated clock restarted at 0 after 100 s: the periodic status goes on at once.
    schedule = StatusSchedule(period_s=1.0)
    assert update(schedule, 100.0) == (None, True)
    assert update(schedule, 100.5)[1] is False
    assert update(schedule, 0.2)[1] is True
    assert update(schedule, 0.7)[1] is False
    assert update(schedule, 1.2)[1] is True
    display = ContactDisplay(3, period_s=0.1)
    assert display.show(50.0, ['a', None, None])
    assert display.due(0.01)
