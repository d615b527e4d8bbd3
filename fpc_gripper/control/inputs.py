"""What the gripper controller has heard, each input checked: pressures, contact forces, goals."""

import math

from fpc_gripper.model.validation import STANDARD_ATMOSPHERE
from fpc_gripper.services.input_limits import check_absolute_pressure
from fpc_gripper.services.input_limits import check_frame
from fpc_gripper.services.input_limits import check_tip_force_value
from fpc_gripper.services.input_limits import checked_bounds
from fpc_gripper.services.input_limits import DEFAULT_BOUNDS
from fpc_gripper.services.input_limits import InputCheck
from fpc_gripper.services.input_limits import lost_detail
from fpc_gripper.services.input_limits import real_or_none
from fpc_gripper.services.input_limits import Rejection
from fpc_gripper.services.logs import bounded

from .controller import FingerMeasurement

__all__ = ['ControllerInputs']


class ControllerInputs:
    """
    The inputs of a gripper controller, checked, and what they leave for the control law.

    Every subscriber callback of the controller node is one call here (``offer_*``),
    free of ROS. A rejected input changes nothing: the last good measurement and the
    goal stay. While the newest input of a source (a topic) is rejected, or the
    middleware lost messages of it (`lost`), `problems` names it, and the node reports
    WARN until that source delivers a good input.

    Parameters
    ----------
    law : GripperControlLaw
        Receives the goals.
    frames : sequence of str
        Each finger's frame: a contact force must be in it (or unframed, '').
    atmospheric_pressure : float
        Gauge reference [Pa].
    bounds : InputBounds
        ``min_absolute_pressure``, ``max_tip_force`` (also ``n`` times it bounds the total
        grasp force goal) and ``max_frame_id_length``.

    """

    def __init__(self, law, frames, atmospheric_pressure=STANDARD_ATMOSPHERE,
                 bounds=DEFAULT_BOUNDS):
        self.law = law
        self.frames = tuple(frames)
        if len(self.frames) != len(law.models):
            raise ValueError(f'`frames` must name one frame per finger ({len(law.models)}), '
                             f'got {len(self.frames)}')
        self.atmospheric_pressure = float(atmospheric_pressure)
        self.bounds = bounds
        n = len(self.frames)
        self.pressure = [None] * n
        self.stamp = [None] * n
        self.tip_force = [(0.0, 0.0)] * n
        self.rejected = 0
        self.last_rejection = 'none'
        self._problems = {}
        self._lost = {}

    @property
    def bounds(self):
        """The `InputBounds` inputs are checked against."""
        return self._bounds

    @bounds.setter
    def bounds(self, value):
        self._bounds = checked_bounds(value, self.frames)

    # -- inputs -----------------------------------------------------------------------------

    def offer_pressure(self, index, absolute, now, frame_id=''):
        """
        Take a measured pressure of a finger (absolute [Pa]) that arrived at `now` [s].

        Returns
        -------
        InputCheck
            ``value`` is the gauge pressure [Pa].

        """
        source = f'{self.frames[index]}/pressure'
        frame = check_frame(frame_id, max_length=self._bounds.max_frame_id_length)
        check = frame if not frame.accepted else check_absolute_pressure(
            absolute, atmospheric_pressure=self.atmospheric_pressure,
            min_absolute_pressure=self._bounds.min_absolute_pressure)
        if self._record(source, check):
            self.pressure[index] = check.value
            self.stamp[index] = float(now)
        return check

    def offer_tip_force(self, index, fx, fz, frame_id):
        """
        Take the measured contact force (F_X, F_Z) [N] of a finger, in its frame or unframed.

        Returns
        -------
        InputCheck
            ``value`` is (F_X, F_Z) [N].

        """
        expected = self.frames[index]
        source = f'{expected}/tip_force'
        check = check_frame(frame_id, expected if frame_id else None,
                            max_length=self._bounds.max_frame_id_length)
        if check.accepted:
            check = check_tip_force_value(fx, fz, limits=self._bounds.limits)
        if self._record(source, check):
            self.tip_force[index] = check.value
        return check

    def offer_aperture(self, aperture, now):
        """
        Take an aperture goal [m] at `now` [s] (see `GripperControlLaw.set_aperture`).

        Returns
        -------
        InputCheck
            ``value`` is the aperture target in use [m] (clamped to the reachable range).

        """
        return self._goal('aperture_command', self.law.set_aperture, aperture, now)

    def offer_grasp_force(self, force, now):
        """
        Take a total normal force goal [N] at `now` [s], at most n x ``max_tip_force``.

        Returns
        -------
        InputCheck
            ``value`` is the goal [N].

        """
        limit = len(self.frames) * self._bounds.max_tip_force
        value = real_or_none(force)
        if value is not None and math.isfinite(value) and value > limit:
            return self.reject('grasp_force_command', Rejection.OUT_OF_RANGE,
                               f'grasp force {value:.6g} N is over {len(self.frames)} fingers x '
                               f'max_tip_force = {limit:g} N')
        return self._goal('grasp_force_command', self.law.set_grasp_force, force, now)

    def reject(self, source, rejection, detail):
        """Record an input of `source` refused before it became a value; return the check."""
        check = InputCheck(None, Rejection(rejection), bounded(detail))
        self._record(source, check)
        return check

    def lost(self, source, count):
        """Record `count` messages of `source` that the middleware lost; return the check."""
        count = max(int(count), 0)
        self._lost[source] = self._lost.get(source, 0) + count
        return self.reject(source, Rejection.LOST, lost_detail(count, self._lost[source]))

    def _goal(self, source, setter, value, now):
        number = real_or_none(value)
        if number is None or not math.isfinite(number):
            return self.reject(source, Rejection.NOT_FINITE, f'{bounded(value, 40)} is not a '
                                                             'finite number')
        try:
            used = setter(number, now)
        except (TypeError, ValueError) as exc:
            return self.reject(source, Rejection.OUT_OF_RANGE, str(exc))
        check = InputCheck(number if used is None else used)
        self._record(source, check)
        return check

    def _record(self, source, check):
        if check.accepted:
            self._problems.pop(source, None)
            return True
        lost = check.rejection is Rejection.LOST
        self.rejected += not lost
        self.last_rejection = bounded(f'{source} ({check.rejection.value}): {check.detail}')
        self._problems[source] = ('' if lost else 'rejected ') + self.last_rejection
        return False

    # -- outputs ----------------------------------------------------------------------------

    @property
    def lost_messages(self):
        """Messages the middleware lost, over every source."""
        return sum(self._lost.values())

    @property
    def problems(self):
        """The sources whose newest input was rejected or lost, with why ('' when none)."""
        return bounded('; '.join(self._problems.values()))

    def measurements(self):
        """Return every finger's `FingerMeasurement`, from the last good inputs."""
        return tuple(FingerMeasurement(p, s, f) for p, s, f in
                     zip(self.pressure, self.stamp, self.tip_force))
