"""
Rig of the recorder-under-load check: received against recorded, with and without a CPU hog.

A publisher node streams finger shapes (129-pose Paths, as model_node publishes them) on
reliable, transient-local topics whose history holds every message, so nothing can be
lost on the publisher's side; a reliable subscriber in this process counts what it
receives; ``mcap_recorder`` runs as a process beside them, optionally with busy-loop
processes (the hog) taking the CPU. The publisher stops, waits until every reader has
acknowledged every message, and only then is the recorder stopped with SIGINT, so every
message the subscriber received had reached the recorder before its stop.

Run it inside the private network namespace, for the figures of the README::

    scripts/isolated .venv/bin/python tests/io/recorder_load.py --runs 5
"""

import argparse
import os
import pathlib
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time

from mcap.reader import make_reader
from nav_msgs.msg import Path
import rclpy
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from fpc_gripper.io.cdr import header_stamp
from fpc_gripper.io.messages import serialized_shape

_HOG = 'while True:\n    pass\n'
#: Stamp of shape i of finger f: a clear base, then f and i in the nanoseconds.
_BASE = 1_700_000_000_000_000_000


class _Arc:
    """A CCM-result stand-in: an arc of 129 points (what serialized_shape reads)."""

    def __init__(self, kappa, n=129, length=0.09):
        import numpy as np
        s = np.linspace(0.0, length, n)
        self.points = np.stack([np.sin(kappa * s) / kappa, (np.cos(kappa * s) - 1.0) / kappa],
                               axis=1)
        self.tangent = -kappa * s
        self.curvature = kappa


def stamp_of(finger, i):
    """Stamp [ns] that identifies message i of a finger."""
    return _BASE + finger * 100_000_000 + i


def start_hog(cores):
    """Start `cores` busy-loop processes; return them (stop with `stop_hog`)."""
    return [subprocess.Popen([sys.executable, '-c', _HOG]) for _ in range(cores)]


def stop_hog(hogs):
    """Stop the busy-loop processes started by `start_hog`, by their PIDs."""
    for hog in hogs:
        hog.kill()
    for hog in hogs:
        hog.wait()


def recorded_stamps(path):
    """Publish times (the shapes' header stamps) by topic, read with mcap's own reader."""
    got = {}
    with open(path, 'rb') as stream:
        for _, channel, message in make_reader(stream).iter_messages(log_time_order=False):
            got.setdefault(channel.topic, set()).add(message.publish_time)
    return got


def record_under_load(out_dir, *, fingers=3, rate_hz=200.0, seconds=3.0, hog=0,
                      namespace='/load', flush_period_s=0.2, depth=None, timeout=60.0,
                      module='fpc_gripper.nodes.mcap_recorder'):
    """
    Stream shapes past a recorder process and a subscriber; compare what each kept.

    Parameters
    ----------
    out_dir : pathlib.Path
        Directory of the recording.
    fingers : int
        Shape topics, one per finger.
    rate_hz : float
        Publish rate of each topic [Hz].
    seconds : float
        Streaming time [s].
    hog : int
        Busy-loop processes running while the recorder records.
    namespace : str
        Namespace of the topics and the recorder.
    flush_period_s : float
        The recorder's flush period [s].
    depth : int, optional
        History depth of the publishers (default: every message, so none can be lost
        on their side).
    timeout : float
        Longest wait for discovery, acknowledgements and the recorder's exit [s].
    module : str
        The recorder, run as ``python -m module`` (to compare versions of it).

    Returns
    -------
    dict
        ``published, received, recorded`` (counts), ``missing`` (received but not
        recorded: set of (topic, stamp)), ``returncode`` and ``log`` of the recorder.

    """
    out_dir = pathlib.Path(out_dir)
    output = out_dir / 'load.mcap'
    topics = [f'{namespace}/finger_{f}/shape' for f in range(fingers)]
    total = int(rate_hz * seconds)
    # Transient local with a history of every message: the recorder gets all of them
    # whenever it matches, and the publisher can never drop one a reader has not acked.
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth or total + 10,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node('load_rig', namespace=namespace, context=context)
    received = set()
    lock = threading.Lock()

    def on_shape(topic, data):
        with lock:
            received.add((topic, header_stamp(data)))

    pubs = [node.create_publisher(Path, t, qos) for t in topics]
    for t in topics:
        node.create_subscription(Path, t, lambda data, t=t: on_shape(t, data), qos, raw=True)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinning = threading.Event()
    spinning.set()

    def spin():
        while spinning.is_set():
            executor.spin_once(timeout_sec=0.05)

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    shapes = [[serialized_shape(_Arc(5.0 + 0.01 * i), f'finger_{f}', stamp_of(f, i))
               for i in range(total)] for f in range(fingers)]
    recorder = subprocess.Popen(
        [sys.executable, '-m', module, '--ros-args',
         '-r', f'__ns:={namespace}', '-p', f'output_path:={output}',
         '-p', f'flush_period_s:={flush_period_s}', '-p', 'discovery_period_s:=0.1',
         '-p', f'topics:=[{",".join(repr(t) for t in topics)}]'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    hogs = []
    try:
        deadline = time.monotonic() + timeout
        while not all(p.get_subscription_count() == 2 for p in pubs):
            if recorder.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError('recorder never subscribed: ' + recorder.stdout.read().decode())
            time.sleep(0.05)
        hogs = start_hog(hog)
        t0 = time.monotonic()
        for i in range(total):
            for f, pub in enumerate(pubs):
                pub.publish(shapes[f][i])
            time.sleep(max(0.0, t0 + (i + 1) / rate_hz - time.monotonic()))
        for pub in pubs:
            if not pub.wait_for_all_acked(Duration(seconds=timeout)):
                raise RuntimeError(f'{pub.topic_name}: not acknowledged in {timeout} s')
        # Acknowledged: every message is in each reader's queue, the recorder's included,
        # though maybe not yet taken by the node. Stop now, as a user would.
        recorder.send_signal(signal.SIGINT)
        code = recorder.wait(timeout=timeout)
        while len(received) < total * fingers and time.monotonic() < deadline + 2 * timeout:
            time.sleep(0.05)
        with lock:
            got = set(received)
    finally:
        stop_hog(hogs)
        if recorder.poll() is None:
            recorder.kill()
            recorder.wait()
        spinning.clear()
        spinner.join(timeout=5.0)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    recorded = recorded_stamps(output) if code == 0 else {}
    in_file = {(t, s) for t, stamps in recorded.items() for s in stamps}
    return {'published': total * fingers, 'received': len(got),
            'recorded': len(in_file), 'missing': got - in_file, 'returncode': code,
            'log': recorder.stdout.read().decode()}


def main(argv=None):
    """Measure received against recorded over repeated runs, without and with a hog."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--runs', type=int, default=5)
    parser.add_argument('--hog', type=int, default=os.cpu_count() or 2,
                        help='busy-loop processes of the loaded runs (default: one per core)')
    parser.add_argument('--rate', type=float, default=200.0, help='per topic [Hz]')
    parser.add_argument('--seconds', type=float, default=3.0)
    parser.add_argument('--fingers', type=int, default=3)
    parser.add_argument('--depth', type=int, default=None,
                        help="publishers' history depth (default: every message)")
    parser.add_argument('--module', nargs='+', default=['fpc_gripper.nodes.mcap_recorder'],
                        help='recorder module(s) to compare, run in turn')
    args = parser.parse_args(argv)
    rows = {}
    for run in range(args.runs):
        for hog in (0, args.hog):
            for module in args.module:
                with tempfile.TemporaryDirectory() as tmp:
                    r = record_under_load(tmp, fingers=args.fingers, rate_hz=args.rate,
                                          seconds=args.seconds, hog=hog,
                                          namespace=f'/load{run}', depth=args.depth,
                                          module=module)
                rows.setdefault((hog, module), []).append(r)
                print(f'{module}, hog {hog}: run {run}: published {r["published"]}, '
                      f'received {r["received"]}, recorded {r["recorded"]}, received but not '
                      f'recorded {len(r["missing"])}, exit {r["returncode"]}', flush=True)
    for (hog, module), runs in rows.items():
        print(f'{module}, hog {hog}: median of {len(runs)}: received '
              f'{statistics.median(r["received"] for r in runs)}, recorded '
              f'{statistics.median(r["recorded"] for r in runs)}, lost '
              f'{statistics.median(len(r["missing"]) for r in runs)} '
              f'(range {min(len(r["missing"]) for r in runs)}-'
              f'{max(len(r["missing"]) for r in runs)})', flush=True)


if __name__ == '__main__':
    sys.exit(main())
