"""The scripted gripper session without ROS: its phases, how each is judged, the summary."""

from dataclasses import dataclass, field
import math

__all__ = ['Phase', 'Session', 'default_phases', 'format_summary']

#: Time after the start before the first goal, once the controller is heard [s].
WARM_UP_S = 1.0
#: Time after the start by which the controller must be heard [s].
COME_UP_S = 20.0


@dataclass
class Phase:
    """
    One step of the scripted session.

    Attributes
    ----------
    name : str
    kind : {'aperture', 'grasp', 'hold'}
    value : float
        Aperture [m], grasp force [N], or the duration of a hold [s].
    timeout : float
        Longest time allowed to reach the goal [s].
    reached : bool
    time_to_goal : float
        [s] (nan if never reached).
    start, end : float
        Node-clock times [s].
    final : dict
        Last controller_state values of the phase.
    arcs : list
        Contact arc (start, end) [m] of every finger at the end of the phase, or None.
    holding : float
        Holding force of the grasp at the end of the phase [N] (hold phase only).

    """

    name: str
    kind: str
    value: float
    timeout: float = 10.0
    reached: bool = False
    time_to_goal: float = math.nan
    start: float = math.nan
    end: float = math.nan
    detail: str = ''
    final: dict = field(default_factory=dict)
    arcs: list = field(default_factory=list)
    holding: float = math.nan


def default_phases(open_aperture=0.120, grasp_force=1.5, hold_s=3.0):
    """Open, close on the object and grasp, hold, release (open)."""
    return [Phase('open', 'aperture', open_aperture, timeout=8.0),
            Phase('grasp', 'grasp', grasp_force, timeout=10.0),
            Phase('hold', 'hold', hold_s, timeout=hold_s + 1.0),
            Phase('release', 'aperture', open_aperture, timeout=8.0)]


class Session:
    """
    Take a controller through a list of phases, step by step, and judge each one.

    An aperture or grasp phase starts with its goal and waits for the controller's state
    to report that goal (same target) as reached, then dwells `dwell_s`. A hold phase
    checks for its duration that the goal stays reached and that every finger's normal
    force stays within `force_band` of its share of the grasp force. The session ends
    after the last phase or the first failure; `arcs` (optional) gives every finger's
    contact arc, stored with each phase as it ends.

    Parameters
    ----------
    phases : iterable of Phase
    grasp_force : float
        Total normal force of the grasp [N].
    started : float
        Time of the start [s].
    dwell_s : float
        Time a goal must stay reached [s].
    force_band : float
        Largest relative deviation of a finger's normal force from its share [-].
    arcs : callable, optional
        Returns every finger's contact arc (start, end) [m] or None.

    Attributes
    ----------
    state : dict
        The newest controller_state values (with ``level`` and ``message``).
    finished : bool
        True once the last phase ended or one failed.

    """

    def __init__(self, phases, grasp_force, started, dwell_s=0.5, force_band=0.10, arcs=None):
        self.phases = list(phases)
        self.grasp_force = float(grasp_force)
        self.started = float(started)
        self.dwell_s = float(dwell_s)
        self.force_band = float(force_band)
        self.state = {}
        self.finished = False
        self._arcs = arcs
        self._index = -1
        self._goal_seen_active = False
        self._reached_at = None
        self._starting = None

    @property
    def passed(self):
        """True when every phase reached its goal."""
        return all(p.reached for p in self.phases)

    def step(self, now, ready):
        """
        Advance the session at `now` [s]; return the phase that started (None if none did).

        Parameters
        ----------
        now : float
            Node clock [s].
        ready : bool
            Whether the controller hears the goals (the state must have been heard too).

        """
        self._starting = None
        if self.finished:
            return None
        if self._index < 0:
            if ready and self.state and now - self.started > WARM_UP_S:
                self._start(0, now)
            elif now - self.started > COME_UP_S:
                self.phases[0].detail = 'the controller did not come up'
                self._index = 0
                self._finish(now, False)
            return self._starting
        phase = self.phases[self._index]
        if phase.kind == 'hold':
            self._hold(phase, now)
        else:
            self._goal(phase, now)
        return self._starting

    def _start(self, index, now):
        self._index = index
        phase = self.phases[index]
        phase.start = now
        self._goal_seen_active = False
        self._reached_at = None
        self._starting = phase

    def _finish(self, now, reached, detail=''):
        phase = self.phases[self._index]
        phase.end = now
        phase.reached = reached
        phase.detail = detail or phase.detail
        phase.final = dict(self.state)
        if self._arcs is not None:
            phase.arcs = list(self._arcs())
        if not reached or self._index + 1 >= len(self.phases):
            for rest in self.phases[self._index + 1:]:
                rest.detail = 'not run'
            self.finished = True
            return
        self._start(self._index + 1, now)

    def _matches(self, phase):
        try:
            if phase.kind == 'aperture':
                return abs(float(self.state['aperture_target_m']) - phase.value) < 1e-6 \
                    or 'clamped' in self.state.get('message', '')
            return abs(float(self.state['force_target_n']) - phase.value) < 1e-3
        except (KeyError, ValueError):
            return False

    def _hold(self, phase, now):
        status = self.state.get('goal_status', '')
        forces = [float(v) for k, v in self.state.items() if k.endswith('contact_force_n')]
        share = self.grasp_force / max(len(forces), 1)
        worst = max((abs(f - share) for f in forces), default=math.inf)
        phase.final = dict(self.state)
        if status != 'reached' or worst > self.force_band * share:
            self._finish(now, False, f'left the goal: status {status}, worst force error '
                                     f'{worst:.3f} N')
        elif now - phase.start >= phase.value:
            phase.time_to_goal = 0.0
            self._finish(now, True)

    def _goal(self, phase, now):
        status = self.state.get('goal_status', '')
        if self._matches(phase) and status == 'active':
            self._goal_seen_active = True
        if self._reached_at is None and self._goal_seen_active and status == 'reached':
            self._reached_at = now
            phase.time_to_goal = now - phase.start
        if self._reached_at is not None and now - self._reached_at >= self.dwell_s:
            self._finish(now, True)
        elif now - phase.start > phase.timeout:
            self._finish(now, False, f'not reached in {phase.timeout:.1f} s (status {status})')


def _arc_text(arc):
    """'s0-s1' in mm of a contact arc, a single value for a point, '-' for none."""
    if arc is None:
        return '-'
    start, end = arc[0] * 1e3, arc[1] * 1e3
    return f'{start:.1f}' if end - start < 0.05 else f'{start:.1f}-{end:.1f}'


def format_summary(phases, info):
    """Return the summary table printed at the end of the session."""
    lines = [f'{"phase":<9} {"goal":>12} {"result":>8} {"t_goal[s]":>9} {"aperture[mm]":>12} '
             f'{"normal force[N]":>22} {"contact arc s[mm]":>32} {"holding[N]":>10}  detail']
    for p in phases:
        goal = {'aperture': f'{p.value * 1e3:.1f} mm', 'grasp': f'{p.value:.3f} N',
                'hold': f'{p.value:.1f} s'}[p.kind]
        aperture = p.final.get('aperture_m')
        aperture = f'{float(aperture) * 1e3:.2f}' if aperture else '-'
        forces = [v for k, v in sorted(p.final.items()) if k.endswith('contact_force_n')]
        forces = ' '.join(f'{float(f):.3f}' for f in forces) or '-'
        arcs = ' '.join(_arc_text(a) for a in p.arcs) or '-'
        holding = f'{p.holding:.3f}' if math.isfinite(p.holding) else '-'
        result = 'REACHED' if p.reached else 'FAILED'
        lines.append(f'{p.name:<9} {goal:>12} {result:>8} {p.time_to_goal:>9.2f} '
                     f'{aperture:>12} {forces:>22} {arcs:>32} {holding:>10}  {p.detail}')
    lines.append(f'recording: {info["mcap"]} ({info["messages"]} messages); largest command '
                 f'{info["max_command"] * 1e-3:.1f} kPa (limit {info["max_pressure"] * 1e-3:.0f});'
                 f' model-node tip (tip-force model) to the contact model tip during hold '
                 f'{info["contact_residual"] * 1e3:.3f} mm; wall time {info["wall_s"]:.1f} s')
    return '\n'.join(lines)
