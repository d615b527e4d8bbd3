"""A fixed-size ring of timed samples, in arrays allocated once: its memory never grows."""

import numpy as np

from fpc_gripper.model.validation import integer

__all__ = ['SampleRing']


class SampleRing:
    """
    The newest `capacity` (time, value) samples, in two float64 arrays allocated up front.

    A ``collections.deque(maxlen=n)`` of ``(t, value)`` tuples is bounded too, but each
    entry is a tuple and two floats (some 130 bytes from the allocator) made as the
    samples come: a node that keeps 100,000 of them grows by 13 MiB over the minutes it
    takes to fill, which a soak cannot tell from a leak. Here the arrays (16 bytes a
    sample) are written, never grown, from the first sample on.

    Parameters
    ----------
    capacity : int
        Samples kept; the oldest is overwritten by each one past it.

    """

    def __init__(self, capacity):
        self.capacity = integer('capacity', capacity, 1, unit='[samples]')
        # Zeros, not empty: the pages are touched now, so the footprint is there from
        # the start instead of arriving with the samples.
        self._times = np.zeros(self.capacity)
        self._values = np.zeros(self.capacity)
        self._next = 0
        self._count = 0

    def __len__(self):
        """Return the number of samples held (at most `capacity`)."""
        return self._count

    @property
    def nbytes(self):
        """Bytes of the two arrays [bytes]: fixed at construction."""
        return self._times.nbytes + self._values.nbytes

    def append(self, time, value):
        """Keep the sample (`time` [s], `value`), over the oldest when full."""
        self._times[self._next] = time
        self._values[self._next] = value
        self._next = (self._next + 1) % self.capacity
        self._count = min(self._count + 1, self.capacity)

    def samples(self):
        """Return (times, values) of the samples held, oldest first (copies)."""
        order = (np.arange(self._count) + (self._next - self._count)) % self.capacity
        return self._times[order], self._values[order]

    def max_between(self, start, end, default=np.nan):
        """Largest value of the samples with `start` <= time <= `end` [s], or `default`."""
        times = self._times[:self._count]
        picked = self._values[:self._count][(times >= start) & (times <= end)]
        return float(picked.max()) if picked.size else default
