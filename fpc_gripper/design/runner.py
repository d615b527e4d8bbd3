"""Where a sweep's chunks run: in this process, or on a Dask cluster, with a progress bar."""

import contextlib
import logging
import os

from fpc_gripper.progress import Progress

__all__ = ['run_chunks', 'dask_available', 'DASK_HINT']

#: How to get the optional Dask extra.
DASK_HINT = "install the Dask extra (pip install 'fpc_gripper[dask]') to run on a cluster"


def dask_available():
    """Whether dask.distributed can be imported."""
    try:
        import dask  # noqa: F401
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def _bar(total, progress, unit):
    """Progress on stderr after a second: a bar on a terminal, else a line every 5 s."""
    return Progress(total, unit, 'fpc-design', show=progress)


def run_chunks(function, chunks, weights=None, scheduler=None, progress=None, unit='design'):
    """
    Return ``[function(*chunk) for chunk in chunks]``, locally or on Dask, in chunk order.

    Parameters
    ----------
    function : callable
        Pure: a chunk's result depends on the chunk alone, so a chunk retried after a
        worker died gives the same result, and the output has neither gaps nor
        duplicates.
    chunks : sequence of tuple
        Arguments of every call (picklable for Dask).
    weights : sequence of int, optional
        Progress units of every chunk (default 1 each).
    scheduler : str, optional
        None: this process. ``'local:N'``: a LocalCluster of N single-threaded worker
        processes on loopback, started and closed here. ``'tcp://host:port'``: the
        scheduler of an existing dask.distributed cluster (its workers must have
        fpc_gripper installed).
    progress : bool, optional
        False: no progress. Default: after a second, a bar on a terminal, a line every
        few seconds otherwise (`fpc_gripper.progress.Progress`).
    unit : str
        Progress unit.

    Returns
    -------
    list
        One result per chunk, in the order of `chunks`.

    Raises
    ------
    ValueError
        On a malformed scheduler, or one given without Dask installed (with the hint).

    """
    chunks = list(chunks)
    weights = [1] * len(chunks) if weights is None else list(weights)
    if scheduler is None:
        out = []
        with _bar(sum(weights), progress, unit) as bar:
            for chunk, weight in zip(chunks, weights):
                out.append(function(*chunk))
                bar.update(weight)
        return out
    with _client(scheduler) as (client, threads):
        return _run_dask(client, threads, function, chunks, weights, progress, unit)


def _parse(scheduler):
    text = str(scheduler)
    if text.startswith('local:'):
        try:
            workers = int(text[len('local:'):])
        except ValueError:
            workers = 0
        if workers < 1:
            raise ValueError(f"`scheduler` 'local:N' needs an integer N >= 1, got {text!r}")
        return workers
    if text.startswith(('tcp://', 'tls://', 'inproc://')):
        return None
    raise ValueError(f"`scheduler` must be 'local:N' or a scheduler address "
                     f"('tcp://host:port'), got {text!r}")


@contextlib.contextmanager
def _client(scheduler):
    """Yield (Client, numba threads per task or None) for a scheduler spec."""
    workers = _parse(scheduler)
    if not dask_available():
        raise ValueError(f'`scheduler` {scheduler!r} needs dask.distributed: {DASK_HINT}')
    from distributed import Client, LocalCluster
    if workers is None:
        with Client(str(scheduler)) as client:
            yield client, None
        return
    # Single-threaded workers; each task's compiled loops share the cores between them.
    threads = max(1, (os.cpu_count() or 1) // workers)
    # Quiet: a closing cluster logs its workers' last heartbeats as errors. Its HTTP
    # server (health, and the dashboard where bokeh is installed) takes a free port.
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                      host='127.0.0.1', dashboard_address=':0',
                      silence_logs=logging.CRITICAL) as cluster, \
            Client(cluster) as client:
        yield client, threads


def _task(function, threads, chunk):
    """Run one chunk on a worker, with its compiled loops on `threads` threads."""
    if threads is not None:
        import numba
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    return function(*chunk)


def _run_dask(client, threads, function, chunks, weights, progress, unit):
    from distributed import as_completed
    futures = [client.submit(_task, function, threads, chunk, pure=False)
               for chunk in chunks]
    index = {future.key: k for k, future in enumerate(futures)}
    out = [None] * len(chunks)
    done = [False] * len(chunks)
    with _bar(sum(weights), progress, unit) as bar:
        # Results come to this process as they finish: a worker that dies later costs
        # only the chunks it was running or holding, which the scheduler reruns.
        for future in as_completed(futures):
            k = index[future.key]
            out[k] = future.result()
            done[k] = True
            bar.update(weights[k])
            future.release()
    if not all(done):
        raise RuntimeError('a Dask sweep ended with chunks missing')
    return out
