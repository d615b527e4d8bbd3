"""Benchmark of model_node's start-up: process start to the first shape answering a command."""

# Run inside the private network namespace:
#   scripts/isolated .venv/bin/python bench/bench_startup.py
# Each run starts `python -m fpc_gripper.nodes.model_node` (default parameters), publishes a
# stamped pressure command to finger_0 every 50 ms from the moment the process starts, and
# times the first finger_0/shape whose stamp is one of those commands. --cold also starts it
# once as a new user would: HOME an empty folder, numba's caches empty, the package's compiled
# engine (built at install) its only compiled code.

import argparse
import json
import os
import pathlib
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from timing import machine  # noqa: E402

from fpc_gripper.io.messages import ns_to_time, time_to_ns  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
RESULTS = ROOT / 'bench' / 'results' / 'startup.json'
#: Target of the issue "One equilibrium engine": start-up to the first shape, warm cache [s].
TARGET_S = 3.0
ATM = 101325.0


def one_start(namespace, env=None):
    """Start the node, command it and return seconds from process start to the answer."""
    from nav_msgs.msg import Path
    from sensor_msgs.msg import FluidPressure
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node('startup_probe', namespace=namespace, context=context)
    reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    sent, answered = set(), threading.Event()

    def on_shape(msg):
        if time_to_ns(msg.header.stamp) in sent:
            answered.set()

    node.create_subscription(Path, 'finger_0/shape', on_shape, reliable)
    publisher = node.create_publisher(FluidPressure, 'finger_0/pressure_command', reliable)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    start = time.monotonic()
    process = subprocess.Popen(
        [sys.executable, '-m', 'fpc_gripper.nodes.model_node', '--ros-args',
         '-r', f'__ns:={namespace}'], cwd=ROOT, stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL, env=env)
    try:
        while not answered.is_set() and time.monotonic() - start < 120.0:
            msg = FluidPressure()
            stamp = time.time_ns()
            msg.header.stamp = ns_to_time(stamp)
            msg.fluid_pressure = ATM + 100e3
            sent.add(stamp)
            publisher.publish(msg)
            answered.wait(0.05)
        elapsed = time.monotonic() - start
    finally:
        process.send_signal(signal.SIGINT)
        process.wait(timeout=30)
        executor.shutdown(timeout_sec=5.0)
        spinner.join(timeout=5.0)
        node.destroy_node()
        context.try_shutdown()
    return elapsed if answered.is_set() else float('nan')


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--cold', action='store_true',
                        help='first a start with an empty HOME and no numba cache')
    args = parser.parse_args(argv)
    if os.environ.get('FPC_NETNS') != '1':
        parser.error('run inside the private namespace: scripts/isolated .venv/bin/python '
                     'bench/bench_startup.py')
    out = {'machine': machine(), 'target_s': TARGET_S}
    if args.cold:
        with tempfile.TemporaryDirectory() as home:
            env = {k: v for k, v in os.environ.items() if not k.startswith('NUMBA_')}
            env.update(HOME=home, XDG_CACHE_HOME=os.path.join(home, '.cache'))
            out['first_ever_s'] = one_start('/startup_cold', env)
        print(f'first start, empty HOME: {out["first_ever_s"]:.2f} s')
    warm = [one_start(f'/startup_{i}') for i in range(args.repeats)]
    out['warm_s'] = warm
    out['warm_median_s'] = statistics.median(warm)
    out['meets'] = out['warm_median_s'] <= TARGET_S
    print(f'warm: median {out["warm_median_s"]:.2f} s over {len(warm)} starts '
          f'(target <= {TARGET_S:g} s)')
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(out, indent=2) + '\n')
    print(f'wrote {RESULTS}')


if __name__ == '__main__':
    main()
