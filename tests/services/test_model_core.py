"""Tests of the model node's ROS-free state machine (no rclpy)."""

import math
import subprocess
import sys

import numpy as np
from numpy.testing import assert_allclose
import pytest

from fpc_gripper.model import ActuatorDesign, CCMSolver
from fpc_gripper.services.model_core import check_pressure
from fpc_gripper.services.model_core import check_tip_force
from fpc_gripper.services.model_core import Level
from fpc_gripper.services.model_core import ModelCore
from fpc_gripper.services.model_core import RATE_BURST
from fpc_gripper.services.model_core import Rejection
from fpc_gripper.services.model_core import stale_detail

ATM = 101325.0
NAMES = ('finger_0', 'finger_1', 'finger_2')
MS = 1_000_000
DESIGN = ActuatorDesign.paper(prestrain=0.25)


class CountingSolver:
    """CCMSolver wrapper that records every solve call (pressure, force, initial)."""

    def __init__(self, design, n_segments=8, pressure_model='adiabatic'):
        self.inner = CCMSolver(design, n_segments=n_segments, pressure_model=pressure_model)
        self.calls = []
        self.rigidity_calls = []

    def solve(self, pressure, tip_force=(0.0, 0.0), initial=None):
        self.calls.append((pressure, tuple(tip_force), initial))
        return self.inner.solve(pressure, tip_force, initial=initial)

    def rigidity(self, pressure, axis='x', displacement=0.010, initial=None):
        self.rigidity_calls.append((pressure, axis, initial))
        return self.inner.rigidity(pressure, axis=axis, displacement=displacement,
                                   initial=initial)


class Factory:
    """Solver factory that keeps the solvers it built."""

    def __init__(self, **kwargs):
        self.kwargs = kwargs
        self.built = []

    def __call__(self, design):
        solver = CountingSolver(design, **self.kwargs)
        self.built.append(solver)
        return solver

    @property
    def calls(self):
        return [c for s in self.built for c in s.calls]


def make_core(designs=(DESIGN,) * 3, **kwargs):
    factory = Factory(**kwargs.pop('solver_kwargs', {}))
    core = ModelCore(list(zip(NAMES, designs)), factory, atmospheric_pressure=ATM, **kwargs)
    return core, factory


def reference(gauge, force=(0.0, 0.0), n_segments=8):
    return CCMSolver(DESIGN, n_segments=n_segments).solve(gauge, force)


def assert_same_state(result, expected):
    assert_allclose(result.points, expected.points, rtol=0, atol=1e-9)
    assert_allclose(result.curvature, expected.curvature, rtol=1e-9, atol=1e-9)


# -- input checks ---------------------------------------------------------------------------

@pytest.mark.parametrize('absolute, rejection, text', [
    (math.nan, Rejection.NOT_FINITE, 'not finite'),
    (math.inf, Rejection.NOT_FINITE, 'not finite'),
    (-math.inf, Rejection.NOT_FINITE, 'not finite'),
    (-1.0, Rejection.BELOW_VACUUM, '-1.0 Pa absolute is below vacuum'),
    # A default-constructed FluidPressure reads 0 Pa: no command and no reading.
    (0.0, Rejection.BELOW_VACUUM, '0.0 Pa absolute is below min_absolute_pressure = 10000 Pa'),
    (9999.9, Rejection.BELOW_VACUUM, 'below min_absolute_pressure'),
    (ATM + 400e3 + 1.0, Rejection.OVER_LIMIT, '400001.0 Pa gauge, over the limit 400000.0'),
])
def test_check_pressure_rejects(absolute, rejection, text):
    check = check_pressure(absolute, atmospheric_pressure=ATM, max_pressure=400e3)
    assert not check.accepted
    assert check.rejection is rejection
    assert text in check.detail


@pytest.mark.parametrize('absolute, gauge, clamped', [
    (ATM, 0.0, False),
    (ATM + 400e3, 400e3, False),  # exactly the limit
    (ATM + 123.5, 123.5, False),
    (ATM - 300.0, 0.0, True),  # vented channel, a little under atmosphere
    (1.0e4, 0.0, True),  # exactly the plausibility bound
    (np.float32(ATM + 1000.0), 1000.0, False),
])
def test_check_pressure_accepts_and_converts_to_gauge(absolute, gauge, clamped):
    check = check_pressure(absolute, atmospheric_pressure=ATM, max_pressure=400e3)
    assert check.accepted
    assert check.value == pytest.approx(gauge, abs=1e-9)
    assert check.clamped is clamped


@pytest.mark.parametrize('stamp_s, now_s, limit, stale', [
    (10.0, 11.5, 1.0, True),
    (10.0, 10.5, 1.0, False),
    (10.0, 11.0, 1.0, False),  # exactly the limit
    (10.0, 9.0, 1.0, False),  # future stamp
    (10.0, 100.0, 0.0, False),  # disabled
    (0.0, 100.0, 1.0, False),  # unstamped
    (10.0, 0.0, 1.0, False),  # clock not started (simulated time)
])
def test_stale_detail(stamp_s, now_s, limit, stale):
    detail = stale_detail(int(stamp_s * 1e9), int(now_s * 1e9), limit)
    assert (detail is not None) is stale
    if stale:
        assert '1.500 s old' in detail and 'stale_after_s = 1 s' in detail


def test_check_pressure_stale():
    check = check_pressure(ATM + 1e3, atmospheric_pressure=ATM, max_pressure=400e3,
                           stamp_ns=1, now_ns=3 * 10 ** 9, stale_after_s=0.5)
    assert check.rejection is Rejection.STALE


@pytest.mark.parametrize('force, frame, rejection', [
    ((math.nan, 0.0), 'finger_0', Rejection.NOT_FINITE),
    ((0.0, math.inf), 'finger_0', Rejection.NOT_FINITE),
    ((0.1, 0.0), 'finger_1', Rejection.WRONG_FRAME),
    ((0.1, 0.0), '', Rejection.WRONG_FRAME),
    ((0.1, 0.0), '/finger_0', Rejection.WRONG_FRAME),
    ((0.1, 0.0), 'finger_0', None),
])
def test_check_tip_force(force, frame, rejection):
    check = check_tip_force(*force, frame, expected_frame='finger_0')
    assert check.rejection is rejection
    if rejection is None:
        assert check.value == force
    elif rejection is Rejection.WRONG_FRAME:
        assert repr(frame) in check.detail and "'finger_0'" in check.detail


# -- state machine --------------------------------------------------------------------------

def at_rest(core, now_ns=0):
    """Offer every finger 0 Pa gauge and solve: the state most tests start from."""
    for i in range(len(core.fingers)):
        assert core.offer_pressure(i, ATM, now_ns=now_ns).accepted
    return core.process(range(len(core.fingers)), now_ns)


def test_nothing_is_solved_before_a_pressure_then_one_shared_solve_at_rest():
    core, factory = make_core()
    assert core.ready(0) == () and core.process(range(3), 0) == [] and not core.pending
    for i in range(3):
        status = core.status(i)
        assert status.level is Level.WARN and status.message == 'waiting for pressure input'
    # A tip force alone answers nothing: the finger still has no pressure to solve at.
    assert core.offer_tip_force(0, 0.0, 0.0, 'finger_0', now_ns=1).accepted
    assert core.ready(0) == () and core.process(range(3), 0) == [] and factory.calls == []
    assert core.status(0).message == 'waiting for pressure input'
    for i in range(3):
        assert core.offer_pressure(i, ATM, now_ns=2).accepted
    assert core.ready(0) == (0, 1, 2)
    updates = core.process(core.ready(0), 0)
    assert [u.index for u in updates] == [0, 1, 2]
    assert [u.solved for u in updates] == [True, False, False]
    assert len(factory.built) == 1 and factory.calls == [(0.0, (0.0, 0.0), None)]
    expected = reference(0.0)
    for update in updates:
        assert update.result is updates[0].result
        assert_same_state(update.result, expected)
        assert core.status(update.index).level is Level.OK
    assert core.fingers[0].coalesced == 0


def test_warm_up_solves_once_per_solver_and_leaves_no_state():
    stiff = DESIGN.replace(prestrain=0.15)
    core, factory = make_core(designs=(DESIGN, stiff, DESIGN))
    core.warm_up()
    assert [len(s.calls) for s in factory.built] == [1, 1]
    assert [len(s.rigidity_calls) for s in factory.built] == [1, 1]
    assert all(s.calls[0] == (0.0, (0.0, 0.0), None) for s in factory.built)
    assert core.ready(0) == () and not core.pending
    assert all(state.result is None and state.solves == 0 for state in core.fingers)
    assert core.status(0).message == 'waiting for pressure input'
    # The first real solve is cold, as without the warm-up: the same answer.
    core.offer_pressure(0, ATM + 1e5, now_ns=1)
    (update, *_) = core.process((0,), 0)
    assert factory.built[0].calls[-1][2] is None
    assert_same_state(update.result, reference(1e5))


def test_frame_prefix_names_the_expected_tip_force_frame():
    core, _ = make_core(frame_prefix='left/')
    assert core.offer_tip_force(1, 0.1, 0.0, 'left/finger_1').accepted
    check = core.offer_tip_force(1, 0.1, 0.0, 'finger_1')
    assert check.rejection is Rejection.WRONG_FRAME
    assert check.detail == "frame_id 'finger_1' is not 'left/finger_1'"


def test_distinct_designs_get_their_own_solvers():
    stiff = DESIGN.replace(prestrain=0.15)
    core, factory = make_core(designs=(DESIGN, stiff, DESIGN))
    updates = at_rest(core)
    assert len(factory.built) == 2
    assert [u.solved for u in updates] == [True, False, True]
    assert updates[1].result is updates[0].result
    assert updates[2].result.curvature < updates[0].result.curvature


def test_latest_input_wins_and_warm_starts_from_the_last_good_state():
    core, factory = make_core()
    at_rest(core)
    rest = core.fingers[0].result
    for kpa in (50, 100, 150):
        assert core.offer_pressure(0, ATM + kpa * 1e3, stamp_ns=kpa, now_ns=1).accepted
    assert core.fingers[0].coalesced == 2
    (update,) = core.process(core.ready(10 * MS), 10 * MS)
    assert update.stamp_ns == 150
    pressure, force, initial = factory.calls[-1]
    assert pressure == pytest.approx(150e3) and force == (0.0, 0.0)
    assert initial is rest
    assert_same_state(update.result, reference(150e3))
    assert len(factory.calls) == 2


def test_identical_inputs_share_one_solve_and_known_states_are_reused():
    core, factory = make_core()
    at_rest(core)
    for i in range(3):
        core.offer_pressure(i, ATM + 2e5, now_ns=5)
    updates = core.process(core.ready(10 * MS), 10 * MS)
    assert sum(u.solved for u in updates) == 1
    assert len({id(u.result) for u in updates}) == 1
    # The same input later, on one finger only: its state already answers it.
    core.offer_pressure(1, ATM + 2e5, now_ns=6)
    (update,) = core.process(core.ready(20 * MS), 20 * MS)
    assert not update.solved and update.result is updates[0].result
    assert len(factory.calls) == 2
    assert core.fingers[1].shared == 3 and core.fingers[0].solves == 2


def test_tip_force_enters_the_solve():
    core, factory = make_core()
    at_rest(core)
    assert core.offer_tip_force(2, 0.05, -0.1, 'finger_2', now_ns=1).accepted
    core.offer_pressure(2, ATM + 1e5, now_ns=1)
    (update,) = core.process(core.ready(MS), MS)
    assert factory.calls[-1][0] == pytest.approx(1e5, abs=1e-9)  # gauge = absolute - ATM
    assert factory.calls[-1][1] == (0.05, -0.1)  # the message's force, passed through
    assert_same_state(update.result, reference(1e5, (0.05, -0.1)))
    assert not np.allclose(update.result.points, reference(1e5).points, atol=1e-6)


def test_rate_cap_is_a_token_bucket_per_finger():
    core, _ = make_core(max_rate_hz=100.0)
    at_rest(core)
    # The bucket started full (RATE_BURST) and the rest state spent one token.
    assert RATE_BURST == 2.0
    core.offer_pressure(0, ATM + 1e3, now_ns=0)
    assert core.ready(0) == (0,)
    core.process((0,), 0)
    core.offer_pressure(0, ATM + 2e3, now_ns=0)
    assert core.ready(5 * MS) == ()  # half a token since
    assert core.ready(10 * MS) == (0,)
    core.process((0,), 10 * MS)
    core.offer_pressure(0, ATM + 3e3, now_ns=0)
    assert core.ready(19 * MS) == ()
    assert core.ready(20 * MS) == (0,)
    # Other fingers keep their own budget.
    core.offer_pressure(1, ATM + 3e3, now_ns=0)
    assert core.ready(20 * MS) == (0, 1)


def test_forced_processing_overdraws_the_bucket():
    core, _ = make_core(max_rate_hz=100.0)
    at_rest(core)
    for _ in range(2):
        core.offer_pressure(0, ATM, now_ns=0)
        core.process((0,), 0)
    assert core.fingers[0].tokens == pytest.approx(RATE_BURST - 3)
    core.offer_pressure(0, ATM + 1.0, now_ns=0)
    assert core.ready(19 * MS) == ()
    assert core.ready(20 * MS) == (0,)


def test_rejected_input_keeps_the_state_and_warns_until_an_accepted_one():
    core, factory = make_core(stale_after_s=1.0)
    at_rest(core)
    core.offer_pressure(0, ATM + 1e5, now_ns=1)
    core.process((0,), MS)
    good = core.fingers[0].result
    calls = len(factory.calls)
    bad = [
        core.offer_pressure(0, math.nan, now_ns=2 * MS),
        core.offer_pressure(0, -5.0, now_ns=2 * MS),
        core.offer_pressure(0, ATM + 5e5, now_ns=2 * MS),
        core.offer_pressure(0, ATM + 2e5, stamp_ns=1, now_ns=5 * 10 ** 9),
        core.offer_tip_force(0, 0.1, 0.0, '', now_ns=2 * MS),
        core.offer_tip_force(0, 0.1, 0.0, 'finger_1', now_ns=2 * MS),
    ]
    assert [c.rejection for c in bad] == [
        Rejection.NOT_FINITE, Rejection.BELOW_VACUUM, Rejection.OVER_LIMIT, Rejection.STALE,
        Rejection.WRONG_FRAME, Rejection.WRONG_FRAME]
    state = core.fingers[0]
    assert not state.pending and core.ready(10 ** 10) == ()
    assert core.process(range(3), 10 ** 10) == []
    assert state.result is good and state.gauge == pytest.approx(1e5)
    assert state.tip_force == (0.0, 0.0) and state.rejected == 6
    assert len(factory.calls) == calls
    status = core.status(0)
    assert status.level is Level.WARN
    assert status.values['last_rejection'] == \
        "tip_force (wrong frame): frame_id 'finger_1' is not 'finger_0'"
    assert status.values['pressure_pa'] == '100000.0' and status.values['rejected'] == '6'
    assert core.status(1).level is Level.OK
    core.offer_pressure(0, ATM + 1e5, now_ns=3 * MS)
    assert core.status(0).level is Level.OK
    assert 'finger_1' in core.status(0).values['last_rejection']


def test_solver_failure_keeps_the_last_good_state_and_is_not_retried():
    # One segment cannot carry (-2.5, 4.3) N, back and up, inside the model's 5 N
    # envelope: the continuation stalls.
    core, factory = make_core(solver_kwargs={'n_segments': 1})
    at_rest(core)
    good = core.fingers[2].result
    core.offer_tip_force(2, -2.5, 4.3, 'finger_2', now_ns=1)
    (update,) = core.process((2,), MS)
    assert update.result is None and not update.solved
    assert 'continuation' in update.failure
    state = core.fingers[2]
    assert state.result is good and state.failures == 1
    status = core.status(2)
    assert status.level is Level.ERROR
    assert status.values['solver_message'] == update.failure
    assert 'keeping the last good state' in status.message
    assert status.values['tip_force'] == 'f0=0 N, p0=0 N'
    assert status.values['input_tip_force'] == 'f0=-2.5 N, p0=4.3 N'
    calls = len(factory.calls)
    # The same input again from the same warm start would fail the same way: not re-solved.
    core.offer_tip_force(2, -2.5, 4.3, 'finger_2', now_ns=2)
    (again,) = core.process((2,), 100 * MS)
    assert again.failure == update.failure and len(factory.calls) == calls
    # A reachable input clears the error; at rest it is a state other fingers hold. (The
    # single-segment rest state breaks the small-rotation rule, so it stays a warning.)
    core.offer_tip_force(2, 0.0, 0.0, 'finger_2', now_ns=3)
    (back,) = core.process((2,), 200 * MS)
    assert back.result is good and state.failure is None
    assert core.status(2).level is Level.WARN and not good.valid


def test_solver_exception_is_a_failure():
    class Raising(CountingSolver):
        def solve(self, pressure, tip_force=(0.0, 0.0), initial=None):
            if pressure > 1e5:
                raise np.linalg.LinAlgError('singular matrix')
            return super().solve(pressure, tip_force, initial)

    core = ModelCore(list(zip(NAMES, (DESIGN,) * 3)), Raising, atmospheric_pressure=ATM)
    at_rest(core)
    core.offer_pressure(1, ATM + 2e5, now_ns=1)
    (update,) = core.process((1,), MS)
    assert update.failure == 'solver raised LinAlgError: singular matrix'
    assert core.status(1).level is Level.ERROR


def test_invalid_state_is_published_with_a_warning():
    core, _ = make_core(solver_kwargs={'n_segments': 1})
    at_rest(core)
    core.offer_tip_force(0, 0.0, -1.0, 'finger_0', now_ns=1)
    (update,) = core.process((0,), MS)
    assert update.result is not None and not update.result.valid
    status = core.status(0)
    assert status.level is Level.WARN and 'valid=False' in status.message
    assert status.values['valid'] == 'False'


def test_rebuild_solves_again_from_cold():
    core, factory = make_core()
    at_rest(core)
    core.offer_pressure(0, ATM + 1e5, now_ns=1)
    core.process((0,), 0)
    old = core.fingers[0].result
    core.rebuild(Factory(n_segments=4))
    assert core.ready(100 * MS) == (0, 1, 2)
    assert core.fingers[0].result is old  # still the published state meanwhile
    updates = core.process(range(3), 100 * MS)
    assert [u.solved for u in updates] == [True, True, False]
    assert updates[0].result.coefficients.shape == (4, 4)
    assert_same_state(updates[0].result, reference(1e5, n_segments=4))
    assert_same_state(updates[1].result, reference(0.0, n_segments=4))


def test_rigidity_is_shared_and_matches_the_solver():
    core, factory = make_core()
    at_rest(core)
    for i in range(3):
        core.offer_pressure(i, ATM + 55.2e3, now_ns=1)
    core.process(range(3), MS)
    k_x = [core.rigidity(i, 'x') for i in range(3)]
    assert k_x[0] is k_x[1] is k_x[2]
    assert len(factory.built[0].rigidity_calls) == 1
    assert factory.built[0].rigidity_calls[0][2] is core.fingers[0].result
    expected = CCMSolver(DESIGN).rigidity(55.2e3, axis='x')
    assert_allclose(k_x[0].value, expected.value, rtol=1e-6)
    assert k_x[0].value == pytest.approx(1.396e-3, rel=1e-3)  # SPEC reference
    assert core.rigidity(0, 'z').value > 0.0


@pytest.mark.parametrize('name, value, text', [
    ('atmospheric_pressure', -1.0, '`atmospheric_pressure` must be in [0, inf] [Pa], got -1.0'),
    ('stale_after_s', math.nan, '`stale_after_s` must be in'),
    ('max_rate_hz', 0.0, '`max_rate_hz` must be > 0 [Hz], got 0.0'),
])
def test_settings_are_checked(name, value, text):
    core, _ = make_core()
    with pytest.raises(ValueError) as info:
        setattr(core, name, value)
    assert text in str(info.value)
    with pytest.raises(TypeError, match=f'`{name}` must be a real number'):
        setattr(core, name, '1')


def test_core_imports_without_rclpy():
    code = ('import sys; import fpc_gripper.services.model_core; '
            'bad = [m for m in sys.modules if m.split(".")[0] in '
            '("rclpy", "rosidl_runtime_py", "std_msgs")]; '
            'assert not bad, bad')
    subprocess.run([sys.executable, '-c', code], check=True, timeout=60)
