"""A reader's memory behind deep writers, per Fast DDS reader sample limit (docs/soak.md)."""

# Usage (each pair in its own ROS domain, inside the private network namespace):
#   scripts/isolated .venv/bin/python bench/reader_pool.py [--duration 300] [--depth 500]
#       [--limits default,1000,100] [--out PATH]
# For each limit, one writer process publishes model_node's inputs (three fingers'
# pressure_command and tip_force, 200 Hz each, reliable, keep-last --depth) and one reader
# process takes them (six raw reliable keep-last-10 subscriptions, a callback that only
# counts, the SingleThreadedExecutor) under the package's Fast DDS profile with its data
# reader's max_samples and max_samples_per_instance set to the limit ('default': Fast DDS's
# own, 5000). Every 2.5 s the readers are stopped together with SIGSTOP for 0.2-1.0 s
# (seeded), as an overloaded machine holds up a node; on resuming, each writer resends what
# its history still holds. Each reader logs glibc's bytes in use every 5 s; the script
# prints them per minute and writes them to --out.

import argparse
import json
import math
import os
import pathlib
import random
import re
import signal
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'bench'))

from fpc_gripper.nodes.middleware import PROFILE  # noqa: E402, I100 - after the path insert

RATE_HZ = 200.0
FINGERS = 3
STALL_PERIOD_S = 2.5
STALL_RANGE_S = (0.2, 1.0)
HEAP_PERIOD_S = 5.0
_READER = re.compile(r'(<data_reader [^>]*>)')


def profile_text(limit):
    """Return the package's profile, its readers' sample limit `limit` (None: Fast DDS's)."""
    text = PROFILE.read_text()
    if len(_READER.findall(text)) != 1 or 'resourceLimitsQos' in text:
        raise RuntimeError(f'{PROFILE} has no single data reader without limits to vary')
    if limit is None:
        return text
    block = ('\n      <topic>\n        <resourceLimitsQos>\n'
             f'          <max_samples>{limit}</max_samples>\n'
             f'          <max_samples_per_instance>{limit}</max_samples_per_instance>\n'
             '        </resourceLimitsQos>\n      </topic>')
    return _READER.sub(lambda m: m.group(1) + block, text, count=1)


def writer(depth, duration):
    """Publish the inputs for `duration` [s] from writers of keep-last `depth`."""
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import FluidPressure

    rclpy.init()
    node = rclpy.create_node('reader_pool_writer')
    qos = QoSProfile(depth=depth, history=HistoryPolicy.KEEP_LAST,
                     reliability=ReliabilityPolicy.RELIABLE)
    commands = [node.create_publisher(FluidPressure, f'finger_{i}/pressure_command', qos)
                for i in range(FINGERS)]
    forces = [node.create_publisher(WrenchStamped, f'finger_{i}/tip_force', qos)
              for i in range(FINGERS)]
    ticks = [0]

    def tick():
        ticks[0] += 1
        sec, nanosec = divmod(time.time_ns(), 10 ** 9)
        for i in range(FINGERS):
            command = FluidPressure()
            command.header.frame_id = f'finger_{i}'
            command.header.stamp.sec, command.header.stamp.nanosec = sec, nanosec
            command.fluid_pressure = 2.0e5 + 5.0e4 * math.sin(0.01 * ticks[0] + i)
            commands[i].publish(command)
            force = WrenchStamped(header=command.header)
            force.wrench.force.x = 0.01 * math.sin(0.013 * ticks[0])
            forces[i].publish(force)

    node.create_timer(1.0 / RATE_HZ, tick)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    end = time.monotonic() + duration
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.5)
    print(f'published {ticks[0]} ticks', flush=True)


def reader(heap_path):
    """Take the inputs until SIGINT, logging the allocator to `heap_path`."""
    from fpc_gripper.nodes.middleware import apply_allocator_settings
    apply_allocator_settings()            # as the nodes do, before rclpy starts threads
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from sensor_msgs.msg import FluidPressure
    from soak_nodes import HeapLog

    from fpc_gripper.io.qos import RELIABLE_QOS

    rclpy.init()
    node = rclpy.create_node('reader_pool_reader')
    taken = [0]

    def count(_):
        taken[0] += 1

    for i in range(FINGERS):
        for msg_type, topic in ((FluidPressure, 'pressure_command'),
                                (WrenchStamped, 'tip_force')):
            node.create_subscription(msg_type, f'finger_{i}/{topic}', count, RELIABLE_QOS,
                                     raw=True)
    HeapLog(node, heap_path, HEAP_PERIOD_S)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass  # SIGINT: rclpy's handler shuts the context down under the spin
    print(f'taken {taken[0]}', flush=True)


def stall(pids, duration, seed):
    """SIGSTOP `pids` for 0.2-1.0 s every 2.5 s, for `duration` [s]."""
    rng = random.Random(seed)
    end = time.monotonic() + duration
    while time.monotonic() < end:
        held = rng.uniform(*STALL_RANGE_S)
        for pid in pids:
            os.kill(pid, signal.SIGSTOP)
        try:
            time.sleep(held)
        finally:
            for pid in pids:
                os.kill(pid, signal.SIGCONT)
        time.sleep(STALL_PERIOD_S - held)


def in_use(path):
    """Return [(t [s] since the first line, glibc's bytes in use [MiB])] of a heap log."""
    from soak import read_heap_log                 # the soak's reader of the same logs
    lines = read_heap_log(path, 0.0)
    return [(line['t'] - lines[0]['t'], line['in_use_mib']) for line in lines
            if 'in_use_mib' in line]


def run(args):
    from soak import stop_process                  # SIGINT, then SIGTERM and SIGKILL

    limits = [None if text == 'default' else int(text) for text in args.limits.split(',')]
    work = pathlib.Path(tempfile.mkdtemp(prefix='reader_pool_'))
    base = int(os.environ.get('ROS_DOMAIN_ID', '0'))
    me = [sys.executable, str(pathlib.Path(__file__).resolve())]
    pairs = []
    for k, limit in enumerate(limits):
        name = 'default' if limit is None else str(limit)
        profile = work / f'profile_{name}.xml'
        profile.write_text(profile_text(limit))
        env = dict(os.environ, ROS_DOMAIN_ID=str((base + 1 + k) % 101),
                   FASTRTPS_DEFAULT_PROFILES_FILE=str(profile),
                   RMW_FASTRTPS_USE_QOS_FROM_XML='1')
        heap = work / f'heap_{name}.jsonl'
        log = open(work / f'reader_{name}.log', 'w')
        read = subprocess.Popen(me + ['--role', 'reader', '--heap', str(heap)], env=env,
                                stdout=log, stderr=subprocess.STDOUT)
        write = subprocess.Popen(me + ['--role', 'writer', '--depth', str(args.depth),
                                       '--duration', str(args.duration + 20)], env=env,
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        pairs.append((name, heap, read, write, log))
    try:
        time.sleep(10.0)
        stall([p[2].pid for p in pairs], args.duration, args.seed)
    finally:
        for _, _, read, write, log in pairs:
            stop_process(read, 30.0)
            stop_process(write, 30.0)
            log.close()
    results = {'depth': args.depth, 'duration_s': args.duration, 'seed': args.seed,
               'workdir': str(work), 'readers': {}, 'taken': {}}
    print(f'writers keep-last {args.depth}; readers stopped {STALL_RANGE_S[0]}-'
          f'{STALL_RANGE_S[1]} s every {STALL_PERIOD_S} s; malloc in use [MiB] by minute:')
    for name, heap, *_ in pairs:
        curve = in_use(heap)
        results['readers'][name] = curve
        taken = re.findall(r'^taken (\d+)$', (work / f'reader_{name}.log').read_text(), re.M)
        results['taken'][name] = int(taken[-1]) if taken else None
        minutes = [v for t, v in curve if t % 60.0 < HEAP_PERIOD_S] + [curve[-1][1]]
        print(f'  limit {name:>7}: ' + ', '.join(f'{v:.2f}' for v in minutes)
              + f' (+{curve[-1][1] - curve[0][1]:.2f} over {curve[-1][0]:.0f} s); '
              f'samples taken {results["taken"][name]}')
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=1) + '\n')
    print(f'wrote {out}; logs in {work}')


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--role', choices=('run', 'writer', 'reader'), default='run',
                        help=argparse.SUPPRESS)
    parser.add_argument('--heap', help=argparse.SUPPRESS)
    parser.add_argument('--duration', type=float, default=300.0, help='[s] of stalls')
    parser.add_argument('--depth', type=int, default=500, help="the writers' keep-last depth")
    parser.add_argument('--limits', default='default,1000,100',
                        help="comma-separated reader sample limits, 'default' for Fast DDS's")
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--out', default=str(ROOT / 'bench' / 'results' / 'reader_pool.json'))
    args = parser.parse_args(argv)
    if args.role == 'writer':
        return writer(args.depth, args.duration)
    if args.role == 'reader':
        return reader(args.heap)
    return run(args)


if __name__ == '__main__':
    sys.exit(main())
