"""Benchmark of the model node: pressure-to-shape latency and the highest sustained input rate."""

# Run inside the private network namespace:
#   scripts/isolated .venv/bin/python bench/bench_node.py
# The model node runs in its own process (python -m fpc_gripper.nodes.model_node); this
# process publishes stamped finger_<i>/pressure_command messages for three fingers and
# receives finger_<i>/shape serialized (no Python message objects on the receiving side),
# reading the header stamp, which the node copies from the command it answers.
# Latency = receipt - command stamp, both on the system clock. The sustained rate is the
# highest per-finger input rate of a ladder at which >= KEEP_UP of the commands get their own
# shape, measured with the rate cap lifted (max_rate_hz 10000). Writes bench/results/node.json
# and prints a table.

import argparse
import json
import math
import os
import pathlib
import signal
import statistics
import struct
import subprocess
import sys
import threading
import time

from nav_msgs.msg import Path
import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from sensor_msgs.msg import FluidPressure

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from timing import machine, median_time  # noqa: E402

from fpc_gripper.io.config import load_gripper_config  # noqa: E402
from fpc_gripper.io.messages import serialized_shape  # noqa: E402
from fpc_gripper.model.pipeline import finger_model, ModelSettings  # noqa: E402

RESULTS = pathlib.Path(__file__).resolve().parent / 'results' / 'node.json'
ROOT = pathlib.Path(__file__).resolve().parents[1]
#: Issue targets: latency at 100 Hz input on 3 fingers [ms], and the sustained rate [Hz].
TARGETS = {'p50_ms': 5.0, 'p99_ms': 20.0, 'sustained_hz': 200.0}
FINGERS = ('finger_0', 'finger_1', 'finger_2')
ATM = 101325.0
#: Per-finger command rates of the per-command runs [Hz].
RATES = (100.0, 200.0, 500.0)
#: Output/input ratio below which the node has fallen behind.
KEEP_UP = 0.95
#: Commands as the conventions say (reliable, depth 10).
COMMAND_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
#: The shape sink keeps a deep queue: with depth 10 this Python process, not the node, was
#: the first to fall behind (its own reader overflowed) at a few hundred messages per second.
SINK_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)


def command_gauge(tick, finger, mode):
    """Gauge pressure of a command [Pa]: a sweep, so that every command needs a solve."""
    gauge = 150e3 + 100e3 * math.sin(2.0 * math.pi * tick / 97.0)
    return gauge + (7e3 * finger if mode == 'distinct' else 0.0)


def fill_command(msg, tick, finger, mode):
    """Stamp a FluidPressure now and set its absolute pressure; return the stamp [ns]."""
    stamp = time.time_ns()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
    msg.fluid_pressure = ATM + command_gauge(tick, finger, mode)
    return stamp


class ModelProcess:
    """The model node in a child process, in its own namespace."""

    def __init__(self, namespace, max_rate_hz, tolerance, parameters=()):
        self.namespace = namespace
        extra = [arg for p in parameters for arg in ('-p', p)]
        self.process = subprocess.Popen(
            [sys.executable, '-m', 'fpc_gripper.nodes.model_node', '--ros-args',
             '-r', f'__ns:={namespace}', '-p', f'max_rate_hz:={float(max_rate_hz)}',
             '-p', f'tolerance:={float(tolerance)}', *extra],
            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)

    def cpu_s(self):
        """CPU time of the node process so far, user + system [s]."""
        fields = pathlib.Path(f'/proc/{self.process.pid}/stat').read_text().rsplit(')', 1)[1]
        utime, stime = fields.split()[11:13]
        return (int(utime) + int(stime)) / os.sysconf('SC_CLK_TCK')

    def stop(self):
        self.process.send_signal(signal.SIGINT)
        try:
            _, err = self.process.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            self.process.kill()
            _, err = self.process.communicate()
        if self.process.returncode != 0:
            print(f'model node exited with {self.process.returncode}:\n{err[-2000:]}',
                  file=sys.stderr)


class FloorProcess(ModelProcess):
    """bench/floor_node.py in a child process: rclpy's own cost per command, no model."""

    def __init__(self, namespace):
        self.namespace = namespace
        self.process = subprocess.Popen(
            [sys.executable, str(ROOT / 'bench' / 'floor_node.py'), namespace], cwd=ROOT,
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


class Driver:
    """Publishes stamped commands and records (stamp, receipt) of every shape."""

    def __init__(self, context, namespace):
        self.node = rclpy.create_node(f'bench_driver{namespace.replace("/", "_")}',
                                      context=context)
        self.pubs = [self.node.create_publisher(FluidPressure,
                                                f'{namespace}/{f}/pressure_command',
                                                COMMAND_QOS)
                     for f in FINGERS]
        self.received = [[] for _ in FINGERS]
        for i, f in enumerate(FINGERS):
            self.node.create_subscription(Path, f'{namespace}/{f}/shape',
                                          self._recorder(self.received[i]), SINK_QOS,
                                          raw=True)

    @staticmethod
    def _recorder(store):
        def record(data):
            now = time.time_ns()
            sec, nanosec = struct.unpack_from('<iI', data, 4)
            store.append((sec * 1_000_000_000 + nanosec, now))
        return record

    def wait_for_initial_state(self, timeout=60.0):
        """Send a first command per finger every 0.1 s until each finger's shape has come."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if all(self.received):
                return True
            self.drive(10.0, 0.1, 'same')
        return False

    def drive(self, rate_hz, duration_s, mode, tick0=0):
        """Publish one command per finger per period; return the stamps sent per finger."""
        msgs = [FluidPressure() for _ in FINGERS]
        sent = [[] for _ in FINGERS]
        period = 1.0 / rate_hz
        ticks = int(round(rate_hz * duration_s))
        start = time.perf_counter()
        for k in range(ticks):
            target = start + k * period
            delay = target - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            for i, (pub, msg) in enumerate(zip(self.pubs, msgs)):
                stamp = fill_command(msg, tick0 + k, i, mode)
                pub.publish(msg)
                sent[i].append(stamp)
        elapsed = time.perf_counter() - start
        return sent, elapsed

    def window(self, sent, drain_s=0.5):
        """Latencies [ms] and output/input ratio of the commands in `sent`."""
        time.sleep(drain_s)
        latencies, ratios = [], []
        for i, stamps in enumerate(sent):
            first, last = stamps[0], stamps[-1]
            got = [(s, r) for s, r in list(self.received[i]) if first <= s <= last]
            latencies.extend((r - s) * 1e-6 for s, r in got)
            ratios.append(len(got) / len(stamps))
        return np.array(latencies), min(ratios)


def baseline_ms(tolerance):
    """In-process work per finger, same run: warm solve + samples + circle fit + Path bytes."""
    design = load_gripper_config().fingers[0].design
    solver = finger_model(design, ModelSettings(tolerance=tolerance))
    state = {'r': solver.solve(150e3), 'k': 0}

    def step():
        state['k'] += 1
        r = solver.solve(command_gauge(state['k'], 0, 'same'), initial=state['r'])
        serialized_shape(r, 'finger_0', 0)
        float(r.curvature)
        state['r'] = r

    return median_time(step, repeats=200) * 1e3


def solver_us(tolerance, count=600):
    """
    In-process solve time per command [us] of the per-command runs' sequence, same run.

    Three fingers, distinct sweeps, each solve warm from that finger's previous answer, as
    model_node solves them (outputs 'all': the state, samples and circle fit it publishes).
    """
    design = load_gripper_config().fingers[0].design
    solver = finger_model(design, ModelSettings(tolerance=tolerance))
    last = [solver.solve(command_gauge(0, i, 'distinct')) for i in range(len(FINGERS))]
    times = []
    for k in range(1, count + 1):
        for i in range(len(FINGERS)):
            t0 = time.perf_counter()
            last[i] = solver.solve(command_gauge(k, i, 'distinct'), initial=last[i])
            times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e6


def in_process_us(tolerance, paces_hz, ticks=600, paced_ticks=300, repeats=3):
    """
    model_node's CPU per command in this process, without the middleware [us].

    A ModelNode of this process (its own context, never spun) gets the per-command runs'
    commands (three fingers, distinct sweeps, serialized) through its guarded pressure
    callbacks, called directly; its outputs have no subscriber. After one warm-up run:
    back to back, then at each of `paces_hz` one finger's command every 1/(3 pace) s with
    the thread asleep in between, as a node waits between messages. Each is the median over
    `repeats` of the thread's CPU time per command.

    Returns
    -------
    dict
        ``'back_to_back'`` and ``str(int(pace))`` for each pace, to [us].
    """
    from rclpy.parameter import Parameter
    from fpc_gripper.nodes.model_node import ModelNode
    context = Context()
    rclpy.init(context=context)
    node = ModelNode('in_process', namespace='/bench_in_process', context=context,
                     parameter_overrides=[Parameter('max_rate_hz', value=10000.0),
                                          Parameter('tolerance', value=float(tolerance))])
    try:
        by_topic = {sub.topic_name: sub for sub in node.subscriptions}
        callbacks = [by_topic[f'/bench_in_process/{f}/pressure_command'].callback
                     for f in FINGERS]
        msg = FluidPressure()
        tick = 0

        def run(count, gap):
            nonlocal tick
            spent = 0
            for k in range(tick, tick + count):
                for i, callback in enumerate(callbacks):
                    fill_command(msg, k, i, 'distinct')
                    payload = serialize_message(msg)
                    start = time.thread_time_ns()
                    callback(payload)
                    spent += time.thread_time_ns() - start
                    if gap:
                        time.sleep(gap)
            tick += count
            return spent * 1e-3 / (count * len(callbacks))

        run(ticks, None)
        out = {'back_to_back': statistics.median(run(ticks, None) for _ in range(repeats))}
        for pace in paces_hz:
            gap = 1.0 / (len(FINGERS) * pace)
            out[str(int(pace))] = statistics.median(run(paced_ticks, gap)
                                                    for _ in range(repeats))
        return out
    finally:
        node.destroy_node()
        context.try_shutdown()


def per_command_run(driver, model, rate_hz, duration_s, repeats, solve_us):
    """
    Node CPU per answered command, and its part outside the solver, at `rate_hz` x 3.

    Distinct commands per finger; the node's rate cap lifted (max_rate_hz 1000). Returns
    medians over repeats of the node's CPU (fraction of a core), the answered ratio,
    latency p50/p99 [ms] and CPU per answered command [us].
    """
    rows = []
    tick = 0
    for _ in range(repeats):
        sent, elapsed, cpu = measured_drive(driver, model, rate_hz, duration_s, 'distinct',
                                            tick)
        tick += len(sent[0])
        lat, ratio = driver.window(sent)
        answered = lat.size
        per_command = cpu['node_cpu'] * elapsed / max(answered, 1) * 1e6
        rows.append({'node_cpu': cpu['node_cpu'], 'answered_ratio': answered / sum(
            len(s) for s in sent), 'p50_ms': float(np.percentile(lat, 50)),
            'p99_ms': float(np.percentile(lat, 99)), 'cpu_per_command_us': per_command,
            'outside_solver_us': per_command - solve_us})
    return {key: statistics.median(r[key] for r in rows) for key in rows[0]} | {
        'rate_hz': rate_hz, 'repeats': rows}


def measured_drive(driver, model, rate_hz, duration_s, mode, tick0=0):
    """Drive and also return the CPU fractions (of one core) of the node and this process."""
    node0, own0 = model.cpu_s(), time.process_time()
    sent, elapsed = driver.drive(rate_hz, duration_s, mode, tick0=tick0)
    cpu = {'node_cpu': (model.cpu_s() - node0) / elapsed,
           'bench_cpu': (time.process_time() - own0) / elapsed}
    return sent, elapsed, cpu


def latency_run(driver, model, mode, rate_hz, duration_s, repeats):
    rows = []
    tick = 0
    for _ in range(repeats):
        sent, elapsed, cpu = measured_drive(driver, model, rate_hz, duration_s, mode, tick)
        tick += len(sent[0])
        lat, ratio = driver.window(sent)
        rows.append({'p50_ms': float(np.percentile(lat, 50)),
                     'p99_ms': float(np.percentile(lat, 99)),
                     'max_ms': float(lat.max()), 'samples': int(lat.size),
                     'output_ratio': ratio, 'input_hz': len(sent[0]) / elapsed, **cpu})
    return {
        'mode': mode, 'rate_hz': rate_hz, 'duration_s': duration_s, 'repeats': rows,
        'p50_ms': statistics.median(r['p50_ms'] for r in rows),
        'p99_ms': statistics.median(r['p99_ms'] for r in rows),
        'output_ratio': statistics.median(r['output_ratio'] for r in rows),
        'node_cpu': statistics.median(r['node_cpu'] for r in rows),
    }


def ladder_run(driver, model, mode, rates, duration_s):
    steps = []
    best = 0.0
    for rate in rates:
        sent, elapsed, cpu = measured_drive(driver, model, rate, duration_s, mode)
        lat, ratio = driver.window(sent)
        achieved = len(sent[0]) / elapsed
        steps.append({'rate_hz': rate, 'input_hz': achieved, 'output_ratio': ratio, **cpu,
                      'p50_ms': float(np.percentile(lat, 50)) if lat.size else None,
                      'p99_ms': float(np.percentile(lat, 99)) if lat.size else None})
        if ratio < KEEP_UP or achieved < KEEP_UP * rate:
            break
        best = rate
    return best, steps


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--duration', type=float, default=4.0,
                        help='seconds per latency repeat')
    parser.add_argument('--step', type=float, default=2.0, help='seconds per ladder step')
    parser.add_argument('--rates', type=float, nargs='+',
                        default=[100, 200, 300, 400, 500, 600, 800])
    parser.add_argument('--tolerance', type=float, default=0.0,
                        help='model_node tolerance [m]: 0 is the fixed paper CCM8, 5e-5 the '
                             "node's default adaptive model")
    parser.add_argument('--output', type=pathlib.Path, default=None,
                        help='default bench/results/node.json, or node_tolerance.json')
    parser.add_argument('--per-command', action='store_true',
                        help="issue 22's runs instead: the default model (tolerance 5e-5), "
                             'max_rate_hz 1000, 3 fingers x 100/200/500 Hz of distinct '
                             'commands; CPU per answered command and its part outside the '
                             'solver (bench/results/node_per_command.json)')
    parser.add_argument('--node-param', action='append', default=[], metavar='NAME:=VALUE',
                        help='a further model_node parameter for --per-command, e.g. '
                             'rigidity_rate_hz:=0.0 (repeatable)')
    args = parser.parse_args(argv)
    if args.per_command:
        args.tolerance = 5e-5
        args.output = args.output or RESULTS.with_name('node_per_command.json')
    if args.output is None:
        args.output = RESULTS if args.tolerance == 0.0 else \
            RESULTS.with_name('node_tolerance.json')
    if os.environ.get('FPC_NETNS') != '1':
        parser.error('run inside the private namespace: scripts/isolated .venv/bin/python '
                     'bench/bench_node.py')

    if args.per_command:
        return per_command_main(args)
    base = baseline_ms(args.tolerance)
    context = Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    results = {'machine': machine(), 'targets': TARGETS, 'baseline_ms': base,
               'tolerance_m': args.tolerance,
               'fingers': len(FINGERS), 'keep_up_ratio': KEEP_UP,
               'modes': {'same': 'one command value for all three fingers (one shared solve)',
                         'distinct': 'a different value per finger (three solves)'},
               'load_average': os.getloadavg()}
    try:
        # Latency: the node as shipped (max_rate_hz 200), 100 Hz per finger.
        model = ModelProcess('/bench_latency', 200.0, args.tolerance)
        driver = Driver(context, '/bench_latency')
        executor.add_node(driver.node)
        try:
            if not driver.wait_for_initial_state():
                raise RuntimeError('the model node published no initial state')
            driver.drive(100.0, 1.0, 'same')  # warm-up
            results['latency'] = {
                mode: latency_run(driver, model, mode, 100.0, args.duration, args.repeats)
                for mode in ('same', 'distinct')}
            # With the default cap, the node keeps up with commands at the cap itself.
            results['at_default_cap'] = latency_run(driver, model, 'distinct', 200.0, args.step,
                                                    1)
        finally:
            model.stop()
        # Throughput: lift the cap to find what the node itself sustains.
        model = ModelProcess('/bench_rate', 10000.0, args.tolerance)
        driver = Driver(context, '/bench_rate')
        executor.add_node(driver.node)
        try:
            if not driver.wait_for_initial_state():
                raise RuntimeError('the model node published no initial state')
            driver.drive(100.0, 1.0, 'same')
            # The load: 3 fingers x 500 Hz of distinct commands on the node's model.
            results['at_500hz'] = latency_run(driver, model, 'distinct', 500.0, args.duration,
                                              args.repeats)
            ladders = {}
            for mode in ('same', 'distinct'):
                runs = [ladder_run(driver, model, mode, args.rates, args.step)
                        for _ in range(args.repeats)]
                ladders[mode] = {'sustained_hz': statistics.median(b for b, _ in runs),
                                 'runs': [s for _, s in runs]}
            results['sustained'] = ladders
        finally:
            model.stop()
    finally:
        executor.shutdown(timeout_sec=5.0)
        spinner.join(timeout=5.0)
        context.try_shutdown()

    lat = results['latency']
    results['meets'] = {
        'p50_ms': all(lat[m]['p50_ms'] <= TARGETS['p50_ms'] for m in lat),
        'p99_ms': all(lat[m]['p99_ms'] <= TARGETS['p99_ms'] for m in lat),
        'sustained_hz': all(results['sustained'][m]['sustained_hz'] >= TARGETS['sustained_hz']
                            for m in results['sustained']),
    }
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(results, indent=2) + '\n')

    print(f'baseline (in-process warm solve + samples + fit + Path bytes): {base:.2f} ms')
    print(f'{"commands":<28}{"p50 [ms]":>10}{"p99 [ms]":>10}{"out/in":>8}{"node CPU":>10}')
    rows = [(f'100 Hz x 3, {mode}', row) for mode, row in lat.items()]
    rows.append(('200 Hz x 3, distinct, cap', results['at_default_cap']))
    rows.append(('500 Hz x 3, distinct, no cap', results['at_500hz']))
    for label, row in rows:
        print(f'{label:<28}{row["p50_ms"]:>10.2f}{row["p99_ms"]:>10.2f}'
              f'{row["output_ratio"]:>8.2f}{row["node_cpu"]:>10.2f}')
    for mode, row in results['sustained'].items():
        print(f'sustained per finger, 3 fingers, {mode}: {row["sustained_hz"]:.0f} Hz')
    print(f'targets {TARGETS}; met {results["meets"]}; p50/baseline '
          f'{lat["same"]["p50_ms"] / base:.1f}')
    print(f'wrote {args.output}')


def _started(context, executor, namespace):
    """Return a Driver once the node under `namespace` answers, after a second of warm-up."""
    driver = Driver(context, namespace)
    executor.add_node(driver.node)
    if not driver.wait_for_initial_state():
        raise RuntimeError(f'the node in {namespace} published no shape')
    driver.drive(100.0, 1.0, 'distinct')
    return driver


def per_command_main(args):
    """
    Run issue 22's per-command measurement and write its JSON.

    Also measured, in the same run: the floor, bench/floor_node.py's CPU per command
    (a raw take and one raw publish, no Python work), which no rclpy node goes below; and
    the node's own work per command in this process, without the middleware, back to
    back and paced at each rate (`in_process_us`).
    """
    solve = solver_us(args.tolerance)
    in_process = in_process_us(args.tolerance, RATES)
    context = Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    results = {'machine': machine(), 'tolerance_m': args.tolerance, 'solver_us': solve,
               'executor': os.environ.get('FPC_GRIPPER_EXECUTOR', 'default'),
               'node_parameters': args.node_param,
               'load_average_before': os.getloadavg(), 'in_process_us': in_process,
               'rates': {}}
    try:
        # The floor first: the same driver, commands and QoS against a node that only takes
        # each command raw and publishes fixed shape bytes.
        floor = {}
        process = FloorProcess('/bench_floor')
        try:
            driver = _started(context, executor, '/bench_floor')
            for rate in RATES:
                floor[rate] = per_command_run(driver, process, rate, args.duration,
                                              args.repeats, 0.0)['cpu_per_command_us']
        finally:
            process.stop()
        model = ModelProcess('/bench_per_command', 1000.0, args.tolerance, args.node_param)
        try:
            driver = _started(context, executor, '/bench_per_command')
            for rate in RATES:
                row = per_command_run(driver, model, rate, args.duration, args.repeats, solve)
                row['floor_us'] = floor[rate]
                row['above_floor_us'] = row['outside_solver_us'] - floor[rate]
                results['rates'][str(int(rate))] = row
        finally:
            model.stop()
    finally:
        executor.shutdown(timeout_sec=5.0)
        spinner.join(timeout=5.0)
        context.try_shutdown()
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(results, indent=2) + '\n')
    print(f'in-process solve per command: {solve:.0f} us')
    print('in-process node work per command, no middleware: '
          f'{in_process["back_to_back"]:.0f} us back to back, ' + ', '.join(
              f'{in_process[str(int(rate))]:.0f} us paced at 3 x {rate:.0f} Hz'
              for rate in RATES))
    print(f'{"3 fingers x":<14}{"node CPU":>9}{"answered":>9}{"p50 ms":>8}{"p99 ms":>8}'
          f'{"CPU/cmd us":>11}{"outside solver":>15}{"floor":>7}{"above floor":>12}')
    for rate, row in results['rates'].items():
        print(f'{rate + " Hz":<14}{row["node_cpu"]:>9.2f}{row["answered_ratio"]:>9.3f}'
              f'{row["p50_ms"]:>8.2f}{row["p99_ms"]:>8.2f}{row["cpu_per_command_us"]:>11.0f}'
              f'{row["outside_solver_us"]:>15.0f}{row["floor_us"]:>7.0f}'
              f'{row["above_floor_us"]:>12.0f}')
    print(f'wrote {args.output}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
