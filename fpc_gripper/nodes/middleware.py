"""The middleware and allocator settings a node process makes for itself before rclpy.init."""

import ctypes
import os
import pathlib

__all__ = ['MMAP_THRESHOLD_BYTES', 'OPT_OUT_ENV', 'PROFILE', 'apply_middleware_settings',
           'middleware_settings', 'settings_wanted']

#: Set to ``0`` to leave Fast DDS's profile and glibc's allocator as the environment has them.
OPT_OUT_ENV = 'FPC_GRIPPER_MIDDLEWARE_SETTINGS'
#: The Fast DDS profile: rmw_fastrtps's own settings, with freed history memory (see the file).
PROFILE = pathlib.Path(__file__).resolve().parent.parent / 'data' / 'fastdds_profile.xml'
_FASTDDS_RMWS = ('', 'rmw_fastrtps_cpp', 'rmw_fastrtps_dynamic_cpp')
# Any of these set by the user is a Fast DDS configuration of their own: it is kept whole
# (RMW_FASTRTPS_USE_QOS_FROM_XML=1 would make rmw ignore RMW_FASTRTPS_PUBLICATION_MODE).
_USER_FASTDDS_ENV = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE',
                     'RMW_FASTRTPS_USE_QOS_FROM_XML', 'RMW_FASTRTPS_PUBLICATION_MODE')
#: glibc's mallopt parameter and the fixed threshold [bytes]. Left to itself, glibc raises
#: its mmap threshold to the size of each large block freed (up to 32 MiB), after which
#: blocks of that size come from the heap and their pages stay with the process when they
#: are freed: after one burst of 1 MB messages the process kept their memory.
_M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD_BYTES = 128 * 1024


def settings_wanted(environ):
    """Whether the process makes its own middleware and allocator settings (no opt-out)."""
    return environ.get(OPT_OUT_ENV, '1') != '0'


def middleware_settings(environ):
    """
    Return the environment variables to set, and the mmap threshold to fix.

    Parameters
    ----------
    environ : mapping
        The process environment.

    Returns
    -------
    env : dict
        Variables to set: the profile and ``RMW_FASTRTPS_USE_QOS_FROM_XML=1`` when the
        RMW is Fast DDS and the user has not configured Fast DDS; else empty.
    mmap_threshold : int or None
        Bytes for ``mallopt(M_MMAP_THRESHOLD)``, or None when ``MALLOC_MMAP_THRESHOLD_``
        is already set (glibc applied it at start).

    """
    if not settings_wanted(environ):
        return {}, None
    env = {}
    if environ.get('RMW_IMPLEMENTATION', '') in _FASTDDS_RMWS \
            and not any(environ.get(name) for name in _USER_FASTDDS_ENV):
        env = {'FASTRTPS_DEFAULT_PROFILES_FILE': str(PROFILE),
               'RMW_FASTRTPS_USE_QOS_FROM_XML': '1'}
    threshold = None if environ.get('MALLOC_MMAP_THRESHOLD_') else MMAP_THRESHOLD_BYTES
    return env, threshold


def apply_middleware_settings(environ=os.environ):
    """
    Make `middleware_settings` in this process; call before ``rclpy.init``.

    The variables also reach the processes this one starts. The mmap threshold is set
    only where the C library is glibc (``mallopt`` found); elsewhere it is skipped.

    Returns
    -------
    dict
        What was set: the variables, and ``'mmap_threshold'`` when it was.

    """
    env, threshold = middleware_settings(environ)
    environ.update(env)
    done = dict(env)
    if threshold is not None:
        try:
            mallopt = ctypes.CDLL(None).mallopt
        except (OSError, AttributeError):
            mallopt = None
        if mallopt is not None and mallopt(_M_MMAP_THRESHOLD, threshold) == 1:
            done['mmap_threshold'] = threshold
    return done
