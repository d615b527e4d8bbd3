"""A writer thread for recordings: receivers only queue; it writes, compresses and syncs."""

import collections
import threading
import time

from .mcap_writer import McapWriterError

__all__ = ['BackgroundWriter', 'DEFAULT_MAX_QUEUE_BYTES']

#: Default bound of the queue [bytes] (rosbag2's default cache is 100 MiB too).
DEFAULT_MAX_QUEUE_BYTES = 100 * 1024 * 1024
# What a write or flush can raise that loses messages but must not stop the thread: the
# disk (OSError), a time out of range or a topic not added (ValueError, McapWriterError).
_WRITE_ERRORS = (OSError, ValueError, McapWriterError)


class BackgroundWriter:
    """
    Write messages to a `Rosbag2McapWriter` from a thread of its own.

    `put` only appends to a queue, so the thread that receives messages never waits for
    compression or the disk: chunk compression and the ``fsync`` of each flush (tens of
    milliseconds on a loaded disk) stalled the recorder's executor, and its subscription
    queues overflowed meanwhile. The thread writes every queued message in order, and
    every ``flush_period_s / 2`` flushes the open chunk and syncs the file, so a
    ``kill -9`` loses at most the last `flush_period_s` of messages, as before.

    The queue is bounded in bytes: a message that would take it past `max_queue_bytes`
    (when the disk cannot keep up for long) is dropped and counted in `dropped`, never
    blocking the caller, as rosbag2 drops when its cache is full. A failed write or flush
    is counted in `errors` and passed to `on_error`; the thread goes on.

    Parameters
    ----------
    writer : Rosbag2McapWriter
        The recording; `close` closes it.
    flush_period_s : float
        Longest time a queued message waits before it is in a completed chunk on disk
        [s]; see `flush_period_s`.
    max_queue_bytes : int
        Bound of the payload bytes waiting in the queue [bytes].
    on_error : callable, optional
        ``on_error(exception)``, called from the writer thread for each failed write or
        flush (the recorder logs it).
    clock : callable
        Monotonic seconds.

    """

    def __init__(self, writer, *, flush_period_s=1.0, max_queue_bytes=DEFAULT_MAX_QUEUE_BYTES,
                 on_error=None, clock=time.monotonic):
        if not max_queue_bytes > 0:
            raise ValueError(f'`max_queue_bytes` must be > 0 [bytes], got {max_queue_bytes!r}')
        self._writer = writer
        self._max_bytes = int(max_queue_bytes)
        self._on_error = on_error
        self._clock = clock
        self._queue = collections.deque()
        self._bytes = 0
        self._closing = False
        self._failure = None
        self._cond = threading.Condition()
        self._half_period = 0.0
        self.flush_period_s = flush_period_s
        self.written = 0
        self.dropped = 0
        self.errors = 0
        self._thread = threading.Thread(target=self._run, name='fpc_gripper-mcap-writer',
                                        daemon=True)
        self._thread.start()

    @property
    def flush_period_s(self):
        """Longest wait of a message before it is in a completed chunk on disk [s]."""
        return 2.0 * self._half_period

    @flush_period_s.setter
    def flush_period_s(self, value):
        if not value > 0.0:
            raise ValueError(f'`flush_period_s` must be > 0 [s], got {value!r}')
        with self._cond:
            self._half_period = 0.5 * float(value)
            self._cond.notify()

    @property
    def writer(self):
        """The `Rosbag2McapWriter`."""
        return self._writer

    @property
    def queued(self):
        """Messages waiting for the thread."""
        return len(self._queue)

    @property
    def queued_bytes(self):
        """Payload bytes waiting for the thread [bytes]."""
        return self._bytes

    def put(self, topic, data, log_time, publish_time):
        """
        Queue one serialised message for `Rosbag2McapWriter.write`.

        Returns
        -------
        bool
            False if the queue was full and the message was dropped (counted).

        Raises
        ------
        McapWriterError
            After `close`, or once the thread failed (naming the failure).

        """
        size = len(data)
        with self._cond:
            if self._closing:
                raise McapWriterError(
                    'the writer is closed' if self._failure is None else
                    f'the writer thread failed: {type(self._failure).__name__}: '
                    f'{self._failure}')
            # Bytes count until written, so the bound holds the batch being written too;
            # a message larger than the bound still goes through an idle writer.
            if self._bytes and self._bytes + size > self._max_bytes:
                self.dropped += 1
                return False
            self._queue.append((topic, data, log_time, publish_time))
            self._bytes += size
            self._cond.notify()
        return True

    def close(self):
        """Write everything queued, stop the thread, then close the writer (idempotent)."""
        with self._cond:
            self._closing = True
            self._cond.notify()
        self._thread.join()
        self._writer.close()

    def _run(self):
        try:
            self._loop()
        except Exception as error:
            # A bug, not the disk: `put` says so from now on instead of queueing in vain.
            with self._cond:
                self._failure = error
                self._closing = True
            self._failed(error)

    def _loop(self):
        next_flush = self._clock() + self._half_period
        while True:
            with self._cond:
                while not self._queue and not self._closing:
                    wait = next_flush - self._clock()
                    if wait <= 0.0:
                        break
                    self._cond.wait(wait)
                batch, self._queue = self._queue, collections.deque()
                closing = self._closing
            done = 0
            for item in batch:
                try:
                    self._writer.write(*item)
                    self.written += 1
                except _WRITE_ERRORS as error:
                    self._failed(error)
                done += len(item[1])
            with self._cond:
                self._bytes -= done
            if closing:
                return
            if self._clock() >= next_flush:
                if self._writer.pending_count:
                    try:
                        self._writer.flush()
                    except _WRITE_ERRORS as error:
                        self._failed(error)
                next_flush = self._clock() + self._half_period

    def _failed(self, error):
        self.errors += 1
        if self._on_error is not None:
            self._on_error(error)
