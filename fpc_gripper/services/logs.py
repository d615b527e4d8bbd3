"""Log lines of the nodes that input cannot crash: throttled per key, bounded, never raising."""

import enum
import time

__all__ = ['MAX_LOG_CHARS', 'NodeLog', 'Severity', 'bounded']

#: Longest log line or diagnostic string built from input [characters].
MAX_LOG_CHARS = 600
#: Default least time between two lines of one (severity, key) [s].
THROTTLE_S = 2.0


class Severity(enum.IntEnum):
    """Severity of a log line (the values of rcutils' LoggingSeverity)."""

    DEBUG = 10
    INFO = 20
    WARN = 30
    ERROR = 40


def bounded(text, limit=MAX_LOG_CHARS):
    """
    Return `text` cut to at most about `limit` characters, saying how much was cut.

    Parameters
    ----------
    text : object
        Anything; ``str(text)`` is used, or a placeholder when even that raises.
    limit : int
        Characters kept [characters].

    Returns
    -------
    str
        Valid UTF-8 without NUL characters (escaped): a C logger cuts a line at a NUL
        and refuses a lone surrogate, and a DDS string carries neither.

    """
    try:
        text = text if isinstance(text, str) else str(text)
    except Exception:  # noqa: B902 -- a message must come out whatever the object does
        text = f'<unprintable {type(text).__name__}>'
    if len(text) > limit:
        text = f'{text[:limit]}... ({len(text) - limit} more characters)'
    text = text.encode('utf-8', 'backslashreplace').decode('utf-8')
    return text.replace('\x00', '\\x00')


class NodeLog:
    """
    A node's log for lines whose text or rate the input decides.

    rclpy keys its logger state on the call site, and raises ValueError when one call
    site logs at two severities, or with two throttle settings: a helper that logs
    whatever severity it is given, from one line, dies the first time two kinds of
    input meet. Here each severity has its own call site, throttling is done here (per
    severity and key, not per call site), every line is `bounded`, and nothing raises:
    a line the logger refuses is counted in `dropped`.

    Parameters
    ----------
    logger : object
        ``rclpy`` logger (``node.get_logger()``) or any object with ``debug``,
        ``info``, ``warning`` and ``error`` taking one string.
    throttle_s : float
        Least time between two lines of the same severity and key [s].
    max_chars : int
        Longest line [characters].
    clock : callable
        Monotonic seconds.

    """

    def __init__(self, logger, throttle_s=THROTTLE_S, max_chars=MAX_LOG_CHARS,
                 clock=time.monotonic):
        self._logger = logger
        self.throttle_s = float(throttle_s)
        self.max_chars = int(max_chars)
        self._clock = clock
        self._last = {}
        self.dropped = 0
        self.suppressed = 0

    def debug(self, text, key=None):
        """Log at DEBUG; with a `key`, at most once per throttle period. Return whether sent."""
        return self.log(Severity.DEBUG, text, key)

    def info(self, text, key=None):
        """Log at INFO; with a `key`, at most once per throttle period. Return whether sent."""
        return self.log(Severity.INFO, text, key)

    def warning(self, text, key=None):
        """Log at WARN; with a `key`, at most once per throttle period. Return whether sent."""
        return self.log(Severity.WARN, text, key)

    def error(self, text, key=None):
        """Log at ERROR; with a `key`, at most once per throttle period. Return whether sent."""
        return self.log(Severity.ERROR, text, key)

    def log(self, severity, text, key=None):
        """
        Log one line at `severity`, throttled per (severity, key) when `key` is given.

        Parameters
        ----------
        severity : Severity
        text : object
            The line (made `bounded`).
        key : hashable, optional
            Throttling key, e.g. (finger index, kind of problem).

        Returns
        -------
        bool
            True when the line went to the logger.

        """
        try:
            severity = Severity(severity)
            if key is not None:
                now = self._clock()
                last = self._last.get((severity, key))
                if last is not None and now - last < self.throttle_s:
                    self.suppressed += 1
                    return False
                self._last[(severity, key)] = now
            self._write(severity, bounded(text, self.max_chars))
            return True
        except Exception:  # noqa: B902 -- a log line must never take the node down
            self.dropped += 1
            return False

    def _write(self, severity, line):
        # One call site per severity: rclpy refuses a second severity at a call site.
        if severity is Severity.ERROR:
            self._logger.error(line)
        elif severity is Severity.WARN:
            self._logger.warning(line)
        elif severity is Severity.INFO:
            self._logger.info(line)
        else:
            self._logger.debug(line)
