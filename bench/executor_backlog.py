"""An overloaded subscriber: what rclpy's EventsExecutor holds, against the single-threaded one."""

# Run inside the private network namespace:
#   scripts/isolated .venv/bin/python bench/executor_backlog.py
# A publisher process sends WrenchStamped on 3 topics at RATE_HZ each (reliable, keep-last
# 10, the commands' QoS); a reader process subscribes to them with the same QoS and, when
# overloaded, sleeps SLEEP_S after every `every`-th message, so that it handles far fewer
# messages than arrive. Every 5 s the reader reads its malloc bytes in use (mallinfo2).
# Both processes make the nodes' middleware and allocator settings. The keep-last reader
# history holds at most 10 messages per topic whichever the executor, so growth beyond
# that is the executor's own: the EventsExecutor queues an event for every message that
# arrives and takes one message per event, with no bound on the queue. The reader also runs
# the nodes' executor watch (fpc_gripper/nodes/executor_watch.py): how often its 0.5 s
# heartbeat timer ran, and how late. Writes bench/results/executor_backlog.json and prints
# a table.

import argparse
import json
import os
import pathlib
import subprocess
import sys
import time
import types

RESULTS = pathlib.Path(__file__).resolve().parent / 'results' / 'executor_backlog.json'
ROOT = pathlib.Path(__file__).resolve().parents[1]
RATE_HZ = 1000.0
TOPICS = 3
SLEEP_S = 0.08
SAMPLE_S = 5.0


def child(role, executor_kind, every, duration_s):
    """Publish, or read and report, for `duration_s` [s]; the reader prints one JSON line."""
    from fpc_gripper.nodes.middleware import apply_allocator_settings
    apply_allocator_settings()
    from fpc_gripper.nodes.middleware import apply_middleware_settings
    apply_middleware_settings()
    from geometry_msgs.msg import WrenchStamped
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.experimental import EventsExecutor
    from rclpy.serialization import serialize_message

    from fpc_gripper.io.qos import RELIABLE_QOS
    from fpc_gripper.nodes.executor_watch import ExecutorWatch

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
    from soak_nodes import mallinfo2
    read_mallinfo = mallinfo2()

    def in_use_mib():
        info = read_mallinfo()
        return (info.uordblks + info.hblkhd) / 2**20

    rclpy.init(args=[])
    node = rclpy.create_node(f'backlog_{role}')
    handled = [0]
    if role == 'pub':
        payload = serialize_message(WrenchStamped())
        pubs = [node.create_publisher(WrenchStamped, f'backlog_{i}', RELIABLE_QOS)
                for i in range(TOPICS)]
        node.create_timer(1.0 / RATE_HZ, lambda: [p.publish(payload) for p in pubs])
    else:
        def on_message(_):
            handled[0] += 1
            if every and handled[0] % every == 0:
                time.sleep(SLEEP_S)
        for i in range(TOPICS):
            node.create_subscription(WrenchStamped, f'backlog_{i}', on_message, RELIABLE_QOS,
                                     raw=True)
    lines = []
    log = types.SimpleNamespace(warning=lines.append, info=lines.append)
    watch = ExecutorWatch(node, log) if role == 'sub' else None
    executor = EventsExecutor() if executor_kind == 'events' else SingleThreadedExecutor()
    executor.add_node(node)
    samples = []
    t0 = next_sample = time.monotonic()
    while time.monotonic() - t0 < duration_s:
        executor.spin_once(timeout_sec=0.05)
        if time.monotonic() >= next_sample:
            samples.append((time.monotonic() - t0, in_use_mib(), handled[0]))
            next_sample += SAMPLE_S
    if role == 'sub':
        watch.close()
        lag = watch.lag
        print(json.dumps({'samples': samples, 'beats': watch.beats, 'episodes': lag.episodes,
                          'worst_late_s': max(lag.worst_s, lag.late(time.monotonic())),
                          'watch_lines': lines}), flush=True)


def run(executor_kind, every, duration_s):
    """Start a reader and a publisher; return the reader's report (`child`'s JSON line)."""
    command = [sys.executable, __file__, '--child']
    reader = subprocess.Popen([*command, 'sub', executor_kind, str(every), str(duration_s)],
                              cwd=ROOT, stdout=subprocess.PIPE, text=True)
    publisher = subprocess.Popen([*command, 'pub', executor_kind, '0', str(duration_s)],
                                 cwd=ROOT)
    out, _ = reader.communicate(timeout=duration_s + 120)
    publisher.wait(timeout=60)
    return json.loads(out.strip().splitlines()[-1])


def slope(samples, first_s):
    """Least-squares slope of the bytes in use after `first_s` [MiB/s] (soak's fit)."""
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
    from soak import slope_per_hour
    points = [(t, mib) for t, mib, _ in samples if t >= first_s]
    return slope_per_hour(*zip(*points)) / 3600.0


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--duration', type=float, default=40.0, help='seconds per run')
    parser.add_argument('--every', type=int, default=20,
                        help='the overloaded reader sleeps after every this many messages')
    parser.add_argument('--child', nargs=4, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        role, kind, every, duration = args.child
        return child(role, kind, int(every), float(duration))
    if os.environ.get('FPC_NETNS') != '1':
        parser.error('run inside the private namespace: scripts/isolated .venv/bin/python '
                     'bench/executor_backlog.py')
    # Here, not at the top: a child makes its allocator settings before rclpy is imported.
    from fpc_gripper.nodes.executor_watch import BEAT_PERIOD_S
    rows = []
    for kind in ('events', 'single'):
        for every in (0, args.every):
            report = run(kind, every, args.duration)
            samples = report['samples']
            handled_per_s = samples[-1][2] / samples[-1][0]
            rows.append({'executor': kind, 'overloaded': bool(every),
                         'handled_per_s': handled_per_s,
                         'arriving_per_s': RATE_HZ * TOPICS,
                         'in_use_slope_mib_per_s': slope(samples, 10.0),
                         'heartbeats': report['beats'],
                         'heartbeats_due': int(args.duration / BEAT_PERIOD_S),
                         'behind_episodes': report['episodes'],
                         'worst_late_s': report['worst_late_s'],
                         'watch_lines': report['watch_lines'],
                         'samples': samples})
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps({'rate_hz': RATE_HZ, 'topics': TOPICS, 'sleep_s': SLEEP_S,
                                   'every': args.every, 'duration_s': args.duration,
                                   'rows': rows}, indent=2) + '\n')
    print(f'{"executor":<10}{"reader":<14}{"handled/s":>11}{"arriving/s":>12}'
          f'{"in use [MiB/s]":>16}{"heartbeats":>12}{"latest [s]":>12}')
    for row in rows:
        print(f'{row["executor"]:<10}{"overloaded" if row["overloaded"] else "keeps up":<14}'
              f'{row["handled_per_s"]:>11.0f}{row["arriving_per_s"]:>12.0f}'
              f'{row["in_use_slope_mib_per_s"]:>16.3f}'
              f'{row["heartbeats"]:>6} of {row["heartbeats_due"]:<3}'
              f'{row["worst_late_s"]:>12.1f}')
    print(f'wrote {RESULTS}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
