"""Progress of a long job on stderr: a bar on a terminal, a line every few seconds otherwise."""

import sys
import threading
import time

__all__ = ['Progress', 'DELAY_S', 'LINE_PERIOD_S']

#: Nothing is shown for a job shorter than this [s].
DELAY_S = 1.0
#: Period of the plain lines when stderr is not a terminal [s].
LINE_PERIOD_S = 5.0


class Progress:
    """
    Count a job's units; show them on stderr once the job has taken a second.

    On a terminal this is a tqdm bar (cleared at the end); otherwise (a pipe, a log
    file) one line ``label: done/total unit (p %), t s`` every `period` seconds and one
    at the end, so that a slow job is never silent: a heartbeat thread prints the line
    even while one long unit runs (`heartbeat`). ``show=False`` shows nothing.
    Use as a context manager; `update` adds done units, and it is a callable
    ``progress(done, total)`` for cores that report absolute counts.

    Parameters
    ----------
    total : int
        Units of the whole job.
    unit : str
    label : str
        What runs (the tool and command), at the start of every line.
    show : bool, optional
        None: a bar on a terminal, lines otherwise; True: the same; False: nothing.
    stream : file, optional
        Default sys.stderr.
    period : float
        Seconds between lines when not on a terminal.
    clock : callable
        Monotonic seconds (injectable for tests).
    heartbeat : bool
        Also show progress from a thread while one long unit runs.

    """

    def __init__(self, total, unit='item', label='', show=None, stream=None,
                 period=LINE_PERIOD_S, clock=time.monotonic, heartbeat=True):
        self.total = int(total)
        self.unit = unit
        self.label = label
        self.stream = sys.stderr if stream is None else stream
        self.period = float(period)
        self.clock = clock
        self.done = 0
        self._bar = None
        self._lines = False
        self._printed = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = None
        self._start = clock()
        self._next = self._start + DELAY_S
        if show is False:
            return
        isatty = getattr(self.stream, 'isatty', None)
        if isatty is not None and isatty():
            from tqdm.auto import tqdm
            self._bar = tqdm(total=self.total, unit=unit, delay=DELAY_S, leave=False,
                             file=self.stream, desc=label or None)
        else:
            self._lines = True
        if heartbeat:
            self._thread = threading.Thread(target=self._beat, daemon=True,
                                            name='progress-heartbeat')
            self._thread.start()

    def _beat(self):
        """While a long unit runs: redraw the bar, or print the line once a period passed."""
        wait = DELAY_S
        while not self._stop.wait(wait):
            with self._lock:
                if self._bar is not None:
                    self._bar.update(0)     # shows the bar after its delay, and the time
                    wait = 0.5
                    continue
                if self._lines and self.clock() >= self._next:
                    self._line()
                    self._next = self.clock() + self.period
                wait = max(0.05, self._next - self.clock())

    def __enter__(self):
        """Return the counter."""
        return self

    def __exit__(self, *exc):
        """Close the bar, or print the final line if any line was printed."""
        self.close()
        return False

    def __call__(self, done, total=None, final=False):
        """Set the done units (and the total, when it changed); `final` is for closers."""
        if total is not None and int(total) != self.total:
            self.total = int(total)
            if self._bar is not None:
                self._bar.total = self.total
        self.update(int(done) - self.done)

    def update(self, count=1):
        """Add `count` done units."""
        with self._lock:
            self.done += int(count)
            if self._bar is not None:
                self._bar.update(count)
            elif self._lines and self.clock() >= self._next:
                self._line()
                self._next = self.clock() + self.period

    def _line(self):
        percent = 100.0 * self.done / self.total if self.total else 100.0
        prefix = f'{self.label}: ' if self.label else ''
        print(f'{prefix}{self.done}/{self.total} {self.unit}s ({percent:.0f} %), '
              f'{self.clock() - self._start:.0f} s', file=self.stream, flush=True)
        self._printed = True

    def close(self):
        """End the display: clear the bar, or a last line after earlier ones."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        elif self._lines and self._printed:
            self._line()
            self._lines = False
