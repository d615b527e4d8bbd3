"""The regulator bridge without ROS: its parameter table and checks, session and schedule."""

import inspect

import pytest
from regulator_test_utils import FakeClock

from fpc_gripper.io.config import default_gripper_config_path
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.regulators.base import BackendFault
from fpc_gripper.regulators.bridge import BridgeSession
from fpc_gripper.regulators.bridge import DiagnosticsSchedule
from fpc_gripper.regulators.bridge_parameters import LIMIT_PARAMETERS
from fpc_gripper.regulators.bridge_parameters import limits
from fpc_gripper.regulators.bridge_parameters import PARAMETERS
from fpc_gripper.regulators.bridge_parameters import refusal
from fpc_gripper.regulators.bridge_parameters import SIM_PARAMETERS
from fpc_gripper.regulators.bridge_parameters import SIM_TIME_REFUSED
from fpc_gripper.regulators.bridge_parameters import STRUCTURAL
from fpc_gripper.regulators.core import ChannelReport
from fpc_gripper.regulators.core import Level
from fpc_gripper.regulators.safety import SupervisorMode
from fpc_gripper.regulators.sim import SimulatedRegulator
from fpc_gripper.safe_yaml import ConfigError
from fpc_gripper.services.input_limits import DEFAULT_BOUNDS

CONFIG = load_gripper_config(default_gripper_config_path())
DEFAULTS = {name: default for name, default, _, _ in PARAMETERS}


def values(**changes):
    """The parameter values a bridge configures with: the table's defaults, then `changes`."""
    return {**DEFAULTS, 'use_sim_time': False, **changes}


# -- the parameter table ---------------------------------------------------------------------

def test_the_named_groups_are_parameters_of_the_table():
    assert len(DEFAULTS) == len(PARAMETERS)
    assert set(STRUCTURAL) | set(LIMIT_PARAMETERS) <= set(DEFAULTS)
    assert len(SIM_PARAMETERS) == 8


def test_the_simulated_backend_defaults_are_the_simulated_regulators():
    # The table's sim_* rows are SimulatedRegulator's arguments: the same defaults.
    signature = inspect.signature(SimulatedRegulator)
    for name in SIM_PARAMETERS:
        argument = signature.parameters[name[len('sim_'):]].default
        assert DEFAULTS[name] == pytest.approx(argument), name


# -- the checks on a change ------------------------------------------------------------------

def test_a_structural_parameter_is_refused_while_configured_and_says_so():
    reason = refusal('sim_seed', 3, configured=True, state='inactive', backend_kind='sim')
    assert '`sim_seed` is read at configure' in reason and 'inactive' in reason
    assert refusal('sim_seed', 3, configured=False) is None
    assert refusal('max_pressure', 3.0e5, configured=True, state='active') is None


@pytest.mark.parametrize('name, good, bad', [('backend', 'modbus', 'serial'),
                                             ('safe_state', 'hold', 'drop')])
def test_a_choice_outside_its_list_is_refused_naming_the_value(name, good, bad):
    assert refusal(name, good) is None
    reason = refusal(name, bad)
    assert reason.startswith(f'`{name}` must be one of') and repr(bad) in reason


def test_simulated_time_is_refused_only_for_a_configured_real_regulator():
    assert refusal('use_sim_time', True, configured=True, backend_kind='modbus') \
        == SIM_TIME_REFUSED
    assert refusal('use_sim_time', True, configured=True, backend_kind='sim') is None
    assert refusal('use_sim_time', True, configured=False, backend_kind='modbus') is None
    assert refusal('use_sim_time', False, configured=True, backend_kind='modbus') is None


def test_the_limits_are_capped_by_the_gripper_config():
    wanted = values(max_pressure=5.0e5, safe_state='hold')
    assert limits(wanted, 4.0e5)['max_pressure'] == pytest.approx(4.0e5)
    assert limits(wanted, 6.0e5)['max_pressure'] == pytest.approx(5.0e5)
    assert limits(wanted)['safe_state'] == 'hold'
    assert set(limits(wanted)) == set(LIMIT_PARAMETERS)


# -- the session -----------------------------------------------------------------------------

def test_load_names_the_fingers_and_their_frames_and_says_nothing_by_default():
    session = BridgeSession()
    assert session.load(values(frame_prefix='left/')) == []
    assert session.finger_names == CONFIG.names
    assert session.frames == tuple('left/' + name for name in CONFIG.names)
    assert session.backend is None and session.core is None


def test_load_notes_what_the_gripper_config_overrides():
    notes = BridgeSession().load(values(max_pressure=6.0e5, atmospheric_pressure=9.0e4))
    assert [level for level, _ in notes] == [Level.WARN, Level.OK]
    assert 'max_pressure 600000 Pa exceeds the gripper config limit 400000' in notes[0][1]
    assert 'atmospheric_pressure parameter 90000 Pa differs' in notes[1][1]


def test_load_refuses_a_bad_choice_and_a_real_regulator_on_simulated_time():
    with pytest.raises(ValueError, match='`safe_state` must be one of'):
        BridgeSession().load(values(safe_state='drop'))
    with pytest.raises(ConfigError, match='use_sim_time') as error:
        BridgeSession().load(values(backend='modbus', use_sim_time=True))
    assert error.value.reason == SIM_TIME_REFUSED
    with pytest.raises(ConfigError, match='modbus_config: is empty'):
        BridgeSession().load(values(backend='modbus'))


def test_connect_builds_the_simulated_backend_from_the_sim_parameters():
    session = BridgeSession()
    wanted = values(sim_time_constant_s=0.3, sim_adc_bits=10, max_pressure=3.0e5)
    session.load(wanted)
    session.connect(wanted, DEFAULT_BOUNDS, FakeClock())
    assert session.kind == 'sim'
    assert isinstance(session.backend, SimulatedRegulator)
    assert session.backend.n_channels == len(CONFIG.names)
    assert session.backend.time_constant_s == pytest.approx(0.3)
    assert session.backend.adc_bits == 10
    assert [s.max_pressure for s in session.core.supervisors] == pytest.approx(
        [3.0e5] * len(CONFIG.names))


class Backend:
    """A backend with too few channels or failing writes, that says whether it was closed."""

    def __init__(self, n_channels, fail=False):
        self.n_channels = n_channels
        self.fail = fail
        self.closed = False
        self.written = {}

    def connect(self):
        pass

    def close(self):
        self.closed = True

    def set_pressure(self, channel, pressure):
        if self.fail:
            raise BackendFault(f'channel {channel} unreachable')
        self.written[channel] = pressure


def test_a_backend_with_too_few_channels_is_refused_and_abandoned_unused():
    backend = Backend(1)
    session = BridgeSession(backend)
    session.load(values())
    with pytest.raises(ValueError, match='backend has 1 channels, the gripper config needs 3'):
        session.connect(values(), DEFAULT_BOUNDS, FakeClock())
    assert session.kind == 'injected' and session.core is None
    session.abandon()
    assert backend.closed and backend.written == {} and session.backend is None


def test_release_sends_each_channel_its_safe_state_then_closes():
    backend = Backend(3)
    session = BridgeSession(backend)
    session.load(values(safe_state='vent'))
    session.connect(values(), DEFAULT_BOUNDS, FakeClock())
    session.core.command(1, 2.0e5, 100.0)
    failed = session.release(100.1)
    assert backend.closed and session.backend is None
    assert failed == []
    assert backend.written == pytest.approx({0: 0.0, 1: 0.0, 2: 0.0})


def test_release_lists_the_channels_it_could_not_reach():
    backend = Backend(3)
    session = BridgeSession(backend)
    session.load(values())
    session.connect(values(), DEFAULT_BOUNDS, FakeClock())
    backend.fail = True
    failed = session.release(100.0)
    assert [channel for channel, _ in failed] == [0, 1, 2]
    assert 'unreachable' in failed[0][1] and backend.closed


# -- the diagnostics schedule ----------------------------------------------------------------

def reports(level=Level.OK, mode=SupervisorMode.TRACKING):
    return [ChannelReport(level, mode, 'ok', {}), ChannelReport(Level.OK, mode, 'ok', {})]


def test_diagnostics_are_due_first_then_once_a_period():
    schedule = DiagnosticsSchedule()
    assert schedule.due(10.0, reports(), 0.5)
    assert not schedule.due(10.2, reports(), 0.5)
    assert not schedule.due(10.49, reports(), 0.5)
    assert schedule.due(10.5, reports(), 0.5)
    assert not schedule.due(10.6, reports(), 0.5)


def test_diagnostics_are_due_at_a_change_of_level_or_mode_and_when_forced():
    schedule = DiagnosticsSchedule()
    schedule.due(10.0, reports(), 0.5)
    assert schedule.due(10.1, reports(Level.WARN), 0.5)
    assert not schedule.due(10.2, reports(Level.WARN), 0.5)
    assert schedule.due(10.3, reports(Level.WARN, SupervisorMode.WATCHDOG), 0.5)
    assert schedule.due(10.35, reports(Level.WARN, SupervisorMode.WATCHDOG), 0.5, force=True)


def test_a_clock_that_steps_back_does_not_silence_the_diagnostics():
    schedule = DiagnosticsSchedule()
    schedule.due(100.0, reports(), 0.5)
    assert schedule.due(3.0, reports(), 0.5)
    assert not schedule.due(3.1, reports(), 0.5)


def test_a_restart_makes_the_next_report_due():
    schedule = DiagnosticsSchedule()
    schedule.due(10.0, reports(), 0.5)
    schedule.restart()
    assert schedule.due(10.1, reports(), 0.5)
