"""Helpers shared by the test directories: designs compared, finite differences, goals sent."""

import dataclasses
import enum
import math
import numbers
import pathlib
import time

import numpy as np

#: Default relative tolerance of `assert_designs_close`. Design fields are inputs or
#: shipped literals; the only field ever seen to differ between machines was a fitted
#: PEMC coefficient, by 1.5e-14 relative (BLAS round-off). 1e-12 leaves a margin of 100
#: over that while a real change of a design (even a YAML value rounded to 10 digits)
#: still fails.
DESIGN_RTOL = 1e-12
#: A goal unanswered this long is sent again by `send_goal` [s] (a hang guard, no judgement).
GOAL_RESEND_S = 5.0


def assert_designs_close(actual, expected, rtol=DESIGN_RTOL, atol=0.0, where='design'):
    """
    Assert that two ActuatorDesigns (or any frozen dataclasses) are the same design.

    Real numbers compare to `rtol` (and `atol`; rtol = atol = 0 demands exact
    equality); nested dataclasses (the Material laminae) and tuples (the PEMC
    coefficients) compare element by element; bools, strings, enums and None compare
    exactly, and a bool never equals a number. The message names the first field that
    differs, e.g. ``design.fluidic_layer.nu``.
    """
    assert dataclasses.is_dataclass(expected) and not isinstance(expected, type), where
    _assert_close(actual, expected, float(rtol), float(atol), where)


def _assert_close(actual, expected, rtol, atol, where):
    if dataclasses.is_dataclass(expected) and not isinstance(expected, type):
        assert type(actual) is type(expected), \
            f'{where}: {type(actual).__name__} is not {type(expected).__name__}'
        for field in dataclasses.fields(expected):
            _assert_close(getattr(actual, field.name), getattr(expected, field.name), rtol,
                          atol, f'{where}.{field.name}')
    elif isinstance(expected, (tuple, list)):
        assert isinstance(actual, (tuple, list)) and len(actual) == len(expected), \
            f'{where}: {actual!r} does not match {expected!r}'
        for i, (a, e) in enumerate(zip(actual, expected)):
            _assert_close(a, e, rtol, atol, f'{where}[{i}]')
    elif isinstance(expected, (bool, str, enum.Enum)) or expected is None:
        assert type(actual) is type(expected) and actual == expected, \
            f'{where}: {actual!r} != {expected!r}'
    elif isinstance(expected, numbers.Real):
        assert isinstance(actual, numbers.Real) and not isinstance(actual, bool), \
            f'{where}: {actual!r} is not a number'
        if rtol == 0.0 and atol == 0.0:
            close = actual == expected
        else:
            close = math.isclose(actual, expected, rel_tol=rtol, abs_tol=atol)
        assert close, (f'{where}: {actual!r} != {expected!r} '
                       f'(rtol {rtol:g}, atol {atol:g})')
    else:
        assert actual == expected, f'{where}: {actual!r} != {expected!r}'


def deviation(actual, expected, scale=None):
    """
    Return max |actual - expected| / scale (default: max |expected|), shapes equal.

    Structural zeros (a one-segment load Hessian) must come out exactly zero.
    """
    actual, expected = np.asarray(actual), np.asarray(expected)
    assert actual.shape == expected.shape and actual.dtype == expected.dtype
    if scale is None:
        scale = np.abs(expected).max()
    error = np.abs(actual - expected).max()
    if scale == 0.0:
        return 0.0 if error == 0.0 else np.inf
    return float(error / scale)


def fd_derivative(fun, x, h):
    """Fourth-order central differences of fun at x, one column per component of x."""
    cols = []
    for k in range(x.size):
        e = np.zeros_like(x)
        e[k] = h
        cols.append((-fun(x + 2 * e) + 8.0 * fun(x + e) - 8.0 * fun(x - e) + fun(x - 2 * e))
                    / (12.0 * h))
    return np.stack(cols, axis=-1)


def read_with_rosbags(path):
    """
    Read every message of a recording with rosbags (PyPI), a reader independent of mcap's.

    `path` is an MCAP file or a rosbag2 bag directory. The message types come from the
    recording's own ros2msg schemas, and rosbags checks each against the recorded
    RIHS01 type hash. Returns ``[(topic, type name, log time [ns], message)]``.
    """
    from rosbags.highlevel import AnyReader

    out = []
    with AnyReader([pathlib.Path(path)]) as reader:
        for connection, log_time, raw in reader.messages():
            out.append((connection.topic, connection.msgtype, log_time,
                        reader.deserialize(raw, connection.msgtype)))
    return out


def spin_until(executor, condition, timeout, step=0.05):
    """Run `executor`'s callbacks until `condition()` holds or `timeout` [s] passes: if it did."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        executor.spin_once(timeout_sec=step)
    return True


def send_goal(client, goal, spin_until, attempts=12, resend_s=GOAL_RESEND_S, **kwargs):
    """
    Send an action goal until the server answers it; return the ClientGoalHandle.

    ``client.server_is_ready()`` sees the server from the client's side only. Once, on a
    loaded CI machine, a goal sent after it was never answered (60 s): the answer's way
    back (the server's response writer matching the client's reader) can still be in
    discovery, and the middleware then drops the answer. So a goal unanswered within
    `resend_s` is sent again, up to `attempts` times; a server that did get the first one
    takes the second as a new goal, which preempts it. `spin_until(condition, timeout)`
    runs callbacks until `condition()` holds and says whether it did; `kwargs` go to
    ``send_goal_async`` (a feedback callback).
    """
    for _ in range(attempts):
        future = client.send_goal_async(goal, **kwargs)
        if spin_until(future.done, resend_s):
            return future.result()
    raise AssertionError(f'the action server answered none of {attempts} goals sent '
                         f'{resend_s} s apart')
