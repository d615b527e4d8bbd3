"""The Fast DDS profile and allocator setting: when they apply, and that they free memory."""

import json
import os
import shutil
import subprocess
import sys

import pytest

from fpc_gripper.nodes.middleware import (apply_middleware_settings, middleware_settings,
                                          OPT_OUT_ENV, PROFILE)

PROFILE_ENV = {'FASTRTPS_DEFAULT_PROFILES_FILE': str(PROFILE),
               'RMW_FASTRTPS_USE_QOS_FROM_XML': '1'}
ALLOCATOR = {'mmap_threshold': 131072, 'arena_max': 1}
_OWN_ALLOCATOR_ENV = ('MALLOC_MMAP_THRESHOLD_', 'MALLOC_ARENA_MAX')


@pytest.mark.parametrize('environ, env, allocator', [
    ({}, PROFILE_ENV, ALLOCATOR),
    ({'RMW_IMPLEMENTATION': 'rmw_fastrtps_cpp'}, PROFILE_ENV, ALLOCATOR),
    ({'RMW_IMPLEMENTATION': 'rmw_cyclonedds_cpp'}, {}, ALLOCATOR),
    ({'FASTRTPS_DEFAULT_PROFILES_FILE': '/etc/mine.xml'}, {}, ALLOCATOR),
    ({'RMW_FASTRTPS_USE_QOS_FROM_XML': '0'}, {}, ALLOCATOR),
    ({'RMW_FASTRTPS_PUBLICATION_MODE': 'ASYNCHRONOUS'}, {}, ALLOCATOR),
    ({'MALLOC_MMAP_THRESHOLD_': '65536'}, PROFILE_ENV, {'arena_max': 1}),
    ({'MALLOC_ARENA_MAX': '4'}, PROFILE_ENV, {'mmap_threshold': 131072}),
    ({OPT_OUT_ENV: '0'}, {}, {}),
])
def test_settings_apply_only_where_nobody_else_chose(environ, env, allocator):
    assert middleware_settings(environ) == (env, allocator)


def test_apply_sets_the_variables_in_the_environment_it_is_given():
    environ = {'RMW_IMPLEMENTATION': 'rmw_fastrtps_cpp', 'MALLOC_MMAP_THRESHOLD_': '131072',
               'MALLOC_ARENA_MAX': '2'}
    assert apply_middleware_settings(environ) == PROFILE_ENV
    assert environ == {'RMW_IMPLEMENTATION': 'rmw_fastrtps_cpp',
                       'MALLOC_MMAP_THRESHOLD_': '131072', 'MALLOC_ARENA_MAX': '2',
                       **PROFILE_ENV}
    assert apply_middleware_settings({OPT_OUT_ENV: '0'}) == {}


# Four threads malloc while all of them live, then glibc's malloc_stats (stderr) names
# every arena of the process: one per thread unless arena_max holds them to one.
_ALLOCATE_ON_FOUR_THREADS = r"""
import ctypes, sys, threading

def allocate_on_four_threads():
    libc = ctypes.CDLL(None)
    libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, (ctypes.c_size_t,)
    barrier = threading.Barrier(4)
    def work():
        barrier.wait()
        libc.malloc(1000)
        barrier.wait()
    threads = [threading.Thread(target=work) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    sys.stderr.flush()
    libc.malloc_stats()
"""
_ARENAS = _ALLOCATE_ON_FOUR_THREADS + r"""
import json
from fpc_gripper.nodes.middleware import apply_middleware_settings
done = apply_middleware_settings()
allocate_on_four_threads()
print(json.dumps(done))
"""
# The nodes' console scripts: a node module whose import starts threads, as numpy's and
# rclpy's do, and whose main then allocates on four threads of its own.
_CONSOLE_SCRIPT = _ALLOCATE_ON_FOUR_THREADS + r"""
import types
from fpc_gripper.nodes import entry_points

def main():
    import numpy, rclpy
    allocate_on_four_threads()
    return 0

entry_points.importlib = types.SimpleNamespace(
    import_module=lambda name: types.SimpleNamespace(main=main))
sys.exit(entry_points.model_node())
"""


def _allocator_env(**env):
    """This environment without the user's allocator settings or opt-out, then `env`."""
    environ = {k: v for k, v in os.environ.items()
               if k not in (*_OWN_ALLOCATOR_ENV, OPT_OUT_ENV)}
    return environ | env


@pytest.mark.skipif(not hasattr(__import__('ctypes').CDLL(None), 'malloc_stats'),
                    reason='needs glibc (malloc_stats)')
@pytest.mark.parametrize('env, arenas', [({}, 1), ({OPT_OUT_ENV: '0'}, 5),
                                         ({'MALLOC_ARENA_MAX': '2'}, 2)])
def test_every_thread_shares_one_arena(env, arenas):
    done = subprocess.run([sys.executable, '-c', _ARENAS], env=_allocator_env(**env),
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stderr.count('Arena ') == arenas, done.stderr
    made = json.loads(done.stdout)
    assert made.get('arena_max') == (1 if not env else None)


def test_the_profile_is_installed_with_the_package():
    assert PROFILE.is_file()
    text = PROFILE.read_text()
    assert text.count('<historyMemoryPolicy>DYNAMIC</historyMemoryPolicy>') == 2


def test_readers_are_limited_below_fast_dds_default_and_above_every_readers_depth():
    from xml.etree import ElementTree

    from rclpy.qos import qos_profile_parameters
    from rclpy.qos import qos_profile_sensor_data

    from fpc_gripper.io import qos

    ns = {'dds': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}
    readers = ElementTree.parse(PROFILE).getroot().findall('.//dds:data_reader', ns)
    assert len(readers) == 1
    limits = readers[0].find('dds:topic/dds:resourceLimitsQos', ns)
    max_samples = int(limits.find('dds:max_samples', ns).text)
    per_instance = int(limits.find('dds:max_samples_per_instance', ns).text)
    # Fast DDS's default is 5000: the limit is what bounds a reader's pool of changes.
    assert per_instance == max_samples < 5000
    # Fast DDS would cut a keep-last reader deeper than the limit to it: none is.
    depths = [qos_profile_parameters.depth, qos_profile_sensor_data.depth] + [
        getattr(qos, name).depth for name in qos.__all__ if name.endswith('_QOS')]
    assert max(depths) == 1000 and max_samples >= max(depths)
    assert not ElementTree.parse(PROFILE).getroot().findall('.//dds:data_writer/dds:topic',
                                                            ns)


# A reliable keep-all reader that lets 12 messages of 1 MB queue before it takes any, then
# takes them all: glibc's bytes in use (mallinfo2) before the burst, after it is taken, and
# what the depth-1 reader of a 5-message burst received (the ROS QoS must still hold).
_PROBE = r"""
import ctypes, json, sys, time
import rclpy
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
from fpc_gripper.nodes.middleware import apply_middleware_settings

class Info(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        'arena', 'ordblks', 'smblks', 'hblks', 'hblkhd', 'usmblks', 'fsmblks', 'uordblks',
        'fordblks', 'keepcost')]

libc = ctypes.CDLL(None)
libc.mallinfo2.restype = Info
apply_middleware_settings()
rclpy.init()
node = rclpy.create_node('middleware_probe')
executor = SingleThreadedExecutor()
executor.add_node(node)
reliable = dict(reliability=ReliabilityPolicy.RELIABLE)
taken, latest = [], []
big_sub = node.create_subscription(String, 'big', lambda m: taken.append(len(m.data)),
                                   QoSProfile(depth=0, history=HistoryPolicy.KEEP_ALL, **reliable))
small_sub = node.create_subscription(String, 'small', lambda m: latest.append(m.data),
                                     QoSProfile(depth=1, **reliable))
big = node.create_publisher(String, 'big',
                            QoSProfile(depth=0, history=HistoryPolicy.KEEP_ALL, **reliable))
small = node.create_publisher(String, 'small', QoSProfile(depth=10, **reliable))
deadline = time.monotonic() + 30
while (big.get_subscription_count() < 1 or small.get_subscription_count() < 1) \
        and time.monotonic() < deadline:
    executor.spin_once(timeout_sec=0.05)
for _ in range(3):
    executor.spin_once(timeout_sec=0.01)
def rss():
    with open('/proc/self/statm') as statm:
        return int(statm.read().split()[1]) * 4096

before, rss_before = libc.mallinfo2().uordblks, rss()
for i in range(12):
    big.publish(String(data=chr(97 + i) * 1_000_000))
for i in range(5):
    small.publish(String(data=str(i)))
acked = big.wait_for_all_acked(Duration(seconds=30)) and \
    small.wait_for_all_acked(Duration(seconds=30))
while (len(taken) < 12 or not latest) and time.monotonic() < deadline + 30:
    executor.spin_once(timeout_sec=0.05)
for _ in range(3):
    executor.spin_once(timeout_sec=0.01)
after, rss_after = libc.mallinfo2().uordblks, rss()
print(json.dumps({'acked': acked, 'taken': taken, 'latest': latest,
                  'kept_mib': (after - before) / 2 ** 20,
                  'rss_kept_mib': (rss_after - rss_before) / 2 ** 20}))
"""


def _probe(**env):
    environ = {k: v for k, v in _allocator_env().items()
               if k not in ('FASTRTPS_DEFAULT_PROFILES_FILE', 'RMW_FASTRTPS_USE_QOS_FROM_XML')}
    environ.update(env)
    done = subprocess.run([sys.executable, '-c', _PROBE], env=environ, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    # Fast DDS prints its log (an XML parse error among it) on stdout
    return json.loads(done.stdout.strip().splitlines()[-1]), done.stdout + done.stderr


@pytest.mark.skipif(not hasattr(__import__('ctypes').CDLL(None), 'mallinfo2'),
                    reason='needs glibc 2.33 or later (mallinfo2)')
def test_profile_and_threshold_give_a_drained_backlog_back():
    ours, ours_log = _probe()
    rmw_defaults, _ = _probe(**{OPT_OUT_ENV: '0'})
    # the profile alone (given as a user's own), glibc's sliding mmap threshold left as is
    profile_only, _ = _probe(**{OPT_OUT_ENV: '0'}, **PROFILE_ENV)
    for result in (ours, rmw_defaults, profile_only):
        assert result['acked']
        assert result['taken'] == [1_000_000] * 12
        # depth 1, reliable: of a burst of five the reader keeps the last, as ROS asked
        assert result['latest'] == ['4']
    assert 'XMLPARSER' not in ours_log and 'Error' not in ours_log
    # rmw's own settings keep the reader's 12 buffers of 1 MB after the backlog is taken
    assert rmw_defaults['kept_mib'] > 10.0 and rmw_defaults['rss_kept_mib'] > 10.0
    # the profile frees them, but glibc keeps their pages: above its raised threshold
    # they came from the heap
    assert profile_only['kept_mib'] < 1.0 and profile_only['rss_kept_mib'] > 4.0
    # both settings: the bytes and the pages are given back
    assert ours['kept_mib'] < 1.0 and ours['rss_kept_mib'] < 2.0


def test_a_broken_profile_is_reported_by_fast_dds(tmp_path):
    # The check above that Fast DDS printed no parse error can fail: a profile it cannot
    # read is reported on stderr, and the process still runs on rmw's defaults.
    broken = tmp_path / 'broken.xml'
    shutil.copy(PROFILE, broken)
    broken.write_text(broken.read_text().replace('>DYNAMIC<', '>DYNAMIC_SOMETIMES<'))
    result, log = _probe(FASTRTPS_DEFAULT_PROFILES_FILE=str(broken),
                         RMW_FASTRTPS_USE_QOS_FROM_XML='1')
    assert 'XMLPARSER' in log
    assert result['latest'] == ['4']


@pytest.mark.skipif(not hasattr(__import__('ctypes').CDLL(None), 'malloc_stats'),
                    reason='needs glibc (malloc_stats)')
def test_the_console_scripts_share_one_arena_from_before_their_imports():
    arenas = {}
    for opt_out in ('1', '0'):
        done = subprocess.run([sys.executable, '-c', _CONSOLE_SCRIPT],
                              env=_allocator_env(**{OPT_OUT_ENV: opt_out}),
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
        arenas[opt_out] = done.stderr.count('Arena ')
    # Without the settings, the four (and the imports' threads) take arenas of their own.
    assert arenas['1'] == 1 and arenas['0'] >= 5, arenas
