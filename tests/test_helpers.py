"""The shared test helpers that tests lean on for their verdicts: goals sent until answered."""

from helpers import send_goal
import pytest


class _Future:
    def __init__(self, answered):
        self.answered = answered

    def done(self):
        return self.answered

    def result(self):
        return 'handle'


class _Client:
    """An action client whose first `lost` goals are never answered."""

    def __init__(self, lost):
        self.lost = lost
        self.sent = []

    def send_goal_async(self, goal, **kwargs):
        self.sent.append((goal, kwargs))
        return _Future(len(self.sent) > self.lost)


def _spin_until(condition, timeout):
    return condition()


def test_an_unanswered_goal_is_sent_again_until_answered():
    client = _Client(lost=2)
    assert send_goal(client, 'goal', _spin_until, feedback_callback=print) == 'handle'
    assert client.sent == [('goal', {'feedback_callback': print})] * 3


def test_a_server_that_never_answers_fails_after_the_attempts():
    client = _Client(lost=100)
    with pytest.raises(AssertionError, match='none of 4 goals'):
        send_goal(client, 'goal', _spin_until, attempts=4)
    assert len(client.sent) == 4
