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


def test_readers_keep_fast_dds_resource_limits():
    # A lower sample limit does not bound what Fast DDS 2.14's keep-last readers leak
    # behind resending writers; it makes the reader lose samples sooner (the profile's
    # comment, docs/soak.md stop 54). The in-process test below would see a low one.
    from xml.etree import ElementTree

    ns = {'dds': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}
    root = ElementTree.parse(PROFILE).getroot()
    assert len(root.findall('.//dds:data_reader', ns)) == 1
    assert not root.findall('.//dds:resourceLimitsQos', ns)
    assert not root.findall('.//dds:data_writer/dds:topic', ns)


# One process, so Fast DDS delivers within it. rclpy's parameter services (1000 deep) must
# take 1000 requests sent together, with the server's executor not spinning meanwhile, and
# answer them all; a keep-all reader, not taking while a writer of the same process sends
# 3000 samples, must get them all. Within a process Fast DDS counts what a full reader
# refused as delivered (between processes it sends it again): under a profile that limits
# readers to 100 samples a burst of 300 gave the first 100, and at 1000 one of 3000 the
# first 1000.
_AT_ONCE = r"""
import json, time
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, qos_profile_parameters, QoSProfile, ReliabilityPolicy
from rcl_interfaces.srv import GetParameters, SetParameters
from std_msgs.msg import Int32
from fpc_gripper.nodes.middleware import apply_middleware_settings

REQUESTS, BURST = 1000, 3000
applied = apply_middleware_settings()
rclpy.init()
server = rclpy.create_node('server')
server.declare_parameter('x', 0)
client_node = rclpy.create_node('client')
# As rclpy's AsyncParameterClient (and ros2 param) make them
setter = client_node.create_client(SetParameters, '/server/set_parameters',
                                   qos_profile=qos_profile_parameters)
getter = client_node.create_client(GetParameters, '/server/get_parameters',
                                   qos_profile=qos_profile_parameters)
server_executor, client_executor = SingleThreadedExecutor(), SingleThreadedExecutor()
server_executor.add_node(server)
client_executor.add_node(client_node)

def spin_until(done, seconds):
    deadline = time.monotonic() + seconds
    while not done() and time.monotonic() < deadline:
        server_executor.spin_once(timeout_sec=0.01)
        client_executor.spin_once(timeout_sec=0.01)

spin_until(lambda: setter.service_is_ready() and getter.service_is_ready(), 30)
futures = [setter.call_async(SetParameters.Request(
    parameters=[Parameter('x', value=i).to_parameter_msg()])) for i in range(REQUESTS)]
for _ in range(20):
    client_executor.spin_once(timeout_sec=0.01)
keep_all = QoSProfile(depth=0, history=HistoryPolicy.KEEP_ALL,
                      reliability=ReliabilityPolicy.RELIABLE)
got = []
server.create_subscription(Int32, 'burst', lambda m: got.append(m.data), keep_all)
burst = client_node.create_publisher(Int32, 'burst', keep_all)
spin_until(lambda: burst.get_subscription_count() > 0, 30)
for i in range(BURST):
    burst.publish(Int32(data=i))
time.sleep(0.5)
spin_until(lambda: all(f.done() for f in futures) and len(got) >= BURST, 60)
spin_until(lambda: False, 1.0)  # anything more that would come
last = getter.call_async(GetParameters.Request(names=['x']))
spin_until(last.done, 30)
print(json.dumps({
    'profile': applied.get('FASTRTPS_DEFAULT_PROFILES_FILE'),
    'answered': sum(f.done() and all(r.successful for r in f.result().results)
                    for f in futures),
    'x': last.result().values[0].integer_value if last.done() else None,
    'burst': got}))
"""


def test_a_process_takes_a_burst_its_readers_ask_for_at_once():
    environ = {k: v for k, v in _allocator_env().items()
               if k not in ('FASTRTPS_DEFAULT_PROFILES_FILE', 'RMW_FASTRTPS_USE_QOS_FROM_XML')}
    done = subprocess.run([sys.executable, '-c', _AT_ONCE], env=environ,
                          capture_output=True, text=True, timeout=240)
    assert done.returncode == 0, done.stderr
    assert 'XMLPARSER' not in done.stdout + done.stderr
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result['profile'] == str(PROFILE)
    assert result['answered'] == 1000
    # The requests are taken in order, so the last one sent is the value that stays.
    assert result['x'] == 999
    assert result['burst'] == list(range(3000))


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
