"""Give the allocator's free pages back to the system on a steady timer (glibc's malloc_trim)."""

import ctypes
import time

from rclpy.clock import Clock
from rclpy.clock import ClockType

__all__ = ['HeapTrim', 'TRIM_PERIOD_S', 'malloc_trim']

#: Time between two trims [s] (steady time, also under use_sim_time).
TRIM_PERIOD_S = 30.0


def malloc_trim():
    """Return glibc's ``malloc_trim``, or None where the C library has none."""
    try:
        function = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):
        return None
    function.argtypes = (ctypes.c_size_t,)
    function.restype = ctypes.c_int
    return function


class HeapTrim:
    """
    Call ``malloc_trim(0)`` every `period_s` on a steady timer of `node` (its executor).

    glibc returns a free block's pages to the system only at the top of a heap: the free
    blocks between blocks in use keep their pages for good, and as the blocks in use
    move, more pages are touched. In the soak the composed gripper's RSS grew in lasting
    steps of 0.3-1.3 MiB (6-8 MiB an hour) while the bytes it had in use stayed flat.
    ``malloc_trim(0)`` gives back every whole free page of every arena (madvise), so RSS
    follows the bytes in use. It holds each arena's lock while it walks that arena: the
    executor waits for it, some milliseconds (`last_s`, `max_s`).

    Attributes
    ----------
    count : int
        Trims so far.
    last_s, max_s, total_s : float
        The last, the longest and all trims' wall time [s].
    process : dict
        The same counts (``count``, ``max_s``, ``total_s``) over every HeapTrim of the
        process (a class attribute: the trims are of the whole process's heap anyway).

    """

    process = {'count': 0, 'max_s': 0.0, 'total_s': 0.0}

    def __init__(self, node, period_s=TRIM_PERIOD_S, trim=None):
        self._trim = malloc_trim() if trim is None else trim
        self.count = 0
        self.last_s = self.max_s = self.total_s = 0.0
        self._timer = None if self._trim is None else node.create_timer(
            period_s, self.trim, clock=Clock(clock_type=ClockType.STEADY_TIME))

    @property
    def active(self):
        """Whether there is a malloc_trim to call (glibc)."""
        return self._trim is not None

    def trim(self):
        """Trim now; return whether memory was given back."""
        start = time.perf_counter()
        released = bool(self._trim(0))
        self.last_s = time.perf_counter() - start
        self.count += 1
        self.total_s += self.last_s
        self.max_s = max(self.max_s, self.last_s)
        totals = HeapTrim.process
        totals['count'] += 1
        totals['total_s'] += self.last_s
        totals['max_s'] = max(totals['max_s'], self.last_s)
        return released
