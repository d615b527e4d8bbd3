"""The Modbus device's own watchdog: its register map entry, armed at each connection, kept."""

import copy
import math
import pathlib

import pytest
from regulator_test_utils import FakeClock
from regulator_test_utils import Server
import yaml

from fpc_gripper.regulators.base import BackendFault
from fpc_gripper.regulators.bridge import BridgeSession
from fpc_gripper.regulators.bridge_parameters import PARAMETERS
from fpc_gripper.regulators.bridge_parameters import refusal
from fpc_gripper.regulators.core import MonitorSettings
from fpc_gripper.regulators.core import RegulatorCore
from fpc_gripper.regulators.modbus import ModbusRegulator
from fpc_gripper.regulators.modbus import RegisterMap
from fpc_gripper.regulators.modbus_sim import SimulatedModbusDevice
from fpc_gripper.regulators.sim import SimulatedRegulator
from fpc_gripper.safe_yaml import ConfigError
from fpc_gripper.safe_yaml import parse_yaml

EXAMPLE = pathlib.Path(__file__).resolve().parents[2] / 'msg_configs' / 'modbus_example.yaml'
FC_HOLDING = 3
WATCHDOG_ADDRESS = 16
#: 12-bit, 0-1 MPa: the example's scaling [count/Pa].
GAIN = 4095 / 1.0e6


def _map_data(timeout_s=0.4, counts_per_s=1000, **entry):
    data = copy.deepcopy(parse_yaml(EXAMPLE.read_text()))
    data['watchdog'] = {'register': {'address': WATCHDOG_ADDRESS, 'type': 'holding'},
                        'timeout_s': timeout_s, 'counts_per_s': counts_per_s, **entry}
    return data


def test_the_example_documents_the_entry_and_has_none_armed():
    text = EXAMPLE.read_text()
    assert '# watchdog:' in text and RegisterMap.from_yaml(EXAMPLE).watchdog is None
    # The commented block, uncommented, is a valid entry.
    block = text[text.index('# watchdog:'):].replace('# ', '', 1).replace('\n#', '\n')
    watchdog = RegisterMap.from_dict({**parse_yaml(text), **parse_yaml(block)}).watchdog
    assert watchdog.register.address == 16 and watchdog.word == 1000


def test_the_entry_reads_its_register_timeout_and_unit():
    watchdog = RegisterMap.from_dict(_map_data(timeout_s=0.3, counts_per_s=10)).watchdog
    assert watchdog.register.address == WATCHDOG_ADDRESS and watchdog.register.kind == 'holding'
    assert watchdog.timeout_s == pytest.approx(0.3) and watchdog.counts_per_s == 10.0
    assert watchdog.word == 3                               # tenths of a second
    assert RegisterMap.from_dict(_map_data(timeout_s=1.5)).watchdog.word == 1500


@pytest.mark.parametrize('change, match', [
    ({'register': {'address': 16, 'type': 'input'}},
     r"watchdog\.register\.type: must be 'holding'"),
    ({'register': {'address': 1}},
     r"watchdog\.register\.address: 1 is a register of channel 'finger_1'"),
    ({'timeout_s': 70.0}, r'watchdog\.timeout_s: must be in \[0\.001, 65\.535\] \[s\], got 70'),
    ({'timeout_s': 0.0004}, r'watchdog\.timeout_s: must be in \[0\.001, 65\.535\] \[s\]'),
    ({'counts_per_s': 0}, r'watchdog\.counts_per_s: must be in \(0, 1e\+06\] \[count/s\]'),
    ({'timeout_s': math.nan}, r'watchdog\.timeout_s: must be a finite number \[s\]'),
    ({'period': 1}, r"watchdog: unknown key\(s\) 'period'"),
])
def test_a_bad_entry_is_refused_naming_the_key_value_and_unit(tmp_path, change, match):
    data = _map_data()
    data['watchdog'].update(change)
    path = tmp_path / 'map.yaml'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ValueError, match=match) as info:
        RegisterMap.from_yaml(path)
    assert str(path) in str(info.value)
    data['watchdog'] = {'timeout_s': 1.0}
    with pytest.raises(ValueError, match=r'watchdog\.register: is missing'):
        RegisterMap.from_dict(data)


@pytest.fixture
def served():
    server = Server()
    yield server
    server.close()


def test_connect_arms_it_and_a_reconnection_arms_it_again(served):
    clock = FakeClock()
    reg = ModbusRegulator(RegisterMap.from_dict(_map_data(timeout_s=0.4)), host='127.0.0.1',
                          port=served.port, timeout_s=0.5, reconnect_interval_s=0.0,
                          clock=clock)
    assert reg.device_watchdog_s == pytest.approx(0.4)
    assert served.get(FC_HOLDING, WATCHDOG_ADDRESS) == 0
    reg.connect()
    try:
        assert served.get(FC_HOLDING, WATCHDOG_ADDRESS) == 400
        # The device goes away and comes back with its registers cleared (a power cycle).
        served.stop()
        with pytest.raises(BackendFault):
            reg.set_pressure(0, 1.0e5)
        served.start()
        assert served.get(FC_HOLDING, WATCHDOG_ADDRESS) == 0
        reg.set_pressure(0, 1.0e5)                       # reconnects, and arms first
        assert served.get(FC_HOLDING, WATCHDOG_ADDRESS) == 400
        assert served.get(FC_HOLDING, 0) == round(1.0e5 * GAIN)
    finally:
        reg.close()
    assert ModbusRegulator(EXAMPLE).device_watchdog_s is None


def test_a_device_that_refuses_the_timeout_is_not_connected():
    from pymodbus.constants import ExcCodes

    async def refuse(function_code, start, address, count, registers, values):
        return ExcCodes.ILLEGAL_ADDRESS if values and address == WATCHDOG_ADDRESS else None

    server = Server(action=refuse)
    try:
        reg = ModbusRegulator(RegisterMap.from_dict(_map_data()), host='127.0.0.1',
                              port=server.port)
        with pytest.raises(BackendFault, match=r'cannot arm the device watchdog \(register '
                                               r'16, 0\.4 s\).*exception response'):
            reg.connect()
        assert not reg.status().ok and not reg.status().connected
    finally:
        server.close()


class Rig:
    """The bridge's control step on Modbus; the device a SimulatedRegulator behind a server."""

    def __init__(self, timeout_s=0.4):
        self.clock = FakeClock()
        regulator = SimulatedRegulator(3, time_constant_s=0.15, deadband_pa=0.0,
                                       noise_std_pa=0.0, clock=self.clock)
        regulator.connect()
        rmap = RegisterMap.from_dict(_map_data(timeout_s=timeout_s))
        self.device = SimulatedModbusDevice(rmap, regulator, self.clock)
        self.server = Server(action=self.device.action)
        self.backend = ModbusRegulator(rmap, host='127.0.0.1', port=self.server.port,
                                       clock=self.clock)
        self.backend.connect()
        self.core = RegulatorCore(self.backend, 3, dict(
            max_pressure=4.0e5, rate_limit_pa_s=1.0e7, command_timeout_s=5.0,
            safe_state='hold'), MonitorSettings(tracking_timeout_s=0.0))
        self.core.start(self.clock())

    def steps(self, seconds, dt=0.05, command=2.0e5):
        for _ in range(round(seconds / dt)):
            for i in range(3):
                self.core.command(i, command, self.clock())
            self.last = self.core.step(self.clock())
            self.clock.now += dt

    def close(self):
        self.backend.close()
        self.server.close()


@pytest.fixture
def rig():
    rig = Rig()
    yield rig
    rig.close()


def test_a_stepping_bridge_keeps_the_device_up(rig):
    assert rig.device.timeout_s == pytest.approx(0.4)
    rig.steps(3.0)
    assert rig.device.trips == []
    assert {r.values['device_watchdog_s'] for r in rig.last.reports} == {'0.4'}
    for i in range(3):
        assert rig.device.regulator.setpoint(i) == pytest.approx(2.0e5, abs=1.0 / GAIN)
        assert rig.device.regulator.true_pressure(i) == pytest.approx(2.0e5, rel=1e-3)


def test_a_bridge_that_stops_writing_has_the_device_vent_then_resume(rig):
    rig.steps(2.0)
    last_write = rig.clock.now - 0.05
    # The bridge hangs: nothing talks to the device. Its own watchdog is 5 s away, and
    # `hold` would keep 200 kPa anyway; the device's 0.4 s is what vents.
    rig.clock.now = last_write + 0.39
    assert not rig.device.tick()
    rig.clock.now = last_write + 0.41
    assert rig.device.tick() and len(rig.device.trips) == 1
    assert rig.device.trips[0][1] == pytest.approx(last_write)
    assert not rig.device.tick()                              # vented once, not again
    rig.clock.now += 1.5                                      # 10 time constants
    for i in range(3):
        assert rig.device.regulator.setpoint(i) == 0.0
        assert rig.device.regulator.true_pressure(i) < 2.0e5 * math.exp(-1.5 / 0.15) + 1.0
    # A read of the setpoint register tells a client the device vented.
    assert rig.backend._request('read_holding_registers', 0, count=1).registers == [0]
    # The bridge comes back: its first write brings the channels back.
    rig.steps(2.0)
    assert len(rig.device.trips) == 1
    assert rig.device.regulator.true_pressure(0) == pytest.approx(2.0e5, rel=1e-3)


def test_a_disarmed_device_never_vents(rig):
    rig.backend._request('write_register', WATCHDOG_ADDRESS, 0)
    assert rig.device.timeout_s is None
    rig.steps(1.0)
    rig.clock.now += 60.0
    assert not rig.device.tick() and rig.device.regulator.setpoint(0) == pytest.approx(
        2.0e5, abs=1.0 / GAIN)


def _values(**changes):
    values = {row[0]: row[1] for row in PARAMETERS}
    values.update(use_sim_time=False, **changes)
    return values


def test_the_bridge_refuses_a_device_watchdog_shorter_than_three_control_periods(tmp_path):
    path = tmp_path / 'map.yaml'
    path.write_text(yaml.safe_dump(_map_data(timeout_s=0.05)))
    session = BridgeSession()
    with pytest.raises(ConfigError, match=r'watchdog\.timeout_s: the device watchdog\'s '
                                          r'timeout_s 0\.05 s is shorter than 3 control '
                                          r'periods at `publish_rate_hz` 50 Hz \(0\.06 s\)'):
        session.load(_values(backend='modbus', modbus_config=str(path)))
    session.load(_values(backend='modbus', modbus_config=str(path), publish_rate_hz=100.0))
    # The same check on a change of rate while configured.
    assert refusal('publish_rate_hz', 50.0, device_watchdog_s=0.05).startswith(
        "the device watchdog's timeout_s 0.05 s")
    assert refusal('publish_rate_hz', 60.0, device_watchdog_s=0.05) is None
    assert refusal('publish_rate_hz', 1.0, device_watchdog_s=None) is None
