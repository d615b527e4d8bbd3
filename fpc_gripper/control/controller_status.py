"""What the gripper controller reports, without ROS: its status, when it is sent, the contacts."""

import dataclasses

from fpc_gripper.control.controller import GoalStatus
from fpc_gripper.control.controller import Level
from fpc_gripper.services.logs import bounded
from fpc_gripper.services.logs import Severity
from fpc_gripper.services.periods import period_passed

__all__ = ['CONTACTS_PERIOD_S', 'DIAGNOSTICS_PERIOD_S', 'ContactDisplay', 'Status',
           'StatusSchedule', 'contact_states', 'controller_status']

#: Longest time between two statuses on /diagnostics [s].
DIAGNOSTICS_PERIOD_S = 1.0
#: Contact markers at 10 Hz at most, for people [s].
CONTACTS_PERIOD_S = 0.1
_SEVERITIES = {Level.ERROR: Severity.ERROR, Level.WARN: Severity.WARN}


@dataclasses.dataclass(frozen=True)
class Status:
    """
    The controller's status after a step: a diagnostic_msgs/DiagnosticStatus without ROS.

    Attributes
    ----------
    level : Level
    message : str
        Bounded (`fpc_gripper.services.logs.bounded`).
    values : dict of str to str

    """

    level: Level
    message: str
    values: dict


def controller_status(out, names, inputs):
    """
    Return the status of a control step.

    Parameters
    ----------
    out : ControlOutput
    names : sequence of str
        The fingers' names, the prefix of their keys.
    inputs : ControllerInputs
        A rejected or lost input is a WARN until its source delivers a good one.

    Returns
    -------
    Status

    """
    problems = inputs.problems
    level = Level(max(int(out.level), Level.WARN if problems else Level.OK))
    values = {
        'mode': out.mode.value,
        'goal_status': out.status.name.lower(),
        'aperture_m': f'{out.aperture:.6f}',
        'aperture_target_m': f'{out.aperture_target:.6f}',
        'force_target_n': f'{out.force_target:.4f}',
        'normal_force_n': f'{out.normal_force:.4f}',
    }
    for name, finger in zip(names, out.fingers):
        values[f'{name}/command_pa'] = f'{finger.command:.1f}'
        values[f'{name}/feedforward_pa'] = f'{finger.feedforward:.1f}'
        values[f'{name}/rho_m'] = f'{finger.rho:.6f}'
        values[f'{name}/phase'] = finger.phase.value
        values[f'{name}/contact_force_n'] = f'{finger.contact_force:.4f}'
        values[f'{name}/saturated'] = str(finger.saturated)
    values['rejected_inputs'] = str(inputs.rejected)
    values['lost_messages'] = str(inputs.lost_messages)
    values['last_rejection'] = inputs.last_rejection
    message = bounded(f'{out.message}; {problems}' if problems else out.message)
    return Status(level, message, values)


class StatusSchedule:
    """
    When the status is logged and sent on /diagnostics.

    Logged at a change of mode, goal status or level (a goal still active is not worth
    a line); sent at such a change and once every `period_s`.

    Parameters
    ----------
    period_s : float
        Longest time between two statuses sent [s].

    """

    def __init__(self, period_s=DIAGNOSTICS_PERIOD_S):
        self.period_s = float(period_s)
        self._last_key = None
        self._last_time = None

    def update(self, out, status, now):
        """
        Return the severity to log `status` at (None: not logged), and whether to send it.

        Parameters
        ----------
        out : ControlOutput
        status : Status
        now : float
            Node clock [s].

        """
        key = (out.mode, out.status, status.level)
        changed = key != self._last_key
        severity = None
        if changed:
            severity = _SEVERITIES.get(status.level)
            if severity is None and out.status is not GoalStatus.ACTIVE:
                severity = Severity.INFO
            self._last_key = key
        due = period_passed(self._last_time, now, self.period_s)
        if changed or due:
            self._last_time = now
        return severity, changed or due


def contact_states(law, measurements):
    """Return every finger's contact state at its measured pressure (None where it has none)."""
    states = []
    for i, measurement in enumerate(measurements):
        try:
            states.append(law.contact(i, measurement.pressure))
        except (RuntimeError, ValueError, ArithmeticError):
            states.append(None)         # no contact state here: the finger shows none
    return states


class ContactDisplay:
    """
    When the fingers' contacts are shown: at most once a period, while any is in contact.

    One more display after the last contact ends clears those that were shown.

    Parameters
    ----------
    n_fingers : int
    period_s : float
        Least time between two displays [s].

    """

    def __init__(self, n_fingers, period_s=CONTACTS_PERIOD_S):
        self.period_s = float(period_s)
        self.shown = [False] * int(n_fingers)
        self._last = None

    def due(self, now):
        """Return whether a display may be sent at `now` [s] (the period has passed)."""
        return period_passed(self._last, now, self.period_s)

    def show(self, now, states):
        """Return whether to send the display of `states` at `now` [s]; if so, note it sent."""
        if all(state is None for state in states) and not any(self.shown):
            return False
        self._last = now
        self.shown = [state is not None for state in states]
        return True
