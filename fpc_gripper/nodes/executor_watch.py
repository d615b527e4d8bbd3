"""Say when a node's executor falls behind: a steady heartbeat timer, checked from a thread."""

import threading
import time

from rclpy.clock import Clock
from rclpy.clock import ClockType

__all__ = ['BEAT_PERIOD_S', 'BEHIND_AFTER_S', 'ExecutorWatch', 'Lag']

#: Period of the heartbeat timer and of the watch thread's checks [s] (steady time).
BEAT_PERIOD_S = 0.5
#: How late the heartbeat may run before the node says its executor is behind [s].
BEHIND_AFTER_S = 2.0
_EVENTS_ADVICE = (
    "where it is input, rclpy's EventsExecutor holds an event for each message not yet "
    'handled, with no bound (about 140 B each): on a machine too slow for its graph run '
    'the nodes with FPC_GRIPPER_EXECUTOR=single (README, Executor)')
_SINGLE_ADVICE = 'where it is input, the machine is too slow for this graph'


class Lag:
    """
    How late a heartbeat runs, on a monotonic clock [s]: an episode starts past a limit.

    `beat` is called when the heartbeat runs, `check` from elsewhere at any time. Each
    returns a line to log when an episode starts (`check`) or ends (`beat`), else None;
    one episode gives one of each, however often it is checked.

    Parameters
    ----------
    period_s : float
        The heartbeat's period [s].
    limit_s : float
        Lateness past which the executor is behind [s].
    now : float
        The time of the start, as if a beat ran then [s].

    Attributes
    ----------
    episodes : int
        Episodes started so far.
    worst_s : float
        The largest lateness seen in an episode [s].
    behind : bool
        Whether an episode is under way.

    """

    def __init__(self, period_s, limit_s, now):
        self.period_s = float(period_s)
        self.limit_s = float(limit_s)
        self.episodes = 0
        self.worst_s = 0.0
        self.behind = False
        self._last = float(now)

    def late(self, now):
        """How late the next heartbeat is at `now` [s] (negative while it is not yet due)."""
        return now - self._last - self.period_s

    def beat(self, now):
        """Record a run of the heartbeat at `now`; return the line that ends an episode."""
        line = None
        if self.behind:
            late = self.late(now)
            self.worst_s = max(self.worst_s, late)
            self.behind = False
            line = f'executor caught up: its timers ran {late:.1f} s late'
        self._last = float(now)
        return line

    def check(self, now):
        """Return the line that starts an episode when the heartbeat is late by the limit."""
        late = self.late(now)
        if self.behind or late < self.limit_s:
            return None
        self.behind = True
        self.episodes += 1
        self.worst_s = max(self.worst_s, late)
        return (f'executor {late:.1f} s behind: its timers (diagnostics, watchdogs, rate '
                'limits) wait behind a callback that has not returned, or input not yet handled')


class ExecutorWatch:
    """
    A steady heartbeat timer on `node`, and a thread that warns while it runs late.

    The timer runs on the node's executor like every other callback, so its lateness is
    the executor's: a callback that blocks, or input queued ahead of it. In
    bench/executor_backlog.py an overloaded reader on rclpy's EventsExecutor ran its
    0.5 s timer once in 30 s: input queued ahead of it faster than it was handled. The
    check runs in a thread of its own, which that cannot hold up; it logs one warning
    when an episode starts, with `advice`, and one line when the heartbeat runs again.

    Parameters
    ----------
    node : rclpy.node.Node
        Owns the timer (destroyed with it).
    logger : object
        Has ``warning(str)`` and ``info(str)`` (an rclpy logger; thread-safe).
    period_s, limit_s : float
        See `Lag` [s].
    clock : callable
        Monotonic seconds.

    Attributes
    ----------
    single : bool
        Whether the executor is the single-threaded one (else the EventsExecutor): which
        advice the warning gives. Set it once the executor is made (after the timer: the
        EventsExecutor takes the node's entities when the node is added).
    beats : int
        Runs of the heartbeat so far.

    """

    def __init__(self, node, logger, period_s=BEAT_PERIOD_S, limit_s=BEHIND_AFTER_S,
                 clock=time.monotonic):
        self._logger = logger
        self._clock = clock
        self.single = False
        self._lock = threading.Lock()
        self.lag = Lag(period_s, limit_s, clock())
        self.beats = 0
        self._stop = threading.Event()
        self._timer = node.create_timer(period_s, self._beat,
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._thread = threading.Thread(target=self._run, args=(period_s,), daemon=True,
                                        name='fpc_gripper-executor-watch')
        self._thread.start()

    def _beat(self):
        with self._lock:
            self.beats += 1
            line = self.lag.beat(self._clock())
        if line:
            self._logger.info(line)

    def _run(self, period_s):
        while not self._stop.wait(period_s):
            with self._lock:
                line = self.lag.check(self._clock())
            if line:
                advice = _SINGLE_ADVICE if self.single else _EVENTS_ADVICE
                self._logger.warning(f'{line}; {advice}')

    def close(self):
        """Stop the watch thread (the timer goes with its node)."""
        self._stop.set()
        self._thread.join(timeout=5.0)
