"""A recording's counts without ROS: per topic, the health they report, the closing line."""

import types

from fpc_gripper.io.recording_counts import Health
from fpc_gripper.io.recording_counts import RecordingCounts


def background(dropped=0, errors=0, written=0):
    """The BackgroundWriter counts the report reads."""
    return types.SimpleNamespace(dropped=dropped, errors=errors, written=written, queued=2,
                                 queued_bytes=300)


def test_messages_are_counted_per_topic_and_in_all():
    counts = RecordingCounts()
    counts.add_topic('/a')
    counts.add_topic('/b')
    for dropped in (False, True, False):
        counts.count('/a', dropped)
    counts.count('/b')
    counts.lose('/b', 5)
    counts.add_topic('/a')          # a topic subscribed again keeps its counts
    counts.lose('/b', 2)
    assert counts.topics == {'/a': [3, 1, 0], '/b': [1, 0, 7]}
    assert counts.received == 4
    assert counts.lost == 7


def test_the_report_says_the_worst_since_the_last_one():
    counts = RecordingCounts()
    assert counts.report(background()).health is Health.RECORDING
    counts.invalid_stamps += 2
    report = counts.report(background())
    assert report.health is Health.INVALID_STAMPS and report.log is None
    assert report.message == '2 header stamps not a valid time (publish time = log time)'
    counts.invalid_stamps += 1
    report = counts.report(background(dropped=5))
    assert report.health is Health.QUEUE_FULL
    assert report.log == '5 messages dropped: queue full (5 so far; raise max_queue_mb)'
    counts.add_topic('/a')
    counts.lose('/a', 4)
    report = counts.report(background(dropped=7))
    assert report.message == '2 messages dropped: queue full'
    counts.lose('/a', 3)
    report = counts.report(background(dropped=7))
    assert report.health is Health.MESSAGES_LOST
    assert report.message == '3 messages lost before the recorder (counted by the middleware)'
    assert report.log.startswith(f'{report.message} (7 so far; ')
    assert counts.report(background(dropped=7)).health is Health.RECORDING


def test_failed_and_refused_writes_are_an_error_naming_the_last():
    counts = RecordingCounts()
    counts.write_failed(OSError('disk full'))
    report = counts.report(background(errors=1))
    assert report.health is Health.WRITES_FAILED
    assert report.message == '1 writes failed: OSError: disk full'
    counts.refuse(RuntimeError('the writer is closed'))
    report = counts.report(background(errors=1, dropped=3))
    assert report.health is Health.WRITES_FAILED
    assert report.log == '1 writes failed: RuntimeError: the writer is closed (2 lost so far)'
    assert counts.refused == 1


def test_the_diagnostics_values_are_the_reported_totals_and_every_topic():
    counts = RecordingCounts()
    counts.add_topic('/a')
    counts.count('/a', dropped=True)
    counts.lose('/a', 6)
    counts.invalid_stamps = 1
    counts.report(background(dropped=1, errors=2, written=0))
    counts.lose('/a', 1)            # after the report: in the topic's line only
    values = counts.values('/tmp/x.mcap', background(dropped=9, written=4))
    assert values == {'file': '/tmp/x.mcap', 'messages received': '1',
                      'messages written': '4', 'queued': '2', 'queued bytes': '300',
                      'dropped (queue full)': '1', 'lost before the recorder': '6',
                      'invalid stamps': '1', 'failed writes': '2', 'topics': '1',
                      '/a': 'received 1, dropped 1 (queue full), lost 7 before the recorder'}


def test_the_closing_line_counts_what_was_neither_written_nor_dropped_as_failed():
    counts = RecordingCounts()
    counts.add_topic('/a')
    for _ in range(10):
        counts.count('/a')
    counts.lose('/a', 2)
    counts.invalid_stamps = 3
    line = counts.summary(['/tmp/x_0.mcap', '/tmp/x_1.mcap'], written=6, dropped=1)
    assert line == ('closed /tmp/x_0.mcap, /tmp/x_1.mcap: received 10, written 6, dropped 4 '
                    '(1 queue full, 3 failed writes); 2 lost before the recorder (counted by '
                    'the middleware); 3 invalid header stamps')
