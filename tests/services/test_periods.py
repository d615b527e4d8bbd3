"""Whether a periodic output is due, against a plain reading of its rule."""

import pytest

from fpc_gripper.services.periods import period_passed


@pytest.mark.parametrize('last, now, due', [
    (None, 0.0, True),          # never sent
    (1.0, 1.5, False),          # inside the period
    (1.0, 2.0, True),           # exactly one period later
    (1.0, 7.0, True),           # long after
    (10.0, 3.0, True),          # the clock stepped back
    (1.0, 1.0, False),          # the same instant
])
def test_an_output_is_due_when_never_sent_late_or_dated_after_now(last, now, due):
    assert period_passed(last, now, 1.0) is due
