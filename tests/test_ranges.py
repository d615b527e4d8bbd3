"""The one value-list syntax: lists, stepped and counted ranges, the old form refused."""

import numpy as np
import pytest

from fpc_gripper.ranges import MAX_COUNT, parse_range


@pytest.mark.parametrize('text, expected', [
    ('0:300e3:10e3', [10e3 * k for k in range(31)]),
    ('0:1:0.25', [0.0, 0.25, 0.5, 0.75, 1.0]),
    ('0:1:0.3', [0.0, 0.3, 0.6, 0.9]),
    ('0:1/5', [0.0, 0.25, 0.5, 0.75, 1.0]),
    ('22e-3:30e-3/5', [0.022, 0.024, 0.026, 0.028, 0.030]),
    ('2:2/1', [2.0]),
    ('0.15, 0.25,0.4', [0.15, 0.25, 0.4]),
    ('-3', [-3.0]),
])
def test_ranges(text, expected):
    np.testing.assert_allclose(parse_range(text), expected, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize('text', ['0:300e3:10', '22e-3:30e-3:5', '0:1:+2', '0:4e5:5000'])
def test_the_old_three_part_integer_form_is_refused_with_both_readings(text):
    head, count = text.rsplit(':', 1)
    with pytest.raises(ValueError) as error:
        parse_range(text, '`--pressure`')
    message = str(error.value)
    assert message.startswith('`--pressure`: cannot read') and 'ambiguous' in message
    assert f'{head}/{int(count)} for {int(count)} values' in message
    assert f'{head}:{int(count)}.0 for a step of {int(count)}' in message


def test_the_refusal_counts_what_the_step_reading_would_run():
    with pytest.raises(ValueError, match=r'\(30,001 values\)'):
        parse_range('0:300e3:10')


@pytest.mark.parametrize('text, words', [
    ('0:1', 'start:stop:step or start:stop/count'), ('0:1:0.0', '> 0'),
    ('0:1:-0.5', '> 0'), ('1:0:0.5', 'stop must be >= start'), ('0:1/0', 'count'),
    ('0:1/2.5', 'whole number'), (f'0:1/{MAX_COUNT + 1}', 'count'),
    ('0:1:1e-9', 'at most'), ('1,nan', 'finite'), ('a,b', 'not a number'), ('', 'no values'),
    ('0:inf:1.0', 'finite'), ('0:1:2:3', 'start:stop:step'),
])
def test_malformed_ranges_name_the_option(text, words):
    with pytest.raises(ValueError, match='^`--x`: cannot read') as error:
        parse_range(text, '`--x`')
    assert words in str(error.value)
