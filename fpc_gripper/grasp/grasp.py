"""Three-finger grasp along a pressure path: grasp force, holding force, best grasp pressure."""

from dataclasses import dataclass, field
import enum
import math

import numpy as np

from fpc_gripper.io.config import GripperConfig
from fpc_gripper.model.contact import contact_path, ContactSettings, translated
from fpc_gripper.model.kernels import contact as ck
from fpc_gripper.model.pipeline import contact_model, ModelSettings
from fpc_gripper.model.validation import real_number
from fpc_gripper.ranges import parse_range

__all__ = ['GraspSettings', 'GraspStatus', 'GraspPoint', 'GraspSweep', 'simulate_grasp',
           'holding_force', 'pressure_range']

#: Steps of the pull-out solved between two checks of its end.
_PULL_CHUNK = 8
#: Steady sliding: every contact slips over this many steps with the pull force constant to
#: a relative 1e-3.
_STEADY_STEPS = 8
_STEADY_RTOL = 1e-3
#: The pull is over once the force has fallen below this fraction of its maximum.
_PAST_PEAK = 0.5
#: A pull that cannot go on counts as past its peak when its force has fallen below this
#: fraction of its maximum (a box's edge hopping between contact points makes the force
#: saw by some 15 %).
_STOPPED_PAST_PEAK = 0.75


class GraspStatus(enum.IntEnum):
    """Outcome of one grasp pressure; only SUCCESS has success=True."""

    SUCCESS = 0
    DOES_NOT_FIT = 1         # the object touches the fingers opened at the open pressure
    RELEASE_FAILED = 2       # the contact path did not reach this pressure
    PULL_FAILED = 3          # the pull-out stopped before the holding force was found
    PULL_LIMIT = 4           # the object was pulled by pull_limit and still held harder


_MESSAGES = {
    GraspStatus.SUCCESS: 'grasp force {grasp:.4g} N with {fingers} finger(s) in contact; '
                         'holding force {holding:.4g} N ({ending})',
    GraspStatus.DOES_NOT_FIT: 'the object touches finger {finger} opened at {open:.0f} Pa: '
                              'it cannot be placed',
    GraspStatus.RELEASE_FAILED: 'finger {finger}: the release path stopped above this '
                                'pressure: {why}',
    GraspStatus.PULL_FAILED: 'finger {finger}: the pull-out stopped at {u:.2f} mm: {why}; '
                             'largest force so far {holding:.4g} N',
    GraspStatus.PULL_LIMIT: 'still holding after a pull of {u:.1f} mm (pull_limit): at least '
                            '{holding:.4g} N',
}


@dataclass(frozen=True)
class GraspSettings:
    """
    How a grasp is simulated.

    Parameters
    ----------
    open_pressure : float or None
        Pressure the gripper is opened to before the object is placed [Pa] (None: the
        gripper's max_pressure).
    release_step : float
        Largest pressure step of the release path [Pa].
    pull_step : float
        Displacement step of the pull-out along the palm axis [m].
    pull_limit : float
        Longest pull-out [m].
    model : ModelSettings
        Finger model settings (`pipeline.contact_model`).
    contact : ContactSettings

    """

    open_pressure: float = None
    release_step: float = 10.0e3
    pull_step: float = 0.2e-3
    pull_limit: float = 0.060
    model: ModelSettings = field(default_factory=ModelSettings)
    contact: ContactSettings = field(default_factory=ContactSettings)

    def __post_init__(self):
        """Check every field."""
        if self.open_pressure is not None:
            value = real_number('open_pressure', self.open_pressure, '[Pa]')
            if value <= 0.0:
                raise ValueError(f'`open_pressure` must be > 0 [Pa], got {value}')
            object.__setattr__(self, 'open_pressure', value)
        for name, unit in (('release_step', '[Pa]'), ('pull_step', '[m]'),
                           ('pull_limit', '[m]')):
            value = real_number(name, getattr(self, name), unit)
            if value <= 0.0:
                raise ValueError(f'`{name}` must be > 0 {unit}, got {value}')
            object.__setattr__(self, name, value)
        if not isinstance(self.model, ModelSettings):
            raise TypeError(f'`model` must be a ModelSettings, got {type(self.model).__name__}')
        if not isinstance(self.contact, ContactSettings):
            raise TypeError(f'`contact` must be a ContactSettings, got '
                            f'{type(self.contact).__name__}')


@dataclass
class GraspPoint:
    """
    The grasp at one grasp pressure.

    Attributes
    ----------
    pressure : float
        Grasp pressure [Pa].
    grasp_force : float
        Total normal force of the fingers on the object [N].
    holding_force : float
        Largest pull-out force along the palm axis the grasp resists before it lets go
        (slides or releases the object) [N].
    fingers_in_contact : int
    success : bool
    status : GraspStatus
    message : str
    contacts : tuple of Result
        Every finger's contact at the grasp pressure, before the pull.
    pull : ndarray, shape (P,)
        Pull displacements [m].
    pull_force : ndarray, shape (P,)
        Total pull-out force at each [N].

    """

    pressure: float
    grasp_force: float = math.nan
    holding_force: float = math.nan
    fingers_in_contact: int = 0
    success: bool = False
    status: GraspStatus = GraspStatus.RELEASE_FAILED
    message: str = ''
    contacts: tuple = ()
    pull: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pull_force: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass
class GraspSweep:
    """
    Grasps of one object over grasp pressures (`simulate_grasp`).

    Attributes
    ----------
    points : list of GraspPoint
        In the order the pressures were given.
    obj : object
    mu : float
    open_pressure : float
        [Pa].

    """

    points: list
    obj: object
    mu: float
    open_pressure: float

    @property
    def best(self):
        """The successful GraspPoint of largest holding force (None if none succeeded)."""
        good = [p for p in self.points if p.success]
        return max(good, key=lambda p: p.holding_force) if good else None

    def columns(self):
        """Return the rows of grasp.csv: dict of column name to list."""
        return {
            'pressure_pa': [p.pressure for p in self.points],
            'grasp_force_n': [p.grasp_force for p in self.points],
            'holding_force_n': [p.holding_force for p in self.points],
            'fingers_in_contact': [p.fingers_in_contact for p in self.points],
            'success': [p.success for p in self.points],
            'status': [p.status.name for p in self.points],
        }


def pressure_range(text, name='`pressure`'):
    """
    Parse grasp pressures [Pa gauge]: a list, start:stop:step or start:stop/count.

    The syntax of every tool (`fpc_gripper.ranges.parse_range`), pressures >= 0.

    Raises
    ------
    ValueError
        Naming `name` and the text when it is malformed, not finite, negative or empty.

    """
    pressures = parse_range(text, name)
    if pressures.min() < 0.0:
        raise ValueError(f'{name} must be >= 0 (gauge) [Pa], got {text!r}')
    return pressures


def _release_path(open_pressure, pressures, step):
    """Descending path from the open pressure through every grasp pressure, steps <= step."""
    stops = sorted(set(float(p) for p in pressures), reverse=True)
    path = [open_pressure]
    for stop in stops:
        gap = path[-1] - stop
        if gap <= 0.0:
            continue
        count = int(math.ceil(gap / step - 1e-9))
        path.extend(path[-1] - gap * np.arange(1, count + 1) / count)
        path[-1] = stop
    return path


def _steady(history, count):
    """Every finger slides (or is out of contact) and the force settled, over the last steps."""
    if len(history) < count:
        return False
    forces = np.array([h[0] for h in history[-count:]])
    sliding = all(h[1] for h in history[-count:])
    scale = max(np.abs(forces).max(), 1e-12)
    return sliding and np.ptp(forces) <= _STEADY_RTOL * scale


def holding_force(starts, sections, solvers, mu, settings=GraspSettings()):
    """
    Pull the object out along the palm axis from a grasp: the largest force before it goes.

    The object moves by u along +X of every finger frame (away from the palm) in steps of
    `pull_step`, each finger's contact a friction path from its grasp state; the force
    resisting the pull is the sum over fingers of the X component of their contact force
    on the finger (minus that on the object). The pull ends when the object is free, when
    the force has fallen below half its largest value, or when every contact slides at a
    steady force (then the largest force is the sliding force); its largest value is the
    holding force. A pull that cannot go on (a contact step that does not converge) after
    its force has fallen by a quarter from its largest value has passed its peak too;
    otherwise it is PULL_FAILED and its largest force only a lower bound.

    Parameters
    ----------
    starts : sequence of Result
        Each finger's grasp state, its obstacles at their grasp pose.
    sections : sequence of tuple
        Each finger's obstacles at that pose.
    solvers : sequence of PCCSolver
    mu : float
        [-].
    settings : GraspSettings

    Returns
    -------
    holding : float
        [N].
    pull : ndarray
        Displacements [m].
    force : ndarray
        Pull-out force at each [N].
    status : GraspStatus
    detail : dict
        Finger index and reason of a failure, the displacement reached.

    """
    current = list(starts)
    pull, force = [0.0], [_pull_force(current)]
    history = []
    u = 0.0
    step = settings.pull_step
    while True:
        shifts = step * np.arange(1, _PULL_CHUNK + 1)
        chunk = []
        along = np.stack([shifts, np.zeros_like(shifts)], axis=1)
        for i, (start, section, solver) in enumerate(zip(current, sections, solvers)):
            # The obstacles where the last chunk left them; this chunk moves them on.
            base = tuple(translated(o, (u, 0.0)) for o in section)
            steps = contact_path(solver, [start.pressure] * len(shifts), base, shifts=along,
                                 mu=mu, settings=settings.contact, start=start)
            if len(steps) < len(shifts) or steps[-1].status.name not in ('SUCCESS',
                                                                         'UNSTABLE'):
                reached = u + step * (len(steps) - 1 if steps else 0)
                why = steps[-1].message if steps else 'no step'
                best = float(np.max(force))
                if best > 0.0 and force[-1] <= _STOPPED_PAST_PEAK * best:
                    return best, np.array(pull), np.array(force), GraspStatus.SUCCESS, {
                        'ending': f'past the peak: the pull stopped at {reached * 1e3:.1f} mm, '
                                  f'{1.0 - force[-1] / best:.0%} below it ({why})',
                        'u': reached * 1e3}
                return (best, np.array(pull), np.array(force), GraspStatus.PULL_FAILED,
                        {'finger': i, 'why': why, 'u': reached * 1e3})
            chunk.append(steps)
        for k in range(len(shifts)):
            state = [steps[k] for steps in chunk]
            pull.append(u + shifts[k])
            force.append(_pull_force(state))
            history.append((force[-1], all(_sliding(r) for r in state)))
        current = [steps[-1] for steps in chunk]
        u += shifts[-1]
        best = max(force)
        free = not any(r.in_contact.any() for r in current)
        past = best > 0.0 and force[-1] < _PAST_PEAK * best
        if free or past or _steady(history, _STEADY_STEPS):
            return best, np.array(pull), np.array(force), GraspStatus.SUCCESS, {
                'ending': 'the object came free' if free else (
                    'past the peak' if force[-1] < _PAST_PEAK * best else 'steady sliding'),
                'u': u * 1e3}
        if u >= settings.pull_limit:
            return best, np.array(pull), np.array(force), GraspStatus.PULL_LIMIT, {'u': u * 1e3}


def _pull_force(results):
    """Force resisting a pull along +X: the X force of the object on the fingers [N]."""
    return float(sum(-r.total_force[:, 0].sum() for r in results))


def _sliding(result):
    """No contact sticks (every one slides, or there is none)."""
    return not np.any(result.pair_status[result.in_contact] == ck.STICK)


def simulate_grasp(config, obj, pressures, mu, settings=GraspSettings(), progress=None):
    """
    Grasp an object with every finger of a gripper, at each of several grasp pressures.

    The path is the one the gripper takes: open to `open_pressure`, place the object (it
    must not touch the open fingers), release the pressure through every grasp pressure
    (steps of at most `release_step`; Coulomb friction mu along the way), and at each
    grasp pressure pull the object out along the palm axis (`holding_force`). Every finger
    is solved on its own (its design, its mount angle, its section of the object), with
    the contact model of the finger pipeline (`pipeline.contact_model`).

    Parameters
    ----------
    config : GripperConfig
        Fingers, palm radius and max_pressure.
    obj : CoaxialCylinder, Sphere, CrossCylinder or Box
    pressures : array_like
        Grasp pressures [Pa], 0 <= p <= open_pressure.
    mu : float
        Coulomb coefficient between fingers and object [-], >= 0.
    settings : GraspSettings
    progress : callable, optional
        ``progress(done, total)`` after every finger's release path and every grasp
        pressure's pull-out.

    Returns
    -------
    GraspSweep
        Its `best` is the grasp pressure of largest holding force.

    """
    if not isinstance(config, GripperConfig):
        raise TypeError(f'`config` must be a GripperConfig, got {type(config).__name__}')
    if not hasattr(obj, 'section'):
        raise TypeError(f'`obj` must be a CoaxialCylinder, Sphere, CrossCylinder or Box, got '
                        f'{type(obj).__name__}')
    if not isinstance(settings, GraspSettings):
        raise TypeError(f'`settings` must be a GraspSettings, got {type(settings).__name__}')
    mu = real_number('mu', mu, '[-]')
    if mu < 0.0:
        raise ValueError(f'`mu` must be >= 0 [-], got {mu}')
    pressures = np.atleast_1d(np.asarray(pressures, dtype=float))
    open_pressure = config.max_pressure if settings.open_pressure is None \
        else settings.open_pressure
    if pressures.size == 0 or not np.all(np.isfinite(pressures)) or pressures.min() < 0.0 \
            or pressures.max() > open_pressure:
        raise ValueError(f'`pressures` must be finite, in [0, open_pressure = {open_pressure}] '
                         f'[Pa], got {pressures.tolist()}')
    sections = [obj.section(f.mount_angle, config.palm_radius) for f in config.fingers]
    solvers = [contact_model(f.design, settings.model) for f in config.fingers]
    path = _release_path(open_pressure, pressures, settings.release_step)
    states = {}
    failure = {}
    total = len(solvers) + len(pressures)
    for i, (section, solver) in enumerate(zip(sections, solvers)):
        results = contact_path(solver, path, section, mu=mu, settings=settings.contact)
        if progress is not None:
            progress(i + 1, total)
        if results and results[0].in_contact.any():
            failure[i] = (GraspStatus.DOES_NOT_FIT, {'finger': i, 'open': open_pressure})
            continue
        for p, r in zip(path, results):
            if r.status.name in ('SUCCESS', 'UNSTABLE'):
                states.setdefault(p, [None] * len(solvers))[i] = r
        if len(results) < len(path) or results[-1].status.name not in ('SUCCESS', 'UNSTABLE'):
            failure[i] = (GraspStatus.RELEASE_FAILED, {
                'finger': i, 'why': results[-1].message if results else 'no step',
                'below': path[len(results) - 1] if results else open_pressure})
    points = []
    for pressure in pressures:
        point = GraspPoint(float(pressure))
        fit = [f for f in failure.values() if f[0] is GraspStatus.DOES_NOT_FIT]
        grasp = states.get(float(pressure))
        if fit:
            point.status, detail = fit[0]
        elif grasp is None or any(r is None for r in grasp):
            point.status, detail = GraspStatus.RELEASE_FAILED, next(
                (f[1] for f in failure.values()), {'finger': '?', 'why': 'not reached'})
        else:
            point.contacts = tuple(grasp)
            point.grasp_force = float(sum(r.normal_force_total for r in grasp))
            point.fingers_in_contact = int(sum(r.in_contact.any() for r in grasp))
            moved = [tuple(section) for section in sections]
            holding, pull, force, status, detail = holding_force(grasp, moved, solvers, mu,
                                                                 settings)
            point.holding_force, point.pull, point.pull_force = holding, pull, force
            point.status = status
            detail.update(grasp=point.grasp_force, fingers=point.fingers_in_contact,
                          holding=holding)
        point.success = point.status is GraspStatus.SUCCESS
        detail.setdefault('ending', '')
        detail.setdefault('holding', point.holding_force)
        detail.setdefault('u', 0.0)
        point.message = _MESSAGES[point.status].format(**detail)
        points.append(point)
        if progress is not None:
            progress(len(solvers) + len(points), total)
    return GraspSweep(points, obj, mu, open_pressure)
