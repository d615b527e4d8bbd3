"""Recorder soak: mcap_recorder alone at the graph's rates, its RSS sampled until a stop."""

# Run inside the private network namespace:
#   scripts/isolated .venv/bin/python bench/recorder_memory.py [--duration 600]
#       [--warm-up 300] [--rate 200] [--fingers 3] [--memray out.bin] [--out run.json]
# (--memray needs memray importable by this interpreter: MEMRAY_PATH=<its site-packages>.)
#
# This process publishes, per finger, what model_node and the bridge publish at --rate:
# the shape (a 129-pose nav_msgs/Path, serialised as model_node does, on STATE_QOS), the
# curvature (Float64, STATE_QOS) and the measured pressure (FluidPressure, best effort);
# `mcap_recorder` records them in a process of its own (under `memray run --native` with
# --memray). Every --sample-period it samples the recorder's RSS; at the end it stops the
# recorder with SIGINT and prints the RSS slope after --warm-up (least squares, MiB/h),
# the recorder's stop line and the file's message count.

import argparse
import json
import math
import os
import pathlib
import subprocess
import sys
import tempfile
import threading
import time

from mcap.reader import make_reader
from nav_msgs.msg import Path
import numpy as np
import psutil
import rclpy
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from rclpy.serialization import serialize_message
from sensor_msgs.msg import FluidPressure
from soak import slope_per_hour, stop_process  # bench/ is sys.path[0] for a bench
from std_msgs.msg import Float64

from fpc_gripper.io.messages import serialized_shape, STATE_QOS

#: Where memray is installed, if not in this interpreter's environment (same Python).
MEMRAY_PATH = os.environ.get('MEMRAY_PATH', '')
ARCS = 50


class Arc:
    """A CCM-result stand-in: an arc of 129 points (what serialized_shape reads)."""

    def __init__(self, kappa, n=129, length=0.09):
        s = np.linspace(0.0, length, n)
        self.points = np.stack([np.sin(kappa * s) / kappa, (np.cos(kappa * s) - 1.0) / kappa],
                               axis=1)
        self.tangent = -kappa * s
        self.curvature = kappa


def publish(node, fingers, rate, running, sent):
    """Publish every finger's shape, curvature and pressure at `rate` until `running` clears."""
    shapes = [node.create_publisher(Path, f'finger_{f}/shape', STATE_QOS)
              for f in range(fingers)]
    curvatures = [node.create_publisher(Float64, f'finger_{f}/curvature', STATE_QOS)
                  for f in range(fingers)]
    pressures = [node.create_publisher(FluidPressure, f'finger_{f}/pressure',
                                       qos_profile_sensor_data) for f in range(fingers)]
    arcs = [Arc(5.0 + 0.1 * i) for i in range(ARCS)]
    while running.is_set() and not all(
            p.get_subscription_count() for p in (*shapes, *curvatures, *pressures)):
        time.sleep(0.05)
    pressure = FluidPressure()
    t0 = time.monotonic()
    i = 0
    while running.is_set():
        stamp = time.time_ns()
        for f in range(fingers):
            shapes[f].publish(serialized_shape(arcs[i % ARCS], f'finger_{f}', stamp))
            curvatures[f].publish(Float64(data=5.0 + 0.1 * (i % ARCS)))
            pressure.header.stamp.sec, pressure.header.stamp.nanosec = divmod(stamp, 10**9)
            pressure.fluid_pressure = 101325.0 + i % 1000
            pressures[f].publish(serialize_message(pressure))
        i += 1
        sent[0] = i * fingers * 3
        time.sleep(max(0.0, t0 + i / rate - time.monotonic()))


def stop_line(log):
    """Return the recorder's stop line (its last 'closed' line), or ''."""
    lines = [line for line in log.splitlines() if ': closed ' in line]
    return lines[-1] if lines else ''


def main(argv=None):
    """Run the recorder under the publishers, sample its RSS, stop it and report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration', type=float, default=600.0, help='[s]')
    parser.add_argument('--warm-up', type=float, default=300.0, help='not in the slope [s]')
    parser.add_argument('--rate', type=float, default=200.0, help='per topic [Hz]')
    parser.add_argument('--fingers', type=int, default=3)
    parser.add_argument('--sample-period', type=float, default=5.0, help='[s]')
    parser.add_argument('--memray', default=None, help='memray capture file to write')
    parser.add_argument('--workdir', default=None, help='for the recording and the log')
    parser.add_argument('--out', default=None, help='JSON of the samples and results')
    args = parser.parse_args(argv)
    workdir = pathlib.Path(args.workdir or tempfile.mkdtemp(prefix='fpc_recorder_mem_'))
    workdir.mkdir(parents=True, exist_ok=True)
    output = workdir / 'recording.mcap'
    namespace = '/recmem'
    topics = [f'{namespace}/finger_{f}/{t}' for f in range(args.fingers)
              for t in ('shape', 'curvature', 'pressure')]
    command = [sys.executable, '-m', 'fpc_gripper.nodes.mcap_recorder', '--ros-args',
               '-r', f'__ns:={namespace}', '-p', f'output_path:={output}',
               '-p', 'overwrite:=true', '-p', 'diagnostics_period_s:=1.0',
               '-p', f'topics:=[{",".join(repr(t) for t in topics)}]']
    env = dict(os.environ)
    if args.memray:
        command = [sys.executable, '-m', 'memray', 'run', '--native', '--force',
                   '--trace-python-allocators',
                   '-o', args.memray, *command[1:]]
        env['PYTHONPATH'] = os.pathsep.join(p for p in (env.get('PYTHONPATH'), MEMRAY_PATH)
                                            if p)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node('recorder_memory', namespace=namespace, context=context)
    running = threading.Event()
    running.set()
    sent = [0]
    log_path = workdir / 'recorder.log'
    with open(log_path, 'wb') as log:
        recorder = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, env=env)
    publisher = threading.Thread(target=publish, daemon=True,
                                 args=(node, args.fingers, args.rate, running, sent))
    samples = []
    try:
        process = psutil.Process(recorder.pid)
        publisher.start()
        t0 = time.monotonic()
        while time.monotonic() - t0 < args.duration and recorder.poll() is None:
            time.sleep(args.sample_period)
            t = time.monotonic() - t0
            samples.append((t, process.memory_info().rss / 2**20, sent[0]))
            print(f'{t:7.1f} s  RSS {samples[-1][1]:7.1f} MiB  sent {sent[0]}', flush=True)
    finally:
        running.clear()
        publisher.join(timeout=5.0)
        stop_process(recorder, 60.0)
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    log = log_path.read_text(errors='replace')
    with open(output, 'rb') as stream:
        summary = make_reader(stream).get_summary()
    late = [(t, r) for t, r, _ in samples if t >= args.warm_up]
    result = {
        'rss_first_mib': samples[0][1] if samples else math.nan,
        'rss_last_mib': samples[-1][1] if samples else math.nan,
        'slope_mib_per_h': slope_per_hour(*zip(*late)) if len(late) >= 3 else math.nan,
        'warm_up_s': args.warm_up, 'duration_s': args.duration, 'sent': sent[0],
        'recorded': summary.statistics.message_count if summary else None,
        'chunks': len(summary.chunk_indexes) if summary else None,
        'exit_code': recorder.returncode, 'stop_line': stop_line(log),
        'file_mib': output.stat().st_size / 2**20, 'samples': samples,
    }
    print(f'RSS {result["rss_first_mib"]:.1f} -> {result["rss_last_mib"]:.1f} MiB; slope after '
          f'{args.warm_up:g} s: {result["slope_mib_per_h"]:+.2f} MiB/h; sent {sent[0]}, '
          f'recorded {result["recorded"]} in {result["chunks"]} chunks, file '
          f'{result["file_mib"]:.0f} MiB, '
          f'exit {recorder.returncode}\n{result["stop_line"]}')
    if args.out:
        pathlib.Path(args.out).write_text(json.dumps(result, indent=1))
    output.unlink()
    return 0 if recorder.returncode == 0 else 1


if __name__ == '__main__':
    sys.exit(main())
