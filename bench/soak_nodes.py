"""The soak's two extra node processes: the regulator bridge with a fault hook, the object."""

# Run by bench/soak.py, one process each:
#   python bench/soak_nodes.py regulator_bridge --ros-args ...   (the bridge, sim backend)
#   python bench/soak_nodes.py virtual_object --ros-args ...     (gripper_demo's object)
#   python bench/soak_nodes.py model_node --ros-args ...         (and gripper_controller,
#                                                                  mcap_recorder)
# or, with soak.py --composed, every node in one process as the `gripper` executable runs
# them (with --record --virtual-object):
#   python bench/soak_nodes.py gripper --ros-args ...
# Every node is fpc_gripper's, unchanged, built and spun by the package's run_node exactly
# as its executable does, with a heap log (below) when asked. The bridge only gets one
# more subscription,
# `soak/regulator_fault` (std_msgs/String, JSON), through which the soak injects faults
# into the simulated backend (SimulatedRegulator.inject_fault) from another process:
#   {"kind": "disconnect" | "bad_readback" | "leak" | "stuck_sensor", "channel": 0,
#    "value": NaN, "rate": 1e5, "duration_s": 0.5}
# and clears them all after duration_s.
# With FPC_SOAK_HEAP_LOG=PATH in its environment, a process also appends its allocator's
# state to PATH every HEAP_LOG_PERIOD_S (HeapLog), so that the soak can tell memory in use
# from memory the allocator holds free. With FPC_SOAK_MEMRAY=PATH (memray installed, for
# example through soak.py --node-env), it runs under memray's native tracker, writing PATH.

import ctypes
import functools
import json
import os
import sys
import time
import xml.etree.ElementTree as ElementTree

from fpc_gripper.nodes.middleware import apply_allocator_settings

if __name__ == '__main__':
    # As the nodes' console scripts do, before the imports below start threads.
    apply_allocator_settings()

from rclpy.qos import QoSProfile  # noqa: E402, I100
from rclpy.qos import ReliabilityPolicy  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from fpc_gripper.nodes.gripper import bridge_exit_code  # noqa: E402
from fpc_gripper.nodes.gripper import compose  # noqa: E402
from fpc_gripper.nodes.gripper_controller import GripperController  # noqa: E402
from fpc_gripper.nodes.heap_trim import HeapTrim  # noqa: E402
from fpc_gripper.nodes.mcap_recorder import McapRecorder  # noqa: E402
from fpc_gripper.nodes.model_node import ModelNode  # noqa: E402
from fpc_gripper.nodes.regulator_bridge import activation_exit_code  # noqa: E402
from fpc_gripper.nodes.regulator_bridge import RegulatorBridge  # noqa: E402
from fpc_gripper.nodes.runner import run_node  # noqa: E402
from fpc_gripper.nodes.virtual_object import VirtualObjectNode  # noqa: E402

FAULT_TOPIC = 'soak/regulator_fault'
_FAULT_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


class FaultHook:
    """Inject the faults asked on `FAULT_TOPIC` into a bridge's simulated backend."""

    def __init__(self, node):
        self.node = node
        self._clear_timer = None
        node.create_subscription(String, FAULT_TOPIC, self._on_fault, _FAULT_QOS)

    def _on_fault(self, msg):
        log = self.node.get_logger()
        backend = self.node.backend
        if backend is None or not hasattr(backend, 'inject_fault'):
            log.warning(f'soak fault ignored, no simulated backend: {msg.data}')
            return
        try:
            spec = json.loads(msg.data)
            backend.inject_fault(spec['kind'], channel=spec.get('channel'),
                                 rate=spec.get('rate'), value=spec.get('value'))
        except (KeyError, TypeError, ValueError) as exc:
            log.warning(f'soak fault {msg.data!r} not injected: {exc}')
            return
        log.info(f'soak fault injected: {msg.data}')
        if self._clear_timer is not None:
            self.node.destroy_timer(self._clear_timer)
        self._clear_timer = self.node.create_timer(float(spec.get('duration_s', 0.5)),
                                                   self._clear)

    def _clear(self):
        self.node.destroy_timer(self._clear_timer)
        self._clear_timer = None
        backend = self.node.backend
        if backend is not None:
            backend.clear_faults()
            self.node.get_logger().info('soak faults cleared')


#: Time between two lines of a heap log [s].
HEAP_LOG_PERIOD_S = 5.0


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        'arena', 'ordblks', 'smblks', 'hblks', 'hblkhd', 'usmblks', 'fsmblks', 'uordblks',
        'fordblks', 'keepcost')]


def mallinfo2():
    """Return glibc's function of that name (glibc 2.33 and later), or None where there is none."""
    try:
        function = ctypes.CDLL(None).mallinfo2
    except (AttributeError, OSError):
        return None
    function.restype = _MallInfo2
    function.argtypes = ()
    return function


class HeapLog:
    """
    Append the process's allocator state to a JSON-lines file, on a timer of `node`.

    Each line: ``t`` (CLOCK_MONOTONIC, the soak's clock too) [s]; glibc's bytes in use
    (``in_use_mib``: every arena's allocated chunks and the mmapped ones), held free in
    its arenas (``free_mib``) and mmapped (``mmapped_mib``), all in MiB; and pymalloc's
    live blocks (``pymalloc_blocks``); the process's heap trims so far (``trim_count``,
    ``trim_max_s``, ``trim_total_s``: `HeapTrim.process`); and each arena's size and
    free bytes by chunk size (``arenas``: `arena_summary`). On the executor's thread, so
    the sampling makes no allocator arena of its own.
    """

    def __init__(self, node, path, period_s):
        self._mallinfo = mallinfo2()
        self._malloc_info = _malloc_info()
        self._file = open(path, 'a', buffering=1)
        self._timer = node.create_timer(period_s, self.sample)

    def sample(self):
        """Append one line."""
        line = {'t': time.monotonic(), 'pymalloc_blocks': sys.getallocatedblocks()}
        if self._mallinfo is not None:
            info = self._mallinfo()
            line.update(in_use_mib=(info.uordblks + info.hblkhd) / 2 ** 20,
                        free_mib=info.fordblks / 2 ** 20, mmapped_mib=info.hblkhd / 2 ** 20)
        if self._malloc_info is not None:
            line['arenas'] = arena_summary(self._malloc_info())
        line.update({f'trim_{key}': value for key, value in HeapTrim.process.items()})
        self._file.write(json.dumps(line) + '\n')


#: Upper bounds of the free-chunk size classes of `arena_summary` [bytes].
FREE_CLASSES = (1024, 4096, 65536)


def _malloc_info():
    """Return a call that gives glibc's ``malloc_info`` XML, or None where there is none."""
    try:
        libc = ctypes.CDLL(None)
        info, memstream, fclose, free = (libc.malloc_info, libc.open_memstream, libc.fclose,
                                         libc.free)
    except (AttributeError, OSError):
        return None
    memstream.restype = ctypes.c_void_p
    memstream.argtypes = (ctypes.POINTER(ctypes.c_void_p), ctypes.POINTER(ctypes.c_size_t))
    info.argtypes = (ctypes.c_int, ctypes.c_void_p)
    fclose.argtypes = (ctypes.c_void_p,)
    free.argtypes = (ctypes.c_void_p,)

    def read():
        buffer, size = ctypes.c_void_p(), ctypes.c_size_t()
        stream = memstream(ctypes.byref(buffer), ctypes.byref(size))
        if not stream:
            return '<malloc/>'
        try:
            info(0, stream)
        finally:
            fclose(stream)   # sets buffer and size
        try:
            return ctypes.string_at(buffer, size.value).decode()
        finally:
            free(buffer)
    return read


def arena_summary(xml):
    """
    Each arena of a ``malloc_info`` document: its size and its free bytes by chunk size.

    A list, one dict per ``<heap>``: ``nr``; ``system_mib``, the memory the arena has from
    the kernel now; ``free_mib``, all its free bytes (fast bins and the rest, which holds
    the top chunk); ``free_by_size_mib``, the binned free bytes in chunks of at most 1 KiB,
    4 KiB, 64 KiB and more (`FREE_CLASSES`: what ``malloc_trim`` can give back is in the
    larger ones); ``unsorted_mib``, the chunks not yet binned; and ``top_mib``, the top
    chunk (the rest: glibc counts it in the free bytes and lists it in no bin).
    """
    arenas = []
    for heap in ElementTree.fromstring(xml).iter('heap'):
        by_size = [0] * (len(FREE_CLASSES) + 1)
        for size in heap.iter('size'):
            slot = next((i for i, bound in enumerate(FREE_CLASSES)
                         if int(size.get('to')) <= bound), len(FREE_CLASSES))
            by_size[slot] += int(size.get('total'))
        unsorted = sum(int(u.get('total')) for u in heap.iter('unsorted'))
        totals = {t.get('type'): int(t.get('size')) for t in heap.findall('total')}
        system = {t.get('type'): int(t.get('size')) for t in heap.findall('system')}
        free = totals.get('fast', 0) + totals.get('rest', 0)
        arenas.append({'nr': int(heap.get('nr')),
                       'system_mib': system.get('current', 0) / 2 ** 20,
                       'free_mib': free / 2 ** 20,
                       'free_by_size_mib': [b / 2 ** 20 for b in by_size],
                       'unsorted_mib': unsorted / 2 ** 20,
                       'top_mib': (free - sum(by_size) - unsorted) / 2 ** 20})
    return arenas


def _heap_log(node):
    path = os.environ.get('FPC_SOAK_HEAP_LOG')
    if path:
        node.soak_heap_log = HeapLog(node, path, HEAP_LOG_PERIOD_S)
    return node


#: The nodes run as their own executables run them (their `main`), with a heap log.
PLAIN = {'model_node': ModelNode, 'gripper_controller': GripperController,
         'mcap_recorder': McapRecorder,
         'virtual_object': functools.partial(VirtualObjectNode, 'virtual_object')}


def _gripper_with_hook():
    nodes = compose(record=True, virtual_object=True)
    for node in nodes:
        if isinstance(node, RegulatorBridge):
            node.soak_fault_hook = FaultHook(node)
            _heap_log(node)
    return nodes


def _bridge_with_hook():
    node = RegulatorBridge(auto_activate_default=True)
    node.soak_fault_hook = FaultHook(node)
    _heap_log(node)
    return node


def main(argv=None):
    """Run the node named by the first argument until SIGINT or SIGTERM."""
    argv = sys.argv if argv is None else argv
    kind = argv[1] if len(argv) > 1 else ''
    if kind == 'regulator_bridge':
        # The same exit-code check as the package's regulator_bridge main.
        return run_node(_bridge_with_hook, 'regulator_bridge', argv,
                        check=activation_exit_code)
    if kind == 'gripper':
        return run_node(_gripper_with_hook, 'gripper', argv, check=bridge_exit_code)
    if kind in PLAIN:
        return run_node(lambda: _heap_log(PLAIN[kind]()), kind, argv)
    print(f'usage: soak_nodes.py {{{"|".join(("regulator_bridge", "gripper", *PLAIN))}}} '
          '[--ros-args ...]', file=sys.stderr)
    return 2


def _traced(run):
    """Run `run` under memray's native tracker where FPC_SOAK_MEMRAY names its output."""
    path = os.environ.get('FPC_SOAK_MEMRAY')
    if not path:
        return run()
    # Imported only here: memray is a profiling tool, not a dependency of the package.
    import memray
    with memray.Tracker(path, native_traces=True):
        return run()


if __name__ == '__main__':
    sys.exit(_traced(main))
