"""Growth of a memray capture's live bytes over time, and the stacks that grew."""

# A node of the soak runs under memray with `--node-env NODE:FPC_SOAK_MEMRAY=PATH`
# (bench/soak_nodes.py; memray installed beside the package, not one of its dependencies).
# Then:
#   .venv/bin/python bench/memray_growth.py PATH [--start 180] [--split 0.5] [--top 8]
# prints the least-squares slope of the live bytes memray tracked (every allocator, native
# ones included) over [start, split] and [split, end] of the capture, and the stacks whose
# live bytes grew most between `start` and the last 3 % (before the process's own
# teardown). A history pool that fills to its deepest backlog grows in the first part and
# not in the second; a leak grows in both.

import argparse
import sys

import numpy as np


def live_curve(reader):
    """Return (records, live bytes at each snapshot [MiB], snapshot times [s])."""
    duration = (reader.metadata.end_time - reader.metadata.start_time).total_seconds()
    records = list(reader.get_temporal_allocation_records(merge_threads=True))
    count = 1 + max(iv.deallocated_before_snapshot or iv.allocated_before_snapshot
                    for record in records for iv in record.intervals)
    delta = np.zeros(count + 1)
    for record in records:
        for iv in record.intervals:
            delta[iv.allocated_before_snapshot] += iv.n_bytes
            if iv.deallocated_before_snapshot is not None:
                delta[iv.deallocated_before_snapshot] -= iv.n_bytes
    return records, np.cumsum(delta)[:count] / 2 ** 20, np.arange(count) * duration / count


def live_at(record, snapshot):
    """Bytes of `record`'s allocations live at `snapshot`."""
    return sum(iv.n_bytes for iv in record.intervals
               if iv.allocated_before_snapshot <= snapshot
               and (iv.deallocated_before_snapshot is None
                    or iv.deallocated_before_snapshot > snapshot))


def main(argv=None):
    """Print the slopes and the stacks that grew."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('path')
    parser.add_argument('--start', type=float, default=180.0,
                        help='first second counted (after the warm-up) [s]')
    parser.add_argument('--split', type=float, default=0.5,
                        help='fraction of the capture between the two slopes')
    parser.add_argument('--top', type=int, default=8, help='stacks shown')
    args = parser.parse_args(argv)
    from memray import FileReader  # a profiling tool: only this script needs it
    records, live, times = live_curve(FileReader(args.path))
    end = times[-1] * 0.97
    split = max(args.start, args.split * times[-1])
    print(f'{args.path}: {times[-1]:.0f} s, {len(times)} snapshots')
    for low, high in ((args.start, split), (split, end), (args.start, end)):
        inside = (times >= low) & (times <= high)
        slope = np.polyfit(times[inside], live[inside], 1)[0] * 3600.0
        print(f'  {low:5.0f}-{high:5.0f} s: {slope:+6.2f} MiB/h '
              f'(live {live[inside][0]:.1f} -> {live[inside][-1]:.1f} MiB)')
    first = int(np.searchsorted(times, args.start))
    last = int(np.searchsorted(times, end))
    grown = sorted(((live_at(r, last) - live_at(r, first), r) for r in records),
                   key=lambda item: -item[0])
    for change, record in grown[:args.top]:
        print(f'{change / 2 ** 20:+.3f} MiB')
        for function, path, line in record.hybrid_stack_trace(max_stacks=10):
            print(f'    {function[:100]}  {path.rsplit("/", 1)[-1]}:{line}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
