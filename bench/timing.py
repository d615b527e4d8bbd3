"""Timing helpers shared by the benchmarks: medians, fresh processes, numba caches, machine."""

import os
import pathlib
import platform
import statistics
import subprocess
import sys
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


def numba_cache_files(dispatcher, stem):
    """List the on-disk numba cache (index .nbi, data .nbc) of module `stem` of a kernel."""
    # numba picks __pycache__ beside the source, or a user cache dir if that is read-only.
    path = pathlib.Path(dispatcher._cache._cache_path)
    return sorted(path.glob(f'{stem}.*.nb[ic]'))


def run_process(code):
    """Wall time of a fresh interpreter running `code` [s], and the numbers it printed."""
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True, timeout=600)
    return time.perf_counter() - t0, [float(v) for v in out.stdout.split()]
