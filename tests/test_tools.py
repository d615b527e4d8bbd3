"""What every command-line tool shares: the exit-code table, --version, outputs, progress."""

import io

import pytest

from fpc_gripper.calibration.cli import _parser as calibrate_parser
from fpc_gripper.design.cli import build_parser as design_parser
from fpc_gripper.grasp.cli import build_parser as grasp_parser
from fpc_gripper.io.cli import build_parser as mcap_parser
from fpc_gripper.progress import Progress
from fpc_gripper.tools import EXIT_CODES, FAILED_MARKER, InputError, OUTPUT_MARKER, OutputDir

TOOLS = {
    'fpc-mcap': (mcap_parser, ['info', 'plot', 'export-csv', 'recover', 'replay-model']),
    'fpc-calibrate': (calibrate_parser, []),
    'fpc-grasp': (grasp_parser, []),
    'fpc-design': (design_parser, ['sweep', 'optimize']),
}
HELPS = [(tool, command) for tool, (_, commands) in TOOLS.items()
         for command in [None] + commands]


def _exit(parser, argv, capsys):
    with pytest.raises(SystemExit) as stop:
        parser.parse_args(argv)
    return stop.value.code, capsys.readouterr().out


@pytest.mark.parametrize('tool, command', HELPS, ids=lambda v: str(v))
def test_every_help_ends_with_the_one_exit_code_table(tool, command, capsys):
    code, out = _exit(TOOLS[tool][0](), ([command] if command else []) + ['--help'], capsys)
    assert code == 0
    for line in ('  0    the job was done', '  1    the job ran but produced nothing usable',
                 '  2    bad usage or bad input, found before any work'):
        assert line in out
    assert out.rstrip().endswith(EXIT_CODES.splitlines()[-1])


@pytest.mark.parametrize('tool, command', HELPS, ids=lambda v: str(v))
def test_every_tool_prints_its_version_and_the_engine_build(tool, command, capsys):
    code, out = _exit(TOOLS[tool][0](), ([command] if command else []) + ['--version'],
                      capsys)
    assert code == 0
    assert out.startswith(f'{tool} (fpc_gripper) 0.') and 'engine built' in out
    assert out.rstrip().endswith('(current)')


def test_the_readme_carries_the_table():
    import pathlib
    readme = (pathlib.Path(__file__).resolve().parents[1] / 'README.md').read_text()
    assert EXIT_CODES in readme


def _files(path):
    return sorted(p.name for p in path.iterdir())


def _earlier_output(path, *names):
    path.mkdir()
    (path / OUTPUT_MARKER).write_text('')
    for name in names:
        (path / name).write_text('earlier')


def test_an_output_directory_is_written_whole(tmp_path):
    target = tmp_path / 'deep' / 'out'
    with OutputDir(target) as out:
        (out.tmp / 'a.csv').write_text('new')
        assert not target.exists()
        assert out.commit() == []
    assert _files(target) == [OUTPUT_MARKER, 'a.csv'] and _files(target.parent) == ['out']


def test_existing_outputs_need_force_and_are_replaced_not_merged(tmp_path):
    _earlier_output(tmp_path / 'out', 'old.yaml')
    with pytest.raises(InputError, match='--out .*already holds outputs; pass --force'):
        OutputDir(tmp_path / 'out').check()
    with OutputDir(tmp_path / 'out', force=True) as out:
        (out.tmp / 'new.csv').write_text('new')
        assert out.commit() == ['old.yaml']
    assert _files(tmp_path / 'out') == [OUTPUT_MARKER, 'new.csv'] and _files(tmp_path) == ['out']


def test_force_never_replaces_a_directory_no_tool_wrote(tmp_path, monkeypatch):
    (tmp_path / 'home').mkdir()
    (tmp_path / 'home' / 'thesis.tex').write_text('precious')
    with pytest.raises(InputError, match='holds files that no fpc tool wrote'):
        OutputDir(tmp_path / 'home', force=True).check()
    monkeypatch.chdir(tmp_path / 'home')
    for path in ('.', '..'):
        with pytest.raises(InputError, match='the working directory or above it'):
            OutputDir(path, force=True).check()
    assert _files(tmp_path / 'home') == ['thesis.tex']


def test_a_file_is_not_an_output_directory(tmp_path):
    (tmp_path / 'f').write_text('x')
    with pytest.raises(InputError, match='exists and is not a directory'):
        OutputDir(tmp_path / 'f', force=True).check()


def test_a_crash_leaves_the_earlier_outputs_and_says_so(tmp_path):
    _earlier_output(tmp_path / 'out', 'old.yaml')
    with pytest.raises(RuntimeError) as error:
        with OutputDir(tmp_path / 'out', force=True) as out:
            (out.tmp / 'half.csv').write_text('half')
            raise RuntimeError('solver broke')
    assert "unchanged (it holds an earlier run's outputs)" in error.value.__notes__[0]
    assert _files(tmp_path) == ['out'] and _files(tmp_path / 'out') == [OUTPUT_MARKER, 'old.yaml']


def test_a_failed_run_is_marked_and_replaces_an_earlier_success(tmp_path):
    _earlier_output(tmp_path / 'out', 'actuator.yaml')
    with OutputDir(tmp_path / 'out', force=True) as out:
        (out.tmp / 'report.json').write_text('{}')
        out.commit(failed='the fit did not converge')
    assert _files(tmp_path / 'out') == [OUTPUT_MARKER, FAILED_MARKER, 'report.json']
    assert 'the fit did not converge' in (tmp_path / 'out' / FAILED_MARKER).read_text()


class _Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_progress_off_a_terminal_is_a_line_every_few_seconds():
    stream, clock = io.StringIO(), _Clock()
    with Progress(10, 'row', 'tool', stream=stream, period=5.0, clock=clock) as progress:
        for k in range(10):
            clock.now += 0.75       # 7.5 s in all: lines at 1.5 s and 6.75 s, and the end
            progress.update()
    lines = stream.getvalue().splitlines()
    assert lines[0].startswith('tool: 2/10 rows (20 %)')
    assert lines[1].startswith('tool: 9/10 rows (90 %)')
    assert lines[-1].startswith('tool: 10/10 rows (100 %)') and len(lines) == 3


def test_a_short_job_or_no_progress_prints_nothing():
    for show, step in ((None, 0.05), (False, 10.0)):
        stream, clock = io.StringIO(), _Clock()
        with Progress(10, 'row', stream=stream, show=show, clock=clock) as progress:
            for k in range(10):
                clock.now += step
                progress(k + 1, 10)
        assert stream.getvalue() == ''


def test_a_long_unit_off_a_terminal_still_prints_lines():
    import time
    stream, clock = io.StringIO(), _Clock()
    with Progress(1, 'figure', 'tool', stream=stream, period=5.0, clock=clock) as progress:
        clock.now += 1.5            # one unit still running after 1.5 s (on its clock)
        deadline = time.monotonic() + 30.0
        while not stream.getvalue() and time.monotonic() < deadline:
            time.sleep(0.05)        # the heartbeat thread wakes within a second
        assert stream.getvalue().startswith('tool: 0/1 figures (0 %), 2 s')
        progress.update()
    assert stream.getvalue().splitlines()[-1].startswith('tool: 1/1 figures (100 %)')
