"""The one value-list syntax of every command-line tool: lists, stepped and counted ranges."""

import math
import re

import numpy as np

__all__ = ['parse_range', 'RANGE_HELP', 'MAX_COUNT']

#: Largest number of values one range may hold (a typo guard).
MAX_COUNT = 100_000
#: The syntax, for every tool's --help.
RANGE_HELP = ('Values: a,b,c (a list); start:stop:step (start, start + step, ... up to stop, '
              'stop included when a step lands on it; the step written with a decimal point '
              'or exponent, 5e3 or 10.0); start:stop/count (count values, ends included, as '
              'numpy.linspace). SI units.')
_INTEGER = re.compile(r'^[+-]?\d+$')


def _number(text, what):
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f'{what} {text.strip()!r} is not a number') from None
    if not math.isfinite(value):
        raise ValueError(f'{what} must be finite, got {text.strip()}')
    return value


def _count(text):
    if not _INTEGER.match(text.strip()):
        raise ValueError(f'the count after / must be a whole number, got {text.strip()!r}')
    count = int(text)
    if not 1 <= count <= MAX_COUNT:
        raise ValueError(f'the count must be in [1, {MAX_COUNT}], got {count}')
    return count


def _stepped(start, stop, step_text, text):
    if _INTEGER.match(step_text.strip()):
        # start:stop:<integer> was a count in fpc-design and a step in fpc-grasp.
        step = int(step_text)
        spans = math.floor((stop - start) / step) + 1 if step > 0 and stop >= start else 0
        head = text.rsplit(':', 1)[0]
        raise ValueError(
            'a plain integer after the second colon is ambiguous (it was a count in '
            f'fpc-design and a step in fpc-grasp); write {head}/{step} for {step} values, or '
            f'{head}:{step}.0 for a step of {step} ({spans:,} value{"s" * (spans != 1)})')
    step = _number(step_text, 'the step')
    if step <= 0.0:
        raise ValueError(f'the step must be > 0, got {step_text.strip()}')
    if stop < start:
        raise ValueError(f'stop must be >= start, got {text!r}')
    count = math.floor((stop - start) / step * (1.0 + 1e-12) + 1e-9) + 1
    if count > MAX_COUNT:
        raise ValueError(f'{text!r} spans {count:,} values; at most {MAX_COUNT:,} are allowed')
    return start + step * np.arange(count)


def parse_range(text, name='values'):
    """
    Parse a value list: ``a,b,c``, ``start:stop:step`` or ``start:stop/count``.

    A step is written with a decimal point or an exponent (``0:400e3:5e3``); a plain
    integer there (``0:300e3:10``) is refused, because the tools once read it as a count in
    one place and a step in another. ``start:stop/count`` gives `count` values from start
    to stop inclusive, as ``numpy.linspace``.

    Parameters
    ----------
    text : str
    name : str
        The option the text came from (``--pressure``), for messages.

    Returns
    -------
    ndarray of float
        The values, finite, in the written order.

    Raises
    ------
    ValueError
        Naming `name` and the text, for anything else.

    """
    text = str(text).strip()
    try:
        if ':' in text:
            parts = text.split(':')
            if len(parts) == 2 and '/' in parts[1]:
                stop_text, _, count_text = parts[1].partition('/')
                start, stop = _number(parts[0], 'start'), _number(stop_text, 'stop')
                values = np.linspace(start, stop, _count(count_text))
            elif len(parts) == 3:
                start, stop = _number(parts[0], 'start'), _number(parts[1], 'stop')
                values = _stepped(start, stop, parts[2], text)
            else:
                raise ValueError('a range is start:stop:step or start:stop/count')
        else:
            values = np.array([_number(v, 'value') for v in text.split(',') if v.strip()])
            if not values.size:
                raise ValueError('no values')
    except ValueError as error:
        raise ValueError(f'{name}: cannot read {text!r}: {error}') from None
    return values
