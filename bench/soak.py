"""Soak benchmark: the whole gripper graph at 200 Hz with grasp cycles and injected faults."""

# Run inside the private network namespace (30 minutes by default):
#   scripts/isolated .venv/bin/python bench/soak.py [--duration 1800] [--rate 200] [--seed 1]
#       [--out bench/results/soak.json] [--chart docs/soak.png]
#
# Every node is its own process, as `ros2 launch fpc_gripper gripper.launch.py record:=true`
# starts them (each with its config/<node>.yaml): regulator_bridge (sim backend),
# model_node (pressure_input command), gripper_controller and mcap_recorder (every gripper
# topic), plus gripper_demo's virtual object (a 40 mm cylinder on the palm, which answers
# each measured pressure with the contact force on the finger). Each runs through
# bench/soak_nodes.py, as its executable runs it, with a heap log (its allocator's state
# every 5 s); the bridge also gets a fault hook into its simulated backend. --rate sets the
# bridge's publish_rate_hz, the controller's control_rate_hz and model_node's max_rate_hz.
# --composed runs them all in one process instead, as the `gripper` executable does with
# --record --virtual-object (through soak_nodes.py too, for the fault hook).
#
# This process drives and watches the graph through one probe node:
# - grasp cycles: an aperture goal (open, 100-120 mm), then a grasp-force goal (1-2 N
#   total), each for a fixed time; whether and when controller_state reports it reached;
# - faults, at exponential intervals (seeded): bursts of NaN, infinite and out-of-range
#   pressure commands, absurd and non-finite tip forces, empty and random raw payloads,
#   stale, far-future and negative stamps, megabyte frame ids, and simulated regulator
#   disconnects and bad readbacks;
# - latency: every controller command of a finger is answered by the first shape of that
#   finger whose header stamp is at or after the command's (model_node stamps each output
#   with its newest input, and folds inputs that arrive within one solve period into one
#   solve); latency = receipt of that shape - command stamp, both on the system clock.
#   "exact" answers carry the command's own stamp, "merged" ones a later input's (a tip
#   force, or a newer command); a command with no answer within --answer-timeout is lost;
# - every --sample-period: RSS, open file descriptors, threads and CPU of each process,
#   the latency percentiles, lost and merged commands, faults, goals and the recording's
#   size.
# At the end it stops every process it started by PID (SIGINT, the recorder last), reads
# the recording with the mcap library (a closed file: summary, every message iterated, a
# sample decoded), and compares the stamps the probe received on the pressure_command and
# shape topics with those recorded. It writes the samples (JSON, CSV), a first-minute
# against last-minute table (Markdown) and a chart (PNG), and exits 0 only when no node
# crashed, every node stopped cleanly and the recording is closed and decodable.

import argparse
from array import array
import collections
import csv
import ctypes
import datetime
import json
import math
import os
import pathlib
import re
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Path
import numpy as np
import psutil
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.qos import ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import FluidPressure
from std_msgs.msg import Float64
from std_msgs.msg import String

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from soak_nodes import FAULT_TOPIC  # noqa: E402, I100 - after the path insert
from timing import machine  # noqa: E402

from fpc_gripper.io.cdr import header_stamp, INVALID_STAMP  # noqa: E402
from fpc_gripper.io.config import default_gripper_config_path  # noqa: E402
from fpc_gripper.io.config import load_gripper_config  # noqa: E402
from fpc_gripper.io.qos import MAX_STREAM_HZ, writer_history_s, writer_qos  # noqa: E402
from fpc_gripper.nodes.middleware import apply_middleware_settings  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
BENCH = ROOT / 'bench'
CONFIG = ROOT / 'config'
RESULTS = BENCH / 'results' / 'soak.json'
CHART = ROOT / 'docs' / 'soak.png'
NS = 1_000_000_000
#: Every fault the soak can inject; --faults picks some.
FAULT_KINDS = ('nan_pressure', 'range_pressure', 'bad_force', 'empty_payload', 'raw_payload',
               'stale_stamp', 'future_stamp', 'negative_stamp', 'long_frame_id',
               'regulator_disconnect', 'regulator_readback')
#: The virtual object, and the controller told about it (as gripper_demo does).
OBJECT = ('cylinder', 0.040)
#: Goals of the grasp cycle: open aperture [m] and total grasp force [N], drawn uniformly.
APERTURE_RANGE = (0.100, 0.120)
FORCE_RANGE = (1.0, 2.0)
#: Log text that says each node is up.
READY_TEXT = {'mcap_recorder': 'recording', 'regulator_bridge': 'active:',
              'model_node': 'waiting for pressure input', 'virtual_object': 'touch it below',
              'gripper_controller': 'ready:'}
READY_TEXT['gripper'] = tuple(READY_TEXT.values())
#: Stop order: the controller first (its commands end, the bridge's watchdog vents), the
#: recorder last, so it records everything the others sent.
STOP_ORDER = ('gripper', 'gripper_controller', 'virtual_object', 'model_node',
              'regulator_bridge', 'mcap_recorder')
#: Stamped topics (per finger) whose messages the probe and the recording must agree on.
COMPARED = ('pressure_command', 'shape')
STOP_TIMEOUT_S = 30.0
#: Cumulative counters of model_node's diagnostics, summed over the fingers in each sample.
MODEL_COUNTERS = ('solves', 'shared', 'coalesced', 'rejected', 'failures')
#: Deep reader queues, so that this process is not the first to drop.
PROBE_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
#: The probe's command and force writers keep the history the gripper's writers keep
#: (``FPC_GRIPPER_WRITER_HISTORY_S``, `io.qos.writer_qos`, at up to 1 kHz): at 0.5 s that
#: holds its largest burst of faults (200), of which a recorder that stalled would otherwise
#: lose all but 10.
STREAM = writer_qos(RELIABLE, MAX_STREAM_HZ)
_PR_SET_PDEATHSIG = 1


# -- node processes -------------------------------------------------------------------------

def _die_with_parent():
    """In the child: get SIGTERM when the soak dies, so that no node outlives it."""
    try:
        ctypes.CDLL('libc.so.6', use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    except OSError:
        pass


class ProcessStats:
    """Resource samples of one process: RSS, open fds, threads, CPU since the last sample."""

    def __init__(self, pid):
        self._ps = psutil.Process(pid)
        self._cpu = None

    def sample(self, wall):
        """RSS [MiB], open fds, threads and CPU [% of one core] since the last sample."""
        try:
            with self._ps.oneshot():
                rss = self._ps.memory_info().rss
                fds = self._ps.num_fds()
                threads = self._ps.num_threads()
                times = self._ps.cpu_times()
        except psutil.Error:
            return {'alive': False}
        cpu = times.user + times.system
        last, self._cpu = self._cpu, (wall, cpu)
        pct = 100.0 * (cpu - last[1]) / (wall - last[0]) if last and wall > last[0] \
            else math.nan
        return {'alive': True, 'rss_mib': rss / 2 ** 20, 'fds': fds, 'threads': threads,
                'cpu_pct': pct}


def stop_process(process, timeout=STOP_TIMEOUT_S):
    """
    Stop a child as Ctrl-C would: SIGINT, then SIGTERM and SIGKILL if it does not end.

    Waits `timeout` [s] after SIGINT and 10 s after each of the others. Returns the last
    signal sent (None when the process had ended already).
    """
    sent = None
    for sig, wait in ((signal.SIGINT, timeout), (signal.SIGTERM, 10.0),
                      (signal.SIGKILL, 10.0)):
        if process.poll() is not None:
            break
        sent = sig
        process.send_signal(sig)
        try:
            process.wait(timeout=wait)
        except subprocess.TimeoutExpired:
            continue
    return sent


class NodeProcess:
    """One node in a child process: its log file, resource samples and a clean stop by PID."""

    def __init__(self, name, argv, log_path, env=None):
        self.name = name
        self.argv = [str(a) for a in argv]
        self.log_path = pathlib.Path(log_path)
        # Written by the processes that bench/soak_nodes.py runs (soak_nodes.HeapLog).
        self.heap_log_path = self.log_path.with_name(f'{name}_heap.jsonl')
        self.exit_code = None
        self.exited_at = None
        self.forced = False
        self.stop_s = None
        with open(self.log_path, 'wb') as log:
            # Its own session: a Ctrl-C on the soak's terminal reaches the soak only, which
            # then stops the nodes in order.
            self.process = subprocess.Popen(
                self.argv, cwd=ROOT, stdin=subprocess.DEVNULL, stdout=log,
                stderr=subprocess.STDOUT, start_new_session=True,
                preexec_fn=_die_with_parent,
                env={**os.environ, **(env or {}),
                     'FPC_SOAK_HEAP_LOG': str(self.heap_log_path)})
        self.pid = self.process.pid
        self.stats = ProcessStats(self.pid)

    def log_text(self, tail=None):
        """Return the node's output so far (its last `tail` characters)."""
        data = self.log_path.read_bytes()
        return data[-tail:].decode('utf-8', 'replace') if tail else \
            data.decode('utf-8', 'replace')

    def ready(self):
        """Whether the node logged that it is up."""
        texts = READY_TEXT[self.name]
        log = self.log_text()
        return all(text in log for text in ((texts,) if isinstance(texts, str) else texts))

    def poll(self):
        """Exit code once the process ended, else None."""
        if self.exit_code is None and self.process.poll() is not None:
            self.exit_code = self.process.returncode
            self.exited_at = time.monotonic()
        return self.exit_code

    def sample(self, wall):
        """See `ProcessStats.sample`; ``{'alive': False}`` once the process ended."""
        if self.poll() is not None:
            return {'alive': False}
        return self.stats.sample(wall)

    def stop(self, timeout=STOP_TIMEOUT_S):
        """`stop_process` with `timeout` [s] after SIGINT; return the exit code."""
        start = time.monotonic()
        if self.poll() is None:
            self.forced = stop_process(self.process, timeout) not in (None, signal.SIGINT)
        self.poll()
        self.stop_s = time.monotonic() - start
        return self.exit_code


def node_commands(rate, seed, mcap_path, config_path, composed=False):
    """Return the command line of every node process, keyed by name (the recorder first)."""
    py = sys.executable
    gripper = ['-p', f'gripper_config:={config_path}']
    obj = ['-p', f'object:={OBJECT[0]}', '-p', f'object_diameter:={OBJECT[1]}']
    if composed:
        # The same parameters, each -p rule named after its node (no namespace here).
        def rules(node, *pairs):
            return [arg for pair in pairs for arg in ('-p', f'{node}:{pair}')]

        files = [arg for name in ('mcap_recorder', 'regulator_bridge', 'model_node',
                                  'gripper_controller')
                 for arg in ('--params-file', CONFIG / f'{name}.yaml')]
        return {'gripper': [
            py, BENCH / 'soak_nodes.py', 'gripper', '--ros-args', *files, *gripper,
            *rules('mcap_recorder', f'output_path:={mcap_path}', 'overwrite:=true'),
            *rules('regulator_bridge', f'publish_rate_hz:={rate}', f'sim_seed:={seed}'),
            *rules('model_node', f'max_rate_hz:={rate}'),
            *rules('virtual_object', f'object:={OBJECT[0]}', f'object_diameter:={OBJECT[1]}'),
            *rules('gripper_controller', f'control_rate_hz:={rate}', f'object:={OBJECT[0]}',
                   f'object_diameter:={OBJECT[1]}')]}

    def params(name):
        return ['--ros-args', '--params-file', CONFIG / f'{name}.yaml', *gripper]

    return {
        'mcap_recorder': [py, BENCH / 'soak_nodes.py', 'mcap_recorder',
                          *params('mcap_recorder'), '-p', f'output_path:={mcap_path}',
                          '-p', 'overwrite:=true'],
        'regulator_bridge': [py, BENCH / 'soak_nodes.py', 'regulator_bridge',
                             *params('regulator_bridge'), '-p', f'publish_rate_hz:={rate}',
                             '-p', f'sim_seed:={seed}'],
        'model_node': [py, BENCH / 'soak_nodes.py', 'model_node', *params('model_node'),
                       '-p', f'max_rate_hz:={rate}'],
        'virtual_object': [py, BENCH / 'soak_nodes.py', 'virtual_object', '--ros-args',
                           *gripper, *obj],
        'gripper_controller': [py, BENCH / 'soak_nodes.py', 'gripper_controller',
                               *params('gripper_controller'), '-p', f'control_rate_hz:={rate}',
                               *obj],
    }


# -- CDR ------------------------------------------------------------------------------------

def cdr_header(data, frame=None):
    """
    Stamp [ns] of a serialized message that starts with a std_msgs/Header, or None.

    With `frame` (bytes), also whether the header's frame_id is exactly that:
    ``(stamp, matches)``. CDR: 4 bytes of encapsulation (byte 1 is 1 for little
    endian), int32 sec, uint32 nanosec, uint32 length of frame_id with its NUL, frame_id.
    """
    if len(data) < 16 or data[0] != 0 or data[1] not in (0, 1):
        return None
    sec, nanosec, length = struct.unpack_from('<iII' if data[1] == 1 else '>iII', data, 4)
    stamp = sec * NS + nanosec
    if frame is None:
        return stamp
    return stamp, length == len(frame) + 1 and data[16:16 + len(frame)] == frame


def cdr_fluid_pressure(data):
    """fluid_pressure [Pa] of a serialized sensor_msgs/FluidPressure, or None."""
    if len(data) < 16:
        return None
    order = '<' if data[1] == 1 else '>'
    offset = 16 + struct.unpack_from(order + 'I', data, 12)[0]
    # Doubles are aligned to 8 bytes from the start of the payload (after the 4-byte
    # encapsulation).
    offset += -(offset - 4) % 8
    if offset + 8 > len(data):
        return None
    return struct.unpack_from(order + 'd', data, offset)[0]


# -- latency --------------------------------------------------------------------------------

class Window:
    """What the probe saw since the last sample."""

    def __init__(self):
        self.latencies = []
        self.commands = self.exact = self.merged = self.lost = 0
        self.shapes = self.shape_gaps = 0
        self.solve_ms = []
        self.goals = []
        self.faults = []


class LatencyTracker:
    """
    Match one finger's commands to the shapes that answer them.

    A command stamped s is answered by the first shape of its finger stamped t >= s and
    published at r >= s: latency r - s, exact when t == s. A shape can be taken before the
    command it answers (two topics, one executor), so recent shapes are kept for a look
    back. A command without an answer after `timeout_ns` is lost.
    """

    def __init__(self, timeout_ns, on_answer, on_lost):
        self.timeout_ns = int(timeout_ns)
        self.pending = collections.deque()
        self.recent = collections.deque()
        self._answer = on_answer
        self._lost = on_lost

    def command(self, stamp):
        """Take a command stamped `stamp` [ns]."""
        for t, r in self.recent:
            if t >= stamp and r >= stamp:
                self._answer(r - stamp, t == stamp)
                return
        self.pending.append(stamp)

    def shape(self, stamp, published):
        """Take a shape stamped `stamp`, published at `published` [ns]."""
        self.recent.append((stamp, published))
        while self.recent and published - self.recent[0][1] > self.timeout_ns:
            self.recent.popleft()
        while self.pending and self.pending[0] <= stamp:
            command = self.pending.popleft()
            self._answer(published - command, command == stamp)

    def expire(self, now):
        """Count the commands older than the timeout at `now` [ns] as lost."""
        while self.pending and now - self.pending[0] > self.timeout_ns:
            self.pending.popleft()
            self._lost()


class SpilledArray:
    """
    Numbers appended in memory and moved to an anonymous file at each `spill`.

    The probe keeps every latency and every stamp it received for the end of the run
    (some 60 MiB an hour at 200 Hz as arrays), and its own RSS is one of those the soak
    measures: spilled every sample period, they cost this process no memory as the run
    goes on. ``np.asarray`` gives every value appended, in order.

    Parameters
    ----------
    typecode : str
        The `array.array` type code ('d', 'q').

    """

    def __init__(self, typecode):
        self._typecode = typecode
        self._memory = array(typecode)
        self._file = tempfile.TemporaryFile()
        self._spilled = 0
        # The executor's thread appends while the sampling thread spills.
        self._lock = threading.Lock()

    def append(self, value):
        with self._lock:
            self._memory.append(value)

    def __len__(self):
        with self._lock:
            return self._spilled + len(self._memory)

    def spill(self):
        """Move the values in memory to the file."""
        with self._lock:
            memory, self._memory = self._memory, array(self._typecode)
            self._spilled += len(memory)
            memory.tofile(self._file)

    def __array__(self, dtype=None, copy=None):
        with self._lock:
            self._file.seek(0)
            spilled = np.frombuffer(self._file.read(), dtype=self._typecode)
            self._file.seek(0, 2)
            values = np.concatenate([spilled, np.frombuffer(self._memory, dtype=spilled.dtype)])
        return values if dtype is None else values.astype(dtype)


# -- the probe node -------------------------------------------------------------------------

class Probe(Node):
    """Publishes goals and faults, and watches commands, shapes and controller_state."""

    def __init__(self, fingers, answer_timeout_s):
        super().__init__('soak_probe')
        self.fingers = tuple(fingers)
        self.window = Window()
        self.counting = False
        self.t0 = None
        self.t0_ns = None
        self.t1_ns = None
        self.latency_t = SpilledArray('d')
        self.latency_ms = SpilledArray('d')
        self.received = {(topic, f): SpilledArray('q') for f in self.fingers
                         for topic in COMPARED}
        # Messages with a stamp that is no valid time (the recorder's rule, `header_stamp`):
        # the recording has them at its receive time, not their stamp, so they are
        # counted, not looked up.
        self.invalid_received = collections.Counter()
        self._sequence = [None] * len(self.fingers)
        self.last_command = [None] * len(self.fingers)
        self.goal = None
        self.goals = []
        self._frames = [f.encode() for f in self.fingers]
        self.trackers = [LatencyTracker(answer_timeout_s * NS, self._answered, self._lost)
                         for _ in self.fingers]
        self.aperture_pub = self.create_publisher(Float64, 'aperture_command', RELIABLE)
        self.grasp_pub = self.create_publisher(Float64, 'grasp_force_command', RELIABLE)
        self.command_pubs = [self.create_publisher(FluidPressure, f'{f}/pressure_command',
                                                   STREAM) for f in self.fingers]
        self.force_pubs = [self.create_publisher(WrenchStamped, f'{f}/tip_force', STREAM)
                           for f in self.fingers]
        # Empty payloads get writers of their own. Fast DDS drops a 0-byte payload on
        # receipt and a reliable reader waits for its sequence number, so the writer's
        # next samples wait at every reader until the empties have left its keep-last
        # history (depth samples later; README, Empty payloads): on the writer of the
        # other faults, a burst of empties held a 0.9 MB command for 70 s, and its memory.
        self.empty_pubs = [self.create_publisher(FluidPressure, f'{f}/pressure_command',
                                                 RELIABLE) for f in self.fingers]
        self.fault_pub = self.create_publisher(String, FAULT_TOPIC, RELIABLE)
        for i, f in enumerate(self.fingers):
            # Two-argument callbacks get the message info: source timestamp and sequence.
            self.create_subscription(FluidPressure, f'{f}/pressure_command',
                                     lambda data, info, i=i: self._on_command(i, data, info),
                                     PROBE_QOS, raw=True)
            self.create_subscription(Path, f'{f}/shape',
                                     lambda data, info, i=i: self._on_shape(i, data, info),
                                     PROBE_QOS, raw=True)
        self.create_subscription(DiagnosticStatus, 'controller_state', self._on_state,
                                 PROBE_QOS)
        # model_node's own counters, per finger: solves, coalesced and rejected inputs...
        self.model_counters = {}
        self.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics,
                                 PROBE_QOS)
        self.create_timer(0.1, self._expire)
        self.states = 0

    def start_counting(self):
        self.t0 = time.monotonic()
        self.t0_ns = time.time_ns()
        self.window = Window()
        self.counting = True

    def stop_counting(self):
        self.t1_ns = time.time_ns()
        self.counting = False

    def take_window(self):
        window, self.window = self.window, Window()
        for records in (self.latency_t, self.latency_ms, *self.received.values()):
            records.spill()
        return window

    # -- latency

    def _answered(self, latency_ns, exact):
        if not self.counting:
            return
        ms = latency_ns * 1e-6
        self.window.latencies.append(ms)
        self.window.exact += exact
        self.window.merged += not exact
        self.latency_t.append(time.monotonic() - self.t0)
        self.latency_ms.append(ms)

    def _lost(self):
        if self.counting:
            self.window.lost += 1

    def _expire(self):
        now = time.time_ns()
        for tracker in self.trackers:
            tracker.expire(now)

    def _record(self, topic, index, data, header):
        if not self.counting or header is None:
            return
        key = (topic, self.fingers[index])
        if header_stamp(data) is INVALID_STAMP:
            self.invalid_received[key] += 1
        else:
            self.received[key].append(header[0])

    def _on_command(self, index, data, info):
        header = cdr_header(data, self._frames[index])
        self._record('pressure_command', index, data, header)
        # Only the controller's commands are timed: the soak's own bad inputs carry
        # another frame id.
        if header is None or not header[1]:
            return
        self.last_command[index] = cdr_fluid_pressure(data)
        if self.counting:
            self.window.commands += 1
        self.trackers[index].command(header[0])

    def _on_shape(self, index, data, info):
        header = cdr_header(data, self._frames[index])
        self._record('shape', index, data, header)
        # Every publish of the model node's shape writer has the next sequence number: a
        # gap is shapes this reader never got (a keep-last writer overwrote them).
        sequence = info.get('publication_sequence_number')
        last, self._sequence[index] = self._sequence[index], sequence
        if self.counting and sequence is not None and last is not None and sequence > last:
            self.window.shapes += 1
            self.window.shape_gaps += sequence - last - 1
        if header is not None:
            # The publisher's clock at publish: this process's own delays do not count.
            self.trackers[index].shape(header[0], info['source_timestamp'])

    def _on_diagnostics(self, msg):
        for status in msg.status:
            name = status.name.rpartition(': ')
            if not name[0].endswith('/model_node') or name[2] not in self.fingers:
                continue
            values = {kv.key: kv.value for kv in status.values}
            try:
                self.window.solve_ms.append(float(values['solve_time_ms']))
                self.model_counters[name[2]] = {key: int(values[key]) for key in MODEL_COUNTERS}
            except (KeyError, ValueError):
                pass

    # -- goals

    def set_goal(self, kind, value):
        """Publish an aperture [m] or grasp-force [N] goal; close the previous one."""
        self.finish_goal()
        now = time.monotonic()
        self.goal = {'kind': kind, 'value': value, 'seen_active': False, 'reached_s': None,
                     'status': None, '_t': now}
        (self.aperture_pub if kind == 'aperture' else self.grasp_pub).publish(
            Float64(data=float(value)))

    def finish_goal(self):
        goal, self.goal = self.goal, None
        if goal is None:
            return
        goal['start'] = goal.pop('_t') - self.t0
        goal['reached'] = goal['reached_s'] is not None
        self.goals.append(goal)
        self.window.goals.append(goal)

    def _on_state(self, msg):
        self.states += 1
        goal = self.goal
        if goal is None:
            return
        # The first two keys are mode and goal_status.
        values = {kv.key: kv.value for kv in msg.values[:2]}
        status = values.get('goal_status')
        goal['status'] = status
        if values.get('mode') == goal['kind'] and status == 'active':
            goal['seen_active'] = True
        if goal['seen_active'] and status == 'reached' and goal['reached_s'] is None:
            goal['reached_s'] = time.monotonic() - goal['_t']


# -- scenario: grasp cycles and faults ------------------------------------------------------

class GraspCycle:
    """Open to an aperture for `open_s`, then grasp with a total force for `grasp_s`, again."""

    def __init__(self, probe, rng, open_s, grasp_s):
        self.probe = probe
        self.rng = rng
        self.durations = {'aperture': open_s, 'grasp': grasp_s}
        self.kind = 'grasp'
        self.until = -math.inf

    def step(self, now):
        if now < self.until:
            return
        self.kind = 'aperture' if self.kind == 'grasp' else 'grasp'
        low, high = APERTURE_RANGE if self.kind == 'aperture' else FORCE_RANGE
        self.probe.set_goal(self.kind, round(float(self.rng.uniform(low, high)), 4))
        self.until = now + self.durations[self.kind]


class FaultInjector:
    """Inject one fault of a random kind at exponential intervals of mean `interval_s`."""

    def __init__(self, probe, rng, kinds, interval_s):
        self.probe = probe
        self.rng = rng
        self.kinds = tuple(kinds)
        self.interval_s = float(interval_s)
        self.events = []
        self.next_at = None
        self.backend_until = -math.inf
        # The undecodable payloads sent: the recorder keeps them, as it keeps every message.
        self.junk = set()

    def step(self, now):
        if not self.kinds or self.interval_s <= 0.0:
            return
        if self.next_at is None:
            self.next_at = now + self.rng.exponential(self.interval_s)
        if now < self.next_at:
            return
        self.next_at = now + self.rng.exponential(self.interval_s)
        kind = self.kinds[self.rng.integers(len(self.kinds))]
        if kind.startswith('regulator_') and now < self.backend_until:
            return
        finger = int(self.rng.integers(len(self.probe.fingers)))
        event = {'t': now - self.probe.t0, 'kind': kind, 'finger': finger}
        try:
            event.update(getattr(self, '_' + kind)(finger, now))
        except Exception as exc:  # noqa: BLE001 - a failed injection is recorded, not fatal
            event['error'] = f'{type(exc).__name__}: {exc}'
        self.events.append(event)
        self.probe.window.faults.append(event)

    # One method per kind: each returns what it sent.

    def _pressures(self, finger, values, stamp=None, frame='soak_fault'):
        pub = self.probe.command_pubs[finger]
        for value in values:
            msg = FluidPressure(fluid_pressure=float(value))
            sec, nanosec = stamp if stamp is not None else divmod(time.time_ns(), NS)
            msg.header.stamp.sec, msg.header.stamp.nanosec = int(sec), int(nanosec)
            msg.header.frame_id = frame
            pub.publish(msg)

    def _burst(self, high):
        return int(self.rng.integers(1, high + 1))

    def _last_command(self, finger):
        value = self.probe.last_command[finger]
        return value if value is not None and math.isfinite(value) else 101325.0 + 1.0e5

    def _nan_pressure(self, finger, now):
        count = self._burst(50)
        values = self.rng.choice([math.nan, math.inf, -math.inf], size=count)
        self._pressures(finger, values)
        return {'count': count, 'detail': 'NaN and infinite absolute pressures'}

    def _range_pressure(self, finger, now):
        count = self._burst(20)
        values = self.rng.choice([-1.0e5, 0.0, 1.0e7, 1.0e30, 1.7e308], size=count)
        self._pressures(finger, values)
        return {'count': count, 'detail': 'absolute -1e5, 0, 1e7, 1e30, 1.7e308 Pa'}

    def _bad_force(self, finger, now):
        count = self._burst(20)
        choices = [1.0e3, -1.0e3, 1.0e6, 1.0e30, -1.7e308, math.nan, math.inf]
        pub = self.probe.force_pubs[finger]
        for _ in range(count):
            msg = WrenchStamped()
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), NS)
            msg.header.frame_id = self.probe.fingers[finger]
            msg.wrench.force.x = float(self.rng.choice(choices))
            msg.wrench.force.z = float(self.rng.choice(choices + [0.0]))
            pub.publish(msg)
        return {'count': count, 'detail': 'tip forces +-1e3 .. 1.7e308 N, NaN, inf'}

    def _empty_payload(self, finger, now):
        count = self._burst(200)
        self.junk.add(b'')
        for _ in range(count):
            self.probe.empty_pubs[finger].publish(b'')
        return {'count': count, 'detail': '0-byte pressure_command payloads'}

    def _raw_payload(self, finger, now):
        count = self._burst(50)
        topic = self.rng.choice(['pressure_command', 'tip_force'])
        pub = (self.probe.command_pubs if topic == 'pressure_command'
               else self.probe.force_pubs)[finger]
        for _ in range(count):
            body = self.rng.bytes(int(self.rng.integers(1, 257)))
            # Half of them look like little-endian CDR, so they get past the first check.
            payload = (b'\x00\x01\x00\x00' + body) if self.rng.random() < 0.5 else body
            self.junk.add(payload)
            pub.publish(payload)
        return {'count': count, 'detail': f'random raw payloads on {topic}'}

    def _stale_stamp(self, finger, now):
        count = self._burst(10)
        age = float(self.rng.uniform(2.0, 60.0))
        stamp = divmod(time.time_ns() - int(age * NS), NS)
        self._pressures(finger, [self._last_command(finger)] * count, stamp=stamp)
        return {'count': count, 'detail': f'the last command stamped {age:.1f} s ago'}

    def _future_stamp(self, finger, now):
        count = self._burst(5)
        if self.rng.random() < 0.5:
            stamp, detail = (2147483647, 4000000000), 'sec 2147483647, nanosec 4e9'
        else:
            stamp, detail = divmod(time.time_ns() + 3600 * NS, NS), '1 h ahead'
        self._pressures(finger, [self._last_command(finger)] * count, stamp=stamp)
        return {'count': count, 'detail': f'the last command stamped {detail}'}

    def _negative_stamp(self, finger, now):
        count = self._burst(5)
        stamp = (-1, 0) if self.rng.random() < 0.5 else (-2147483648, 999999999)
        self._pressures(finger, [self._last_command(finger)] * count, stamp=stamp)
        return {'count': count, 'detail': f'the last command stamped sec {stamp[0]}'}

    def _long_frame_id(self, finger, now):
        count = self._burst(3)
        size = int(self.rng.integers(100_000, 1_000_001))
        frame = self.probe.fingers[finger] + 'x' * size
        if self.rng.random() < 0.5:
            self._pressures(finger, [self._last_command(finger)] * count, frame=frame)
            topic = 'pressure_command'
        else:
            topic = 'tip_force'
            for _ in range(count):
                msg = WrenchStamped()
                msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), NS)
                msg.header.frame_id = frame
                self.probe.force_pubs[finger].publish(msg)
        return {'count': count, 'detail': f'{size} byte frame ids on {topic}'}

    def _regulator(self, spec, now):
        self.probe.fault_pub.publish(String(data=json.dumps(spec)))
        self.backend_until = now + spec['duration_s'] + 1.0
        return {'count': 1, 'detail': json.dumps(spec)}

    def _regulator_disconnect(self, finger, now):
        duration = round(float(self.rng.uniform(0.2, 1.5)), 3)
        return self._regulator({'kind': 'disconnect', 'duration_s': duration}, now)

    def _regulator_readback(self, finger, now):
        value = float(self.rng.choice([math.nan, math.inf, 2.0e6, -2.0e5]))
        duration = round(float(self.rng.uniform(0.1, 1.0)), 3)
        return self._regulator({'kind': 'bad_readback', 'channel': finger, 'value': value,
                                'duration_s': duration}, now)


# -- statistics -----------------------------------------------------------------------------

def percentiles(values):
    """p50, p95, p99 and max of `values` [ms] (NaN when empty), and their count."""
    data = np.asarray(values, dtype=float)
    if not data.size:
        return {'p50': math.nan, 'p95': math.nan, 'p99': math.nan, 'max': math.nan, 'n': 0}
    p50, p95, p99 = np.percentile(data, [50, 95, 99])
    return {'p50': float(p50), 'p95': float(p95), 'p99': float(p99), 'max': float(data.max()),
            'n': int(data.size)}


def slope_per_hour(times, values, robust=False):
    """
    Slope of values against times [s], per hour (NaN with < 3 points).

    Least squares by default. With `robust`, Theil-Sen's (scipy): the median of the
    slopes between every two samples, which a bump that comes back (a burst of large
    messages held for a minute) moves little, where it tilts a least-squares line
    fitted near one end of the run.
    """
    t = np.asarray(times, dtype=float)
    v = np.asarray(values, dtype=float)
    good = np.isfinite(t) & np.isfinite(v)
    if good.sum() < 3:
        return math.nan
    if robust:
        from scipy.stats import theilslopes
        return float(theilslopes(v[good], t[good])[0] * 3600.0)
    return float(np.polyfit(t[good], v[good], 1)[0] * 3600.0)


def read_heap_log(path, t0):
    """
    Return the lines of a process's heap log (soak_nodes.HeapLog), ``t`` made [s] since t0.

    Where a line has its arenas, it also gets ``main_arena_mib`` and ``thread_arenas_mib``:
    the memory the main arena, and all the others together, have from the kernel. An empty
    list where there is no log (a process that bench/soak_nodes.py did not run).
    """
    path = pathlib.Path(path)
    if not path.exists():
        return []
    lines = []
    for text in path.read_text().splitlines():
        try:
            line = json.loads(text)
        except ValueError:
            continue                      # the last line, cut by the stop
        line['t'] -= t0
        arenas = line.get('arenas')
        if arenas:
            line['main_arena_mib'] = sum(a['system_mib'] for a in arenas if a['nr'] == 0)
            line['thread_arenas_mib'] = sum(a['system_mib'] for a in arenas if a['nr'] != 0)
        lines.append(line)
    return lines


HEAP_KEYS = ('in_use_mib', 'free_mib', 'pymalloc_blocks', 'main_arena_mib',
             'thread_arenas_mib')


def heap_slopes(lines, robust=False, since=60.0):
    """Slopes per hour of `HEAP_KEYS` over the heap log's lines after `since` [s]."""
    after = [line for line in lines if line['t'] > since]
    return {key: slope_per_hour([line['t'] for line in after],
                                [line.get(key, math.nan) for line in after], robust)
            for key in HEAP_KEYS}


def _finite(values):
    return [v for v in values if v is not None and math.isfinite(v)]


def _mean(values):
    values = _finite(values)
    return sum(values) / len(values) if values else math.nan


def _median(values):
    values = _finite(values)
    return float(np.median(values)) if values else math.nan


def minute_table(samples, latency_t, latency_ms, names, duration, recorded=None):
    """
    First minute against last minute: one row per quantity.

    Parameters
    ----------
    recorded : (probed, absent), optional
        Times [s] of the probe's messages of the compared topics, and of those of them
        missing from the recording.

    Returns
    -------
    list of (quantity, first, last)

    """
    spans = ((0.0, min(60.0, duration)), (max(0.0, duration - 60.0), duration))
    rows = []
    lat_t = np.asarray(latency_t)
    lat = np.asarray(latency_ms)
    chosen = [[s for s in samples if a < s['t'] <= b + 1e-6] for a, b in spans]

    def per_span(fn):
        return tuple(fn(span, picked) for span, picked in zip(spans, chosen))

    for name in names:
        rows.append((f'{name} RSS [MiB]', *per_span(
            lambda span, picked: _mean(s['proc'][name].get('rss_mib') for s in picked))))
    for name in names:
        rows.append((f'{name} open fds', *per_span(
            lambda span, picked: max((s['proc'][name].get('fds', math.nan) for s in picked),
                                     default=math.nan))))
    for name in names:
        rows.append((f'{name} CPU [% of a core]', *per_span(
            lambda span, picked: _mean(s['proc'][name].get('cpu_pct') for s in picked))))
    for key in ('p50', 'p95', 'p99', 'max'):
        rows.append((f'latency {key} [ms]', *per_span(
            lambda span, picked: percentiles(
                lat[(lat_t >= span[0]) & (lat_t <= span[1])])[key])))
    for key, label in (('commands', 'commands timed'), ('lost', 'commands lost'),
                       ('merged', 'commands merged'), ('shapes', 'shapes received'),
                       ('shape_gaps', 'shapes missed (sequence gaps)')):
        rows.append((label, *per_span(lambda span, picked: sum(s[key] for s in picked))))
    rows.append(('recorder growth [MiB/min]', *per_span(
        lambda span, picked: 60.0 * (picked[-1]['mcap_mib'] - picked[0]['mcap_mib'])
        / (picked[-1]['t'] - picked[0]['t']) if len(picked) > 1 else math.nan)))
    rows.append(('model_node solve, median of its diagnostics [ms]', *per_span(
        lambda span, picked: _median(s['model_solve_ms'] for s in picked))))
    for key in MODEL_COUNTERS:
        rows.append((f'model_node {key} (its counters)', *per_span(
            lambda span, picked: picked[-1]['model_counters'][key]
            - picked[0]['model_counters'][key] if picked else math.nan)))
    if recorded is not None:
        probed, absent = recorded
        rows.append(('probe messages missing from the recording', *per_span(
            lambda span, picked: f'{_count_in(absent, span)} of {_count_in(probed, span)}')))
    rows.append(('whole machine CPU [% of a core]', *per_span(
        lambda span, picked: _mean(s['machine_cpu_pct'] for s in picked))))
    rows.append(('faults injected', *per_span(
        lambda span, picked: sum(s['faults'] for s in picked))))
    rows.append(('goals reached / ended', *per_span(
        lambda span, picked: f'{sum(s["goals_reached"] for s in picked)} / '
                             f'{sum(s["goals"] for s in picked)}')))
    return rows


def _count_in(times, span):
    times = np.asarray(times)
    return int(((times >= span[0]) & (times <= span[1])).sum())


def _cell(value):
    if isinstance(value, str):
        return value
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return '-'
    if isinstance(value, int) or float(value).is_integer() and abs(value) >= 100:
        return f'{value:.0f}'
    return f'{value:.3g}' if abs(value) < 100 else f'{value:.1f}'


def format_table(rows, duration, rate):
    """Format the first/last-minute rows as a Markdown table."""
    lines = [f'Soak, {duration / 60:.1f} min at {rate:g} Hz: first minute against last '
             'minute', '', '| quantity | first minute | last minute |', '|---|---|---|']
    lines += [f'| {q} | {_cell(a)} | {_cell(b)} |' for q, a, b in rows]
    return '\n'.join(lines) + '\n'


# -- the recording --------------------------------------------------------------------------

#: The recorder's stop line (`RecordingCounts.summary`).
_STOP_LINE = re.compile(
    r'closed .*: received (?P<received>\d+), written (?P<written>\d+), dropped '
    r'(?P<dropped>\d+) \((?P<queue_full>\d+) queue full, (?P<failed_writes>\d+) failed '
    r'writes\); (?P<lost>\d+) lost before the recorder \(counted by the middleware\); '
    r'(?P<invalid_stamps>\d+) invalid header stamps')


def recorder_counts(log):
    """Return the counts of the recorder's last stop line in a log, or None if it has none."""
    matches = list(_STOP_LINE.finditer(log))
    return {key: int(value) for key, value in matches[-1].groupdict().items()} \
        if matches else None


# The executor watch's lines (fpc_gripper/nodes/executor_watch.py): an episode's start, its end.
_BEHIND_LINE = re.compile(r'executor (?P<late>[0-9.]+) s behind: ')
_CAUGHT_UP_LINE = re.compile(r'executor caught up: its timers ran (?P<late>[0-9.]+) s late')


def executor_episodes(log):
    """
    Return the executor watch's episodes in a node's log, and the worst lateness [s].

    The worst is of the episodes that ended (their heartbeat ran again), else of the
    warnings: an episode still under way at the stop has only its start line.
    """
    starts = [float(m['late']) for m in _BEHIND_LINE.finditer(log)]
    ends = [float(m['late']) for m in _CAUGHT_UP_LINE.finditer(log)]
    return {'episodes': len(starts), 'worst_late_s': max(starts + ends, default=0.0)}


def read_recording(path, probe, junk=frozenset()):
    """
    Read the closed MCAP file: counts, a decoded sample, and the probe comparison.

    Every message is iterated (chunks decompressed); one in every `stride` of each topic
    and the last one are decoded with mcap_ros2. A sampled message that does not decode
    and is one of the `junk` payloads the soak sent is counted as such (``junk_sampled``),
    not as a failure: the recorder keeps what was on the wire. For the compared topics, the
    probe received in the counting window are looked up among the recorded publish times
    (the recorder's header stamps); those whose stamp is no valid time, which the recorder
    logs at their receive time, are counted against the recorded ones with such a stamp.
    """
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    out = {'path': str(path), 'size_mib': path.stat().st_size / 2 ** 20}
    counts = collections.Counter()
    stamps = collections.defaultdict(list)
    invalid = collections.Counter()
    decode = DecoderFactory()
    decoders = {}
    sampled = collections.Counter()
    failures = []
    last = {}
    stride = 997
    wanted = {f'/{f}/{t}': (t, f) for t, f in probe.received}
    with open(path, 'rb') as stream:
        reader = make_reader(stream, validate_crcs=True)
        summary = reader.get_summary()
        out['closed'] = summary is not None
        out['summary_count'] = (summary.statistics.message_count
                                if summary is not None and summary.statistics else None)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            topic = channel.topic
            counts[topic] += 1
            if topic in wanted:
                if message.publish_time != message.log_time:
                    stamps[topic].append(message.publish_time)
                elif (cdr_header(message.data) is not None
                      and header_stamp(message.data) is INVALID_STAMP):
                    invalid[topic] += 1
            if counts[topic] % stride == 1:
                sampled[_decode(decoders, decode, schema, channel, message, junk,
                                failures)] += 1
            last[topic] = (schema, channel, message)
    for schema, channel, message in last.values():
        sampled[_decode(decoders, decode, schema, channel, message, junk, failures)] += 1
    out['iterated_count'] = sum(counts.values())
    out['decoded'] = sampled['decoded']
    out['decode_failures'] = sampled['failure']
    out['junk_sampled'] = sampled['junk']
    out['decode_failure_examples'] = failures
    out['topics'] = dict(sorted(counts.items()))
    comparison = {}
    probed, missing = [], []
    for topic, key in wanted.items():
        got = np.asarray(probe.received[key], dtype=np.int64)
        recorded = np.asarray(stamps.get(topic, ()), dtype=np.int64)
        absent = got[~np.isin(got, recorded)]
        probed.append(got)
        missing.append(absent)
        # The span of the counting period the probe's stamps cover: its own junk and stale or
        # future stamps lie outside that period, and would stretch the span over the
        # warm-up, when the probe kept nothing.
        counted = got[(got >= probe.t0_ns) & (got <= probe.t1_ns)]
        inside = recorded[(recorded >= counted.min()) & (recorded <= counted.max())] \
            if counted.size else recorded[:0]
        odd = int(probe.invalid_received.get(key, 0))
        unseen = inside[~np.isin(inside, got)]
        comparison[topic] = {'probe': int(got.size) + odd,
                             'recorded': int(recorded.size) + invalid[topic],
                             'missing_from_recording': int(absent.size)
                             + max(0, odd - invalid[topic]),
                             'invalid_stamps': {'probe': odd, 'recorded': invalid[topic]},
                             'missing_at_s': [round((a - probe.t0_ns) * 1e-9, 3)
                                              for a in absent[:200].tolist()],
                             'recorded_not_probed': int(unseen.size),
                             'recorded_not_probed_per_minute': _per_minute(unseen, probe.t0_ns)}
    out['comparison'] = comparison
    # Times [s] since the measurement began, for the first/last-minute table.
    out['_times'] = tuple((np.concatenate(x) - probe.t0_ns) * 1e-9 if x else np.zeros(0)
                          for x in (probed, missing))
    return out


def _per_minute(stamps_ns, t0_ns):
    """Count `stamps_ns` by the minute since `t0_ns` they fall in: {minute: count}."""
    minutes = (np.asarray(stamps_ns, dtype=np.int64) - t0_ns) // (60 * NS)
    keys, counts = np.unique(minutes, return_counts=True)
    return {int(k): int(c) for k, c in zip(keys, counts)}


def node_env_item(text):
    """Parse ``NODE:VAR=VALUE`` (``--node-env``) into ``(node, var, value)``."""
    node, sep, assignment = text.partition(':')
    var, eq, value = assignment.partition('=')
    if not (sep and eq and node and var):
        raise argparse.ArgumentTypeError(f'--node-env must be NODE:VAR=VALUE, got {text!r}')
    return node, var, value


def node_envs(items):
    """Gather ``--node-env`` items into node -> {var: value}."""
    envs = {}
    for node, var, value in items:
        envs.setdefault(node, {})[var] = value
    return envs


def count_readable(path):
    """
    Messages readable from the start of a file that has no summary (a recorder that died).

    Returns
    -------
    dict
        ``readable_count`` and the ``error`` that ended the reading ('' at a clean end).

    """
    from mcap.records import Message
    from mcap.stream_reader import StreamReader

    count, error = 0, ''
    with open(path, 'rb') as stream:
        try:
            for record in StreamReader(stream, validate_crcs=True).records:
                count += isinstance(record, Message)
        except Exception as exc:  # noqa: BLE001 - where a damaged file ends is the finding
            error = f'{type(exc).__name__}: {exc}'
    return {'readable_count': count, 'error': error}


def is_junk(data, junk):
    """
    Whether `data`, as recorded, is one of the `junk` payloads the soak sent.

    Fast DDS pads a payload to a multiple of 4 bytes with zeros on its way to another
    process (a 57-byte payload was recorded as 60), so a junk payload may come back with
    1-3 zero bytes after it.
    """
    if data in junk:
        return True
    if len(data) % 4:
        return False
    return any(data.endswith(bytes(pad)) and data[:-pad] in junk for pad in (1, 2, 3))


def _decode(decoders, factory, schema, channel, message, junk=frozenset(), failures=None):
    """
    Decode one message: 'decoded', 'junk' (one of the soak's own, undecodable) or 'failure'.

    A failure is described in `failures` (a list, up to 10 entries): topic, log time,
    size, the first bytes and the error, so a failed run says what it could not read.
    """
    try:
        if channel.id not in decoders:
            decoders[channel.id] = factory.decoder_for(channel.message_encoding, schema)
        decoders[channel.id](message.data)
        return 'decoded'
    except Exception as exc:  # noqa: BLE001 - any failure to decode counts as one
        data = bytes(message.data)
        if is_junk(data, junk):
            return 'junk'
        if failures is not None and len(failures) < 10:
            failures.append({'topic': channel.topic, 'log_time': message.log_time,
                             'size': len(data), 'head': data[:24].hex(),
                             'error': f'{type(exc).__name__}: {exc}'[:300]})
        return 'failure'


# -- chart ----------------------------------------------------------------------------------

def make_chart(results, path):
    """Chart every quantity against time (minutes), one row each; red lines: a node died."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    samples = results['samples']
    names = list(results['processes']) + ['soak']
    t = np.array([s['t'] for s in samples]) / 60.0
    fig, axes = plt.subplots(6, 1, figsize=(13, 15), sharex=True)

    def proc(name, key):
        return np.array([s['proc'][name].get(key, math.nan) for s in samples], dtype=float)

    for ax, key, label in ((axes[0], 'rss_mib', 'RSS [MiB]'), (axes[1], 'fds', 'open fds'),
                           (axes[5], 'cpu_pct', 'CPU [% of one core]')):
        for name in names:
            ax.plot(t, proc(name, key), '--' if name == 'soak' else '-', lw=1.2,
                    label='soak (this process)' if name == 'soak' else name)
        ax.set_ylabel(label)
    for name, log in results.get('heap', {}).items():
        lines = [line for line in log['samples'] if 'in_use_mib' in line]
        axes[0].plot([line['t'] / 60.0 for line in lines],
                     [line['in_use_mib'] for line in lines], ':', lw=1.2,
                     label=f'{name}: malloc in use')
    axes[5].plot(t, [s['machine_cpu_pct'] for s in samples], color='k', lw=1.5,
                 label='whole machine (every process)')
    for key, style in (('p50', '-'), ('p95', '--'), ('p99', '-.'), ('max', ':')):
        axes[2].plot(t, [s['latency'][key] for s in samples], style, lw=1.2,
                     label=f'latency {key}')
    axes[2].set_yscale('log')
    axes[2].set_ylabel('command to shape [ms]')
    period = results['config']['sample_period_s']
    axes[3].step(t, [s['lost'] for s in samples], where='post', label='commands lost')
    axes[3].step(t, [s['shape_gaps'] for s in samples], where='post',
                 label='shapes the probe missed')
    faults = np.array([e['t'] for e in results['faults']]) / 60.0
    axes[3].plot(faults, np.zeros_like(faults), '|', color='tab:red', ms=12,
                 label='fault injected')
    axes[3].set_ylabel(f'per {period:g} s')
    axes[4].plot(t, [s['mcap_mib'] for s in samples], lw=1.5, label='recording')
    axes[4].set_ylabel('recorder file [MiB]')
    for crash in results['crashes']:
        for ax in axes:
            ax.axvline(crash['t'] / 60.0, color='tab:red', lw=1, alpha=0.6)
        axes[0].text(crash['t'] / 60.0, 0.03, f' {crash["node"]} died', color='tab:red',
                     fontsize=8, transform=axes[0].get_xaxis_transform())
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc='upper left', bbox_to_anchor=(1.005, 1.0))
    axes[-1].set_xlabel('time [min]')
    cfg = results['config']
    fig.suptitle(f'fpc_gripper soak: {cfg["measured_s"] / 60:.1f} min at {cfg["rate_hz"]:g} '
                 f'Hz, seed {cfg["seed"]}, {len(results["faults"])} faults '
                 f'({results["started"][:16]})')
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)


# -- the run --------------------------------------------------------------------------------

class Soak:
    """Start the graph, drive it for the duration, sample it, stop it, report."""

    def __init__(self, args):
        self.args = args
        config_path = args.gripper_config or str(default_gripper_config_path())
        self.config_path = config_path
        self.fingers = load_gripper_config(config_path).names
        self.workdir = pathlib.Path(args.workdir or tempfile.mkdtemp(prefix='fpc_soak_'))
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.mcap_path = self.workdir / 'soak.mcap'
        self.procs = {}
        self.samples = []
        self.crashes = []
        self.stop_event = threading.Event()
        self.own = None

    def start_nodes(self):
        commands = node_commands(self.args.rate, self.args.seed, self.mcap_path,
                                 self.config_path, composed=self.args.composed)
        for name, argv in commands.items():
            self.procs[name] = NodeProcess(name, argv, self.workdir / f'{name}.log',
                                           self.args.node_env.get(name))
        deadline = time.monotonic() + self.args.startup_timeout
        waiting = set(self.procs)
        while waiting and time.monotonic() < deadline and not self.stop_event.is_set():
            for name in list(waiting):
                proc = self.procs[name]
                if proc.ready():
                    waiting.discard(name)
                elif proc.poll() is not None:
                    raise RuntimeError(f'{name} exited with {proc.exit_code} at start:\n'
                                       f'{proc.log_text(3000)}')
            time.sleep(0.2)
        if waiting:
            raise RuntimeError(f'not up after {self.args.startup_timeout:.0f} s: '
                               f'{", ".join(sorted(waiting))}')

    def check_processes(self, probe):
        """Record every node that ended since the last check (to within the polling period)."""
        for name, p in self.procs.items():
            if p.poll() is not None and not any(c['node'] == name for c in self.crashes):
                self.crashes.append({'node': name, 't': p.exited_at - probe.t0,
                                     'exit_code': p.exit_code, 'log_tail': p.log_text(4000)})
                print(f'!! {name} exited with {p.exit_code} at '
                      f'{p.exited_at - probe.t0:.1f} s', flush=True)

    def sample(self, probe):
        wall = time.monotonic()
        window = probe.take_window()
        procs = {name: p.sample(wall) for name, p in self.procs.items()}
        procs['soak'] = self.own.sample(wall)
        try:
            mcap_mib = self.mcap_path.stat().st_size / 2 ** 20
        except OSError:
            mcap_mib = math.nan
        goals = window.goals
        sample = {
            't': wall - probe.t0, 'load1': os.getloadavg()[0],
            'machine_cpu_pct': psutil.cpu_percent() * psutil.cpu_count(), 'proc': procs,
            'latency': percentiles(window.latencies), 'commands': window.commands,
            'exact': window.exact, 'merged': window.merged, 'lost': window.lost,
            'shapes': window.shapes, 'shape_gaps': window.shape_gaps,
            'faults': len(window.faults), 'goals': len(goals),
            'goals_reached': sum(g['reached'] for g in goals), 'mcap_mib': mcap_mib,
            'model_solve_ms': float(np.median(window.solve_ms)) if window.solve_ms
            else math.nan,
            'model_counters': {key: sum(c[key] for c in probe.model_counters.values())
                               for key in MODEL_COUNTERS},
        }
        self.samples.append(sample)
        lat = sample['latency']
        model = procs.get('model_node', procs.get('gripper', {}))
        print(f'{sample["t"]:7.0f} s  model RSS {model.get("rss_mib", math.nan):7.1f} MiB '
              f'fds {model.get("fds", "-")}  latency p50 {lat["p50"]:6.2f} p99 '
              f'{lat["p99"]:7.2f} max {lat["max"]:7.1f} ms  commands {window.commands} '
              f'lost {window.lost}  faults {len(window.faults)}  '
              f'recording {mcap_mib:7.1f} MiB  load {sample["load1"]:.1f}', flush=True)

    def run(self):
        args = self.args
        seeds = np.random.SeedSequence(args.seed).spawn(2)
        started = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds')
        print(f'soak: {args.duration:.0f} s at {args.rate:g} Hz, seed {args.seed}; nodes and '
              f'logs in {self.workdir}', flush=True)
        self.start_nodes()
        # rclpy's handlers would shut the context down under the probe: a signal only asks
        # the run to end, and the nodes are then stopped in order.
        # The probe's readers take the same large faulty payloads as the nodes: the same
        # memory settings (FPC_GRIPPER_MIDDLEWARE_SETTINGS=0 turns them off for all).
        apply_middleware_settings()
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: self.stop_event.set())
        probe = Probe(self.fingers, args.answer_timeout)
        self.own = ProcessStats(os.getpid())
        executor = SingleThreadedExecutor()
        executor.add_node(probe)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()
        cycle = GraspCycle(probe, np.random.default_rng(seeds[0]), args.open_s, args.grasp_s)
        faults = FaultInjector(probe, np.random.default_rng(seeds[1]), args.faults,
                               args.fault_interval)
        timers = []
        try:
            # Warm-up: the controller gets its first goal and the recorder finds every topic.
            probe.t0 = time.monotonic()
            timers.append(probe.create_timer(0.05, lambda: cycle.step(time.monotonic())))
            self.stop_event.wait(args.warmup)
            if probe.states == 0:
                raise RuntimeError('no controller_state during the warm-up')
            probe.start_counting()
            for proc in list(self.procs.values()) + [self.own]:
                proc.sample(probe.t0)
            psutil.cpu_percent()
            timers.append(probe.create_timer(0.02, lambda: faults.step(time.monotonic())))
            end = probe.t0 + args.duration
            next_sample = probe.t0 + args.sample_period
            while not self.stop_event.is_set() and time.monotonic() < end:
                now = time.monotonic()
                self.stop_event.wait(min(0.5, max(0.0, next_sample - now), max(0.0, end - now)))
                self.check_processes(probe)
                if time.monotonic() >= next_sample or time.monotonic() >= end:
                    self.sample(probe)
                    next_sample += args.sample_period
            duration = time.monotonic() - probe.t0
        finally:
            for timer in timers:
                timer.cancel()
            probe.finish_goal()
            probe.stop_counting()
            stopped = self.stop_nodes()
            executor.shutdown(timeout_sec=5.0)
            spinner.join(timeout=5.0)
            probe.destroy_node()
            rclpy.try_shutdown()
        return self.report(probe, faults, started, duration, stopped)

    def stop_nodes(self):
        stopped = {}
        for name in STOP_ORDER:
            proc = self.procs.get(name)
            if proc is None:
                continue
            if name == 'mcap_recorder':
                # Let the last messages of the others reach the recorder.
                time.sleep(1.0)
            already = proc.exit_code is not None or proc.poll() is not None
            code = proc.stop()
            stopped[name] = {'exit_code': code, 'forced': proc.forced,
                             'stop_s': round(proc.stop_s, 3), 'died_before_stop': already}
            print(f'stopped {name} (pid {proc.pid}): exit {code}'
                  f'{" (forced)" if proc.forced else ""}'
                  f'{" (had died)" if already else ""} in {proc.stop_s:.2f} s', flush=True)
        left = [c.pid for c in psutil.Process().children(recursive=True)]
        for pid in left:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        stopped['left_running'] = left
        return stopped

    def _rss_slopes(self, names, robust, since=60.0):
        """
        Each process's RSS slope [MiB/h] over the samples after `since` [s].

        The whole run's slope (after the first minute) cannot tell a pool that fills and
        stops from a leak; the second half's, beside it, can: a fill flattens, a leak keeps
        its slope.
        """
        after = [s for s in self.samples if s['t'] > since]
        return {name: slope_per_hour([s['t'] for s in after],
                                     [s['proc'][name].get('rss_mib', math.nan) for s in after],
                                     robust)
                for name in names}

    def report(self, probe, faults, started, duration, stopped):
        args = self.args
        names = list(self.procs) + ['soak']
        try:
            recording = read_recording(self.mcap_path, probe, faults.junk)
        except Exception as exc:  # noqa: BLE001 - an unreadable recording is the finding
            recording = {'path': str(self.mcap_path), 'closed': False, 'decode_failures': None,
                         'size_mib': self.mcap_path.stat().st_size / 2 ** 20
                         if self.mcap_path.exists() else math.nan,
                         'read_error': f'{type(exc).__name__}: {exc}'}
            if self.mcap_path.exists():
                recording.update(count_readable(self.mcap_path))
        recorder = self.procs.get('gripper' if args.composed else 'mcap_recorder')
        recording['recorder'] = None if recorder is None else recorder_counts(
            recorder.log_text())
        if not args.keep_mcap and self.mcap_path.exists():
            self.mcap_path.unlink()
            recording['deleted'] = True
        rows = minute_table(self.samples, probe.latency_t, probe.latency_ms, names, duration,
                            recording.pop('_times', None))
        table = format_table(rows, duration, args.rate)
        kinds = collections.Counter(e['kind'] for e in faults.events)
        goals = probe.goals
        heap = {}
        for name, proc in self.procs.items():
            lines = read_heap_log(proc.heap_log_path, probe.t0)
            if lines:
                heap[name] = {'slope_per_h': heap_slopes(lines),
                              'slope_theil_sen_per_h': heap_slopes(lines, robust=True),
                              'slope_second_half_per_h': heap_slopes(lines,
                                                                     since=duration / 2),
                              'samples': lines}
        results = {
            'started': started, 'machine': machine(), 'workdir': str(self.workdir),
            'config': {'duration_s': args.duration, 'measured_s': duration,
                       'rate_hz': args.rate, 'seed': args.seed, 'faults': list(args.faults),
                       'writer_history_s': writer_history_s(), 'node_env': args.node_env,
                       'fault_interval_s': args.fault_interval,
                       'sample_period_s': args.sample_period, 'warmup_s': args.warmup,
                       'answer_timeout_s': args.answer_timeout, 'open_s': args.open_s,
                       'grasp_s': args.grasp_s, 'object': list(OBJECT),
                       'composed': args.composed,
                       'gripper_config': self.config_path, 'fingers': list(self.fingers)},
            'processes': {name: {'argv': p.argv, 'pid': p.pid, 'log': str(p.log_path),
                                 **stopped.get(name, {})} for name, p in self.procs.items()},
            'left_running': stopped.get('left_running', []),
            'crashes': self.crashes,
            'latency_ms': percentiles(probe.latency_ms),
            'commands': {key: sum(s[key] for s in self.samples)
                         for key in ('commands', 'exact', 'merged', 'lost', 'shapes',
                                     'shape_gaps')},
            'rss_slope_mib_per_h': self._rss_slopes(names, robust=False),
            'rss_slope_theil_sen_mib_per_h': self._rss_slopes(names, robust=True),
            'rss_slope_second_half_mib_per_h': self._rss_slopes(names, robust=False,
                                                                since=duration / 2),
            'heap': heap,
            'faults': faults.events, 'fault_counts': dict(sorted(kinds.items())),
            'goals': goals,
            'goals_reached': f'{sum(g["reached"] for g in goals)} / {len(goals)}',
            'recording': recording, 'first_last_minute': rows, 'samples': self.samples,
            'executor_watch': {name: executor_episodes(p.log_text())
                               for name, p in self.procs.items()},
        }
        out = pathlib.Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(results, indent=1, default=str) + '\n')
        write_csv(out.with_suffix('.csv'), self.samples, names)
        table_path = out.with_name(out.stem + '_table.md')
        table_path.write_text(table)
        make_chart(results, pathlib.Path(args.chart))
        print()
        print(table)
        print(f'latency over the run: {_latency_text(results["latency_ms"])}; commands '
              f'{results["commands"]}; goals reached {results["goals_reached"]}')
        print(f'faults: {results["fault_counts"]}; model_node counters at the end: '
              f'{self.samples[-1]["model_counters"] if self.samples else {}}')
        print(f'recording: {_recording_text(recording)}')
        print('RSS slope after the first minute [MiB/h], least squares (Theil-Sen): ' + ', '.join(
            f'{n} {v:+.1f} ({results["rss_slope_theil_sen_mib_per_h"][n]:+.1f})'
            for n, v in results['rss_slope_mib_per_h'].items()))
        print('RSS slope over the second half [MiB/h], least squares: ' + ', '.join(
            f'{n} {v:+.1f}' for n, v in results['rss_slope_second_half_mib_per_h'].items()))
        for name, log in heap.items():
            ls, ts = log['slope_per_h'], log['slope_theil_sen_per_h']
            print(f'{name} allocator after the first minute, least squares (Theil-Sen): '
                  f'malloc in use {ls["in_use_mib"]:+.1f} ({ts["in_use_mib"]:+.1f}) MiB/h '
                  f'(second half {log["slope_second_half_per_h"]["in_use_mib"]:+.1f}), '
                  f'held free {ls["free_mib"]:+.1f} ({ts["free_mib"]:+.1f}) MiB/h, pymalloc '
                  f'blocks {ls["pymalloc_blocks"]:+.0f} ({ts["pymalloc_blocks"]:+.0f}) /h'
                  f'{_arena_text(log["samples"][-1], ls, ts)}{_trim_text(log["samples"][-1])}')
        print('executor watch (episodes, worst lateness): ' + ', '.join(
            f'{n} {w["episodes"]} ({w["worst_late_s"]:.1f} s)'
            for n, w in results['executor_watch'].items()))
        for crash in self.crashes:
            print(f'CRASH: {crash["node"]} exited {crash["exit_code"]} at {crash["t"]:.1f} s; '
                  f'log tail:\n{crash["log_tail"][-1500:]}')
        print(f'wrote {out}, {out.with_suffix(".csv")}, {table_path}, {args.chart}; '
              f'logs in {self.workdir}')
        clean = (not self.crashes and not results['left_running']
                 and all(not p.get('forced') and p.get('exit_code') == 0
                         for p in results['processes'].values())
                 and recording.get('closed') and recording.get('decode_failures') == 0)
        return 0 if clean else 1


def _arena_text(line, ls, ts):
    """Describe the arenas' slopes, least squares (`ls`) and Theil-Sen (`ts`), if logged."""
    arenas = line.get('arenas')
    if not arenas:
        return ''
    return (f'; {len(arenas)} arenas: the main one {ls["main_arena_mib"]:+.1f} '
            f'({ts["main_arena_mib"]:+.1f}) MiB/h, the others {ls["thread_arenas_mib"]:+.1f} '
            f'({ts["thread_arenas_mib"]:+.1f}) MiB/h')


def _trim_text(line):
    """Describe the heap trims of a heap log's last line, as the report prints them."""
    count = line.get('trim_count', 0)
    if not count:
        return '; no heap trims'
    return (f'; {count} heap trims, mean {line["trim_total_s"] / count * 1e3:.1f} ms, '
            f'longest {line["trim_max_s"] * 1e3:.1f} ms')


def _latency_text(lat):
    return (f'p50 {lat["p50"]:.2f}, p95 {lat["p95"]:.2f}, p99 {lat["p99"]:.2f}, max '
            f'{lat["max"]:.1f} ms over {lat["n"]} commands')


def _recording_text(rec):
    if 'read_error' in rec:
        return (f'{rec["path"]} ({rec["size_mib"]:.1f} MiB) is not a closed MCAP file '
                f'({rec["read_error"]}); {rec.get("readable_count", 0)} messages readable '
                f'from its start, then {rec.get("error") or "its end"}')
    missing = {t: c['missing_from_recording'] for t, c in rec['comparison'].items()
               if c['missing_from_recording']}
    odd_probe = sum(c['invalid_stamps']['probe'] for c in rec['comparison'].values())
    odd_recorded = sum(c['invalid_stamps']['recorded'] for c in rec['comparison'].values())
    counts = rec.get('recorder')
    stop = ('no stop line from the recorder' if counts is None else
            "the recorder's stop line: {received} received, {written} written, {dropped} "
            'dropped, {lost} lost before it'.format(**counts))
    return (f'{stop}; {rec["size_mib"]:.1f} MiB, closed {rec["closed"]}, {rec["iterated_count"]} '
            f'messages iterated (summary {rec["summary_count"]}), {rec["decoded"]} decoded, '
            f'{rec["decode_failures"]} failures ({rec["junk_sampled"]} of the soak\'s own junk '
            f'payloads among the sampled); probe messages missing from it: '
            f'{missing or "none"} of {sum(c["probe"] for c in rec["comparison"].values())} '
            f'({odd_probe} of them with a stamp that is no valid time, counted against the '
            f'{odd_recorded} such messages recorded)'
            + ''.join(f'\n  undecodable: {f["topic"]} at log time {f["log_time"]}, {f["size"]} '
                      f'bytes ({f["head"]}...): {f["error"]}'
                      for f in rec.get('decode_failure_examples', ())))


def write_csv(path, samples, names):
    """One row per sample, the per-process values flattened to <process>_<key>."""
    keys = ('rss_mib', 'fds', 'threads', 'cpu_pct')
    header = ['t', 'load1', 'machine_cpu_pct', *[f'{n}_{k}' for n in names for k in keys],
              *[f'latency_{k}_ms' for k in ('p50', 'p95', 'p99', 'max')], 'latency_n',
              'commands', 'exact', 'merged', 'lost', 'shapes', 'shape_gaps', 'faults', 'goals',
              'goals_reached', 'mcap_mib', 'model_solve_ms',
              *[f'model_{key}' for key in MODEL_COUNTERS]]
    with open(path, 'w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(header)
        for s in samples:
            writer.writerow([
                f'{s["t"]:.3f}', f'{s["load1"]:.2f}', f'{s["machine_cpu_pct"]:.1f}',
                *[s['proc'].get(n, {}).get(k, '') for n in names for k in keys],
                *[s['latency'][k] for k in ('p50', 'p95', 'p99', 'max')], s['latency']['n'],
                s['commands'], s['exact'], s['merged'], s['lost'], s['shapes'],
                s['shape_gaps'], s['faults'], s['goals'], s['goals_reached'],
                f'{s["mcap_mib"]:.3f}', s['model_solve_ms'],
                *[s['model_counters'][key] for key in MODEL_COUNTERS]])


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--duration', type=float, default=1800.0,
                        help='measured time after the warm-up [s]')
    parser.add_argument('--rate', type=float, default=200.0,
                        help="bridge publish, controller loop and model_node's cap [Hz]")
    parser.add_argument('--seed', type=int, default=1, help='goals, faults and sim noise')
    parser.add_argument('--out', default=str(RESULTS),
                        help='JSON; the CSV and the Markdown table go beside it')
    parser.add_argument('--chart', default=str(CHART), help='PNG')
    parser.add_argument('--faults', default='all',
                        help=f'comma-separated kinds, "all" or "none": {", ".join(FAULT_KINDS)}')
    parser.add_argument('--fault-interval', type=float, default=4.0,
                        help='mean time between faults [s]')
    parser.add_argument('--sample-period', type=float, default=5.0, help='[s]')
    parser.add_argument('--warmup', type=float, default=15.0,
                        help='graph running before the measurement starts (the RSS slopes '
                             'start one minute after it) [s]')
    parser.add_argument('--answer-timeout', type=float, default=2.0,
                        help='a command without a shape after this long is lost [s]')
    parser.add_argument('--open-s', type=float, default=6.0,
                        help='time on each aperture goal [s]')
    parser.add_argument('--grasp-s', type=float, default=10.0,
                        help='time on each grasp-force goal [s]')
    parser.add_argument('--startup-timeout', type=float, default=120.0,
                        help='longest wait for every node to be up (2-5 s on 2 cores) [s]')
    parser.add_argument('--gripper-config', default=None, help='gripper YAML')
    parser.add_argument('--composed', action='store_true',
                        help='every node in one process (the gripper executable) instead of '
                             'one process each')
    parser.add_argument('--workdir', default=None,
                        help='node logs and the recording (default a new /tmp/fpc_soak_*)')
    parser.add_argument('--node-env', action='append', type=node_env_item, default=[],
                        metavar='NODE:VAR=VALUE',
                        help='set VAR in one node process only (repeatable), e.g. '
                             'model_node:FPC_GRIPPER_WRITER_HISTORY_S=0.5')
    parser.add_argument('--keep-mcap', action='store_true',
                        help='keep the recording (some 100 MiB a minute at 200 Hz) after '
                             'reading it')
    args = parser.parse_args(argv)
    if os.environ.get('FPC_NETNS') != '1':
        parser.error('run inside the private namespace: scripts/isolated .venv/bin/python '
                     'bench/soak.py')
    kinds = {'all': FAULT_KINDS, 'none': ()}.get(args.faults)
    if kinds is None:
        kinds = tuple(k.strip() for k in args.faults.split(',') if k.strip())
        unknown = sorted(set(kinds) - set(FAULT_KINDS))
        if unknown:
            parser.error(f'unknown fault kinds {unknown}; choose from {list(FAULT_KINDS)}')
    args.faults = kinds
    args.node_env = node_envs(args.node_env)
    unknown = sorted(set(args.node_env) - set(STOP_ORDER))
    if unknown:
        parser.error(f'--node-env names no node process: {unknown}; choose from '
                     f'{list(STOP_ORDER)}')
    if args.duration <= 0 or args.rate <= 0 or args.sample_period <= 0:
        parser.error('--duration, --rate and --sample-period must be > 0')
    return args


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    soak = Soak(args)
    try:
        return soak.run()
    except RuntimeError as exc:
        print(f'soak failed: {exc}', file=sys.stderr)
        return 1
    finally:
        # Whatever happened, nothing this run started stays up.
        for proc in soak.procs.values():
            if proc.poll() is None:
                proc.stop(timeout=5.0)
        if not args.keep_mcap and soak.mcap_path.exists():
            soak.mcap_path.unlink()


if __name__ == '__main__':
    sys.exit(main())
