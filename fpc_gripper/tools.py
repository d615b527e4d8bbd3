"""What every command-line tool shares: the exit codes, error lines, --version and outputs."""

import argparse
import json
import os
import pathlib
import re
import shutil
import sys

__all__ = ['EXIT_CODES', 'EXIT_DONE', 'EXIT_FAILED', 'EXIT_INPUT', 'EXIT_SKIPPED',
           'EXIT_INTERRUPTED', 'FAILED_MARKER', 'InputError', 'JobFailed', 'OUTPUT_MARKER',
           'OutputDir',
           'add_version', 'run', 'version_text']

#: The job was done.
EXIT_DONE = 0
#: The job ran but produced nothing usable; a line says why.
EXIT_FAILED = 1
#: Bad usage or bad input, found before any work (argparse's own code for usage).
EXIT_INPUT = 2
#: fpc-mcap: done, but skipped messages it could not decode (each named on stderr).
EXIT_SKIPPED = 3
#: Stopped by Ctrl-C.
EXIT_INTERRUPTED = 130
#: The table every tool prints in its --help, and the README repeats.
EXIT_CODES = """\
exit status (the same for every fpc tool):
  0    the job was done
  1    the job ran but produced nothing usable (a line says why)
  2    bad usage or bad input, found before any work (one line names the option)
  3    done, but some input messages could not be decoded and were skipped
       (fpc-mcap; each is named on stderr)
  130  interrupted (Ctrl-C)"""
#: The file a failed run leaves in its output directory, saying why.
FAILED_MARKER = 'FAILED.txt'
#: The file that marks a directory as a tool's output: only such a one is replaced.
OUTPUT_MARKER = '.fpc_gripper_output'
#: Errors of bad input when raised before the job starts, or of a failed job after.
_ERRORS = (ValueError, TypeError, OSError, RuntimeError, ArithmeticError)


class InputError(ValueError):
    """Bad usage or bad input: exit 2, wherever it is found."""


class JobFailed(RuntimeError):
    """The job ran but produced nothing usable: exit 1."""


def version_text(prog):
    """Return ``prog``'s version line: the package version and the compiled engine's build."""
    from importlib import metadata
    try:
        package = metadata.version('fpc_gripper')
    except metadata.PackageNotFoundError:
        package = 'unknown (not installed)'
    from .model import compiled
    try:
        manifest = json.loads((compiled.BUILD_DIR / 'manifest.json').read_text())
    except (OSError, ValueError):
        manifest = {}
    usable, reason = compiled.build_status()
    engine = (f"engine built {manifest.get('built', '?')}, sources "
              f"{str(manifest.get('sources', '?'))[:12]}, numba {manifest.get('numba', '?')}"
              if manifest else 'engine not built')
    state = 'current' if usable else f'not usable: {reason}'
    return f'{prog} (fpc_gripper) {package}; {engine} ({state})'


class _Version(argparse.Action):
    """--version: print `version_text` and exit 0 (computed only when asked)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS,
                 **kwargs):
        kwargs.setdefault('help', 'print the package version and the compiled engine '
                                  'build, and exit')
        super().__init__(option_strings, dest=dest, default=default, nargs=0, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        print(version_text(parser.prog.split()[0]))
        parser.exit(EXIT_DONE)


def add_version(parser):
    """Give `parser` ``--version`` and the exit-code table at the end of its help."""
    parser.add_argument('--version', action=_Version)
    epilog = parser.epilog or ''
    parser.epilog = (epilog.rstrip('\n') + '\n\n' if epilog else '') + EXIT_CODES
    if parser.formatter_class is argparse.HelpFormatter:
        parser.formatter_class = argparse.RawDescriptionHelpFormatter
    return parser


def _one_line_errors(parser):
    """Make argparse's usage errors one line (no usage dump), here and in subcommands."""
    def error(message, parser=parser):
        parser.exit(EXIT_INPUT, f'{parser.prog}: error: {message} (see --help)\n')
    parser.error = error
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                _one_line_errors(sub)


def _flags(parser):
    """Map every option's destination to its long flag, over the subcommands too."""
    out = {}
    for action in parser._actions:
        long = [s for s in action.option_strings if s.startswith('--')]
        if long:
            out.setdefault(action.dest, long[0])
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                for dest, flag in _flags(sub).items():
                    out.setdefault(dest, flag)
    return out


def _message(error, flags):
    """One line of an error, with the Python argument names (`name`) as their flags."""
    text = '; '.join([str(error)] + list(getattr(error, '__notes__', ())))
    text = ' '.join(text.split()) or type(error).__name__
    return re.sub(r'`(\w+)`', lambda m: f'`{flags[m[1]]}`' if m[1] in flags else m[0], text)


def run(parser, prepare, argv=None, input_errors=()):
    """
    Run a tool: parse, check the input, do the job; return the exit code of `EXIT_CODES`.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The tool's parser (`add_version` is applied here if it was not).
    prepare : callable
        ``prepare(args) -> job``: checks every input before any work (its errors exit 2
        with one line) and returns ``job()``, which does the work and returns the exit
        code (its errors exit 1 with one line).
    argv : list of str, optional
    input_errors : tuple of type
        Exceptions that mean bad input wherever they are raised (exit 2).

    Returns
    -------
    int

    """
    if not any(isinstance(a, _Version) for a in parser._actions):
        add_version(parser)
    _one_line_errors(parser)
    args = parser.parse_args(argv)
    prog = parser.prog + (f' {args.command}' if getattr(args, 'command', None) else '')
    flags = _flags(parser)
    stage = 'input'
    try:
        job = prepare(args)
        stage = 'job'
        return job()
    except KeyboardInterrupt:
        print(f'{prog}: interrupted', file=sys.stderr)
        return EXIT_INTERRUPTED
    except JobFailed as error:
        print(f'{prog}: failed: {_message(error, flags)}', file=sys.stderr)
        return EXIT_FAILED
    except (InputError,) + tuple(input_errors) as error:
        print(f'{prog}: error: {_message(error, flags)}', file=sys.stderr)
        return EXIT_INPUT
    except _ERRORS as error:
        if stage == 'input':
            print(f'{prog}: error: {_message(error, flags)}', file=sys.stderr)
            return EXIT_INPUT
        print(f'{prog}: failed: {_message(error, flags)}', file=sys.stderr)
        return EXIT_FAILED


class OutputDir:
    """
    A tool's output directory, written whole or not at all.

    `check` (before any work) refuses a path that is not a directory, the working
    directory or one above it, a non-empty directory without `OUTPUT_MARKER` (the tools
    never replace a directory they did not write) and an earlier output without `force`.
    Entered, it makes an empty temporary directory beside the target (`tmp`), where the
    job writes. `commit` moves it into place, in
    place of any earlier outputs: a successful run leaves exactly its files; a run that
    produced nothing usable (``commit(failed=reason)``) leaves its diagnostics and
    `FAILED_MARKER`, never an earlier run's results beside them. An exception before
    `commit` removes the temporary directory and leaves the target as it was; the error
    then says so (a note on the exception).

    Parameters
    ----------
    path : path-like
    force : bool
        Replace an existing output directory.
    flag : str
        The option that named it, for messages.

    """

    def __init__(self, path, force=False, flag='--out'):
        self.path = pathlib.Path(path)
        self.force = bool(force)
        self.flag = flag
        self.tmp = self._staging = None
        self.replaced = []

    def check(self):
        """Raise InputError for a file, a directory of other files, or outputs without force."""
        if self.path.exists() and not self.path.is_dir():
            raise InputError(f'{self.flag} {self.path}: exists and is not a directory')
        resolved = self.path.resolve()
        if resolved == pathlib.Path.cwd().resolve() or resolved in pathlib.Path.cwd().parents:
            raise InputError(f'{self.flag} {self.path}: is the working directory or above it; '
                             'name a new directory for the outputs')
        if self.path.is_dir() and any(self.path.iterdir()):
            if not (self.path / OUTPUT_MARKER).exists():
                # --force replaces the whole directory: never one an fpc tool did not write.
                raise InputError(f'{self.flag} {self.path}: holds files that no fpc tool '
                                 'wrote; name a new or empty directory')
            if not self.force:
                raise InputError(f'{self.flag} {self.path}: already holds outputs; pass '
                                 '--force to replace them')
        return self

    def __enter__(self):
        """Make the temporary directory beside the target; return self."""
        self.check()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = self._staging = self.path.parent / f'.{self.path.name}.{os.getpid()}.tmp'
        shutil.rmtree(self.tmp, ignore_errors=True)
        self.tmp.mkdir()
        return self

    def __exit__(self, kind, error, traceback):
        """Remove the temporary directory; note in the error that the target is unchanged."""
        if self.tmp is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            self.tmp = None
            if isinstance(error, Exception):
                error.add_note(f"{self.path} is unchanged (it holds an earlier run's outputs)"
                               if self.path.exists() else f'nothing written to {self.path}')
        return False

    def commit(self, failed=None):
        """
        Move the outputs into place; with `failed` (the reason) mark them as a failed run.

        Returns
        -------
        list of str
            Names of the earlier outputs this replaced.

        """
        (self.tmp / OUTPUT_MARKER).write_text('outputs of an fpc_gripper tool; --force '
                                              'replaces this directory whole\n')
        if failed is not None:
            (self.tmp / FAILED_MARKER).write_text(
                f'This run failed: {failed}\nNo file here is a usable result.\n')
        old = None
        if self.path.exists():
            self.replaced = sorted(p.name for p in self.path.iterdir()
                                   if p.name != OUTPUT_MARKER)
            old = self.path.parent / f'.{self.path.name}.{os.getpid()}.old'
            shutil.rmtree(old, ignore_errors=True)
            os.replace(self.path, old)
        os.replace(self.tmp, self.path)
        self.tmp = None
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        return self.replaced

    def file(self, name):
        """Return the temporary path of output `name`."""
        return self.tmp / name

    def final(self, path):
        """Return where a file written under `tmp` ends up."""
        return self.path / pathlib.Path(path).relative_to(self._staging)

    def replaced_note(self):
        """Return a sentence naming the earlier outputs that were replaced ('' if none)."""
        if not self.replaced:
            return ''
        return f'replaced the earlier outputs in {self.path} ({", ".join(self.replaced)})'
