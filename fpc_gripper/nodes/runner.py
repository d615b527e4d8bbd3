"""The body of every node's main(): spin until SIGINT or SIGTERM, then shut down cleanly."""

import gc
import os
import signal
import socket
import sys
import threading
import time

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.executors import SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.logging import get_logger
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

from fpc_gripper.io.qos import WRITER_HISTORY_ENV
from fpc_gripper.io.qos import writer_history_s
from fpc_gripper.nodes.executor_watch import ExecutorWatch
from fpc_gripper.nodes.heap_trim import HeapTrim
from fpc_gripper.nodes.middleware import apply_middleware_settings
from fpc_gripper.nodes.middleware import settings_wanted
from fpc_gripper.safe_yaml import ConfigError

__all__ = ['EXECUTOR_ENV', 'FORCE_AFTER_S', 'START_ERRORS', 'StopRequest', 'make_executor',
           'own_arguments', 'run_node']

#: Set to ``single`` for rclpy's SingleThreadedExecutor instead of its EventsExecutor.
EXECUTOR_ENV = 'FPC_GRIPPER_EXECUTOR'
#: A stop signal this long after the first one interrupts a callback still running [s].
FORCE_AFTER_S = 1.0
#: Longest wait for what the nodes' ``stopping()`` left to the executor [s], and the
#: spins after it that send what it queued (an aborted goal's result).
_FLUSH_S = 0.5
_FLUSH_SPINS = 10
#: The longest one spin waits: the EventsExecutor's spin_once() without a timeout does
#: not return on its own wake() in the Jazzy wheel, so a stop is seen within this [s].
SPIN_TIMEOUT_S = 0.1
#: What a node's constructor raises when it cannot start: exit 1 with a message (a
#: `ConfigError`, an unusable config file, exits 2).
START_ERRORS = (ValueError, OSError, ParameterException)
_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
RCLError = rclpy_implementation.RCLError


class StopRequest:
    """
    The process's SIGINT and SIGTERM handler: the first asks for a stop, repeats are absorbed.

    A terminal's Ctrl-C under ``ros2 launch`` reaches every node twice within
    milliseconds (the terminal signals launch's whole process group, and launch passes
    the signal on), and launch follows up with SIGTERM after its timeout. None of these
    may interrupt the shutdown that the first one started, so the handler never raises
    while the shutdown runs. A signal that comes `force_after_s` or more after the
    first, while a callback still holds the executor (a long one: numba's fallback compile
    when the built engine does not match the CPU takes minutes), raises
    KeyboardInterrupt, once, to end that callback: the node is then destroyed as after
    any other stop.

    Parameters
    ----------
    force_after_s : float
        See above [s].
    clock : callable
        Monotonic seconds.

    """

    def __init__(self, force_after_s=FORCE_AFTER_S, clock=time.monotonic):
        self.signum = None
        self.stopping = False
        self._first = None
        self._force_after_s = float(force_after_s)
        self._clock = clock

    @property
    def requested(self):
        """True once a stop signal arrived."""
        return self.signum is not None

    def __call__(self, signum, frame=None):
        """Handle one signal (the signature of a `signal.signal` handler)."""
        now = self._clock()
        if self.signum is None:
            self.signum, self._first = signum, now
        elif not self.stopping and now - self._first >= self._force_after_s:
            self.stopping = True
            raise KeyboardInterrupt


class _Waker:
    """
    Wake a spinning executor when a signal arrives.

    Python runs signal handlers between bytecodes only, and the executor waits inside
    rcl; the interpreter's C-level handler writes the signal number to the wake-up fd,
    and this thread turns that into `wake()`: the EventsExecutor's own, or the trigger
    of a guard condition of the node's.
    """

    def __init__(self, wake):
        self._read, self._write = socket.socketpair()
        self._write.setblocking(False)
        self._previous = signal.set_wakeup_fd(self._write.fileno(), warn_on_full_buffer=False)
        self._thread = threading.Thread(target=self._run, args=(wake,), daemon=True,
                                        name='fpc_gripper-signal-waker')
        self._thread.start()

    def _run(self, wake):
        while self._read.recv(64):
            wake()

    def close(self):
        signal.set_wakeup_fd(self._previous)
        self._write.close()
        self._thread.join(timeout=1.0)
        self._read.close()


def make_executor(nodes):
    """
    Return an executor spinning `nodes`, and a thread-safe call that wakes it.

    rclpy's EventsExecutor (the Jazzy wheel's ``rclpy.experimental``) when it is there:
    it waits on rcl's events instead of rebuilding the wait set on every spin, which was
    64 % of model_node's samples at 3 x 200 Hz. It takes no guard conditions, so it is
    woken by its own `wake`. Its event queue has no bound: a node that cannot keep up
    holds one queued event per message it is behind (bench/executor_backlog.py). Else (or
    with ``FPC_GRIPPER_EXECUTOR=single``, whose backlog is the readers' depths) the
    SingleThreadedExecutor, woken by a guard condition.
    """
    context = nodes[0].context
    executor = None
    if os.environ.get(EXECUTOR_ENV, 'events') != 'single':
        try:
            from rclpy.experimental import EventsExecutor
        except ImportError:
            pass
        else:
            executor = EventsExecutor(context=context)
            wake = executor.wake
    if executor is None:
        executor = SingleThreadedExecutor(context=context)
        wake = nodes[0].create_guard_condition(lambda: None).trigger
    for node in nodes:
        executor.add_node(node)
    return executor, wake


def own_arguments(args, name):
    """
    Return the command line without its ROS arguments, or None when those do not parse.

    For a program with options of its own, before `run_node`: rcl's complaint (say a
    ``-p`` rule it cannot read) becomes one fatal log line under `name`, not a traceback.
    """
    try:
        return remove_ros_args(sys.argv if args is None else args)
    except RCLError as exc:
        get_logger(name).fatal(f'cannot start: {exc}')
        return None


def _flush_stops(nodes, executor):
    """
    Let nodes end what clients wait for (a running action goal) while the executor lives.

    A node's ``stopping()`` returns None, or a callable that is True once the executor has
    run the work it left (the execution of an aborted goal). The executor spins until then,
    at most `_FLUSH_S`, and a little more to send what that work queued (the result).
    """
    waiting = [node.stopping() for node in nodes if hasattr(node, 'stopping')]
    waiting = [done for done in waiting if done is not None]
    if not waiting:
        return
    deadline = time.monotonic() + _FLUSH_S
    while not all(done() for done in waiting) and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.01)
    for _ in range(_FLUSH_SPINS):
        executor.spin_once(timeout_sec=0.01)


def _warn_of_writer_history(name):
    """Log once per process what the writer-history option costs, when it is set."""
    history_s = writer_history_s()           # a bad value raises ValueError: a start error
    if history_s > 0.0:
        get_logger(name).warning(
            f'{WRITER_HISTORY_ENV}={history_s:g}: writers keep {history_s:g} s of history; '
            "behind them Fast DDS 2.14's keep-last readers leak the older samples resent "
            'to them until their sample pools are full, after which a reader that falls '
            'behind refuses samples: use it for recordings shorter than an hour '
            '(README, Topics and QoS)')


def run_node(build, name, args=None, check=None):
    """
    Build a node (or several), spin until SIGINT or SIGTERM, destroy them, shut rclpy down.

    rclpy's own signal handlers are not installed: they shut the context down from
    another thread while a callback may still be publishing, and then raise
    KeyboardInterrupt wherever the main thread happens to be (``destroy_node`` included),
    which is what printed tracebacks under ``ros2 launch``. Here a signal only asks for a
    stop (see `StopRequest`); the running callback finishes, the node is destroyed (so
    the recorder closes its file and the bridge vents), and only then is the context
    shut down.
    The first node carries the process's `ExecutorWatch` (``node.executor_watch``),
    which warns while the executor's timers run late.

    Parameters
    ----------
    build : callable
        ``build()`` returns the node, or a list of nodes for one executor (destroyed in
        reverse order); called after ``rclpy.init``.
    name : str
        Logger name for a failed start.
    args : list of str, optional
        Command-line arguments for ``rclpy.init`` (default ``sys.argv``).
    check : callable, optional
        ``check(built)`` after the build returns an exit code when it must not spin
        (it has logged why), or None.

    Returns
    -------
    int
        0 after a stop signal or an external shutdown; 2 when a config file is invalid
        and 1 when the node could not start otherwise (one fatal log line names the
        reason); or what `check` returned.

    """
    stop = StopRequest()
    for signum in _STOP_SIGNALS:
        signal.signal(signum, stop)
    built = executor = waker = watch = None
    nodes = ()
    try:
        try:
            apply_middleware_settings()
            _warn_of_writer_history(name)
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
            built = build()
            nodes = tuple(built) if isinstance(built, (list, tuple)) else (built,)
            if settings_wanted(os.environ):
                # The allocator settings' other half: pages freed amid the heap go back.
                nodes[0].heap_trim = HeapTrim(nodes[0])
        except ConfigError as exc:
            get_logger(name).fatal(f'invalid config: {exc}')
            return 2
        except (*START_ERRORS, RCLError) as exc:
            # RCLError: rcl refused the command line (say a --params-file it cannot parse).
            get_logger(name).fatal(f'cannot start: {exc}')
            return 1
        code = None if check is None else check(built)
        if code is not None:
            return code
        # Everything built so far (numba's and the model's object graphs among it) lives as
        # long as the node: out of the collector's sight, a full collection no longer walks
        # it while messages wait (at 3 x 200 Hz its pauses made the p99 latency).
        gc.freeze()
        # Before the executor: the EventsExecutor takes the node's timers when it is added.
        watch = ExecutorWatch(nodes[0], nodes[0].get_logger())
        executor, wake = make_executor(nodes)
        watch.single = isinstance(executor, SingleThreadedExecutor)
        nodes[0].executor_watch = watch
        waker = _Waker(wake)
        while not stop.requested and rclpy.ok():
            executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)
    except ExternalShutdownException:
        # Someone shut the context down (rclpy.shutdown()): a stop like any other.
        pass
    except KeyboardInterrupt:
        # A forced stop (see StopRequest): the node is destroyed as after any other.
        get_logger(name).warning('stop forced: a callback that did not finish was interrupted')
    finally:
        stop.stopping = True
        if waker is not None:
            waker.close()
        if watch is not None:
            watch.close()
        if executor is not None:
            _flush_stops(nodes, executor)
            executor.shutdown()
        for node in reversed(nodes):
            node.destroy_node()
        rclpy.try_shutdown()
        # The process ends now. A repeat of the stop signal that comes during the
        # interpreter's exit (Ctrl-C reaches a node under ros2 launch twice, 30 ms apart)
        # would raise KeyboardInterrupt there, with the default handler back, and turn the
        # clean exit into -2: from here on the stop signals are ignored.
        for signum in _STOP_SIGNALS:
            signal.signal(signum, signal.SIG_IGN)
    return 0
