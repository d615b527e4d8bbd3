"""run_node says what the writer-history option costs when it is set, and refuses a bad value."""

import os
import subprocess
import sys

import pytest

from fpc_gripper.io.qos import WRITER_HISTORY_ENV

# run_node with a node that stops its own process at once.
_RUN_NODE = """
import os, signal, sys
import rclpy
from fpc_gripper.nodes.runner import run_node

def build():
    node = rclpy.create_node('history_probe')
    node.create_timer(0.2, lambda: os.kill(os.getpid(), signal.SIGINT))
    return node

sys.exit(run_node(build, 'history_probe', [sys.argv[0]]))
"""


@pytest.mark.parametrize('value, code, warnings', [
    (None, 0, 0), ('0', 0, 0), ('0.5', 0, 1), ('soon', 1, 0), ('11', 1, 0)])
def test_the_option_is_named_with_its_cost_once(value, code, warnings):
    environ = {k: v for k, v in os.environ.items() if k != WRITER_HISTORY_ENV}
    if value is not None:
        environ[WRITER_HISTORY_ENV] = value
    done = subprocess.run([sys.executable, '-c', _RUN_NODE], env=environ,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == code, done.stderr
    lines = done.stderr.splitlines()
    cost = [line for line in lines if 'leak' in line and f'{WRITER_HISTORY_ENV}=' in line]
    assert len(cost) == warnings
    if warnings:
        assert '[WARN]' in cost[0] and '[history_probe]' in cost[0]
        assert 'recordings shorter than an hour' in cost[0]
    if code:
        # A value that is no number of seconds in [0, 10]: one fatal line names it.
        fatal = [line for line in lines if '[FATAL]' in line]
        assert len(fatal) == 1 and WRITER_HISTORY_ENV in fatal[0] and repr(value) in fatal[0]
        assert 'Traceback' not in done.stderr
