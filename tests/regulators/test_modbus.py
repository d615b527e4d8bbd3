"""Tests of the Modbus backend against an in-process pymodbus TCP server on 127.0.0.1."""

import copy
import math
import pathlib
import subprocess
import sys

from numpy.testing import assert_allclose
import pytest
from regulator_test_utils import Server
import yaml

from fpc_gripper.regulators.base import BackendFault
from fpc_gripper.regulators.base import RegulatorBackend
from fpc_gripper.regulators.factory import make_backend
from fpc_gripper.regulators.modbus import ModbusRegulator
from fpc_gripper.regulators.modbus import RegisterMap
from fpc_gripper.regulators.sim import SimulatedRegulator
from fpc_gripper.safe_yaml import parse_yaml

EXAMPLE = pathlib.Path(__file__).resolve().parents[2] / 'msg_configs' / 'modbus_example.yaml'
FC_HOLDING, FC_INPUT = 3, 4


@pytest.fixture(scope='module')
def server():
    srv = Server()
    yield srv
    srv.close()


@pytest.fixture
def regulator(server):
    reg = ModbusRegulator(EXAMPLE, host='127.0.0.1', port=server.port, timeout_s=1.0)
    reg.connect()
    yield reg
    reg.close()


def test_example_map_describes_a_3_channel_0_10_bar_12_bit_regulator():
    rmap = RegisterMap.from_yaml(EXAMPLE)
    assert len(rmap.channels) == 3
    for i, channel in enumerate(rmap.channels):
        assert channel.setpoint.kind == 'holding' and channel.readback.kind == 'input'
        assert channel.setpoint.address == i
        assert channel.scaling.to_counts(1.0e6) == 4095
        assert channel.scaling.to_counts(0.0) == 0
        assert_allclose(channel.scaling.to_pressure(4095), 1.0e6)


def test_is_a_regulator_backend(regulator):
    assert isinstance(regulator, RegulatorBackend)
    assert regulator.status().ok and regulator.n_channels == 3


@pytest.mark.parametrize('pressure', [0.0, 1234.5, 2.0e5, 4.0e5, 9.99e5])
def test_setpoint_register_readback_round_trip(server, regulator, pressure):
    channel = 1
    regulator.set_pressure(channel, pressure)
    counts = server.get(FC_HOLDING, channel)
    assert counts == round(pressure * 4095 / 1.0e6)
    # The "device" reaches its setpoint: copy the setpoint word into the readback register.
    server.put(FC_INPUT, channel, counts)
    value, variance = regulator.read_pressure(channel)
    lsb = 1.0e6 / 4095
    assert_allclose(value, counts * lsb, rtol=1e-12)
    assert abs(value - pressure) <= lsb / 2
    assert_allclose(variance, 500.0 ** 2 + lsb ** 2 / 12)


def test_setpoint_saturates_to_the_register_range(server, regulator):
    regulator.set_pressure(2, 5.0e6)
    assert server.get(FC_HOLDING, 2) == 4095
    regulator.set_pressure(2, -3.0e4)
    assert server.get(FC_HOLDING, 2) == 0


def test_offset_signed_and_holding_readback(server):
    data = {
        'connection': {'host': '127.0.0.1', 'port': server.port, 'unit': 1},
        'channels': [
            {'setpoint': {'address': 10}, 'readback': {'address': 11, 'type': 'holding'},
             'scaling': {'full_scale_counts': 4095, 'full_scale_pa': 1.0e6,
                         'offset_counts': 819}},
            {'setpoint': {'address': 12}, 'readback': {'address': 12, 'type': 'input'},
             'scaling': {'counts_per_pa': 0.01, 'offset_counts': -1000, 'signed': True}},
        ],
    }
    reg = ModbusRegulator(RegisterMap.from_dict(data))
    reg.connect()
    try:
        reg.set_pressure(0, 5.0e5)
        assert server.get(FC_HOLDING, 10) == round(819 + 5.0e5 * (4095 - 819) / 1.0e6)
        server.put(FC_HOLDING, 11, 819 + 3276)
        assert_allclose(reg.read_pressure(0)[0], 1.0e6)
        reg.set_pressure(1, 5.0e4)               # -1000 + 500 = -500 counts, int16
        assert server.get(FC_HOLDING, 12) == 0x10000 - 500
        server.put(FC_INPUT, 12, 0x10000 - 1500)
        assert_allclose(reg.read_pressure(1)[0], -5.0e4)
    finally:
        reg.close()


def test_exception_response_is_a_backend_fault_that_clears(server):
    data = parse_yaml(EXAMPLE.read_text())
    data['channels'][0]['readback']['address'] = 500      # outside the device's registers
    reg = ModbusRegulator(RegisterMap.from_dict(data), host='127.0.0.1', port=server.port)
    reg.connect()
    try:
        with pytest.raises(BackendFault, match='read_input_registers'):
            reg.read_pressure(0)
        status = reg.status()
        assert not status.ok and 'exception response' in status.fault
        reg.read_pressure(1)
        assert reg.status().ok
    finally:
        reg.close()


def test_unreachable_device_raises_backend_fault():
    import socket
    with socket.socket() as probe:                   # a port nobody listens on
        probe.bind(('127.0.0.1', 0))
        port = probe.getsockname()[1]
    reg = ModbusRegulator(EXAMPLE, host='127.0.0.1', port=port, timeout_s=0.2)
    with pytest.raises(BackendFault, match='cannot connect'):
        reg.connect()
    assert not reg.status().ok
    with pytest.raises(BackendFault):
        reg.set_pressure(0, 1.0e5)


def _mutate(path, value):
    data = copy.deepcopy(parse_yaml(EXAMPLE.read_text()))
    node = data
    for key in path[:-1]:
        node = node[key]
    if value is _DELETE:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return data


_DELETE = object()


@pytest.mark.parametrize('path, value, match', [
    (('colour',), 'red', r"unknown key\(s\) 'colour'"),
    (('channels', 1, 'readback'), _DELETE, r'channels\[1\]\.readback: is missing'),
    (('channels', 0, 'setpoint', 'type'), 'input',
     r"channels\[0\]\.setpoint\.type: must be 'holding'"),
    (('channels', 2, 'readback', 'type'), 'coil',
     r'channels\[2\]\.readback\.type: must be one of holding, input'),
    (('channels', 0, 'setpoint', 'address'), 70000,
     r'channels\[0\]\.setpoint\.address: must be an integer in \[0, 65535\], got 70000'),
    (('channels', 0, 'setpoint', 'adress'), 3,
     r"channels\[0\]\.setpoint: unknown key\(s\) 'adress'"),
    (('scaling', 'counts_per_pa'), 0.004, r"scaling: needs either 'counts_per_pa' or both"),
    (('scaling', 'full_scale_pa'), -1.0,
     r'scaling\.full_scale_pa: must be in \(0, 1e\+08\] \[Pa\], got -1\.0'),
    (('scaling', 'full_scale_pa'), _DELETE, r'scaling\.full_scale_pa: is missing'),
    (('connection', 'port'), 'http', r'connection\.port: must be an integer in \[1, 65535\]'),
    (('connection', 'unit'), 2, r"connection: give 'device_id' or its alias 'unit', not both"),
    (('channels',), [], r'channels: must hold 1 to 64 channel mappings, got 0'),
    (('channels', 0, 'name'), 'x' * 65, r'channels\[0\]\.name: must be at most 64 characters'),
    (('connection', 'timeout_s'), 1.0e9, r'connection\.timeout_s: must be in \(0, 60\] \[s\]'),
])
def test_bad_register_maps_name_the_key(tmp_path, path, value, match):
    bad = tmp_path / 'bad.yaml'
    bad.write_text(yaml.safe_dump(_mutate(path, value)))
    with pytest.raises(ValueError, match=match) as info:
        RegisterMap.from_yaml(bad)
    assert str(bad) in str(info.value)


def test_malformed_yaml_and_missing_file(tmp_path):
    bad = tmp_path / 'broken.yaml'
    bad.write_text('channels: [\n  {setpoint: ')
    with pytest.raises(ValueError, match='malformed YAML'):
        RegisterMap.from_yaml(bad)
    with pytest.raises(ValueError, match='cannot read Modbus register map'):
        RegisterMap.from_yaml(tmp_path / 'absent.yaml')
    bad.write_text('- 1\n- 2\n')
    with pytest.raises(ValueError, match='expected a mapping'):
        RegisterMap.from_yaml(bad)


def test_factory_builds_both_kinds_and_lists_valid_kinds():
    assert isinstance(make_backend('sim', n_channels=2), SimulatedRegulator)
    reg = make_backend('modbus', register_map=EXAMPLE, port=1502)
    assert isinstance(reg, ModbusRegulator) and reg.register_map.port == 1502
    with pytest.raises(ValueError, match=r"\['sim', 'modbus'\], got 'serial'"):
        make_backend('serial')


def test_pymodbus_is_imported_lazily():
    code = ('import sys, fpc_gripper.regulators.factory as f; '
            'f.make_backend("modbus", register_map=sys.argv[1]); '
            'print("pymodbus" in sys.modules)')
    out = subprocess.run([sys.executable, '-c', code, str(EXAMPLE)], capture_output=True,
                         text=True, check=True, timeout=60)
    assert out.stdout.strip() == 'False'


def test_variance_matches_the_resolution_of_the_map():
    rmap = RegisterMap.from_yaml(EXAMPLE)
    lsb = rmap.channels[0].scaling.resolution_pa
    assert_allclose(lsb, 1.0e6 / 4095)
    assert math.isclose(rmap.noise_std_pa, 500.0)
