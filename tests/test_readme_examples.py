"""Every example of the README and of each tool's --help runs as written, from a clone."""

import contextlib
import io
import os
import pathlib
import re
import shlex

import pytest

from fpc_gripper.calibration.cli import _parser as calibrate_parser, main as calibrate_main
from fpc_gripper.design.cli import build_parser as design_parser, main as design_main
from fpc_gripper.grasp.cli import build_parser as grasp_parser, main as grasp_main
from fpc_gripper.io.cli import build_parser as mcap_parser, main as mcap_main

ROOT = pathlib.Path(__file__).resolve().parents[1]
#: The console scripts, run in this process (the import is the slow part of a command).
TOOLS = {'fpc-mcap': mcap_main, 'fpc-calibrate': calibrate_main, 'fpc-grasp': grasp_main,
         'fpc-design': design_main}
#: Commands that are not run here, by their first word, and why.
NOT_RUN = {
    'ros2': 'needs a ROS 2 Jazzy install (ros2cli, launch_ros); tests/test_package_layout.py',
    'colcon': 'the Jazzy install section; tests/test_package_layout.py builds with colcon',
    'cd': 'the Jazzy install section (a colcon workspace)',
    'rosdep': 'the Jazzy install section', 'source': 'shell set-up',
    'scripts/demo.sh': 'a ROS graph for a minute; tests/control/test_gripper_demo.py',
    'scripts/test.sh': 'the test suite itself',
    'scripts/isolated': 'the 30-minute soak (bench/)',
    'model_node': 'a node (runs until stopped); tests/nodes/', 'gripper': 'a node; tests/nodes/',
    'regulator_bridge': 'a node; tests/nodes/', 'mcap_recorder': 'a node; tests/io/',
}
#: Relative paths the examples name, as a clone has them.
CLONE = ('examples', 'msg_configs', 'config')


def _fenced(text, language):
    return re.findall(rf'^```{language}\n(.*?)^```', text, re.MULTILINE | re.DOTALL)


def _commands(block):
    """Shell commands of a block: continuations joined, comments dropped."""
    joined = re.sub(r'\\\n\s*', ' ', block)
    return [shlex.split(line, comments=True) for line in joined.splitlines()
            if shlex.split(line, comments=True)]


def _help_examples():
    """The example commands of every --help (indented lines that start with the tool)."""
    out = []
    parsers = {'fpc-mcap': mcap_parser, 'fpc-calibrate': calibrate_parser,
               'fpc-grasp': grasp_parser, 'fpc-design': design_parser}
    for tool, build in parsers.items():
        epilogs = [build().epilog or '']
        for action in build()._actions:
            if hasattr(action, 'choices') and isinstance(action.choices, dict):
                epilogs += [sub.epilog or '' for sub in action.choices.values()]
        for epilog in epilogs:
            joined = re.sub(r'\\\n\s*', ' ', epilog)
            out += [shlex.split(line) for line in joined.splitlines()
                    if line.startswith(f'  {tool} ')]
    return out


README = (ROOT / 'README.md').read_text()
BLOCKS = [_commands(b) for b in _fenced(README, 'bash')]
HELP = _help_examples()
#: The README's blocks in order (a block's commands share a directory), then each --help
#: example the README does not show already.
CASES = [[c for c in block if c[0] in TOOLS] for block in BLOCKS]
CASES = [block for block in CASES if block]
_shown = {tuple(c) for block in CASES for c in block}
CASES += [[c] for k, c in enumerate(HELP) if tuple(c) not in _shown and c not in HELP[:k]]
PYTHON = _fenced(README, 'python')


@pytest.fixture
def clone(tmp_path, monkeypatch):
    """A working directory that looks like the clone's root (its data linked, not copied)."""
    for name in CLONE:
        (tmp_path / name).symlink_to(ROOT / name)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv('MPLBACKEND', 'Agg')
    return tmp_path


def test_every_readme_command_is_run_or_said_why_not():
    commands = [c for block in BLOCKS for c in block]
    unknown = [' '.join(c) for c in commands if c[0] not in TOOLS and c[0] not in NOT_RUN]
    assert unknown == []
    assert sum(c[0] in TOOLS for c in commands) >= 10
    assert {c[0] for c in HELP} == set(TOOLS)


@pytest.mark.parametrize('block', CASES, ids=lambda b: ' '.join(b[0][:3])[:60])
def test_the_command_runs_as_written(block, clone):
    for argv in block:
        err = io.StringIO()
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
            try:
                code = TOOLS[argv[0]](argv[1:])
            except SystemExit as stop:      # --version and --help exit through argparse
                code = stop.code
        assert code == 0, f'{shlex.join(argv)} exited {code}: {err.getvalue()[-2000:]}'
        assert 'Traceback' not in err.getvalue()


@pytest.mark.parametrize('code', PYTHON, ids=lambda c: c.splitlines()[0][:60])
def test_the_python_example_runs_as_written(code, clone):
    with contextlib.redirect_stdout(io.StringIO()):
        exec(compile(code, 'README.md', 'exec'), {'__name__': '__readme__'})


def test_the_clone_fixture_is_a_fresh_directory(clone):
    assert sorted(os.listdir(clone)) == sorted(CLONE)
