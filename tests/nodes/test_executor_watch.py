"""The executor watch: a node says when its timers run late, and when they run again."""

import json
import os
import subprocess
import sys

import pytest

from fpc_gripper.nodes.executor_watch import BEAT_PERIOD_S
from fpc_gripper.nodes.executor_watch import BEHIND_AFTER_S
from fpc_gripper.nodes.executor_watch import Lag
from fpc_gripper.nodes.runner import EXECUTOR_ENV


def test_beats_on_time_start_no_episode():
    lag = Lag(0.5, 2.0, now=100.0)
    for k in range(1, 40):
        assert lag.beat(100.0 + 0.5 * k) is None
        # Checked between beats, and just before the next one would be late by the limit.
        assert lag.check(100.0 + 0.5 * k + 0.25) is None
        assert lag.check(100.0 + 0.5 * k + 0.5 + 1.999) is None
    assert lag.episodes == 0 and lag.worst_s == 0.0 and not lag.behind


def test_a_late_beat_starts_one_episode_and_its_run_ends_it():
    lag = Lag(0.5, 2.0, now=10.0)
    assert lag.check(12.49) is None                      # 1.99 s late
    line = lag.check(12.5)                               # 2.0 s late: behind
    assert line.startswith('executor 2.0 s behind: ') and lag.behind
    # However often it is checked, one episode says so once.
    assert [lag.check(12.5 + 0.5 * k) for k in range(1, 10)] == [None] * 9
    assert lag.episodes == 1
    end = lag.beat(17.5)                                 # ran 7.0 s late
    assert end == 'executor caught up: its timers ran 7.0 s late'
    assert not lag.behind and lag.worst_s == pytest.approx(7.0)
    # On time again: nothing; late again: a second episode.
    assert lag.beat(18.0) is None and lag.check(18.5) is None
    assert lag.check(21.0).startswith('executor 2.5 s behind') and lag.episodes == 2
    assert lag.worst_s == pytest.approx(7.0)


# run_node with a callback that holds the executor for `block` seconds, once, then a stop.
_RUN_NODE = """
import json, os, signal, sys, time
import rclpy
from fpc_gripper.nodes.runner import run_node
block = float(sys.argv[1])
seen = {}

def build():
    node = rclpy.create_node('watch_probe')
    state = {'blocked': False}

    def hold():
        if not state['blocked']:
            state['blocked'] = True
            time.sleep(block)

    def stop():
        watch = node.executor_watch
        seen.update(beats=watch.beats, episodes=watch.lag.episodes, single=watch.single)
        os.kill(os.getpid(), signal.SIGINT)
    node.create_timer(0.3, hold)
    node.create_timer(block + 2.5, stop)
    return node

code = run_node(build, 'watch_probe', [sys.argv[0]])
print(json.dumps({'code': code, **seen}))
"""


@pytest.mark.parametrize('executor', ['events', 'single'])
@pytest.mark.parametrize('block', [0.0, BEHIND_AFTER_S + 2.0 * BEAT_PERIOD_S + 1.0])
def test_run_node_warns_while_a_callback_holds_the_executor(executor, block):
    environ = {**os.environ, EXECUTOR_ENV: executor}
    done = subprocess.run([sys.executable, '-c', _RUN_NODE, str(block)], env=environ,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    assert seen['code'] == 0 and seen['single'] == (executor == 'single')
    warnings = [line for line in done.stderr.splitlines() if ' s behind: ' in line]
    caught_up = [line for line in done.stderr.splitlines() if 'executor caught up' in line]
    if block:
        # The hold ran at 0.3 s: the heartbeat was due within the period and ran after it.
        assert seen['episodes'] == 1 and len(warnings) == 1 and len(caught_up) == 1
        assert '[WARN]' in warnings[0] and '[watch_probe]' in warnings[0]
        advice = 'the machine is too slow' if executor == 'single' else \
            'FPC_GRIPPER_EXECUTOR=single'
        assert advice in warnings[0]
        late = float(caught_up[0].rsplit('ran ', 1)[1].split(' s late')[0])
        assert block - 2.0 * BEAT_PERIOD_S <= late <= block + 1.0
    else:
        assert seen['episodes'] == 0 and warnings == [] and caught_up == []
        assert seen['beats'] >= 2
