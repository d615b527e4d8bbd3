"""Tests of the fixed-size sample ring (the virtual object's tip residuals), without ROS."""

import collections
import math
import tracemalloc

import numpy as np
from numpy.testing import assert_array_equal
import pytest

from fpc_gripper.services.sample_ring import SampleRing


def _feed(ring, reference, n, seed=0):
    rng = np.random.default_rng(seed)
    for i in range(n):
        value = float(rng.uniform(0.0, 1e-3))
        ring.append(0.01 * i, value)
        reference.append((0.01 * i, value))


@pytest.mark.parametrize('n', [0, 1, 7, 10, 11, 35])
def test_holds_the_newest_samples_in_order(n):
    ring, reference = SampleRing(10), collections.deque(maxlen=10)
    _feed(ring, reference, n)
    times, values = ring.samples()
    assert len(ring) == len(reference) == min(n, 10)
    assert_array_equal(times, [t for t, _ in reference])
    assert_array_equal(values, [v for _, v in reference])


def test_window_maximum_matches_a_plain_scan():
    ring, reference = SampleRing(50), collections.deque(maxlen=50)
    _feed(ring, reference, 173, seed=3)
    for start, end in [(0.0, 10.0), (1.3, 1.6), (1.5, 1.5), (1.55, 1.56), (-1.0, 0.5),
                       (1.72, 1.72), (9.0, 10.0)]:
        expected = max((v for t, v in reference if start <= t <= end), default=math.nan)
        got = ring.max_between(start, end)
        assert got == expected or (math.isnan(got) and math.isnan(expected))


def test_stays_the_same_size_after_many_times_its_capacity():
    # The soak's virtual_object grew 13 MiB while a deque(maxlen=100_000) of (t, r) tuples
    # filled. The ring's storage is fixed at construction: entries stop at the capacity,
    # the arrays keep their size, and appends allocate nothing that stays.
    ring = SampleRing(1000)
    nbytes = ring.nbytes
    ring.append(0.0, 0.0)
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for i in range(20_000):
            ring.append(float(i), float(i % 97))
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert len(ring) == 1000
    assert ring.nbytes == nbytes == 16 * 1000
    # 20,000 (t, r) tuples in a deque would hold some 2.6 MB.
    assert grown < 16 * 1024
    assert ring.max_between(0.0, 1e9) == 96.0


@pytest.mark.parametrize('capacity', [0, -1, 2.5, True, '10', None])
def test_rejects_a_capacity_that_is_not_a_positive_integer(capacity):
    with pytest.raises(ValueError, match='`capacity` must be an integer >= 1'):
        SampleRing(capacity)


def test_accepts_a_numpy_integer_capacity():
    assert SampleRing(np.int64(3)).capacity == 3
