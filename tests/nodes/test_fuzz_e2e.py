"""End-to-end fuzz of a real model node: raw random and empty payloads from another process."""

import math
import subprocess
import sys
import threading
import time

from nav_msgs.msg import Path
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.io.messages import time_to_ns
from fpc_gripper.model import CCMSolver
from fpc_gripper.nodes.model_node import ModelNode

pytestmark = pytest.mark.ros

NS = '/fuzz_e2e'
CONFIG = load_gripper_config()
NAMES = CONFIG.names
ATM = 101325.0
TIMEOUT = 15.0
ROUNDS = 18
SEED = 20261215

# The fuzzer, in its own process so that its payloads cross the middleware as a remote
# node's do. Per finger and topic: a junk writer (random, empty, oversized, hostile
# payloads) and a valid writer. It reads commands on stdin and answers on stdout.
FUZZER = r"""
import math, random, sys, time
import rclpy
from builtin_interfaces.msg import Time
from geometry_msgs.msg import WrenchStamped
from rclpy.serialization import serialize_message
from sensor_msgs.msg import FluidPressure

NS, NAMES, SEED = sys.argv[1], sys.argv[2].split(','), int(sys.argv[3])
TOPICS = {'pressure_command': FluidPressure, 'tip_force': WrenchStamped}
rclpy.init()
node = rclpy.create_node('fuzzer', namespace=NS)
rng = random.Random(SEED)
junk, valid = ({(n, t): node.create_publisher(c, f'{n}/{t}', 10)
                for n in NAMES for t, c in TOPICS.items()} for _ in range(2))


def hostile(kind):
    msg = TOPICS[kind]()
    msg.header.frame_id = rng.choice(['', 'finger_9', 'x' * 300, NAMES[0]])
    msg.header.stamp = rng.choice([Time(sec=2147483647, nanosec=4000000000), Time(sec=-1),
                                   Time(sec=2147483647, nanosec=999999999), Time()])
    # Always something to reject, whatever the frame and stamp.
    if kind == 'pressure_command':
        msg.fluid_pressure = rng.choice([math.nan, math.inf, -1.0, 0.0, 9999.0, 1e30])
    else:
        msg.wrench.force.x = rng.choice([math.nan, -math.inf, 5.0001, 1e30, 1.7e308])
    return serialize_message(msg)


def payload(kind):
    choice = rng.randrange(6)
    if choice == 0:
        return b''
    if choice == 1:
        return rng.randbytes(rng.randrange(1, 48))
    if choice == 2:
        return b'\x00\x01\x00\x00' + rng.randbytes(rng.randrange(0, 96))
    if choice == 3:
        return b'\x00\x01\x00\x00' + bytes(rng.randrange(4100, 9000))
    return hostile(kind)


def stamp():
    ns = node.get_clock().now().nanoseconds
    return Time(sec=ns // 10 ** 9, nanosec=ns % 10 ** 9), ns


def send(name, kind, values):
    msg = TOPICS[kind]()
    msg.header.frame_id = name
    msg.header.stamp, ns = stamp()
    if kind == 'pressure_command':
        msg.fluid_pressure = ATM + values[0]
    else:
        msg.wrench.force.x, msg.wrench.force.z = values
    valid[name, kind].publish(msg)
    return ns


ATM = 101325.0
deadline = time.monotonic() + 20.0
while not all(p.get_subscription_count() for p in [*junk.values(), *valid.values()]):
    assert time.monotonic() < deadline, 'the model node never subscribed'
    time.sleep(0.02)
print('ready', flush=True)
for line in sys.stdin:
    words = line.split()
    if words[0] == 'junk':
        for _ in range(int(words[1])):
            kind = rng.choice(list(TOPICS))
            junk[rng.choice(NAMES), kind].publish(payload(kind))
        print('done', flush=True)
    elif words[0] == 'valid':
        name, kind = words[1], words[2]
        print(send(name, kind, [float(v) for v in words[3:]]), flush=True)
    elif words[0] == 'stall':
        # An empty payload, then ten good commands, all from the valid writer.
        name = words[1]
        valid[name, 'pressure_command'].publish(b'')
        for k in range(10):
            ns = send(name, 'pressure_command', [1000.0 * (k + 1)])
        print(ns, flush=True)
    else:
        break
node.destroy_node()
rclpy.try_shutdown()
"""


class Ros:
    """The node under test and a probe, spun by one executor thread of this process."""

    def __init__(self):
        self.context = Context()
        rclpy.init(context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.model = ModelNode(context=self.context, namespace=NS, parameter_overrides=[
            Parameter('tolerance', value=0.0), Parameter('n_segments', value=2)])
        self.probe = rclpy.create_node('probe', namespace=NS, context=self.context)
        self.cond = threading.Condition()
        self.shapes = {name: {} for name in NAMES}
        for name in NAMES:
            self.probe.create_subscription(Path, f'{name}/shape',
                                           lambda msg, n=name: self._store(n, msg), 50)
        for node in (self.model, self.probe):
            self.executor.add_node(node)
        self.crash = None
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self):
        try:
            while not self.stop.is_set():
                self.executor.spin_once(timeout_sec=0.05)
        except BaseException as exc:  # noqa: B902 -- recorded: the test fails on it
            self.crash = exc

    def _store(self, name, msg):
        with self.cond:
            self.shapes[name][time_to_ns(msg.header.stamp)] = msg
            self.cond.notify_all()

    def shape(self, name, stamp_ns):
        with self.cond:
            assert self.cond.wait_for(lambda: stamp_ns in self.shapes[name], TIMEOUT), \
                f'{name}: no answer to the input stamped {stamp_ns} (crash: {self.crash!r})'
            return self.shapes[name][stamp_ns]

    def close(self):
        self.stop.set()
        self.thread.join(timeout=5.0)
        self.executor.shutdown(timeout_sec=5.0)
        for node in (self.model, self.probe):
            node.destroy_node()
        self.context.try_shutdown()


class Fuzzer:
    """The fuzzer process: one command line in, one answer line out."""

    def __init__(self):
        self.proc = subprocess.Popen(
            [sys.executable, '-c', FUZZER, NS, ','.join(NAMES), str(SEED)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout.readline().strip() == 'ready'

    def ask(self, line):
        self.proc.stdin.write(line + '\n')
        self.proc.stdin.flush()
        answer = self.proc.stdout.readline().strip()
        assert answer, f'the fuzzer died on {line!r}'
        return answer

    def close(self):
        try:
            self.proc.stdin.write('quit\n')
            self.proc.stdin.close()
            self.proc.wait(timeout=10.0)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()


def tip(path):
    return path.poses[-1].pose.position.x, path.poses[-1].pose.position.z


def test_junk_from_another_process_never_stops_the_answers():
    ros = Ros()
    fuzzer = None
    try:
        fuzzer = Fuzzer()
        solver = CCMSolver(CONFIG.fingers[0].design, n_segments=2)
        state = {name: [0.0, (0.0, 0.0)] for name in NAMES}
        for k in range(ROUNDS):
            assert fuzzer.ask('junk 25') == 'done'
            name = NAMES[k % len(NAMES)]
            if k < len(NAMES) or k % 2:
                state[name][0] = 5.0e3 * (k + 1)
                line = f'valid {name} pressure_command {state[name][0]}'
            else:
                state[name][1] = (0.02 * k, -0.01 * k)
                line = f'valid {name} tip_force {state[name][1][0]} {state[name][1][1]}'
            answer = ros.shape(name, int(fuzzer.ask(line)))
            # Whatever junk came before, the answer is the one of the good inputs alone.
            expected = solver.solve(*state[name]).points[-1]
            assert math.dist(tip(answer), expected) <= 1e-9
        fingers = ros.model.core.fingers
        refused = ros.model._guard.refused
        lost_before = sum(f.lost for f in fingers)
        # A writer's own good messages after its empty payload are held back by the
        # middleware until it has written its history depth (10) more; then they come,
        # and the node reports the lost one.
        last = int(fuzzer.ask(f'stall {NAMES[0]}'))
        assert math.dist(tip(ros.shape(NAMES[0], last)),
                         solver.solve(1.0e4, state[NAMES[0]][1]).points[-1]) <= 1e-9
        deadline = time.monotonic() + TIMEOUT
        while sum(f.lost for f in fingers) == lost_before and time.monotonic() < deadline:
            time.sleep(0.05)
        assert ros.crash is None and ros.thread.is_alive()
        assert refused > 0 and sum(f.rejected for f in fingers) >= refused
        assert sum(f.lost for f in fingers) > lost_before
    finally:
        if fuzzer is not None:
            fuzzer.close()
        ros.close()
