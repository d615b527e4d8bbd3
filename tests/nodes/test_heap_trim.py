"""The heap trim: pages freed amid glibc's heap go back to the system; run_node sets it up."""

import ctypes
import json
import os
import subprocess
import sys

import pytest

from fpc_gripper.nodes.heap_trim import HeapTrim
from fpc_gripper.nodes.heap_trim import malloc_trim
from fpc_gripper.nodes.heap_trim import TRIM_PERIOD_S
from fpc_gripper.nodes.middleware import OPT_OUT_ENV

GLIBC = malloc_trim() is not None

# In a process of its own: 40,000 blocks of 1 KiB from the main heap, then the 30,000 in
# the middle freed. free() gives back only the top of the heap, which is still in use, so
# the freed pages stay resident until the trim.
_FRAGMENT = """
import ctypes, json, os
from rclpy.clock import ClockType
from fpc_gripper.nodes.heap_trim import HeapTrim

class Node:
    def create_timer(self, period, callback, clock=None):
        self.period, self.callback, self.clock = period, callback, clock

def rss_mib():
    with open('/proc/self/statm') as f:
        return int(f.read().split()[1]) * os.sysconf('SC_PAGE_SIZE') / 2 ** 20

libc = ctypes.CDLL(None)
libc.malloc.restype = ctypes.c_void_p
libc.free.argtypes = (ctypes.c_void_p,)
libc.mallopt(-3, 128 * 1024)          # the nodes' fixed mmap threshold (middleware.py)
blocks = [libc.malloc(1024) for _ in range(40_000)]
for address in blocks:
    ctypes.memset(address, 1, 1024)
for address in blocks[5_000:35_000]:
    libc.free(address)
node = Node()
trim = HeapTrim(node)
before = rss_mib()
released = node.callback()
after = rss_mib()
print(json.dumps({'before': before, 'after': after, 'released': released,
                  'count': trim.count, 'process': HeapTrim.process,
                  'period': node.period,
                  'steady': node.clock.clock_type == ClockType.STEADY_TIME}))
"""


@pytest.mark.skipif(not GLIBC, reason='needs glibc (malloc_trim)')
def test_the_trim_gives_back_the_pages_freed_amid_the_heap():
    done = subprocess.run([sys.executable, '-c', _FRAGMENT], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout.strip().splitlines()[-1])
    # 30,000 freed blocks of 1 KiB (and their headers): some 29 MiB of whole pages.
    assert result['released'] is True
    assert result['before'] - result['after'] == pytest.approx(29.5, abs=3.0)
    assert result['count'] == 1 and result['process']['count'] == 1
    assert result['period'] == TRIM_PERIOD_S and result['steady'] is True


class _Node:
    def __init__(self):
        self.timers = []

    def create_timer(self, period, callback, clock=None):
        self.timers.append((period, callback, clock))


def test_the_trim_counts_its_calls_and_their_time():
    calls = []
    node = _Node()
    start = dict(HeapTrim.process)
    trim = HeapTrim(node, period_s=5.0, trim=lambda pad: calls.append(pad) or 1)
    assert trim.active and [t[0] for t in node.timers] == [5.0]
    assert node.timers[0][1] == trim.trim
    assert trim.trim() is True and trim.trim() is True
    assert calls == [0, 0] and trim.count == 2
    assert 0.0 <= trim.last_s <= trim.max_s <= trim.total_s
    assert HeapTrim.process['count'] == start['count'] + 2
    assert HeapTrim.process['total_s'] >= start['total_s'] + trim.total_s - 1e-12


def test_no_malloc_trim_no_timer(monkeypatch):
    monkeypatch.setattr(ctypes, 'CDLL', lambda name: object())
    assert malloc_trim() is None
    node = _Node()
    trim = HeapTrim(node)
    assert not trim.active and node.timers == []


_RUN_NODE = """
import json, os, signal, sys
import rclpy
from fpc_gripper.nodes.runner import run_node
seen = {}

def build():
    node = rclpy.create_node('trim_probe')

    def stop():
        trim = getattr(node, 'heap_trim', None)
        seen['trim'] = trim is not None and trim.active
        os.kill(os.getpid(), signal.SIGINT)
    node.create_timer(0.2, stop)
    return node

code = run_node(build, 'trim_probe', [sys.argv[0]])
print(json.dumps({'code': code, **seen}))
"""


@pytest.mark.skipif(not GLIBC, reason='needs glibc (malloc_trim)')
@pytest.mark.parametrize('env, trimmed', [
    ({}, True), ({OPT_OUT_ENV: '1'}, True),
    # a threshold of the user's own is kept (middleware.py); the trim still runs
    ({'MALLOC_MMAP_THRESHOLD_': '65536'}, True),
    ({OPT_OUT_ENV: '0'}, False)])
def test_run_node_trims_unless_the_settings_are_opted_out(env, trimmed):
    environ = {k: v for k, v in os.environ.items()
               if k not in (OPT_OUT_ENV, 'MALLOC_MMAP_THRESHOLD_')}
    environ.update(env)
    done = subprocess.run([sys.executable, '-c', _RUN_NODE], env=environ, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1]) == {'code': 0, 'trim': trimmed}
