"""A logged, slowed sweep chunk for the Dask tests: which worker ran what, and when."""

import os
import time

from fpc_gripper.design.parametric import solve_designs


def logged_chunk(log, index, hold, *chunk):
    """Run `solve_designs(*chunk)`, logging start and end with this process's PID."""
    with open(log, 'a') as out:
        out.write(f'start {index} {os.getpid()}\n')
    result = solve_designs(*chunk)
    # Long enough for the test to kill a worker while it holds this chunk.
    time.sleep(hold)
    with open(log, 'a') as out:
        out.write(f'end {index} {os.getpid()}\n')
    return result


def read_log(log):
    """Return [(event, chunk, pid)] of a log."""
    if not os.path.exists(log):
        return []
    with open(log) as lines:
        return [(e, int(k), int(p)) for e, k, p in (line.split() for line in lines)]
