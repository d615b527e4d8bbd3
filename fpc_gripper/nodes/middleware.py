"""The middleware and allocator settings a node process makes for itself before rclpy.init."""

import ctypes
import os
import pathlib

__all__ = ['ALLOCATOR_SETTINGS', 'MMAP_THRESHOLD_BYTES', 'OPT_OUT_ENV', 'PROFILE',
           'apply_allocator_settings', 'apply_middleware_settings', 'middleware_settings',
           'settings_wanted']

#: Set to ``0`` to leave Fast DDS's profile and glibc's allocator as the environment has them.
OPT_OUT_ENV = 'FPC_GRIPPER_MIDDLEWARE_SETTINGS'
#: The Fast DDS profile: rmw_fastrtps's own settings, with freed history memory (see the file).
PROFILE = pathlib.Path(__file__).resolve().parent.parent / 'data' / 'fastdds_profile.xml'
_FASTDDS_RMWS = ('', 'rmw_fastrtps_cpp', 'rmw_fastrtps_dynamic_cpp')
# Any of these set by the user is a Fast DDS configuration of their own: it is kept whole
# (RMW_FASTRTPS_USE_QOS_FROM_XML=1 would make rmw ignore RMW_FASTRTPS_PUBLICATION_MODE).
_USER_FASTDDS_ENV = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE',
                     'RMW_FASTRTPS_USE_QOS_FROM_XML', 'RMW_FASTRTPS_PUBLICATION_MODE')
#: glibc's allocator settings: for each, its ``mallopt`` parameter, the value set, and the
#: environment variable with which a user sets it instead (glibc applied it at start).
#:
#: - ``mmap_threshold`` [bytes]: left to itself, glibc raises its mmap threshold to the
#:   size of each large block freed (up to 32 MiB), after which blocks of that size come
#:   from the heap and their pages stay with the process when they are freed: after one
#:   burst of 1 MB messages the process kept their memory.
#: - ``arena_max``: glibc gives each new thread an arena of its own (up to 8 per core),
#:   and ``malloc_trim`` gives back only the free pages inside an arena, never the top of
#:   a thread's arena: in the composed gripper one thread's arena grew from 0.4 to 2.0
#:   MiB in 25 minutes, most of it free at its top. One arena for every thread puts
#:   all free memory where the heap trim reaches it.
ALLOCATOR_SETTINGS = {'mmap_threshold': (-3, 128 * 1024, 'MALLOC_MMAP_THRESHOLD_'),
                      'arena_max': (-8, 1, 'MALLOC_ARENA_MAX')}
MMAP_THRESHOLD_BYTES = ALLOCATOR_SETTINGS['mmap_threshold'][1]


def settings_wanted(environ):
    """Whether the process makes its own middleware and allocator settings (no opt-out)."""
    return environ.get(OPT_OUT_ENV, '1') != '0'


def middleware_settings(environ):
    """
    Return the environment variables to set, and the allocator settings to make.

    Parameters
    ----------
    environ : mapping
        The process environment.

    Returns
    -------
    env : dict
        Variables to set: the profile and ``RMW_FASTRTPS_USE_QOS_FROM_XML=1`` when the
        RMW is Fast DDS and the user has not configured Fast DDS; else empty.
    allocator : dict
        Name to value of each of `ALLOCATOR_SETTINGS` whose variable the user has not set.

    """
    if not settings_wanted(environ):
        return {}, {}
    env = {}
    if environ.get('RMW_IMPLEMENTATION', '') in _FASTDDS_RMWS \
            and not any(environ.get(name) for name in _USER_FASTDDS_ENV):
        env = {'FASTRTPS_DEFAULT_PROFILES_FILE': str(PROFILE),
               'RMW_FASTRTPS_USE_QOS_FROM_XML': '1'}
    allocator = {name: value for name, (_, value, variable) in ALLOCATOR_SETTINGS.items()
                 if not environ.get(variable)}
    return env, allocator


def apply_allocator_settings(environ=os.environ):
    """
    Make the allocator half of `middleware_settings` in this process.

    Call it before anything starts a thread (numpy's BLAS and rclpy start some when they are
    imported): a thread keeps the arena it has, so ``arena_max`` holds only for threads
    that first allocate after it. The nodes' console scripts call it before they import
    anything else; `apply_middleware_settings` calls it again. Made only where the C
    library is glibc (``mallopt`` found); elsewhere skipped.

    Returns
    -------
    dict
        Each allocator setting that was made, name to value.

    """
    _, allocator = middleware_settings(environ)
    done = {}
    if allocator:
        try:
            mallopt = ctypes.CDLL(None).mallopt
        except (OSError, AttributeError):
            return done
        for name, value in allocator.items():
            if mallopt(ALLOCATOR_SETTINGS[name][0], value) == 1:
                done[name] = value
    return done


def apply_middleware_settings(environ=os.environ):
    """
    Make `middleware_settings` in this process; call before ``rclpy.init``.

    The variables also reach the processes this one starts. See `apply_allocator_settings`
    for the allocator's, which are best made earlier still.

    Returns
    -------
    dict
        What was set: the variables, and each allocator setting that was made.

    """
    env, _ = middleware_settings(environ)
    environ.update(env)
    return {**env, **apply_allocator_settings(environ)}
