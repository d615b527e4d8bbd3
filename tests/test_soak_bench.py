"""The soak benchmark's own measuring parts: CDR headers, command-shape matching, the recording."""

import json
import math
import os
import pathlib
import re
import subprocess
import sys
import threading
import types

from nav_msgs.msg import Path
import numpy as np
from numpy.testing import assert_array_equal
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import FluidPressure

BENCH = pathlib.Path(__file__).resolve().parents[1] / 'bench'
sys.path.insert(0, str(BENCH))
from soak import cdr_fluid_pressure, cdr_header, LatencyTracker, NS  # noqa: E402, I100
from soak import executor_episodes  # noqa: E402
from soak import FAULT_KINDS  # noqa: E402
from soak import FaultInjector, is_junk, read_recording, recorder_counts  # noqa: E402
from soak import heap_slopes, read_heap_log, slope_per_hour, SpilledArray  # noqa: E402
from soak import parse_args  # noqa: E402
from soak_nodes import arena_summary, HeapLog  # noqa: E402

from fpc_gripper.io.mcap_writer import Rosbag2McapWriter  # noqa: E402
from fpc_gripper.io.recording_counts import RecordingCounts  # noqa: E402
from fpc_gripper.nodes.executor_watch import Lag  # noqa: E402


#: The fault kinds that put messages on the gripper's topics (not the regulator's).
FAULT_KINDS_ON_WIRE = tuple(k for k in FAULT_KINDS if not k.startswith('regulator_'))


def _pressure(sec, nanosec, frame, value):
    msg = FluidPressure(fluid_pressure=value, variance=3.0)
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    msg.header.frame_id = frame
    return serialize_message(msg)


def test_header_and_pressure_read_back_from_rclpy_serialization():
    # Frame lengths 0..9 walk the double through every alignment pad.
    for n in range(10):
        frame = 'f' * n
        data = _pressure(-5, 999_999_999, frame, 101325.5 + n)
        assert cdr_header(data) == -5 * NS + 999_999_999
        assert cdr_header(data, frame.encode()) == (-5 * NS + 999_999_999, True)
        if n:
            assert cdr_header(data, b'g' * n)[1] is False
        assert cdr_header(data, (frame + 'x').encode())[1] is False
        assert cdr_fluid_pressure(data) == 101325.5 + n
    path = Path()
    path.header.stamp.sec, path.header.frame_id = 7, 'finger_1'
    assert cdr_header(serialize_message(path), b'finger_1') == (7 * NS, True)


def test_garbage_is_not_a_header():
    for data in (b'', b'\x00\x01\x00', b'\x01\x00' + bytes(30), b'\x00\x07' + bytes(30)):
        assert cdr_header(data) is None
    assert cdr_fluid_pressure(b'\x00\x01\x00\x00' + bytes(12)) is None
    assert math.isnan(cdr_fluid_pressure(_pressure(0, 0, '', math.nan)))


def test_latency_tracker_exact_merged_look_back_and_lost():
    answers, lost = [], []
    tracker = LatencyTracker(2 * NS, lambda ns, exact: answers.append((ns, exact)),
                             lambda: lost.append(1))
    tracker.command(100)
    tracker.command(200)
    # A shape stamped with a later input (a tip force at 250) answers both, merged.
    tracker.shape(250, 1_000)
    assert answers == [(900, False), (800, False)]
    tracker.command(300)
    tracker.shape(300, 1_300)
    assert answers[-1] == (1_000, True)
    # The shape taken before its command: found by the look back.
    tracker.shape(400, 2_000)
    tracker.command(400)
    assert answers[-1] == (1_600, True)
    # A shape published before the command was stamped answers nothing.
    tracker.shape(10 * NS, 3_000)
    tracker.command(5_000)
    assert len(answers) == 4
    tracker.expire(5_000 + 2 * NS)
    assert lost == []
    tracker.expire(5_001 + 2 * NS)
    assert lost == [1]
    assert not tracker.pending


def test_spilled_records_keep_every_value_and_hold_only_one_period_in_memory():
    # The probe's latencies and stamps were arrays that grew all run (the soak's own RSS
    # is measured): spilled at every sample, memory holds at most one period's values.
    stamps, latencies = SpilledArray('q'), SpilledArray('d')
    assert np.asarray(stamps, dtype=np.int64).size == 0 and len(latencies) == 0
    expected = []
    for period in range(50):
        for i in range(200):
            value = period * 1_000_000_007 + i * NS
            stamps.append(value)
            latencies.append(value * 1e-9)
            expected.append(value)
        assert len(stamps._memory) == 200
        stamps.spill()
        latencies.spill()
        assert len(stamps._memory) == len(latencies._memory) == 0
    stamps.append(-1)
    expected.append(-1)
    assert len(stamps) == 50 * 200 + 1
    assert_array_equal(np.asarray(stamps, dtype=np.int64), expected)
    assert_array_equal(np.asarray(latencies), np.asarray(expected[:-1]) * 1e-9)


def test_spilling_from_another_thread_loses_nothing():
    # The sampling thread spills while the executor's thread appends.
    records = SpilledArray('q')
    done = threading.Event()

    def append():
        for i in range(200_000):
            records.append(i)
        done.set()

    thread = threading.Thread(target=append)
    thread.start()
    while not done.is_set():
        records.spill()
    thread.join()
    assert_array_equal(np.asarray(records), np.arange(200_000))


def test_the_recording_check_counts_the_soaks_own_junk_apart_from_a_failure(tmp_path):
    # One message per topic: each is sampled as its topic's first and again as its last.
    good = _pressure(1, 0, 'finger_0', 1.0e5)
    junk = b'\x00\x01\x00\x00' + bytes(range(9))       # sent by the soak's faults
    corrupt = good[:len(good) // 2]                       # sent by no one: a real failure
    path = tmp_path / 'r.mcap'
    with Rosbag2McapWriter(path) as writer:
        for i, (topic, data) in enumerate((('/good', good), ('/junk', junk),
                                           ('/corrupt', corrupt))):
            writer.add_topic(topic, 'sensor_msgs/msg/FluidPressure')
            writer.write(topic, data, NS + i)
    probe = types.SimpleNamespace(received={}, invalid_received={}, t0_ns=0, t1_ns=NS ** 2)
    out = read_recording(path, probe, junk={junk, b''})
    assert (out['decoded'], out['junk_sampled'], out['decode_failures']) == (2, 2, 2)
    # Each failure says what it was: the corrupt message, twice (first and last of its topic).
    assert [(f['topic'], f['log_time'], f['size']) for f in out['decode_failure_examples']] \
        == [('/corrupt', NS + 2, len(corrupt))] * 2
    assert out['decode_failure_examples'][0]['head'] == corrupt[:24].hex()
    # Without the soak's list, its junk is a failure like any other.
    out = read_recording(path, probe)
    assert (out['decoded'], out['junk_sampled'], out['decode_failures']) == (2, 0, 4)


@pytest.mark.parametrize('probe_odd, missing', [(1, 0), (2, 1), (3, 2)])
def test_messages_with_invalid_stamps_are_counted_against_the_recording(
        tmp_path, probe_odd, missing):
    # The recorder logs a message whose stamp is no valid time at its receive time, so the
    # check cannot find it by its stamp: it compares how many such messages each side has.
    topic = '/finger_0/pressure_command'
    path = tmp_path / 'r.mcap'
    with Rosbag2McapWriter(path) as writer:
        writer.add_topic(topic, 'sensor_msgs/msg/FluidPressure')
        for k in range(3):
            writer.write(topic, _pressure(1, k, 'finger_0', 1.0e5), 5 * NS + k, NS + k)
        odd = _pressure(2147483647, 4_000_000_000, 'finger_0', 1.0e5)
        writer.write(topic, odd, 6 * NS, 6 * NS)
        # Logged at its receive time but with a valid stamp: the recorder found no header
        # stamp in it (junk), so it is none of the invalid-stamped ones.
        writer.write(topic, b'\x00\x01\x00\x00\x07', 7 * NS, 7 * NS)
    key = ('pressure_command', 'finger_0')
    probe = types.SimpleNamespace(received={key: [NS, NS + 1, NS + 2]},
                                  invalid_received={key: probe_odd}, t0_ns=0,
                                  t1_ns=NS ** 2)
    compared = read_recording(path, probe)['comparison'][topic]
    assert compared['invalid_stamps'] == {'probe': probe_odd, 'recorded': 1}
    assert compared['missing_from_recording'] == missing
    assert compared['probe'] == 3 + probe_odd
    # A valid stamp the probe had and the recording lacks is missing as before.
    probe.received[key].append(NS + 3)
    assert read_recording(path, probe)['comparison'][topic]['missing_from_recording'] \
        == missing + 1


def test_recorded_messages_the_probe_never_got_are_counted_by_minute(tmp_path):
    # Between the first and the last stamp the probe got while counting, the recording has
    # two it did not get: one in the first minute after the probe's t0, one in the second.
    # The warm-up's (-50 s) is outside: the probe's stale stamp (-100 s) does not stretch
    # the span back over it.
    topic = '/finger_0/shape'
    t0 = 1000 * NS
    stamps = [t0 + int(s * NS) for s in (-100.0, -50.0, 0.5, 30.0, 70.0, 130.0)]
    path = tmp_path / 'r.mcap'
    with Rosbag2McapWriter(path) as writer:
        writer.add_topic(topic, 'sensor_msgs/msg/FluidPressure')
        for k, stamp in enumerate(stamps):
            writer.write(topic, _pressure(*divmod(stamp, NS), 'finger_0', 1.0e5),
                         t0 + 200 * NS + k, stamp)
    key = ('shape', 'finger_0')
    probe = types.SimpleNamespace(received={key: [stamps[0], stamps[2], stamps[5]]},
                                  invalid_received={}, t0_ns=t0, t1_ns=t0 + 200 * NS)
    compared = read_recording(path, probe)['comparison'][topic]
    assert (compared['recorded_not_probed'], compared['missing_from_recording']) == (2, 0)
    assert compared['recorded_not_probed_per_minute'] == {0: 1, 1: 1}


class _Writer:
    def __init__(self):
        self.sent = []

    def publish(self, data):
        self.sent.append(data)


def test_empty_payloads_go_out_on_writers_that_send_nothing_else():
    # Fast DDS drops a 0-byte payload on receipt, and a reliable reader then holds the same
    # writer's next samples until the writer gives up on it: the other faults must not
    # share its writer.
    fingers = ('finger_0', 'finger_1')
    probe = types.SimpleNamespace(
        fingers=fingers, last_command=[None, None],
        command_pubs=[_Writer() for _ in fingers], force_pubs=[_Writer() for _ in fingers],
        empty_pubs=[_Writer() for _ in fingers])
    assert 'empty_payload' in FAULT_KINDS_ON_WIRE
    faults = FaultInjector(probe, np.random.default_rng(5), FAULT_KINDS_ON_WIRE, 1.0)
    for kind in FAULT_KINDS_ON_WIRE:
        for finger in range(len(fingers)):
            getattr(faults, '_' + kind)(finger, 0.0)
    for finger in range(len(fingers)):
        empties = probe.empty_pubs[finger].sent
        assert empties and all(data == b'' for data in empties)
        others = probe.command_pubs[finger].sent + probe.force_pubs[finger].sent
        assert others and all(not isinstance(data, bytes) or data for data in others)


def test_junk_comes_back_padded_to_four_bytes_with_zeros():
    # A 57-byte random payload the soak sent was recorded as those 57 bytes and 3 zeros.
    sent = bytes.fromhex('07acf90af74a3bae531f3bf2b065a61aaaa72785964fee22226c81687050b23c'
                         '9360b7c16369e818b0f4010a440548097cf117e5277d533145')
    junk = {sent, b'\x00\x01\x00\x00\x05\x06\x07\x08'}
    assert len(sent) == 57
    assert is_junk(sent, junk) and is_junk(sent + bytes(3), junk)
    assert is_junk(b'\x00\x01\x00\x00\x05\x06\x07\x08', junk)
    # Not padding: more than 3 bytes, bytes that are not zeros, or a length that is no
    # multiple of 4.
    assert not is_junk(sent + bytes(7), junk)
    assert not is_junk(sent + b'\x00\x00\x01', junk)
    assert not is_junk(sent + bytes(2), junk)
    assert not is_junk(sent[:-1] + bytes(4), junk)


def test_rss_slopes_least_squares_and_theil_sen():
    # 30 min sampled every 5 s: 350 MiB rising 1 MiB/h, and 7 MiB held for a minute from
    # minute 26 (a bump that comes back, as a burst of large messages leaves).
    t = np.arange(60.0, 1800.0 + 1e-9, 5.0)
    rss = 350.0 + t / 3600.0
    bumped = rss + np.where((t >= 1560.0) & (t < 1620.0), 7.0, 0.0)
    assert slope_per_hour(t, rss) == pytest.approx(1.0, rel=1e-9)
    assert slope_per_hour(t, rss, robust=True) == pytest.approx(1.0, rel=1e-9)
    # Least squares by hand (numpy's polyfit is what the soak calls): the bump tilts it.
    centred = t - t.mean()
    by_hand = (centred * (bumped - bumped.mean())).sum() / (centred ** 2).sum() * 3600.0
    assert by_hand > 2.0
    assert slope_per_hour(t, bumped) == pytest.approx(by_hand, rel=1e-9)
    assert slope_per_hour(t, bumped, robust=True) == pytest.approx(1.0, abs=0.05)
    # NaN samples (a process gone) are left out; fewer than three points give NaN.
    holes = rss.copy()
    holes[::7] = np.nan
    assert slope_per_hour(t, holes, robust=True) == pytest.approx(1.0, rel=1e-9)
    assert math.isnan(slope_per_hour(t[:2], rss[:2], robust=True))


def test_the_recorders_stop_line_is_read_from_its_log():
    # The line the recorder writes (RecordingCounts.summary), among other log lines: the
    # soak reads the last one, and says so when there is none.
    counts = RecordingCounts()
    counts.add_topic('/a')
    for _ in range(12):
        counts.count('/a')
    counts.lose('/a', 5)
    counts.invalid_stamps = 1
    line = counts.summary(['/tmp/s.mcap'], written=9, dropped=2)
    log = f'[INFO] recording 1 topics\n[INFO] [mcap_recorder]: {line}\n[INFO] done\n'
    assert recorder_counts(log) == {'received': 12, 'written': 9, 'dropped': 3,
                                    'queue_full': 2, 'failed_writes': 1, 'lost': 5,
                                    'invalid_stamps': 1}
    assert recorder_counts('[INFO] recording 1 topics\n') is None


def test_the_executor_watchs_episodes_are_read_from_a_log():
    # The lines the watch writes (Lag's), as a node logs them: two episodes, the first
    # ended 6.3 s late, the second still under way at the stop (4.7 s at its warning).
    lag = Lag(0.5, 2.0, now=0.0)
    lines = [lag.check(2.6), lag.beat(6.8), lag.check(12.0)]
    assert None not in lines
    log = '\n'.join(f'[WARN] [1.0] [model_node]: {line}; advice' for line in lines)
    assert executor_episodes(log) == {'episodes': 2, 'worst_late_s': pytest.approx(6.3)}
    assert executor_episodes(f'[WARN] [1.0] [n]: {lines[0]}; x') == {
        'episodes': 1, 'worst_late_s': pytest.approx(2.1)}
    assert executor_episodes('[INFO] ready\n') == {'episodes': 0, 'worst_late_s': 0.0}


class _TimerNode:
    """What HeapLog needs of a node: create_timer, whose callback the test calls itself."""

    def create_timer(self, period, callback):
        self.period, self.callback = period, callback


def test_the_heap_log_sees_an_allocation_and_its_slopes_read_back(tmp_path):
    path = tmp_path / 'gripper_heap.jsonl'
    node = _TimerNode()
    log = HeapLog(node, path, 5.0)
    assert node.period == 5.0 and node.callback == log.sample
    log.sample()
    block = bytearray(64 * 2 ** 20)             # 64 MiB, mmapped: in use until freed
    log.sample()
    del block
    log.sample()
    lines = read_heap_log(path, t0=0.0)
    assert len(lines) == 3 and all(line['pymalloc_blocks'] > 0 for line in lines)
    assert all(line['arenas'][0]['nr'] == 0 and line['arenas'][0]['system_mib'] > 0.0
               for line in lines)
    use = [line['in_use_mib'] for line in lines]
    assert use[1] - use[0] == pytest.approx(64.0, abs=2.0)
    assert use[2] - use[0] == pytest.approx(0.0, abs=2.0)
    # The soak's clock is CLOCK_MONOTONIC too: t0 makes the times its own.
    later = read_heap_log(path, t0=lines[0]['t'])
    assert later[0]['t'] == 0.0 and 0.0 <= later[2]['t'] < 60.0


def test_heap_slopes_skip_the_first_minute_and_a_cut_last_line(tmp_path):
    path = tmp_path / 'h.jsonl'
    rows = [{'t': 1000.0 + t, 'in_use_mib': 100.0 + (50.0 if t <= 60 else 0.0) + t / 1800.0,
             'free_mib': 5.0, 'pymalloc_blocks': 1000 + t} for t in range(0, 1800, 5)]
    path.write_text(''.join(json.dumps(r) + '\n' for r in rows) + '{"t": 28')
    lines = read_heap_log(path, t0=1000.0)
    assert len(lines) == len(rows)
    for robust in (False, True):
        slopes = heap_slopes(lines, robust)
        # 1 MiB per 1800 s is 2 MiB/h; the first minute's 50 MiB is left out.
        assert slopes['in_use_mib'] == pytest.approx(2.0, rel=1e-6)
        assert slopes['free_mib'] == pytest.approx(0.0, abs=1e-9)
        assert slopes['pymalloc_blocks'] == pytest.approx(3600.0, rel=1e-6)
    assert read_heap_log(tmp_path / 'none.jsonl', 0.0) == []


def test_the_second_halfs_slope_tells_a_pool_that_fills_from_a_leak():
    # A pool filling at 12 MiB/h for 15 minutes, then full; and a leak at 1 MiB/h.
    t = np.arange(0.0, 1800.0, 5.0)
    fill = 100.0 + np.minimum(t, 900.0) * 12.0 / 3600.0
    leak = 100.0 + t / 3600.0
    lines = [{'t': float(ti), 'in_use_mib': float(f), 'free_mib': float(k),
              'pymalloc_blocks': 0.0} for ti, f, k in zip(t, fill, leak)]
    whole, half = heap_slopes(lines), heap_slopes(lines, since=900.0)
    assert whole['in_use_mib'] > 4.0                     # the whole run calls the fill growth
    assert half['in_use_mib'] == pytest.approx(0.0, abs=1e-9)
    assert whole['free_mib'] == pytest.approx(1.0, rel=1e-9)
    assert half['free_mib'] == pytest.approx(1.0, rel=1e-9)


def test_heap_slopes_of_the_main_arena_and_the_others(tmp_path):
    path = tmp_path / 'h.jsonl'
    # The main arena flat at 130 MiB; two thread arenas, one growing 3 MiB in 30 minutes.
    rows = [{'t': float(t), 'in_use_mib': 100.0, 'free_mib': 5.0, 'pymalloc_blocks': 1000,
             'arenas': [{'nr': 0, 'system_mib': 130.0}, {'nr': 4, 'system_mib': 0.5},
                        {'nr': 9, 'system_mib': 1.0 + 3.0 * t / 1800.0}]}
            for t in range(0, 1800, 5)]
    path.write_text(''.join(json.dumps(r) + '\n' for r in rows))
    lines = read_heap_log(path, t0=0.0)
    assert lines[0]['main_arena_mib'] == 130.0 and lines[0]['thread_arenas_mib'] == 1.5
    slopes = heap_slopes(lines)
    assert slopes['main_arena_mib'] == pytest.approx(0.0, abs=1e-9)
    assert slopes['thread_arenas_mib'] == pytest.approx(6.0, rel=1e-6)
    # a log from before the arenas were logged has neither
    assert math.isnan(heap_slopes([{k: v for k, v in r.items() if k != 'arenas'}
                                   for r in rows])['thread_arenas_mib'])


# malloc_info's document as glibc 2.36 writes it: arena 0 with a fast bin, two bins and
# the unsorted bin; arena 1 with its top chunk only; then the process's totals.
_MALLOC_INFO = """<malloc version="1">
<heap nr="0">
<sizes>
  <size from="33" to="48" total="480" count="10"/>
  <size from="2049" to="2049" total="40980" count="20"/>
  <size from="100001" to="200000" total="150000" count="1"/>
  <unsorted from="65" to="8193" total="20000" count="5"/>
</sizes>
<total type="fast" count="10" size="480"/>
<total type="rest" count="27" size="1258576"/>
<system type="current" size="4194304"/>
<system type="max" size="8388608"/>
<aspace type="total" size="4194304"/>
<aspace type="mprotect" size="4194304"/>
</heap>
<heap nr="1">
<sizes>
</sizes>
<total type="fast" count="0" size="0"/>
<total type="rest" count="1" size="131072"/>
<system type="current" size="135168"/>
<system type="max" size="135168"/>
<aspace type="total" size="135168"/>
<aspace type="mprotect" size="135168"/>
</heap>
<total type="fast" count="10" size="480"/>
<total type="rest" count="28" size="1389648"/>
<total type="mmap" count="2" size="1048576"/>
<system type="current" size="4329472"/>
<system type="max" size="8523776"/>
<aspace type="total" size="4329472"/>
<aspace type="mprotect" size="4329472"/>
</malloc>
"""


def test_arena_summary_reads_each_arena_of_a_malloc_info_document():
    mib = 2.0 ** -20
    first, second = arena_summary(_MALLOC_INFO)
    assert first['nr'] == 0 and second['nr'] == 1
    assert first['system_mib'] == pytest.approx(4.0) and second['system_mib'] == pytest.approx(
        135168 * mib)
    assert first['free_mib'] == pytest.approx((480 + 1258576) * mib)
    # <= 1 KiB: the fast bin; <= 4 KiB: the 2049-byte bin; > 64 KiB: the large one.
    assert first['free_by_size_mib'] == pytest.approx([480 * mib, 40980 * mib, 0.0,
                                                       150000 * mib])
    assert first['unsorted_mib'] == pytest.approx(20000 * mib)
    assert first['top_mib'] == pytest.approx((1258576 - 40980 - 150000 - 20000) * mib)
    assert second['free_by_size_mib'] == [0.0] * 4
    assert second['top_mib'] == pytest.approx(131072 * mib)


# In a process of its own, so that no other test's threads or allocator settings share
# the arena: 2,000 chunks of 3,000 bytes, every other one freed, read before and after.
_FREE_CHUNKS = r"""
import ctypes, json, sys
sys.path.insert(0, sys.argv[1])
from soak_nodes import _malloc_info, arena_summary
libc = ctypes.CDLL(None)
libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, (ctypes.c_size_t,)
libc.free.argtypes = (ctypes.c_void_p,)
read = _malloc_info()
before = arena_summary(read())[0]
blocks = [libc.malloc(3000) for _ in range(2000)]
for block in blocks[::2]:
    libc.free(block)
libc.free(libc.malloc(100_000))     # sorts the unsorted chunks into their bins
after = arena_summary(read())[0]
print(json.dumps([before, after]))
"""


def test_malloc_info_sees_free_chunks_between_chunks_in_use():
    """3,000-byte chunks freed between chunks in use show as free bytes of 1-4 KiB."""
    environ = {k: v for k, v in os.environ.items() if not k.startswith('MALLOC_')}
    done = subprocess.run([sys.executable, '-c', _FREE_CHUNKS, str(BENCH)], env=environ,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    before, after = json.loads(done.stdout.strip().splitlines()[-1])

    def between(arena):
        return arena['free_by_size_mib'][1] + arena['unsorted_mib']

    # 1,000 free chunks of 3,008 bytes (3,000 and glibc's 8-byte header, 16-aligned).
    assert between(after) - between(before) == pytest.approx(1000 * 3008 / 2 ** 20, rel=0.05)
    assert after['system_mib'] >= after['free_mib'] > 2.8


def test_node_env_sets_a_variable_in_one_node_process_and_refuses_what_is_no_assignment(
        monkeypatch):
    monkeypatch.setenv('FPC_NETNS', '1')
    args = parse_args(['--node-env', 'model_node:FPC_GRIPPER_WRITER_HISTORY_S=0.5',
                       '--node-env', 'model_node:A=b=c', '--node-env', 'virtual_object:X='])
    assert args.node_env == {'model_node': {'FPC_GRIPPER_WRITER_HISTORY_S': '0.5', 'A': 'b=c'},
                             'virtual_object': {'X': ''}}
    for bad in ('model_node', 'model_node:VAR', ':VAR=1', 'model_node:=1'):
        with pytest.raises(SystemExit):
            parse_args(['--node-env', bad])
    with pytest.raises(SystemExit):
        parse_args(['--node-env', 'no_such_node:VAR=1'])


def test_the_reader_pool_bench_varies_only_the_readers_sample_limit():
    from xml.etree import ElementTree

    from reader_pool import profile_text

    from fpc_gripper.nodes.middleware import PROFILE

    ns = {'dds': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}

    def limits(text):
        found = ElementTree.fromstring(text).find(
            './/dds:data_reader/dds:topic/dds:resourceLimitsQos', ns)
        return None if found is None else {e.tag.split('}')[1]: int(e.text) for e in found}

    assert limits(PROFILE.read_text()) is None
    assert profile_text(None) == PROFILE.read_text()
    assert limits(profile_text(50)) == {'max_samples': 50, 'max_samples_per_instance': 50}
    # Everything else is the package's profile.
    block = re.compile(r'\s*<topic>\s*<resourceLimitsQos>.*?</topic>', re.DOTALL)
    assert block.sub('', profile_text(100)) == PROFILE.read_text()


def test_stop_process_escalates_only_as_far_as_it_must():
    import signal

    from soak import stop_process

    def child(code):
        process = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE)
        assert process.stdout.readline() == b'ready\n'   # its handlers are set
        return process

    # Python leaves SIGINT ignored when it starts so (a background job's): set its handler.
    ends_on_sigint = child('import signal, time; '
                           'signal.signal(signal.SIGINT, signal.default_int_handler); '
                           'print("ready", flush=True); time.sleep(60)')
    assert stop_process(ends_on_sigint, 10.0) == signal.SIGINT
    assert ends_on_sigint.returncode != 0
    ignores_sigint = child('import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); '
                           'print("ready", flush=True); time.sleep(60)')
    assert stop_process(ignores_sigint, 0.2) == signal.SIGTERM
    assert ignores_sigint.returncode == -signal.SIGTERM
    assert stop_process(ignores_sigint, 0.2) is None             # ended already


def test_a_node_process_stops_on_sigint_and_says_when_it_was_forced(tmp_path):
    import signal
    import time

    from soak import NodeProcess

    def started(name, code):
        node = NodeProcess(name, [sys.executable, '-c', code], tmp_path / f'{name}.log')
        deadline = time.monotonic() + 60.0
        while 'ready' not in node.log_text() and time.monotonic() < deadline:
            time.sleep(0.02)
        assert 'ready' in node.log_text()
        return node

    clean = started('model_node', 'import signal, sys, time; '
                    'signal.signal(signal.SIGINT, lambda *_: sys.exit(0)); '
                    'print("ready", flush=True); time.sleep(60)')
    assert clean.stop(10.0) == 0 and not clean.forced
    assert clean.stop(10.0) == 0 and not clean.forced           # ended already: not forced
    stubborn = started('gripper_controller', 'import signal, time; '
                       'signal.signal(signal.SIGINT, signal.SIG_IGN); '
                       'print("ready", flush=True); time.sleep(60)')
    assert stubborn.stop(0.2) == -signal.SIGTERM and stubborn.forced
    assert stubborn.stop(0.2) == -signal.SIGTERM                # ended already: as it was
