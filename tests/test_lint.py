"""House style as ament_lint checks it: flake8 (setup.cfg) and pep257 with D213."""

import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
TARGETS = ['fpc_gripper', 'tests', 'bench', 'scripts', 'launch', 'setup.py']
# ament_pep257's default ignores, with the summary on the second line (D213).
PEP257_IGNORE = 'D100,D101,D102,D103,D104,D105,D106,D107,D203,D212,D404'


# One flake8 job: its default takes every core for seconds, which starves the closed-loop
# tests running beside it on the other worker.
@pytest.mark.parametrize('command', [
    [sys.executable, '-m', 'flake8', '--jobs=1', *TARGETS],
    [sys.executable, '-m', 'pydocstyle', '--add-select=D213', f'--add-ignore={PEP257_IGNORE}',
     *TARGETS],
], ids=['flake8', 'pep257'])
def test_style(command):
    out = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
