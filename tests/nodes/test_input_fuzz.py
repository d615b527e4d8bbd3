"""
Property-based fuzzing of every node's subscriber callbacks through their ROS-free cores.

Each callback of model_node, gripper_controller and regulator_bridge is one call of its
core (``ModelCore.offer_*``, ``ControllerInputs.offer_*``, ``RegulatorCore.offer_command``)
or, for a payload the guard refuses, ``reject``. Hypothesis feeds arbitrary field values
(any double, any int32/uint32 stamp, any frame_id) in arbitrary interleavings of good and
bad inputs per finger. The invariants: no exception escapes; a rejected input changes
nothing, so nothing is published for it; after any sequence a valid input gives the
answer of a fresh core. Fixed seeds and no example database: CI runs the same cases.
"""

import math

from hypothesis import event, given
from hypothesis import HealthCheck, seed, settings, strategies as st
from numpy.testing import assert_allclose
import rclpy.logging
from sensor_msgs.msg import FluidPressure

from fpc_gripper.control.controller import ControllerConfig
from fpc_gripper.control.controller import GripperControlLaw
from fpc_gripper.control.geometry import PalmGeometry
from fpc_gripper.control.inputs import ControllerInputs
from fpc_gripper.control.inverse import InverseModel
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.io.messages import serialized_shape
from fpc_gripper.model import CCMSolver
from fpc_gripper.model.pipeline import ModelSettings
from fpc_gripper.nodes.guard import decode
from fpc_gripper.regulators.core import MonitorSettings
from fpc_gripper.regulators.core import RegulatorCore
from fpc_gripper.regulators.sim import SimulatedRegulator
from fpc_gripper.services.input_limits import MAX_STAMP_NS
from fpc_gripper.services.input_limits import Rejection
from fpc_gripper.services.logs import NodeLog
from fpc_gripper.services.logs import Severity
from fpc_gripper.services.model_core import ModelCore

ATM = 101325.0
S = 1_000_000_000
MS = 1_000_000
START_NS = 1_800_000_000 * S
CONFIG = load_gripper_config()
NAMES = CONFIG.names
DESIGN = CONFIG.fingers[0].design
N = len(NAMES)
#: Longest string a node may put in a log line or a diagnostic [characters].
MAX_TEXT = 1000


def fuzz(examples):
    """Hypothesis settings of the properties here: reproducible, no database, no deadline."""
    return settings(max_examples=examples, database=None, deadline=None, print_blob=False,
                    derandomize=False,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


# -- field values -----------------------------------------------------------------------------

def mostly(good, bad, weight=3):
    """`good` about `weight` times as often as `bad`: good inputs must meet the bad ones."""
    # st.one_of(good, good, good, bad) is no weighting: it draws its branches unevenly.
    return st.integers(0, weight).flatmap(lambda k: good if k else bad)


def weighted(*choices):
    """Draw from (weight, strategy) pairs, each about in proportion to its weight."""
    pool = [strategy for weight, strategy in choices for _ in range(weight)]
    return st.integers(0, len(pool) - 1).flatmap(lambda k: pool[k])


ANY_DOUBLE = st.floats(allow_nan=True, allow_infinity=True)
EDGES = st.sampled_from([0.0, -0.0, 1e30, -1e30, 1.7e308, -1.7e308, 5e-324, 9999.9, 1e4,
                         math.nan, math.inf, -math.inf])
#: A FluidPressure.fluid_pressure: plausible commands mostly, any double or an edge else.
PRESSURES = mostly(st.floats(ATM - 2e4, ATM + 4.5e5), st.one_of(ANY_DOUBLE, EDGES), 2)
#: A force component: inside the envelope mostly.
FORCES = mostly(st.floats(-3.0, 3.0), st.one_of(ANY_DOUBLE, EDGES), 6)
FINGERS = st.integers(0, N - 1)
#: A header stamp's (sec, nanosec) as the message types allow (int32, uint32): unstamped
#: or near the node clock mostly.
STAMPS = mostly(st.one_of(st.just((0, 0)), st.integers(-3 * S, 3 * S).map(
    lambda d: divmod(START_NS + d, S))),
    st.tuples(st.integers(-2 ** 31, 2 ** 31 - 1), st.integers(0, 2 ** 32 - 1)))
TEXTS = st.one_of(st.text(max_size=12), st.integers(200, 2_000_000).map(lambda n: 'f' * n),
                  st.sampled_from(['', 'finger_9', 'nul\x00', 'surrogate\ud800']))
ADVANCE = st.integers(0, 50 * MS)


#: Loads inside the envelope that one CCM segment cannot carry: the solve fails.
HARD_LOADS = st.sampled_from([(-2.5, 4.3), (-2.4, 4.2), (-2.8, 2.7), (-3.5, 3.5)])
LOADS = mostly(st.tuples(FORCES, FORCES), HARD_LOADS)


def with_frame(*fields):
    """Inputs (finger, *fields, frame) whose frame is the finger's own mostly."""
    return FINGERS.flatmap(lambda i: st.tuples(
        st.just(i), *fields, mostly(st.just(NAMES[i]), TEXTS)))


def state_of(finger):
    """What a rejected input must leave as it was."""
    return (finger.gauge, finger.tip_force, finger.stamp_ns, finger.pending,
            finger.has_pressure, finger.result, finger.result_key, finger.failure)


# -- model_node -------------------------------------------------------------------------------

def _one_segment(design):
    # One segment fails on some loads inside the envelope: failed solves meet rejections.
    return CCMSolver(design, n_segments=1)


def _model_core():
    return ModelCore([(f.name, f.design) for f in CONFIG.fingers], _one_segment,
                     max_pressure=CONFIG.max_pressure, atmospheric_pressure=ATM,
                     stale_after_s=1.0, future_limit_s=1.0, max_rate_hz=200.0)


#: (kind, clock advance [ns], what the callback gets), kinds weighted by repeats.
MODEL_EVENTS = st.lists(weighted(
    (2, st.tuples(st.just('pressure'), ADVANCE, with_frame(PRESSURES, STAMPS))),
    (2, st.tuples(st.just('force'), ADVANCE, with_frame(LOADS, STAMPS))),
    (1, st.tuples(st.just('refused'), ADVANCE, st.tuples(
        FINGERS, st.sampled_from([Rejection.MALFORMED, Rejection.OVERSIZED, Rejection.LOST]),
        st.integers(1, 5), TEXTS))),
    (2, st.tuples(st.just('process'), ADVANCE, st.lists(FINGERS, min_size=1, max_size=N))),
), min_size=4, max_size=24)


@seed(20261210)
@fuzz(300)
@given(events=MODEL_EVENTS, final=st.tuples(FINGERS, st.floats(0.0, 4.0e5),
                                            st.floats(-0.7, 0.7), st.floats(-0.7, 0.7)))
def test_property_model_node_callbacks(events, final):
    core = _model_core()
    now = START_NS
    for kind, advance, body in events:
        now += advance
        if kind == 'process':
            for update in core.process(body, now):
                event('solve failed' if update.result is None else 'solved')
                assert update.result is None or update.result.success
                assert 0 <= update.stamp_ns <= MAX_STAMP_NS
                if update.result is not None:
                    serialized_shape(update.result, NAMES[update.index], update.stamp_ns)
            continue
        index, *args = body
        state = core.fingers[index]
        before, ready = state_of(state), state.ready
        if kind == 'pressure':
            value, stamp, frame = args
            check = core.offer_pressure(index, value, stamp, now, frame_id=frame)
        elif kind == 'force':
            (fx, fz), stamp, frame = args
            check = core.offer_tip_force(index, fx, fz, frame, stamp, now)
        else:
            rejection, count, detail = args
            check = core.lost(index, count, 'x') if rejection is Rejection.LOST else \
                core.reject(index, rejection, detail, 'x')
        event(f'{kind}: {check.rejection.value if check.rejection else "accepted"}')
        if check.accepted:
            assert state.pending and (kind != 'pressure' or state.has_pressure)
            continue
        assert state_of(state) == before and len(check.detail) < MAX_TEXT
        if not ready:
            assert core.process([index], now) == []     # nothing to publish
    for i in range(N):
        status = core.status(i)
        assert len(status.message) < MAX_TEXT
        assert all(len(v) < MAX_TEXT for v in status.values.values())
    index, gauge, f0, p0 = final
    answers = []
    for subject in (core, _model_core()):
        stamp = divmod(now, S)
        assert subject.offer_pressure(index, ATM + gauge, stamp, now).accepted
        assert subject.offer_tip_force(index, f0, p0, NAMES[index], stamp, now).accepted
        (update,) = subject.process([index], now)
        answers.append(update)
    ours, fresh = answers
    event('final: solve failed' if fresh.result is None else 'final: solved')
    assert (ours.result is None) == (fresh.result is None), (ours.failure, fresh.failure)
    assert ours.stamp_ns == fresh.stamp_ns == now
    if fresh.result is not None:
        # A warm start moves the answer by round-off of the solver's tolerance (~1e-12 m);
        # the circle fit of the curvature amplifies it to ~3e-9 relative.
        assert_allclose(ours.result.points, fresh.result.points, rtol=0, atol=1e-9)
        assert_allclose(ours.result.curvature, fresh.result.curvature, rtol=1e-7)


# -- gripper_controller -----------------------------------------------------------------------

_SETTINGS = ModelSettings()
_MODEL = InverseModel(DESIGN, CONFIG.palm_radius, CONFIG.max_pressure, _SETTINGS)
_GEOMETRY = PalmGeometry.from_config(CONFIG)
SOURCES = [f'{n}/{t}' for n in NAMES for t in ('pressure', 'tip_force')] + [
    'aperture_command', 'grasp_force_command']


def _controller():
    law = GripperControlLaw([_MODEL] * N, _GEOMETRY, ControllerConfig())
    return ControllerInputs(law, NAMES, ATM)


def _goal_of(law):
    return (law.mode, law.status, repr(law._aperture_target), repr(law._force_target),
            law._goal_start)


#: (kind, what the callback gets).
CONTROLLER_EVENTS = st.lists(weighted(
    (3, st.tuples(st.just('pressure'),
                  st.tuples(FINGERS, PRESSURES, mostly(st.just(''), TEXTS)))),
    (2, st.tuples(st.just('tip_force'), with_frame(LOADS))),
    (1, st.tuples(st.just('aperture'), mostly(st.floats(0.0, 0.2), ANY_DOUBLE))),
    (1, st.tuples(st.just('grasp'), mostly(st.floats(0.0, 20.0), ANY_DOUBLE))),
    (1, st.tuples(st.just('refused'), st.sampled_from(SOURCES))),
    (1, st.tuples(st.just('step'), st.none())),
), min_size=4, max_size=16)


@seed(20261211)
@fuzz(80)
@given(events=CONTROLLER_EVENTS,
       final=st.tuples(st.lists(st.floats(0.0, 3.0e5), min_size=N, max_size=N),
                       st.lists(st.floats(0.0, 0.3), min_size=N, max_size=N),
                       st.floats(0.03, 0.12)))
def test_property_controller_callbacks(events, final):
    inputs = _controller()
    now = 0.0
    for kind, body in events:
        now += 0.02
        measured, goal = inputs.measurements(), _goal_of(inputs.law)
        if kind == 'pressure':
            index, value, frame = body
            check = inputs.offer_pressure(index, value, now, frame)
        elif kind == 'tip_force':
            index, (fx, fz), frame = body
            check = inputs.offer_tip_force(index, fx, fz, frame)
        elif kind == 'aperture':
            check = inputs.offer_aperture(body, now)
        elif kind == 'grasp':
            check = inputs.offer_grasp_force(body, now)
        elif kind == 'refused':
            check = inputs.reject(body, Rejection.MALFORMED, 'junk')
        else:
            out = inputs.law.step(now, inputs.measurements())
            assert out.commands is None or all(
                0.0 <= c <= CONFIG.max_pressure for c in out.commands)
            continue
        event(f'{kind}: {check.rejection.value if check.rejection else "accepted"}')
        if not check.accepted:
            assert inputs.measurements() == measured and _goal_of(inputs.law) == goal
            assert 'rejected' in inputs.problems and len(inputs.problems) < MAX_TEXT
    gauges, forces, aperture = final
    outputs = []
    for subject in (inputs, _controller()):
        for i in range(N):
            assert subject.offer_pressure(i, ATM + gauges[i], now, NAMES[i]).accepted
            assert subject.offer_tip_force(i, 0.0, forces[i], NAMES[i]).accepted
        assert subject.offer_aperture(aperture, now).accepted
        # Every source just fed is clear; a grasp goal rejected earlier stays reported.
        assert subject.problems in ('', ) or subject.problems.startswith(
            'rejected grasp_force_command') and ';' not in subject.problems
        outputs.append(subject.law.step(now + 0.02, subject.measurements()))
    ours, fresh = outputs
    assert ours.mode == fresh.mode and ours.status == fresh.status
    # The estimate is a function of the measurements alone; commands carry the history
    # (slew limit, integrators) by design.
    assert_allclose(ours.aperture, fresh.aperture, rtol=0, atol=1e-9)
    assert_allclose(ours.aperture_target, fresh.aperture_target, rtol=0, atol=1e-12)


# -- regulator_bridge -------------------------------------------------------------------------

LIMITS = {'max_pressure': 4.0e5, 'rate_limit_pa_s': 1.0e6, 'command_timeout_s': 0.5,
          'safe_state': 'vent'}


def _bridge_core():
    backend = SimulatedRegulator(N, noise_std_pa=0.0)
    backend.connect()
    # No tracking fault: the property is about inputs, not the regulator's dynamics.
    core = RegulatorCore(backend, N, LIMITS, MonitorSettings(tracking_timeout_s=0.0))
    core.start(0.0)
    return core


def _supervisor_state(core, index):
    return repr(sorted(vars(core.supervisors[index]).items()))


BRIDGE_EVENTS = st.lists(weighted(
    (3, st.tuples(st.just('command'), FINGERS, PRESSURES, mostly(st.just(''), TEXTS))),
    (1, st.tuples(st.just('refused'), FINGERS,
                  st.sampled_from([Rejection.MALFORMED, Rejection.OVERSIZED]))),
    (2, st.tuples(st.just('step'), st.just(0))),
), min_size=4, max_size=24)


@seed(20261212)
@fuzz(300)
@given(events=BRIDGE_EVENTS, final=st.tuples(FINGERS, st.floats(-5.0e4, 6.0e5)))
def test_property_bridge_callbacks(events, final):
    core = _bridge_core()
    now = 0.0
    for kind, index, *args in events:
        now += 0.02
        before = _supervisor_state(core, index)
        if kind == 'command':
            check, result = core.offer_command(index, args[0], now, atmospheric_pressure=ATM,
                                               frame_id=args[1])
            assert (result is None) == (not check.accepted)
        elif kind == 'refused':
            check = core.reject(index, args[0], 'junk')
        else:
            step = core.step(now)
            assert all(math.isfinite(s.pressure) for s in step.samples)
            assert all(len(r.message) < MAX_TEXT for r in step.reports)
            continue
        event(f'{kind}: {check.rejection.value if check.rejection else "accepted"}')
        if not check.accepted:
            assert _supervisor_state(core, index) == before
            assert core.step(now).reports[index].level >= 1
    index, gauge = final
    answers = []
    for subject in (core, _bridge_core()):
        check, result = subject.offer_command(index, ATM + gauge, now, atmospheric_pressure=ATM)
        assert check.accepted
        answers.append(result)
    ours, fresh = answers
    assert (ours.accepted, ours.clamped) == (fresh.accepted, fresh.clamped)
    assert_allclose(ours.target, fresh.target, rtol=0, atol=1e-9)


# -- the log helper and the payload guard -----------------------------------------------------

LOG_LINES = st.lists(st.tuples(
    st.sampled_from(list(Severity)),
    st.one_of(TEXTS, st.text(alphabet=st.characters(codec=None, exclude_categories=()),
                             max_size=30)),
    st.one_of(st.none(), st.tuples(FINGERS, st.sampled_from(list(Rejection))))),
    max_size=12)


@seed(20261213)
@fuzz(100)
@given(lines=LOG_LINES)
def test_property_node_log_never_raises(lines):
    log = NodeLog(rclpy.logging.get_logger('fpc_gripper_fuzz_log'), throttle_s=0.0)
    for severity, text, key in lines:
        assert log.log(severity, text, key)
    assert log.dropped == 0


@seed(20261214)
@fuzz(500)
@given(payload=st.one_of(st.binary(max_size=120),
                         st.binary(max_size=120).map(lambda b: b'\x00\x01\x00\x00' + b),
                         st.integers(4000, 6000).map(lambda n: b'\x00\x01\x00\x00' * n)))
def test_property_decode_never_raises(payload):
    message, check = decode(payload, FluidPressure, 4096)
    if check is None:
        assert isinstance(message, FluidPressure)
    else:
        assert message is None and check.rejection in (Rejection.MALFORMED,
                                                       Rejection.OVERSIZED)
        assert len(check.detail) < MAX_TEXT
