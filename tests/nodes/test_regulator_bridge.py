"""Tests of the regulator bridge lifecycle node with real rclpy nodes and the simulated backend."""

import itertools
import math
import pathlib
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from diagnostic_msgs.msg import DiagnosticStatus
import pytest
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.msg import ParameterValue
from rcl_interfaces.srv import SetParameters
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rclpy.qos import ReliabilityPolicy
from sensor_msgs.msg import FluidPressure

from fpc_gripper.io.config import default_gripper_config_path
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.nodes.regulator_bridge import RegulatorBridge
from fpc_gripper.regulators.safety import SAFE_MODES

pytestmark = pytest.mark.ros

ATM = 101325.0
CONFIG = load_gripper_config(default_gripper_config_path())
MODBUS_MAP = pathlib.Path(__file__).resolve().parents[2] / 'msg_configs' / 'modbus_example.yaml'
FINGERS = CONFIG.names
_counter = itertools.count()


@pytest.fixture(scope='module')
def ros():
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    yield context, executor
    executor.shutdown()
    rclpy.shutdown(context=context)


class Rig:
    """A bridge under test plus a probe node that commands it and records its outputs."""

    def __init__(self, ros, **params):
        self.context, self.executor = ros
        self.ns = f'/rb{next(_counter)}'
        overrides = [Parameter(k, value=v) for k, v in params.items()]
        self.bridge = RegulatorBridge.create_active(
            namespace=self.ns, context=self.context, parameter_overrides=overrides)
        self.probe = rclpy.create_node(f'probe{next(_counter)}', namespace=self.ns,
                                       context=self.context)
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        deep_best_effort = QoSProfile(depth=200, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.pressure = {name: [] for name in FINGERS}
        self.diagnostics = []
        self.commands = {name: self.probe.create_publisher(
            FluidPressure, f'{name}/pressure_command', reliable) for name in FINGERS}
        for name in FINGERS:
            self.probe.create_subscription(
                FluidPressure, f'{name}/pressure', self.pressure[name].append, deep_best_effort)
        self.probe.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, reliable)
        self.executor.add_node(self.bridge)
        self.executor.add_node(self.probe)
        self.spin_until(lambda: all(self.pressure.values())
                        and all(p.get_subscription_count() for p in self.commands.values()))

    def _on_diag(self, msg):
        prefix = f'{self.bridge.get_fully_qualified_name()}: '
        mine = [s for s in msg.status if s.name.startswith(prefix)]
        if mine:
            self.diagnostics.append((msg.header.stamp, mine))

    def spin_until(self, condition, timeout=10.0):
        deadline = time.monotonic() + timeout
        while not condition():
            assert time.monotonic() < deadline, 'condition not met in time'
            self.executor.spin_once(timeout_sec=0.01)

    def spin_for(self, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.01)

    def command(self, name, absolute):
        msg = FluidPressure()
        msg.header.frame_id = name
        msg.fluid_pressure = float(absolute)
        self.commands[name].publish(msg)

    def last_status(self, name):
        for _, statuses in reversed(self.diagnostics):
            for status in statuses:
                if status.name.endswith(f': {name}'):
                    return status
        return None

    def close(self):
        for node in (self.bridge, self.probe):
            self.executor.remove_node(node)
            node.destroy_node()


@pytest.fixture
def rig(ros, request):
    rigs = []

    def make(**params):
        rigs.append(Rig(ros, **params))
        return rigs[-1]

    yield make
    for r in rigs:
        r.close()


def values(status):
    return {kv.key: kv.value for kv in status.values}


def stamp_s(msg):
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def test_step_follows_the_exact_first_order_response(rig):
    tau, step = 0.1, 2.0e5
    r = rig(sim_time_constant_s=tau, sim_noise_std_pa=0.0, sim_deadband_pa=0.0,
            sim_slew_rate_pa_s=1.0e10, rate_limit_pa_s=1.0e9, command_timeout_s=5.0)
    lsb = 1.0e6 / 4095
    samples = r.pressure[FINGERS[0]]
    r.command(FINGERS[0], ATM + step)
    r.spin_until(lambda: any(m.fluid_pressure > ATM + 0.99 * step for m in samples))
    # The setpoint is applied at a control step whose own sample is still atmospheric; every
    # later sample must lie on y(t) = step (1 - exp(-(t - t0) / tau)), quantised to 12 bits.
    rising = [i for i, m in enumerate(samples) if m.fluid_pressure > ATM]
    t0 = stamp_s(samples[rising[0] - 1])
    checked = 0
    for msg in samples[rising[0]:]:
        expected = step * (1.0 - math.exp(-(stamp_s(msg) - t0) / tau))
        assert abs(msg.fluid_pressure - ATM - expected) <= lsb / 2 + 2.0, (stamp_s(msg) - t0)
        checked += 1
    assert checked >= 5
    first = samples[rising[0]]
    assert first.header.frame_id == FINGERS[0]
    assert math.isclose(first.variance, lsb ** 2 / 12, rel_tol=1e-9)
    # Exact: an idle channel stays at 0.0 (no noise, no command), quantised to 0.0.
    for name in FINGERS[1:]:
        assert all(m.fluid_pressure == ATM for m in r.pressure[name])


def test_command_above_the_limit_is_clamped(rig):
    r = rig(rate_limit_pa_s=1.0e7, command_timeout_s=5.0, diagnostics_rate_hz=20.0)
    limit = min(4.0e5, CONFIG.max_pressure)
    sim = r.bridge.backend
    name = FINGERS[1]
    r.command(name, ATM + 9.0e5)
    r.spin_until(lambda: r.last_status(name) is not None
                 and values(r.last_status(name))['clamped'] == 'True')
    r.spin_for(0.3)
    # Reached the limit (the last rate-limited step lands on it to round-off), and not
    # beyond: the setpoint is clamped with min(), so `<= limit` is exact.
    assert sim.setpoint(1) == pytest.approx(limit, rel=0, abs=1e-6)
    assert sim.setpoint(1) <= limit
    assert max(float(values(s)['setpoint_pa_gauge'])
               for _, ss in r.diagnostics for s in ss if s.name.endswith(name)) <= limit
    status = r.last_status(name)
    assert values(status)['command_pa_gauge'] == f'{9.0e5:.1f}'
    assert status.level == DiagnosticStatus.OK
    # The sim saturates at 700 kPa, so an unclamped setpoint would show above the limit.
    assert max(m.fluid_pressure for m in r.pressure[name]) - ATM <= limit + 4 * 300.0


def test_invalid_commands_are_rejected(rig):
    r = rig()
    for bad in (math.nan, math.inf, -5.0):
        r.command(FINGERS[0], bad)
    r.spin_for(0.2)
    assert r.bridge.supervisors[0].mode.name == 'IDLE'
    assert r.bridge.backend.setpoint(0) == 0.0          # the idle setpoint, 0.0: exact


@pytest.mark.parametrize('safe_state', ['vent', 'hold'])
def test_watchdog_enters_the_safe_state_and_reports_it(rig, safe_state):
    timeout = 0.3
    r = rig(command_timeout_s=timeout, safe_state=safe_state, rate_limit_pa_s=1.0e7,
            diagnostics_rate_hz=20.0)
    name = FINGERS[2]
    r.command(name, ATM + 1.5e5)
    r.spin_until(lambda: r.last_status(name) is not None
                 and values(r.last_status(name))['mode'] == 'tracking')
    r.spin_until(lambda: r.last_status(name).level == DiagnosticStatus.WARN)
    status = r.last_status(name)
    vals = values(status)
    assert vals['watchdog'] == 'expired' and 'watchdog' in status.message
    assert float(vals['command_age_s']) > timeout
    expected = 0.0 if safe_state == 'vent' else 1.5e5
    assert float(vals['setpoint_pa_gauge']) == pytest.approx(expected, abs=1e-6)
    assert r.bridge.backend.setpoint(2) == pytest.approx(expected, abs=1e-6)
    # A fresh command leaves the safe state.
    r.command(name, ATM + 1.0e5)
    r.spin_until(lambda: values(r.last_status(name))['mode'] == 'tracking')
    assert r.last_status(name).level == DiagnosticStatus.OK


def test_backend_fault_gives_error_diagnostics_and_the_safe_state(rig):
    r = rig(rate_limit_pa_s=1.0e7, command_timeout_s=5.0, diagnostics_rate_hz=20.0)
    sim = r.bridge.backend
    r.command(FINGERS[0], ATM + 2.0e5)
    # The setpoint ramps there through the rate limit: to round-off, not bitwise.
    r.spin_until(lambda: sim.setpoint(0) == pytest.approx(2.0e5, rel=0, abs=1e-6))
    sim.inject_fault('disconnect')
    r.spin_until(lambda: all(r.last_status(n).level == DiagnosticStatus.ERROR for n in FINGERS))
    for name in FINGERS:
        status = r.last_status(name)
        assert 'fault: backend' in status.message and values(status)['mode'] == 'fault'
        assert float(values(status)['setpoint_pa_gauge']) == 0.0    # vented to 0.0: exact
    assert all(sup.mode in SAFE_MODES for sup in r.bridge.supervisors)
    sim.clear_faults()
    r.spin_until(lambda: r.last_status(FINGERS[0]).level == DiagnosticStatus.WARN)
    assert sim.setpoint(0) == 0.0                      # vented, and stays so until commanded
    r.command(FINGERS[0], ATM + 1.0e5)
    r.spin_until(lambda: r.last_status(FINGERS[0]).level == DiagnosticStatus.OK)
    r.spin_until(lambda: sim.setpoint(0) == pytest.approx(1.0e5, rel=0, abs=1e-6))


def test_a_readback_that_is_not_a_measurement_is_never_published(rig):
    r = rig(rate_limit_pa_s=1.0e7, command_timeout_s=5.0, diagnostics_rate_hz=20.0)
    name, other = FINGERS[0], FINGERS[1]
    r.command(name, ATM + 1.0e5)
    r.spin_until(lambda: r.last_status(name) is not None
                 and values(r.last_status(name))['mode'] == 'tracking')
    r.bridge.backend.inject_fault('bad_readback', 0, value=math.nan)
    r.spin_until(lambda: r.last_status(name).level == DiagnosticStatus.ERROR)
    published, still = len(r.pressure[name]), len(r.pressure[other])
    r.spin_for(0.3)
    status = r.last_status(name)
    assert 'not finite' in status.message and values(status)['mode'] == 'fault'
    assert float(values(status)['setpoint_pa_gauge']) == 0.0        # vented to 0.0: exact
    assert all(math.isfinite(m.fluid_pressure) for m in r.pressure[name])
    assert len(r.pressure[name]) == published        # nothing more from the bad channel
    assert len(r.pressure[other]) > still            # the other channels go on


def test_out_of_range_parameters_are_refused_with_a_reason(rig):
    r = rig()
    client = r.probe.create_client(SetParameters, f'{r.ns}/regulator_bridge/set_parameters')
    r.spin_until(client.service_is_ready)

    def set_remote(name, value):
        if isinstance(value, str):
            pv = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value)
        else:
            pv = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)
        future = client.call_async(SetParameters.Request(
            parameters=[ParameterMsg(name=name, value=pv)]))
        r.spin_until(future.done)
        return future.result().results[0]

    result = set_remote('max_pressure', 2.0e6)
    assert not result.successful and 'max_pressure' in result.reason
    result = set_remote('command_timeout_s', -1.0)
    assert not result.successful and result.reason
    result = set_remote('safe_state', 'explode')
    assert not result.successful and "['hold', 'vent']" in result.reason
    result = set_remote('backend', 'modbus')
    assert not result.successful and 'cleanup' in result.reason
    # Exact here and below: parameter values passed through unchanged.
    assert r.bridge.get_parameter('max_pressure').value == 4.0e5
    result = set_remote('max_pressure', 3.0e5)
    assert result.successful
    assert all(s.max_pressure == min(3.0e5, CONFIG.max_pressure) for s in r.bridge.supervisors)


def test_lifecycle_deactivate_vents_and_cleanup_closes(ros):
    context, executor = ros
    bridge = RegulatorBridge(namespace='/lc', context=context, parameter_overrides=[
        Parameter('auto_activate', value=True), Parameter('rate_limit_pa_s', value=1.0e9),
        Parameter('command_timeout_s', value=10.0)])
    executor.add_node(bridge)
    try:
        assert bridge.lifecycle_state == 'active'
        sim = bridge.backend
        bridge.supervisors[0].command(1.0e5, bridge.get_clock().now().nanoseconds * 1e-9)
        deadline = time.monotonic() + 10.0
        while sim.setpoint(0) != pytest.approx(1.0e5, rel=0, abs=1e-6):
            assert time.monotonic() < deadline
            executor.spin_once(timeout_sec=0.01)
        bridge.trigger_deactivate()
        # Exact: deactivating vents to the setpoint 0.0.
        assert bridge.lifecycle_state == 'inactive' and sim.setpoint(0) == 0.0
        bridge.trigger_cleanup()
        assert bridge.lifecycle_state == 'unconfigured' and bridge.backend is None
        assert not sim.status().connected
    finally:
        executor.remove_node(bridge)
        bridge.destroy_node()


def test_a_real_regulator_refuses_simulated_time(ros, tmp_path):
    """Modbus with use_sim_time: refused at configure (before the map is read) and at a set."""
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / 'regulators'))
    from regulator_test_utils import Server

    context, _ = ros
    # The map does not exist: the refusal comes before any file or device is touched.
    bridge = RegulatorBridge(namespace='/simclock', context=context, parameter_overrides=[
        Parameter('backend', value='modbus'), Parameter('use_sim_time', value=True),
        Parameter('modbus_config', value=str(tmp_path / 'absent.yaml'))])
    try:
        assert not bridge.configure_and_activate()
        assert bridge.lifecycle_state == 'unconfigured'
        assert str(bridge.config_error) == (
            'parameters: use_sim_time: `use_sim_time` is true with backend modbus: a real '
            'regulator runs on the wall clock (its watchdog, rate limit and safe state follow '
            'the node clock, and a stopped /clock would hold its last pressure); use backend '
            'sim on simulated time')
    finally:
        bridge.destroy_node()
    server = Server()
    bridge = RegulatorBridge(namespace='/wallclock', context=context, parameter_overrides=[
        Parameter('backend', value='modbus'), Parameter('modbus_config', value=str(MODBUS_MAP)),
        Parameter('modbus_host', value='127.0.0.1'), Parameter('modbus_port', value=server.port)])
    try:
        assert bridge.configure_and_activate() and bridge.lifecycle_state == 'active'
        result = bridge.set_parameters([Parameter('use_sim_time', value=True)])[0]
        assert not result.successful and 'use_sim_time' in result.reason
        assert bridge.get_parameter('use_sim_time').value is False
        assert not bridge.get_clock().ros_time_is_active
    finally:
        bridge.destroy_node()
        server.close()
