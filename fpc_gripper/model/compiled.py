"""The engine's compiled code: built at install into the package, then read-only."""

from concurrent.futures import ThreadPoolExecutor
import hashlib
import json
import os
import pathlib
import sys
import threading
import warnings

import numba
from numba.core import caching
import numpy as np

__all__ = ['BUILD_DIR', 'BUILD_ENV', 'BUILDING', 'REASON', 'STRICT_ENV', 'USABLE',
           'build_status', 'jit', 'machine', 'over_cores', 'sources_stamp',
           'write_manifest']

_HERE = pathlib.Path(__file__).resolve().parent
#: Where the build lives: beside the sources it was built from, installed with them.
BUILD_DIR = _HERE / 'compiled'
#: Set by the build (`fpc_gripper.model.build`) to the directory its worker writes into.
BUILD_ENV = 'FPC_ENGINE_BUILD'
#: Set (as the test suite does) to make a compile outside the build an error.
STRICT_ENV = 'FPC_ENGINE_STRICT'
_MANIFEST = 'manifest.json'
#: The model sources compiled code comes from (paths under model/): the decorator, the
#: kernels and engine it compiles, and the discretisations that register each data type's
#: hooks with the engine. The rest of model/ (selection, pipeline, batch, validation,
#: section laws, the build's driver) is Python around those calls: an edit there, even to
#: the default model's choice, leaves the build valid.
COMPILED_FROM = ('compiled.py', 'kernels', 'engine', 'discretisations')


def sources_stamp(root=_HERE):
    """
    Return the sha256 of every source compiled code comes from, by relative path and content.

    The compiled entries inline kernels of other modules, so any of `COMPILED_FROM` that
    changes makes every entry stale (numba alone checks the file that defines each).
    Content, not mtimes: a copy into a colcon install or a container image keeps it.
    """
    digest = hashlib.sha256()
    for path in sorted(pathlib.Path(root).rglob('*.py')):
        if path.relative_to(root).parts[0] not in COMPILED_FROM:
            continue
        digest.update(str(path.relative_to(root)).encode())
        digest.update(b'\0')
        digest.update(path.read_bytes())
        digest.update(b'\0')
    return digest.hexdigest()


def machine():
    """Return what numba keys compiled code to here: (triple, CPU name, CPU features)."""
    from numba.core.registry import cpu_target
    return tuple(str(part) for part in cpu_target.target_context.codegen().magic_tuple())


def _identity():
    return {'sources': _STAMP, 'numba': numba.__version__,
            'python': '%d.%d' % sys.version_info[:2]}


def build_status(directory=BUILD_DIR):
    """
    Return (usable, reason): whether the build in `directory` is these sources' here.

    Usable means built from byte-identical model sources, by this numba and Python, for
    this machine's CPU; the reason says what differs otherwise.
    """
    path = pathlib.Path(directory) / _MANIFEST
    try:
        manifest = json.loads(path.read_text())
    except FileNotFoundError:
        return False, f'no build at {directory}'
    except (OSError, ValueError) as exc:
        return False, f'unreadable build manifest {path}: {exc}'
    for key, value in _identity().items():
        if manifest.get(key) != value:
            return False, f'built for {key} {manifest.get(key)!r}, this is {value!r}'
    here = list(machine())
    if manifest.get('machine') != here:
        return False, f"built for the CPU {manifest.get('machine')!r}, this is {here!r}"
    return True, f"built {manifest.get('built', '?')} for {here[1]}"


def write_manifest(directory, **extra):
    """Write the manifest that makes `directory` the build of these sources on this machine."""
    manifest = dict(_identity(), machine=list(machine()), **extra)
    path = pathlib.Path(directory) / _MANIFEST
    path.write_text(json.dumps(manifest, indent=1, sort_keys=True) + '\n')


class _BuildLocator(caching._CacheLocator):
    """Locate a function's compiled code in the build directory; readable without writing."""

    directory = None

    def __init__(self, py_func, py_file):
        self._lineno = py_func.__code__.co_firstlineno

    def ensure_cache_path(self):
        # Only the build writes here (into its own worker directory).
        os.makedirs(self.directory, exist_ok=True)

    def get_cache_path(self):
        return str(self.directory)

    def get_source_stamp(self):
        return _STAMP

    def get_disambiguator(self):
        return str(self._lineno)

    @classmethod
    def from_function(cls, py_func, py_file):
        if cls.directory is None:
            return None
        if py_func not in _ADOPTED and not pathlib.Path(py_file).resolve().is_relative_to(_HERE):
            return None
        return cls(py_func, py_file)


class _Impl(caching.CompileResultCacheImpl):
    _locator_classes = [_BuildLocator, *caching.CompileResultCacheImpl._locator_classes]


class _Cache(caching.FunctionCache):
    """numba's function cache, from the build first; a save that cannot write is skipped."""

    _impl_class = _Impl

    def load_overload(self, sig, target_context):
        data = super().load_overload(sig, target_context)
        func = self._py_func
        # A miss of an adopted numba helper is another user's item type: numba compiles it,
        # as it always did.
        if data is None and not BUILDING and func not in _ADOPTED:
            if os.environ.get(STRICT_ENV):
                raise RuntimeError(f'{func.__module__}.{func.__qualname__}{tuple(sig)} is not '
                                   f'in the compiled engine ({REASON}), and {STRICT_ENV} '
                                   f'forbids compiling it here')
            _warn_once(func)
        return data

    def save_overload(self, sig, data):
        if not BUILDING and isinstance(self._impl.locator, _BuildLocator):
            return                  # the installed build is only written by the build
        try:
            super().save_overload(sig, data)
        except OSError:
            # A read-only install that lacks a signature: it runs, compiled in memory.
            pass


_WARNED = []
#: numba's own compiled helpers that the engine calls from Python (`_adopt_typed_list`).
_ADOPTED = set()


def _warn_once(func):
    if not _WARNED:
        _WARNED.append(func)
        warnings.warn(f'fpc_gripper: {func.__module__}.{func.__qualname__} compiles at run '
                      f'time, which takes minutes: {REASON}. Build the engine with '
                      f'`{sys.executable} -m fpc_gripper.model.build` (scripts/setup.sh, pip '
                      f'install and colcon build do).', RuntimeWarning, stacklevel=2)


def jit(function=None, *, parallel=False, error_model='python'):
    """
    Compile `function` with numba (nopython, nogil), its code taken from the build.

    Use it for every compiled function of the model that Python calls. Inside a build
    (`BUILD_ENV` set) the code is written to the build; otherwise it is loaded from the
    package's build, read-only, when that build is this checkout's (`build_status`).
    When it is not, numba compiles at first use into its usual caches, and the first
    such compile warns, once, saying why and how to build.
    """
    def wrap(func):
        dispatcher = numba.njit(nogil=True, parallel=parallel, error_model=error_model)(func)
        # numba 0.68: `enable_caching` would install its FunctionCache here; ours first
        # looks in the build.
        dispatcher._cache = _Cache(dispatcher.py_func)
        return dispatcher
    return wrap if function is None else wrap(function)


def _adopt_typed_list():
    """
    Give numba's typed-list helpers the build's cache, as if they were the engine's own.

    The batches hand their entries a `numba.typed.List` of discretisations. Building one
    from Python calls numba's helpers (`_make_list`, `_append`, ...), which numba compiles
    for each item type in every process (0.47 s here) and never caches. Adopted, they are
    built with the engine (the grids part meets every item type) and loaded read-only.
    """
    from numba.core.registry import CPUDispatcher
    from numba.typed import typedlist
    for dispatcher in vars(typedlist).values():
        if isinstance(dispatcher, CPUDispatcher):
            _ADOPTED.add(dispatcher.py_func)
            dispatcher._cache = _Cache(dispatcher.py_func)


#: Fewest scenes a thread of `over_cores` takes.
_MIN_CHUNK = 8
#: The threads of `over_cores`, started once per process and thread count (a thread's start
#: costs 0.1-0.4 ms, as much as a small batch): size -> executor. One pool per count, so
#: that batches started without waiting never run on more threads than numba's count.
_POOLS = {}
_POOL_LOCK = threading.Lock()


def _pool(size):
    """Return the batches' thread pool of `size` threads."""
    with _POOL_LOCK:
        pool = _POOLS.get(size)
        if pool is None:
            pool = _POOLS[size] = ThreadPoolExecutor(size, thread_name_prefix='fpc_gripper-batch')
        return pool


def _forget_pool():
    # A forked child has none of its parent's threads: it starts pools of its own.
    _POOLS.clear()


os.register_at_fork(after_in_child=_forget_pool)


def over_cores(run, count, starts=None, wait=True):
    """
    Run a serial compiled batch over the cores: ``run(lo, hi)`` on contiguous chunks.

    The batch entries release the GIL (nogil), so one thread per core (numba's thread
    count, which `numba.set_num_threads` lowers) runs them in parallel, as `prange`
    would, without `parallel=True`'s minutes of compiling. Every scene is computed alone,
    or from the scenes before it on its chain where `starts` (the sorted indices where
    chains start) says so; chunks then start only where a chain does, so the answer does
    not depend on the chunks. Returns the chunks' outputs (an array or a tuple of arrays)
    concatenated along the scenes; with `wait` False, at once a function that returns
    them, the chunks running on the pool's threads meanwhile (the caller goes on in
    Python). Whoever waits runs the chunks that no thread has started yet itself, so a
    call never waits behind other batches queued on the pool.
    """
    threads = max(1, min(numba.get_num_threads(), count // _MIN_CHUNK))
    bounds = [count * k // threads for k in range(threads + 1)]
    if starts is not None and threads > 1:
        # Each even split moved to the nearest chain start; a chunk that vanishes goes.
        starts = np.asarray(starts, dtype=np.int64)
        for k in range(1, threads):
            bounds[k] = int(starts[np.argmin(np.abs(starts - bounds[k]))])
        bounds = sorted(set(bounds) | {0, count})
    chunks = list(zip(bounds[:-1], bounds[1:]))
    if wait and len(chunks) == 1:
        return run(0, count)
    # Waiting, the calling thread takes the first chunk; the pool's threads the others.
    futures = [(_pool(threads).submit(run, lo, hi), lo, hi) for lo, hi in chunks[int(wait):]]
    first = [run(*chunks[0])] if wait else []

    def collect():
        # A chunk still queued is taken back and run here.
        parts = first + [run(lo, hi) if future.cancel() else future.result()
                         for future, lo, hi in futures]
        if isinstance(parts[0], tuple):
            return tuple(np.concatenate(chunk) for chunk in zip(*parts))
        return np.concatenate(parts)
    return collect() if wait else collect


_STAMP = sources_stamp()
#: True in the build's workers: compiled code is written to `BUILD_ENV`'s directory.
BUILDING = bool(os.environ.get(BUILD_ENV))
if BUILDING:
    _BuildLocator.directory = pathlib.Path(os.environ[BUILD_ENV])
    USABLE, REASON = False, f'building into {os.environ[BUILD_ENV]}'
else:
    USABLE, REASON = build_status()
    if USABLE:
        _BuildLocator.directory = BUILD_DIR
if _BuildLocator.directory is not None:         # else numba's helpers stay uncached
    _adopt_typed_list()
