"""What a recording received, lost, dropped and failed to write, and what those counts say."""

import dataclasses
import enum

__all__ = ['Health', 'HealthReport', 'RecordingCounts']


class Health(enum.Enum):
    """What the counts of a recording say since its last report, the worst first."""

    WRITES_FAILED = 'writes failed'
    QUEUE_FULL = 'queue full'
    MESSAGES_LOST = 'messages lost'
    INVALID_STAMPS = 'invalid stamps'
    RECORDING = 'recording'


@dataclasses.dataclass(frozen=True)
class HealthReport:
    """
    A recording's health since its last report.

    Attributes
    ----------
    health : Health
    message : str
        The status in words.
    log : str or None
        A line worth logging (failed writes, a full queue), with the totals.

    """

    health: Health
    message: str
    log: str = None


class RecordingCounts:
    """
    Per topic and in all: messages received, lost and dropped, invalid stamps, failed writes.

    Lost messages never reached the recorder: the middleware counts them (its
    message-lost event), as when a reliable publisher's keep-last history moved on
    before the recorder's reader had them, or a best-effort sample did not arrive.
    The counts of the writer thread (messages written, dropped because the queue was
    full, failed writes) are the `BackgroundWriter`'s, passed in where they are needed.

    Attributes
    ----------
    topics : dict of str to list of int
        Per topic: [messages received, of them dropped because the queue was full,
        messages lost before the recorder].
    invalid_stamps : int
        Messages whose header stamp is not a valid time.
    refused : int
        Messages the writer refused (it was closed or its thread had failed).
    last_error : str or None
        The newest failed write, for the diagnostics.

    """

    def __init__(self):
        self.topics = {}
        self.invalid_stamps = 0
        self.refused = 0
        self.last_error = None
        self._reported = (0, 0, 0, 0)

    @property
    def received(self):
        """Messages received so far, over every topic."""
        return sum(counts[0] for counts in self.topics.values())

    @property
    def lost(self):
        """Messages lost before the recorder so far, over every topic."""
        return sum(counts[2] for counts in self.topics.values())

    def add_topic(self, topic):
        """Start counting a topic (a topic counted already keeps its counts)."""
        self.topics.setdefault(topic, [0, 0, 0])

    def count(self, topic, dropped=False):
        """Count a message of `topic` received; `dropped` if the full queue dropped it."""
        counts = self.topics[topic]
        counts[0] += 1
        counts[1] += bool(dropped)

    def lose(self, topic, count):
        """Count `count` messages of `topic` that the middleware lost before the recorder."""
        self.topics[topic][2] += count

    def write_failed(self, error):
        """Keep a failed write's exception for the diagnostics (called from the writer thread)."""
        self.last_error = f'{type(error).__name__}: {error}'

    def refuse(self, error):
        """Count a message the writer refused with `error`."""
        self.refused += 1
        self.write_failed(error)

    def _totals(self, background):
        return (background.dropped, self.lost, self.invalid_stamps,
                background.errors + self.refused)

    def report(self, background):
        """
        Return the health since the last report: what went wrong first, worst first.

        Parameters
        ----------
        background : BackgroundWriter
            Its ``dropped`` and ``errors`` counts are read.

        Returns
        -------
        HealthReport

        """
        totals = self._totals(background)
        dropped, lost, invalid, errors = (
            now - before for now, before in zip(totals, self._reported))
        self._reported = totals
        if errors:
            message = f'{errors} writes failed: {self.last_error}'
            return HealthReport(Health.WRITES_FAILED, message,
                                f'{message} ({totals[3]} lost so far)')
        if dropped:
            message = f'{dropped} messages dropped: queue full'
            return HealthReport(Health.QUEUE_FULL, message,
                                f'{message} ({totals[0]} so far; raise max_queue_mb)')
        if lost:
            message = f'{lost} messages lost before the recorder (counted by the middleware)'
            return HealthReport(Health.MESSAGES_LOST, message,
                                f'{message} ({totals[1]} so far; a publisher with keep-last '
                                'history moved on, or best-effort samples did not arrive)')
        if invalid:
            return HealthReport(Health.INVALID_STAMPS, f'{invalid} header stamps not a valid '
                                                       'time (publish time = log time)')
        return HealthReport(Health.RECORDING, 'recording')

    def values(self, path, background):
        """
        Return the diagnostics key/values of the recording to `path`.

        The totals are those of the last `report`; then one line per topic.
        """
        dropped, lost, invalid, failed = self._reported
        values = {'file': str(path), 'messages received': self.received,
                  'messages written': background.written,
                  'queued': background.queued, 'queued bytes': background.queued_bytes,
                  'dropped (queue full)': dropped, 'lost before the recorder': lost,
                  'invalid stamps': invalid, 'failed writes': failed,
                  'topics': len(self.topics)}
        for topic, (received, full, lost) in self.topics.items():
            values[topic] = (f'received {received}, dropped {full} (queue full), '
                             f'lost {lost} before the recorder')
        return {key: str(value) for key, value in values.items()}

    def summary(self, paths, written, dropped):
        """
        Return the line that ends a recording.

        Parameters
        ----------
        paths : sequence of path
            The files written.
        written : int
            Messages in them.
        dropped : int
            Messages the full queue dropped.

        """
        received = self.received
        # Whatever was received and neither written nor refused by the full queue failed
        # (a write error, or a put after the writer thread died).
        failed = received - written - dropped
        return (f'closed {", ".join(str(p) for p in paths)}: received {received}, written '
                f'{written}, dropped {dropped + failed} ({dropped} queue full, {failed} failed '
                f'writes); {self.lost} lost before the recorder (counted by the middleware); '
                f'{self.invalid_stamps} invalid header stamps')
