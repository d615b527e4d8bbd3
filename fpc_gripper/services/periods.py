"""Whether a periodic output is due: never sent, its period passed, or the clock stepped back."""

__all__ = ['period_passed']


def period_passed(last, now, period_s):
    """
    Return whether an output last sent at `last` is due again at `now`.

    A node clock can step back (a simulated clock restarted, the system time set): an
    output dated after `now` is due at once, or a backwards step would silence it until
    the clock caught up.

    Parameters
    ----------
    last : float or None
        When it was last sent [s]; None if never.
    now : float
        The same clock [s].
    period_s : float
        Least time between two sends [s].

    """
    return last is None or not 0.0 <= now - last < period_s
