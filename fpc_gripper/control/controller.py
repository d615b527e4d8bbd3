"""Gripper control law: model-inverse feedforward plus PI feedback, slew and range limits."""

import copy
from dataclasses import dataclass, field, fields
import enum
import math

import numpy as np

from fpc_gripper.grasp.finger import FingerGrasp
from fpc_gripper.grasp.objects import CoaxialCylinder
from fpc_gripper.services.health import Level

from .geometry import PalmGeometry

__all__ = ['ControllerConfig', 'ControlOutput', 'FingerMeasurement', 'FingerOutput',
           'FingerPhase', 'GoalStatus', 'GripperControlLaw', 'Level', 'Mode', 'SAFE_STATES']

SAFE_STATES = ('vent', 'hold')
#: The force-to-pressure slope is taken at the measured pressure rounded to this [Pa]: a
#: function of the measurement alone, and one pair of contact solves per window.
_SLOPE_WINDOW = 4.0e3
#: Longest step the integrators and the slew limit accept [s]; a longer gap is a restart.
_MAX_DT = 0.2


class Mode(str, enum.Enum):
    """What the controller is doing."""

    IDLE = 'idle'            # no goal yet: nothing is commanded
    APERTURE = 'aperture'    # tracking an aperture
    GRASP = 'grasp'          # closing on an object, then holding a contact force
    SAFE = 'safe'            # pressure feedback lost: vent or hold until a new goal
    HOLD = 'hold'            # a goal canceled: the present commands kept until a new goal


class FingerPhase(str, enum.Enum):
    """Per-finger phase of a grasp."""

    FREE = 'free'            # aperture control
    APPROACH = 'approach'    # closing towards an object, no contact yet
    CONTACT = 'contact'      # contact-force control


class GoalStatus(enum.IntEnum):
    """Outcome of the current goal."""

    NONE = 0
    ACTIVE = 1
    REACHED = 2
    STALLED = 3
    FAULT = 4


@dataclass(frozen=True)
class ControllerConfig:
    """
    Gains and limits of the control law.

    Attributes
    ----------
    max_pressure : float
        Largest command [Pa gauge].
    slew_rate_pa_s : float
        Largest rate of change of each command [Pa/s].
    approach_rate_pa_s : float
        Slew limit while closing on an object and regulating the contact force [Pa/s].
    kp, ki : float
        PI gains on the pressure-equivalent aperture error e = (rho* - rho) / (drho/dP)
        [-] and [1/s].
    kp_force, ki_force : float
        PI gains on the pressure-equivalent force error e = (dP/dN) (N*/n - N_i) of
        each finger (N*: the total normal force goal, n fingers, N_i the finger's
        estimated normal force) [-] and [1/s].
    anti_windup : bool
        Conditional integration (clamping); False only to show what it prevents.
    goal_tolerance_m : float
        Aperture tolerance [m].
    force_tolerance : float
        Relative tolerance of each finger's normal force [-].
    force_tolerance_n : float
        Absolute floor of that tolerance [N].
    settle_time_s : float
        Time the error must stay within tolerance before the goal is reached [s].
    stall_timeout_s : float
        A goal not reached after this long is STALLED [s].
    feedback_timeout_s : float
        Age of the newest pressure reading beyond which the feedback is lost [s].
    safe_state : {'vent', 'hold'}
        Command on lost feedback: 0 Pa gauge, or the last command.
    contact_threshold_n : float
        Normal contact force above which a finger is in contact [N].

    """

    max_pressure: float = 400.0e3
    slew_rate_pa_s: float = 400.0e3
    approach_rate_pa_s: float = 150.0e3
    kp: float = 1.0
    ki: float = 2.0
    kp_force: float = 0.5
    ki_force: float = 3.0
    anti_windup: bool = True
    goal_tolerance_m: float = 1.0e-3
    force_tolerance: float = 0.05
    force_tolerance_n: float = 0.01
    settle_time_s: float = 0.3
    stall_timeout_s: float = 6.0
    feedback_timeout_s: float = 0.5
    safe_state: str = 'vent'
    contact_threshold_n: float = 0.02

    def __post_init__(self):
        """Check every value; messages name the field, its value and unit."""
        positive = {'max_pressure': '[Pa]', 'slew_rate_pa_s': '[Pa/s]',
                    'approach_rate_pa_s': '[Pa/s]', 'goal_tolerance_m': '[m]',
                    'force_tolerance_n': '[N]', 'stall_timeout_s': '[s]',
                    'feedback_timeout_s': '[s]', 'contact_threshold_n': '[N]'}
        non_negative = {'kp': '[-]', 'ki': '[1/s]', 'kp_force': '[-]', 'ki_force': '[1/s]',
                        'force_tolerance': '[-]',
                        'settle_time_s': '[s]'}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == 'anti_windup':
                if not isinstance(value, bool):
                    raise ValueError(f'`anti_windup` must be a bool, got {value!r}')
                continue
            if f.name == 'safe_state':
                if value not in SAFE_STATES:
                    raise ValueError(f'`safe_state` must be one of {list(SAFE_STATES)}, '
                                     f'got {value!r}')
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) \
                    or not math.isfinite(value):
                raise ValueError(f'`{f.name}` must be a finite number '
                                 f'{positive.get(f.name) or non_negative[f.name]}, '
                                 f'got {value!r}')
            if f.name in positive and value <= 0.0:
                raise ValueError(f'`{f.name}` must be > 0 {positive[f.name]}, got {value}')
            if f.name in non_negative and value < 0.0:
                raise ValueError(f'`{f.name}` must be >= 0 {non_negative[f.name]}, got {value}')

    def replace(self, **changes):
        """Return a copy with some fields changed (validated)."""
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        unknown = sorted(set(changes) - set(values))
        if unknown:
            raise ValueError(f'unknown ControllerConfig field(s): {", ".join(unknown)}')
        values.update(changes)
        return ControllerConfig(**values)


@dataclass(frozen=True)
class FingerMeasurement:
    """
    What the controller knows about one finger.

    Attributes
    ----------
    pressure : float or None
        Latest measured gauge pressure [Pa]; None before the first reading.
    stamp : float or None
        Time that reading arrived [s], on the clock `step` is given.
    tip_force : tuple of float
        Latest measured contact force on the finger (F_X, F_Z), the resultant of its
        contact loads in its frame (topic ``finger_<i>/tip_force``) [N]; out of contact,
        a tip load.

    """

    pressure: float = None
    stamp: float = None
    tip_force: tuple = (0.0, 0.0)


@dataclass(frozen=True)
class FingerOutput:
    """
    One finger's share of a control step.

    Attributes
    ----------
    command : float
        Command [Pa gauge] (nan when nothing is commanded).
    feedforward : float
        Model-inverse pressure [Pa gauge].
    error : float
        Pressure-equivalent error fed to the PI [Pa].
    integral : float
        Integrator state [Pa].
    rho : float
        Estimated tip radius [m].
    phase : FingerPhase
    saturated : bool
        The command hit the range or slew limit, or the target is out of reach.
    contact_force : float
        Estimated normal force of the object on the finger [N] (see `GripperControlLaw`).

    """

    command: float
    feedforward: float
    error: float
    integral: float
    rho: float
    phase: FingerPhase
    saturated: bool
    contact_force: float


@dataclass(frozen=True)
class ControlOutput:
    """
    Result of `GripperControlLaw.step`.

    Attributes
    ----------
    time : float
        [s].
    mode : Mode
    status : GoalStatus
    level : Level
    message : str
    commands : tuple of float or None
        Gauge pressures to command [Pa]; None while idle (command nothing).
    aperture : float
        Model estimate from the measured pressures and tip loads [m] (nan if unknown).
    aperture_target : float
        [m] (nan when grasping).
    force_target : float
        Total normal force goal on the object [N] (nan unless grasping).
    fingers : tuple of FingerOutput

    """

    time: float
    mode: Mode
    status: GoalStatus
    level: Level
    message: str
    commands: tuple
    aperture: float
    aperture_target: float
    force_target: float
    fingers: tuple = field(default=())

    @property
    def normal_force(self):
        """Estimated total normal force on the object [N]: the fingers' sum."""
        return float(sum(f.contact_force for f in self.fingers))


def _magnitude(measurement):
    """Magnitude of a measured contact force [N]."""
    return math.hypot(*(float(v) for v in measurement.tip_force))


def _real(name, value, unit):
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
        raise TypeError(f'`{name}` must be a real number {unit}, got {value!r}')
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f'`{name}` must be finite {unit}, got {value}')
    return value


class _Finger:
    """Mutable per-finger controller state."""

    def __init__(self):
        self.integral = 0.0
        self.command = None
        self.phase = FingerPhase.FREE
        # The object of an unknown-object grasp, estimated at contact (a FingerGrasp).
        self.estimated = None

    def reset(self, phase):
        self.integral = 0.0
        self.phase = phase
        self.estimated = None

    def __deepcopy__(self, memo):
        # Numbers, an enum and a FingerGrasp whose caches are pure: the step's undo copy
        # can share the last.
        return copy.copy(self)


class GripperControlLaw:
    """
    Aperture and grasp-force control of the fingers, free of ROS and of wall-clock time.

    Per finger and per step (time `now` is passed in):

    - feedforward P_ff: the model inverse. For an aperture goal (rho* = A*/2) the
      unloaded root find P0(rho*) (cached), shifted for the current tip load by the
      monotone map: P_ff = P0(rho*) + M^-1(rho* - delta) - M^-1(rho*), where delta =
      rho_est - M(P_meas) is the displacement the load causes at the measured state
      (exact at steady state, no loaded root find per step). When holding a grasp of
      total normal force N* on an object: the pressure at which the finger's
      frictionless contact with the object (`FingerGrasp`: the contact model, the
      object's section in the finger's plane) has the normal force N*/n, a root find
      cached per goal;
    - error e [Pa]: the aperture error converted to pressure by the model slope,
      (rho* - rho_est) / s with s the secant of the map between P_meas and P_ff
      scaled to the loaded local slope, or the force error converted by the contact
      model's slope, (N*/n - N_est) / (dN/dP). rho_est is the model at the measured
      pressure and load. Expressing both errors in Pa makes one pair of dimensionless
      gains valid over the whole range although drho/dP varies tenfold (gain scheduling
      by the model);
    - the normal-force estimate N_est of a finger is its measured contact force |F|
      (``tip_force``: the resultant of the contact loads on the finger) times the
      contact model's ratio of the summed normal forces to their resultant at the
      measured pressure: exact for one contact point, and for an arc whose normals
      spread it restores what the resultant loses;
    - u_raw = P_ff + kp e + I; u = clip(u_raw, 0, max_pressure), then limited to
      slew_rate_pa_s (approach_rate_pa_s while closing on and pressing an object);
    - anti-windup by clamping (conditional integration): dI/dt = ki e, except while
      the range or the slew limit binds and e pushes further into it, when I holds.
      (Back-calculation was tried: with the P term on a stuck reading it drives I far
      negative and the release undershoots by half the step.)

    A grasp closes each finger towards 0 Pa until its normal force exceeds
    `contact_threshold_n`, then regulates it to N*/n. Without a known object
    (`grasps` None) the object is taken as a cylinder on the palm axis whose surface
    passes through the finger's inner-face tip corner at the pressure contact was felt.
    A goal is REACHED after its error stays within tolerance for `settle_time_s`,
    STALLED if not reached within
    `stall_timeout_s` (control goes on). When the newest pressure reading of any
    finger is older than `feedback_timeout_s` (or none arrived within that time
    after the goal started), the law enters SAFE: it commands 0 Pa ('vent') or
    keeps the last commands ('hold') and reports ERROR until a new goal arrives.

    Parameters
    ----------
    models : sequence of InverseModel
        One per finger (fingers of the same design may share one).
    geometry : PalmGeometry
    config : ControllerConfig
    grasps : sequence of FingerGrasp, optional
        Each finger's contact with the object to grasp, when the object is known.

    """

    def __init__(self, models, geometry, config=ControllerConfig(), grasps=None):
        if not isinstance(geometry, PalmGeometry):
            raise TypeError(f'`geometry` must be a PalmGeometry, got {type(geometry).__name__}')
        if not isinstance(config, ControllerConfig):
            raise TypeError(f'`config` must be a ControllerConfig, got {type(config).__name__}')
        self.models = tuple(models)
        if len(self.models) != geometry.n_fingers:
            raise ValueError(f'`models` must hold one model per finger ({geometry.n_fingers}), '
                             f'got {len(self.models)}')
        self.geometry = geometry
        self.config = config
        if grasps is not None:
            grasps = tuple(grasps)
            if len(grasps) != len(self.models):
                raise ValueError(f'`grasps` must hold one FingerGrasp per finger '
                                 f'({len(self.models)}), got {len(grasps)}')
        self.grasps = grasps
        self._slopes = {}
        self._fingers = [_Finger() for _ in self.models]
        self.mode = Mode.IDLE
        self.status = GoalStatus.NONE
        self._message = 'idle: waiting for a goal'
        self._aperture_target = math.nan
        self._force_target = math.nan
        self._goal_start = None
        self._in_tolerance_since = None
        self._last_time = None
        self._out_of_range = ''

    # -- limits -----------------------------------------------------------------------------

    @property
    def max_pressure(self):
        """Largest command [Pa gauge]: the config's, never above any model's range."""
        return min([self.config.max_pressure] + [m.max_pressure for m in self.models])

    def aperture_range(self):
        """Apertures at 0 Pa and at max_pressure, unloaded [m]."""
        low = max(m.rho_map(0.0) for m in self.models)
        high = min(m.rho_map(self.max_pressure) for m in self.models)
        return 2.0 * low, 2.0 * high

    def configure(self, config):
        """Replace the gains and limits; the integrators and the goal are kept."""
        if not isinstance(config, ControllerConfig):
            raise TypeError(f'`config` must be a ControllerConfig, got {type(config).__name__}')
        self.config = config

    # -- goals ------------------------------------------------------------------------------

    def _start_goal(self, now, mode, phase):
        self.mode = mode
        self.status = GoalStatus.ACTIVE
        self._goal_start = now
        self._in_tolerance_since = None
        for finger in self._fingers:
            finger.reset(phase)

    def set_aperture(self, aperture, now):
        """
        Track an aperture.

        Parameters
        ----------
        aperture : float
            Target diameter of the fingertip circle [m], >= 0. A target outside the
            reachable range (`aperture_range`) is clamped to it and said so in the
            message.
        now : float
            [s].

        Returns
        -------
        float
            The aperture target in use [m].

        """
        aperture = _real('aperture', aperture, '[m]')
        now = _real('now', now, '[s]')
        if aperture < 0.0:
            raise ValueError(f'`aperture` must be >= 0 [m], got {aperture}')
        low, high = self.aperture_range()
        clamped = min(max(aperture, low), high)
        self._out_of_range = '' if clamped == aperture else (
            f'; {aperture * 1e3:.1f} mm is out of reach, clamped to {clamped * 1e3:.1f} mm')
        self._aperture_target = clamped
        self._force_target = math.nan
        self._start_goal(now, Mode.APERTURE, FingerPhase.FREE)
        self._message = f'aperture goal {clamped * 1e3:.1f} mm{self._out_of_range}'
        return clamped

    def set_grasp_force(self, force, now):
        """
        Close on the object and hold a total normal force on it.

        Parameters
        ----------
        force : float
            Total normal force of the fingers on the object [N], > 0: each finger
            presses with force / n.
        now : float
            [s].

        """
        force = _real('force', force, '[N]')
        now = _real('now', now, '[s]')
        if force <= 0.0:
            raise ValueError(f'`force` must be > 0 [N], got {force}')
        self._force_target = force
        self._aperture_target = math.nan
        self._out_of_range = ''
        self._start_goal(now, Mode.GRASP, FingerPhase.APPROACH)
        self._message = f'grasp goal {force:.3f} N on the object: closing'

    def hold(self, now):
        """
        Keep every finger's present command, with no goal (a canceled goal).

        The commands stop changing from the next step on, until a new goal. A finger
        that was never commanded stays uncommanded.

        Parameters
        ----------
        now : float
            [s].

        """
        now = _real('now', now, '[s]')
        self.mode = Mode.HOLD
        self.status = GoalStatus.NONE
        self._aperture_target = math.nan
        self._force_target = math.nan
        self._goal_start = now
        self._message = 'holding the present pressures: goal canceled'

    # -- the step -------------------------------------------------------------------------

    def step(self, now, measurements):
        """
        Advance the controller to time `now` and return the commands.

        Parameters
        ----------
        now : float
            Current time [s] (any monotonic clock, the one used for the stamps).
        measurements : sequence of FingerMeasurement
            One per finger.

        Returns
        -------
        ControlOutput
            If anything inside the step raises (a model that does not converge, a root
            find that fails), the step is undone and the output holds the last good
            commands at level ERROR with the error in its message.

        """
        now = _real('now', now, '[s]')
        measurements = tuple(measurements)
        if len(measurements) != len(self.models):
            raise ValueError(f'`measurements` must hold one entry per finger '
                             f'({len(self.models)}), got {len(measurements)}')
        saved = {k: v for k, v in self.__dict__.items() if k != '_fingers'}
        fingers = copy.deepcopy(self._fingers)
        try:
            return self._step(now, measurements)
        except Exception as exc:  # noqa: B902 -- whatever the model raised, the loop goes on
            # Undo the half-done step, so the next one starts from the last good state.
            self.__dict__.update(saved)
            self._fingers = fingers
            return self._hold(now, measurements, exc)

    def _hold(self, now, measurements, exc):
        """Output after a step raised: the last good commands held, level ERROR."""
        commands = tuple(f.command for f in self._fingers)
        held = None if any(c is None for c in commands) else commands
        message = (f'model error, holding the last commands: {type(exc).__name__}: {exc}'
                   [:500])
        return ControlOutput(
            time=now, mode=self.mode, status=self.status, level=Level.ERROR, message=message,
            commands=held, aperture=math.nan, aperture_target=self._aperture_target,
            force_target=self._force_target, fingers=tuple(
                FingerOutput(math.nan if c is None else c, math.nan, math.nan, f.integral,
                             math.nan, f.phase, False, _magnitude(m))
                for c, f, m in zip(commands, self._fingers, measurements)))

    def _step(self, now, measurements):
        dt = 0.0 if self._last_time is None else min(max(now - self._last_time, 0.0), _MAX_DT)
        self._last_time = now
        estimates = [self._estimate(i, m) for i, m in enumerate(measurements)]
        rhos = [e[0] for e in estimates]
        aperture = self.geometry.aperture_from_rho(rhos) if all(
            math.isfinite(r) for r in rhos) else math.nan
        if self.mode in (Mode.APERTURE, Mode.GRASP):
            lost = self._lost_feedback(now, measurements)
            if lost:
                self.mode = Mode.SAFE
                self.status = GoalStatus.FAULT
                self._message = (f'pressure feedback lost ({lost}): safe state '
                                 f'{self.config.safe_state}')
        if self.mode is Mode.IDLE:
            return self._output(now, None, aperture, [
                FingerOutput(math.nan, math.nan, math.nan, 0.0, r, f.phase, False,
                             _magnitude(m))
                for r, f, m in zip(rhos, self._fingers, measurements)])
        if self.mode is Mode.HOLD:
            held = tuple(f.command for f in self._fingers)
            return self._output(now, None if None in held else held, aperture, [
                FingerOutput(math.nan if c is None else c, math.nan, math.nan, f.integral, r,
                             f.phase, False, _magnitude(m))
                for c, r, f, m in zip(held, rhos, self._fingers, measurements)])
        if self.mode is Mode.SAFE:
            commands = []
            for finger in self._fingers:
                if self.config.safe_state == 'vent' or finger.command is None:
                    finger.command = 0.0
                finger.command = min(finger.command, self.max_pressure)
                commands.append(finger.command)
            return self._output(now, tuple(commands), aperture, [
                FingerOutput(c, math.nan, math.nan, f.integral, r, f.phase, False,
                             _magnitude(m))
                for c, r, f, m in zip(commands, rhos, self._fingers, measurements)])
        outputs = [self._finger_step(i, now, dt, m, est)
                   for i, (m, est) in enumerate(zip(measurements, estimates))]
        self._update_goal(now, aperture, outputs)
        return self._output(now, tuple(o.command for o in outputs), aperture, outputs)

    def _estimate(self, index, measurement):
        """Model tip radius [m] and linearisation at the measured state (nan, None if none)."""
        if measurement.pressure is None or not math.isfinite(measurement.pressure):
            return math.nan, None
        pressure = min(max(measurement.pressure, 0.0), self.models[index].max_pressure)
        try:
            return self.models[index].estimate(pressure, tuple(measurement.tip_force))
        except (RuntimeError, ValueError, ArithmeticError):
            # No converged model state here: the finger runs on feedforward alone.
            return math.nan, None

    def _lost_feedback(self, now, measurements):
        """Describe the fingers whose pressure feedback is too old ('' when all are fresh)."""
        timeout = self.config.feedback_timeout_s
        lost = []
        for i, m in enumerate(measurements):
            if m.stamp is None or m.pressure is None:
                if now - self._goal_start > timeout:
                    lost.append(f'finger {i}: no reading')
            elif now - m.stamp > timeout:
                lost.append(f'finger {i}: last reading {now - m.stamp:.2f} s old')
        return ', '.join(lost)

    def _finger_step(self, index, now, dt, measurement, estimate):
        """Feedforward + PI + limits for one finger; returns its FingerOutput."""
        cfg = self.config
        model = self.models[index]
        finger = self._fingers[index]
        rho, lin = estimate
        pressure = measurement.pressure
        if finger.command is None:
            start = 0.0 if pressure is None else pressure
            finger.command = min(max(start, 0.0), self.max_pressure)
        rate = cfg.slew_rate_pa_s
        normal = self._normal_force(index, measurement)
        if finger.phase is FingerPhase.APPROACH and normal >= cfg.contact_threshold_n \
                and pressure is not None:
            finger.reset(FingerPhase.CONTACT)
            if self.grasps is None:
                finger.estimated = self._estimated_object(index, pressure)
        elif finger.phase is FingerPhase.CONTACT and normal < 0.5 * cfg.contact_threshold_n:
            finger.reset(FingerPhase.APPROACH)
        if finger.phase is FingerPhase.CONTACT:
            grasp = self._grasp(index)
            rate = min(rate, cfg.approach_rate_pa_s)
            share = self._force_target / len(self.models)
            feedforward, reachable = self._grasp_pressure(index, grasp, share)
            gain_p, gain_i = cfg.kp_force, cfg.ki_force
            slope = self._force_slope(index, grasp, pressure)
            error = (share - normal) / slope if slope < 0.0 else 0.0
        else:
            if finger.phase is FingerPhase.APPROACH:
                target = model.rho_range[0]
                rate = min(rate, cfg.approach_rate_pa_s)
            else:
                target = 0.5 * self._aperture_target
            feedforward, reachable = self._feedforward(model, target, rho, pressure)
            gain_p, gain_i = cfg.kp, cfg.ki
            error = 0.0
            if lin is not None and math.isfinite(rho):
                error = (target - rho) / self._slope(model, lin, pressure, feedforward)
        feedforward = min(max(feedforward, 0.0), self.max_pressure)
        raw = feedforward + gain_p * error + finger.integral
        clamped = min(max(raw, 0.0), self.max_pressure)
        previous = finger.command
        limit = rate * dt
        command = min(max(clamped, previous - limit), previous + limit)
        if cfg.anti_windup and command != raw and error * (raw - command) > 0.0:
            # Clamping anti-windup: the range or slew limit binds and the error pushes
            # further into it, so the integrator holds its value.
            d_integral = 0.0
        else:
            d_integral = gain_i * error
        finger.integral = min(max(finger.integral + d_integral * dt, -self.max_pressure),
                              self.max_pressure)
        finger.command = command
        saturated = (command != raw) or not reachable
        return FingerOutput(command, feedforward, error, finger.integral, rho, finger.phase,
                            saturated, normal)

    def contact(self, index, pressure):
        """
        Return a finger's contact state on the object at a pressure, or None.

        None while the finger is not in contact or no object is known or estimated yet;
        else the frictionless contact Result of its FingerGrasp (positions in the finger
        frame [m], ``in_contact``, forces [N]), as the law's force estimate uses it.
        """
        grasp = self._grasp(index)
        if grasp is None or self._fingers[index].phase is not FingerPhase.CONTACT \
                or pressure is None or not math.isfinite(pressure):
            return None
        return grasp.state(pressure)

    def _grasp(self, index):
        """Return a finger's FingerGrasp: the known object's, or the one estimated at contact."""
        if self.grasps is not None:
            return self.grasps[index]
        return self._fingers[index].estimated

    def _normal_force(self, index, measurement):
        """
        Estimated normal force of the object on a finger [N].

        The measured contact force |F| times the contact model's ratio of the summed
        normal forces to their resultant at the measured pressure (1 for one contact
        point); |F| itself where no contact model applies yet.
        """
        force = _magnitude(measurement)
        grasp = self._grasp(index)
        pressure = measurement.pressure
        if grasp is None or force == 0.0 or pressure is None or not math.isfinite(pressure):
            return force
        state = grasp.state(pressure)
        resultant = math.hypot(*state.total_force.sum(axis=0))
        if state.normal_force_total <= 0.0 or resultant <= 1e-12:
            return force
        return force * state.normal_force_total / resultant

    def _estimated_object(self, index, pressure):
        """
        Return the FingerGrasp of an unknown object, estimated at contact.

        A cylinder on the palm axis through the finger's inner-face tip corner, free, at
        the pressure where contact was felt.
        """
        model = self.models[index]
        solver = FingerGrasp.solver_of(model.design, model.settings)
        free = solver.solve(min(max(pressure, 0.0), model.max_pressure), outputs='tip')
        if not free.success:
            raise RuntimeError(f'finger {index}: no free state at {pressure:.0f} Pa: '
                               f'{free.message}')
        corner = solver.point_positions(solver._pack(free.state), [solver.n_segments - 1],
                                        [solver.lengths[-1]], [-0.5 * model.design.H])[0]
        radius = self.geometry.palm_radius + corner[1]
        section = CoaxialCylinder(2.0 * radius).section(self.geometry.mount_angles[index],
                                                        self.geometry.palm_radius)
        return FingerGrasp(model.design, section, model.max_pressure, model.settings)

    def _grasp_pressure(self, index, grasp, force):
        """Pressure at which a finger presses with `force` [N] (cached per grasp and goal)."""
        key = (index, id(grasp), force)
        hit = self._slopes.get(key)
        if hit is None or hit[0] is not grasp:
            hit = self._slopes[key] = (grasp, grasp.pressure_for_force(force))
        return hit[1]

    def _force_slope(self, index, grasp, pressure):
        """dN/dP of a finger's contact [N/Pa] at the measured pressure, window-rounded."""
        window = round(min(max(pressure, 0.0), grasp.max_pressure) / _SLOPE_WINDOW)
        key = (index, id(grasp), window)
        hit = self._slopes.get(key)
        if hit is None or hit[0] is not grasp:
            hit = self._slopes[key] = (grasp, grasp.slope(window * _SLOPE_WINDOW))
        return hit[1]

    @staticmethod
    def _feedforward(model, target, rho, pressure):
        """
        Model-inverse pressure for a tip radius under the current load [Pa], and reachability.

        The unloaded inverse (a root find, cached by target) is shifted by the load: the
        tip displacement the load causes at the measured state, delta = rho_est -
        rho_unloaded(P_meas), is assumed to be the same at the goal, so the goal pressure
        is the one whose unloaded radius is rho* - delta (from the monotone map). At
        steady state (P_meas = P_ff) this is exact; it needs no loaded root find, so a
        load that changes every step (a tip leaving an object) costs nothing.
        """
        base = model.pressure_for_rho(target)
        if pressure is None or not math.isfinite(rho):
            return base.x, base.success
        delta = rho - model.rho_map(pressure)
        if abs(delta) < 1.0e-6:
            return base.x, base.success
        low, high = model.rho_range
        shifted = target - delta
        reachable = low <= shifted <= high
        return base.x + model.map_pressure(shifted) - model.map_pressure(target), reachable

    @staticmethod
    def _slope(model, lin, pressure, feedforward):
        """
        Pressure-to-radius gain that converts the aperture error to Pa [m/Pa].

        The secant of the unloaded map between the measured and the feedforward
        pressure, scaled by the loaded-to-unloaded ratio of the local slopes: for a
        large error the error in Pa is then the pressure distance to the goal (not the
        radius error over the local slope, which is tenfold too large near 0 Pa),
        and for a small one it is the loaded local slope.
        """
        local = model.slope(pressure)
        if abs(feedforward - pressure) > 1.0e3:
            secant = (model.rho_map(feedforward) - model.rho_map(pressure)) \
                / (feedforward - pressure)
        else:
            secant = local
        return max(secant * lin.drho_dp / max(local, 1e-12), 1e-12)

    def _update_goal(self, now, aperture, outputs):
        """REACHED / STALLED bookkeeping and the message."""
        cfg = self.config
        if self.mode is Mode.APERTURE:
            error = abs(aperture - self._aperture_target)
            inside = math.isfinite(error) and error <= cfg.goal_tolerance_m
            what = (f'aperture {aperture * 1e3:.2f} mm, goal {self._aperture_target * 1e3:.2f} '
                    f'mm{self._out_of_range}')
        else:
            share = self._force_target / len(outputs)
            tolerance = max(cfg.force_tolerance * share, cfg.force_tolerance_n)
            contact = [o.phase is FingerPhase.CONTACT for o in outputs]
            forces = [o.contact_force for o in outputs]
            inside = all(contact) and all(abs(f - share) <= tolerance for f in forces)
            what = (f'grasp {self._force_target:.3f} N: normal force {sum(forces):.3f} N '
                    f'({", ".join(f"{f:.3f}" for f in forces)} N), '
                    f'{sum(contact)}/{len(contact)} fingers in contact')
        if inside:
            if self._in_tolerance_since is None:
                self._in_tolerance_since = now
            if now - self._in_tolerance_since >= cfg.settle_time_s:
                self.status = GoalStatus.REACHED
        else:
            self._in_tolerance_since = None
        if self.status is GoalStatus.ACTIVE and now - self._goal_start > cfg.stall_timeout_s:
            self.status = GoalStatus.STALLED
        words = {GoalStatus.ACTIVE: 'active', GoalStatus.REACHED: 'reached',
                 GoalStatus.STALLED: f'stalled (not reached within {cfg.stall_timeout_s:.1f} s)'}
        self._message = f'{words.get(self.status, self.status.name.lower())}: {what}'

    def _output(self, now, commands, aperture, fingers):
        if self.status is GoalStatus.FAULT:
            level = Level.ERROR
        elif self.status is GoalStatus.STALLED:
            level = Level.WARN
        else:
            level = Level.OK
        return ControlOutput(time=now, mode=self.mode, status=self.status, level=level,
                             message=self._message, commands=commands, aperture=aperture,
                             aperture_target=self._aperture_target,
                             force_target=self._force_target, fingers=tuple(fingers))
