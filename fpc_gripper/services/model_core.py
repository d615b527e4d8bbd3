"""ROS-free state of the model node: input checks, latest-wins coalescing, shared warm solves."""

import math
import time

import numpy as np

from fpc_gripper.model.pipeline import model_label
from fpc_gripper.model.validation import STANDARD_ATMOSPHERE
from fpc_gripper.services.finger_state import check_pressure
from fpc_gripper.services.finger_state import check_tip_force
from fpc_gripper.services.finger_state import FingerState
from fpc_gripper.services.finger_state import FingerStatus
from fpc_gripper.services.finger_state import Level
from fpc_gripper.services.finger_state import RATE_BURST
from fpc_gripper.services.finger_state import real_in_range
from fpc_gripper.services.finger_state import Update
from fpc_gripper.services.input_limits import check_stamp
from fpc_gripper.services.input_limits import checked_bounds
from fpc_gripper.services.input_limits import DEFAULT_BOUNDS
from fpc_gripper.services.input_limits import InputBounds
from fpc_gripper.services.input_limits import InputCheck
from fpc_gripper.services.input_limits import lost_detail
from fpc_gripper.services.input_limits import MAX_STAMP_NS
from fpc_gripper.services.input_limits import Rejection
from fpc_gripper.services.input_limits import stale_detail
from fpc_gripper.services.logs import bounded

__all__ = ['DEFAULT_STALE_AFTER_S', 'RATE_BURST', 'RIGIDITY_DISPLACEMENT', 'FingerState',
           'FingerStatus', 'InputBounds', 'InputCheck', 'Level', 'ModelCore', 'Rejection',
           'Update', 'check_pressure', 'check_tip_force', 'stale_detail']

#: Default largest age of an input's header stamp [s] (model_node's stale_after_s).
DEFAULT_STALE_AFTER_S = 1.0
#: Tip displacement of the rigidity computation, eq. (22) [m].
RIGIDITY_DISPLACEMENT = 0.010
_SOLVER_ERRORS = (ValueError, TypeError, ArithmeticError, np.linalg.LinAlgError)
_RIGIDITY_CACHE = 64
# Round-off allowance of the token count (refills are sums of small increments).
_TOKEN_SLACK = 1e-9


class ModelCore:
    """
    Per-finger model state machine of the model node, free of ROS.

    Inputs are checked and stored (the newest wins; an input that replaces a pending one
    is counted as coalesced), then `process` solves pending fingers: fingers with the same
    solver (same design and settings), gauge pressure and tip force share one solve, a
    finger whose input equals a state some finger already holds reuses that state, and
    every solve is warm-started from the finger's last good result. A failed solve keeps
    the last good state. Solve rate is limited per finger by a token bucket. A finger
    solves nothing before its first accepted pressure: no state answers no input.

    Parameters
    ----------
    fingers : iterable of (str, ActuatorDesign)
        Finger names (frames) and designs, in index order.
    solver_factory : callable
        ``solver_factory(design)`` returns a solver with ``solve(pressure, tip_force,
        initial)`` and ``rigidity(pressure, axis, displacement, initial)`` like
        :class:`~fpc_gripper.model.CCMSolver`; called once per distinct design.
    max_pressure : float
        Gauge limit on top of each design's ``max_pressure`` [Pa].
    atmospheric_pressure : float
        Gauge reference [Pa].
    stale_after_s : float
        Largest accepted age of a header stamp [s]; 0 disables.
    future_limit_s : float
        Largest accepted lead of a header stamp over the clock [s]; 0 disables.
    max_rate_hz : float
        Sustained solve-rate cap per finger [Hz].
    frame_prefix : str
        A tip force must be in the frame ``frame_prefix + name`` of its finger.
    bounds : InputBounds
        Bounds on pressures, forces and frame ids (`check_pressure`, `check_tip_force`).
    timer : callable
        Monotonic seconds for solve timing.

    """

    def __init__(self, fingers, solver_factory, *, max_pressure=math.inf,
                 atmospheric_pressure=STANDARD_ATMOSPHERE, stale_after_s=0.0, max_rate_hz=200.0,
                 frame_prefix='', timer=time.perf_counter, future_limit_s=0.0,
                 bounds=DEFAULT_BOUNDS):
        self._states = tuple(
            FingerState(name=name, design=design,
                        max_pressure=min(float(design.max_pressure), float(max_pressure)))
            for name, design in fingers)
        if not self._states:
            raise ValueError('`fingers` must name at least one finger, got none')
        self._names = tuple(s.name for s in self._states)
        self._frame_prefix = str(frame_prefix)
        self.atmospheric_pressure = atmospheric_pressure
        self.stale_after_s = stale_after_s
        self.future_limit_s = future_limit_s
        self.bounds = bounds
        self.max_rate_hz = max_rate_hz
        self._timer = timer
        self._rigidity = {}
        self.rebuild(solver_factory)

    # -- settings ---------------------------------------------------------------------------

    @property
    def atmospheric_pressure(self):
        """Gauge reference [Pa]."""
        return self._atmospheric_pressure

    @atmospheric_pressure.setter
    def atmospheric_pressure(self, value):
        self._atmospheric_pressure = real_in_range(
            'atmospheric_pressure', value, 0.0, math.inf, '[Pa]')

    @property
    def stale_after_s(self):
        """Largest accepted stamp age [s]; 0 disables the check."""
        return self._stale_after_s

    @stale_after_s.setter
    def stale_after_s(self, value):
        self._stale_after_s = real_in_range('stale_after_s', value, 0.0, math.inf, '[s]')

    @property
    def future_limit_s(self):
        """Largest accepted lead of a stamp over the clock [s]; 0 disables the check."""
        return self._future_limit_s

    @future_limit_s.setter
    def future_limit_s(self, value):
        self._future_limit_s = real_in_range('future_limit_s', value, 0.0, math.inf, '[s]')

    @property
    def bounds(self):
        """The `InputBounds` every input is checked against."""
        return self._bounds

    @bounds.setter
    def bounds(self, value):
        self._bounds = checked_bounds(value, [self._frame_prefix + n for n in self._names])

    @property
    def max_rate_hz(self):
        """Sustained solve-rate cap per finger [Hz]."""
        return self._max_rate_hz

    @max_rate_hz.setter
    def max_rate_hz(self, value):
        value = real_in_range('max_rate_hz', value, 0.0, math.inf, '[Hz]')
        if value <= 0.0:
            raise ValueError(f'`max_rate_hz` must be > 0 [Hz], got {value}')
        self._max_rate_hz = value

    @property
    def fingers(self):
        """The per-finger states, in index order."""
        return self._states

    @property
    def names(self):
        """Finger names in index order."""
        return self._names

    def rebuild(self, solver_factory):
        """
        Build new solvers (one per distinct design) and mark every finger pending.

        The last good states stay published until the new solves succeed; they warm-start
        nothing, since their segmentation may differ. Fingers still waiting for a pressure
        stay waiting.

        Parameters
        ----------
        solver_factory : callable
            ``solver_factory(design)``, see the class.

        """
        solvers = {}
        for state in self._states:
            if state.design not in solvers:
                solvers[state.design] = solver_factory(state.design)
            state.solver = solvers[state.design]
            state.pending = True
            state.failed = None
        self._rigidity.clear()

    def warm_up(self, rigidity=True):
        """
        Solve the rest state once per solver, and throw the answers away.

        The first solve of a process loads (or, the first time ever, compiles) the
        solver's kernels; done here, at start-up, the first input is answered at once.
        Solvers are pure functions of their inputs, so this changes no later answer, and
        no finger state is touched: nothing is published for it.

        Parameters
        ----------
        rigidity : bool
            Also one rigidity computation (the bordered system's kernels).

        """
        for solver in {id(s.solver): s.solver for s in self._states}.values():
            try:
                rest = solver.solve(0.0, (0.0, 0.0))
                if rigidity:
                    solver.rigidity(0.0, axis='x', displacement=RIGIDITY_DISPLACEMENT,
                                    initial=rest)
            except _SOLVER_ERRORS:
                # The first real solve reports it.
                pass

    # -- inputs -----------------------------------------------------------------------------

    def offer_pressure(self, index, absolute, stamp_ns=0, now_ns=0, source='pressure_command',
                       frame_id=''):
        """
        Check an absolute pressure input of a finger and make it pending when accepted.

        Parameters
        ----------
        index : int
            Finger index.
        absolute : float
            Absolute pressure [Pa].
        stamp_ns : int or (int, int)
            Header stamp [ns], or the header's (sec, nanosec); 0 when unstamped.
        now_ns : int
            Node clock [ns].
        source : str
            Topic name for the rejection text.
        frame_id : str
            Header frame (any, of bounded length).

        Returns
        -------
        InputCheck

        """
        state = self._states[index]
        check = check_pressure(absolute, atmospheric_pressure=self._atmospheric_pressure,
                               max_pressure=state.max_pressure, stamp_ns=stamp_ns,
                               now_ns=now_ns, stale_after_s=self._stale_after_s,
                               future_limit_s=self._future_limit_s, frame_id=frame_id,
                               bounds=self._bounds)
        if self._record(state, check, source, stamp_ns, now_ns):
            state.gauge = check.value
            state.clamped += check.clamped
            state.has_pressure = True
        return check

    def offer_tip_force(self, index, f0, p0, frame_id, stamp_ns=0, now_ns=0,
                        source='tip_force'):
        """
        Check a tip force input of a finger and make it pending when accepted.

        Parameters
        ----------
        index : int
            Finger index.
        f0, p0 : float
            Force along the finger's X and Z [N].
        frame_id : str
            Header frame; must be the finger's frame, ``frame_prefix + name``.
        stamp_ns : int or (int, int)
            Header stamp [ns], or the header's (sec, nanosec); 0 when unstamped.
        now_ns : int
            Node clock [ns].
        source : str
            Topic name for the rejection text.

        Returns
        -------
        InputCheck

        """
        state = self._states[index]
        check = check_tip_force(f0, p0, frame_id,
                                expected_frame=self._frame_prefix + state.name,
                                stamp_ns=stamp_ns, now_ns=now_ns,
                                stale_after_s=self._stale_after_s,
                                future_limit_s=self._future_limit_s, bounds=self._bounds)
        if self._record(state, check, source, stamp_ns, now_ns):
            state.tip_force = check.value
        return check

    def reject(self, index, rejection, detail, source):
        """
        Record an input of a finger that never became a message (malformed, too large).

        Parameters
        ----------
        index : int
            Finger index.
        rejection : Rejection
        detail : str
            What was wrong (bounded here).
        source : str
            Topic name.

        Returns
        -------
        InputCheck
            The rejection, as the offers return it.

        """
        check = InputCheck(None, Rejection(rejection), bounded(detail))
        self._record(self._states[index], check, source, 0, 0)
        return check

    def lost(self, index, count, source):
        """
        Record messages the middleware lost on an input of a finger (a WARN until the next input).

        Parameters
        ----------
        index : int
            Finger index.
        count : int
            Messages lost since the last report.
        source : str
            Topic name.

        Returns
        -------
        InputCheck

        """
        state = self._states[index]
        count = max(int(count), 0)
        state.lost += count
        return self.reject(index, Rejection.LOST, lost_detail(count, state.lost), source)

    def _record(self, state, check, source, stamp_ns, now_ns):
        if not check.accepted:
            state.rejection = check.rejection
            state.last_rejection = bounded(f'{source} ({check.rejection.value}): {check.detail}')
            state.rejected += check.rejection is not Rejection.LOST
            return False
        state.rejection = None
        state.coalesced += state.ready
        state.pending = True
        stamp = check_stamp(stamp_ns).value
        # Unstamped: the arrival time, inside the range a header can carry.
        state.stamp_ns = stamp if stamp else min(max(int(now_ns), 0), MAX_STAMP_NS)
        return True

    # -- solving ----------------------------------------------------------------------------

    def _refill(self, state, now_ns):
        if state.tokens_ns is not None:
            gained = max(0, now_ns - state.tokens_ns) * 1e-9 * self._max_rate_hz
            state.tokens = min(RATE_BURST, state.tokens + gained)
        state.tokens_ns = now_ns

    def ready(self, now_ns):
        """
        Return the indices of the fingers with input to solve and solve budget left.

        Parameters
        ----------
        now_ns : int
            Monotonic or node-clock time [ns], the same clock for every call.

        Returns
        -------
        tuple of int

        """
        out = []
        for i, state in enumerate(self._states):
            if state.ready:
                self._refill(state, now_ns)
                if state.tokens >= 1.0 - _TOKEN_SLACK:
                    out.append(i)
        return tuple(out)

    @property
    def pending(self):
        """True while any finger has input to solve."""
        return any(s.ready for s in self._states)

    def process(self, indices, now_ns):
        """
        Solve the pending input of the given fingers (sharing identical solves).

        Each finger spends one token of its rate budget, even when forced past an empty
        bucket (then it waits longer for the next solve).

        Parameters
        ----------
        indices : iterable of int
            Fingers to process; those without input to solve (nothing new, or no pressure
            yet) are skipped.
        now_ns : int
            Time for the rate budget [ns].

        Returns
        -------
        list of Update
            One per processed finger, in order of first appearance.

        """
        groups = {}
        for i in indices:
            state = self._states[i]
            if not state.ready:
                continue
            self._refill(state, now_ns)
            state.tokens -= 1.0
            state.pending = False
            groups.setdefault(state.key, []).append(i)
        updates = []
        for key, members in groups.items():
            updates.extend(self._solve_group(key, members))
        return updates

    def _known(self, key):
        for state in self._states:
            if state.result_key == key:
                return state.result
        return None

    def _solve_group(self, key, members):
        solver, gauge = key[0], key[1]
        force = key[2:]
        lead = self._states[members[0]]
        result = self._known(key)
        solved_by = None
        failure = None
        elapsed = 0.0
        if result is None:
            warm = lead.result if lead.result_key is not None and lead.result_key[0] is solver \
                else None
            if lead.failed is not None and lead.failed[0] == key and lead.failed[1] is warm:
                # Same input, same warm start: the solver is deterministic, so it would
                # fail again; do not spend the time.
                failure = lead.failed[2]
            else:
                start = self._timer()
                try:
                    candidate = solver.solve(gauge, force, initial=warm)
                    ok = bool(candidate.success)
                    message = str(candidate.message)
                except _SOLVER_ERRORS as exc:
                    candidate, ok = None, False
                    message = f'solver raised {type(exc).__name__}: {exc}'
                elapsed = self._timer() - start
                if ok:
                    result, solved_by = candidate, members[0]
                else:
                    failure = message
                for i in members:
                    self._states[i].failed = None if ok else (key, warm, message)
        updates = []
        for i in members:
            state = self._states[i]
            if result is None:
                state.failure = failure
                state.failures += 1
                updates.append(Update(i, None, state.stamp_ns, False, failure))
                continue
            solved = i == solved_by
            state.result = result
            state.result_key = key
            state.result_stamp_ns = state.stamp_ns
            state.failure = None
            state.iterations = result.iterations if solved else 0
            state.solve_time_s = elapsed if solved else 0.0
            state.solves += solved
            state.shared += not solved
            updates.append(Update(i, result, state.stamp_ns, solved))
        return updates

    def rigidity(self, index, axis):
        """
        Flexural rigidity of a finger's last good state along an axis, cached.

        Computed at the state's gauge pressure, unloaded (eq. 22), with the solver's
        ``rigidity``, warm-started from the state; fingers sharing a solver and pressure
        share the computation.

        Parameters
        ----------
        index : int
            Finger index.
        axis : {'x', 'z'}
            Load and displacement direction.

        Returns
        -------
        Result or None
            None before any good state, or when the computation raised.

        """
        state = self._states[index]
        if state.result is None:
            return None
        solver, gauge = state.result_key[:2]
        key = (solver, gauge, axis)
        if key not in self._rigidity:
            if len(self._rigidity) >= _RIGIDITY_CACHE:
                self._rigidity.clear()
            try:
                value = solver.rigidity(gauge, axis=axis,
                                        displacement=RIGIDITY_DISPLACEMENT,
                                        initial=state.result)
            except _SOLVER_ERRORS:
                value = None
            self._rigidity[key] = value
        return self._rigidity[key]

    # -- health -----------------------------------------------------------------------------

    def health(self, index):
        """
        Level of a finger and the kind of its problem, without derived values (cheap).

        ERROR while the newest input's solve failed, WARN while waiting for the first
        pressure, after a rejected input (until the next accepted one) or while the
        published state breaks the small-rotation rule (valid=False), OK otherwise.

        Parameters
        ----------
        index : int
            Finger index.

        Returns
        -------
        tuple
            ``(level, failed, rejection, valid, waiting)``: it changes when the kind of
            problem changes, not when only its values do.

        """
        state = self._states[index]
        valid = None if state.result is None else bool(state.result.valid)
        failed = state.failure is not None
        waiting = not state.has_pressure
        if failed:
            level = Level.ERROR
        elif state.rejection is not None or valid is False or waiting:
            level = Level.WARN
        else:
            level = Level.OK
        return level, failed, state.rejection, valid, waiting

    def status(self, index):
        """
        Summarise a finger's health for diagnostics, with key values.

        Parameters
        ----------
        index : int
            Finger index.

        Returns
        -------
        FingerStatus
            Level as in `health`; the message names every problem.

        """
        state = self._states[index]
        result = state.result
        level, failed, rejection, valid, waiting = self.health(index)
        parts = []
        if waiting:
            parts.append('waiting for pressure input')
        if failed:
            parts.append(f'solver failed, keeping the last good state: {state.failure}')
        if rejection is not None:
            parts.append(f'rejected {state.last_rejection}')
        if valid is False:
            parts.append('state breaks the small-rotation rule (valid=False)')
        if result is None and state.failure is None and not waiting:
            parts.append('no state yet')
        message = bounded('; '.join(parts)) if parts else 'ok'
        pressure = 'none' if result is None else f'{state.result_key[1]:.1f}'
        force = (0.0, 0.0) if result is None else state.result_key[2:]
        values = {
            'pressure_pa': pressure,
            'tip_force': f'f0={force[0]:.6g} N, p0={force[1]:.6g} N',
            'iterations': str(state.iterations),
            'model': model_label(result),
            'solve_time_ms': f'{state.solve_time_s * 1e3:.3f}',
            'valid': str(valid),
            'last_rejection': state.last_rejection,
            'input_pressure_pa': f'{state.gauge:.1f}',
            'input_tip_force': f'f0={state.tip_force[0]:.6g} N, p0={state.tip_force[1]:.6g} N',
            'curvature_per_m': 'none' if result is None else f'{result.curvature:.6g}',
            'solver_message': bounded(state.failure or (
                'none' if result is None else result.message)),
            'rejected': str(state.rejected),
            'lost_messages': str(state.lost),
            'clamped_to_zero_gauge': str(state.clamped),
            'coalesced': str(state.coalesced),
            'solves': str(state.solves),
            'shared': str(state.shared),
            'failures': str(state.failures),
        }
        return FingerStatus(level, message, values)
