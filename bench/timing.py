"""Timing helpers shared by the benchmarks: medians over repeats and machine facts."""

import os
import platform
import statistics
import time


def median_time(fn, repeats=50, warmup=3, min_total=0.0):
    """
    Median wall time of fn() over repeats [s].

    Parameters
    ----------
    fn : callable
        Work to time.
    repeats : int
        Timed calls.
    warmup : int
        Untimed calls first (caches, lazy imports).
    min_total : float
        Keep repeating until this much time has been spent [s].

    """
    for _ in range(warmup):
        fn()
    samples = []
    start = time.perf_counter()
    while len(samples) < repeats or time.perf_counter() - start < min_total:
        t0 = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - t0)
    return statistics.median(samples)


def machine():
    """Facts that make a timing comparable: CPU count, Python, BLAS hints."""
    import numpy
    import scipy
    return {
        'cpus': os.cpu_count(),
        'python': platform.python_version(),
        'numpy': numpy.__version__,
        'scipy': scipy.__version__,
        'machine': platform.machine(),
        'openblas_coretype': os.environ.get('OPENBLAS_CORETYPE'),
    }
