"""A regulator_bridge process stopped with SIGSTOP: the Modbus device's own watchdog vents."""

import asyncio
import os
import pathlib
import signal
import subprocess
import sys
import threading

from helpers import spin_until
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from regulator_test_utils import Server
from sensor_msgs.msg import FluidPressure
import yaml

from fpc_gripper.io.qos import RELIABLE_QOS
from fpc_gripper.model.validation import STANDARD_ATMOSPHERE
from fpc_gripper.regulators.modbus import RegisterMap
from fpc_gripper.regulators.modbus_sim import SimulatedModbusDevice
from fpc_gripper.regulators.sim import SimulatedRegulator
from fpc_gripper.safe_yaml import parse_yaml

pytestmark = pytest.mark.ros

ROOT = pathlib.Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / 'msg_configs' / 'modbus_example.yaml'
FINGERS = ('finger_0', 'finger_1', 'finger_2')
COMMAND = 2.0e5
TIMEOUT_S = 0.5


class Device:
    """The example map's device, with a 0.5 s watchdog, on a real clock behind a server."""

    def __init__(self, tmp_path):
        self.regulator = SimulatedRegulator(3, time_constant_s=0.1, deadband_pa=0.0,
                                            noise_std_pa=0.0)
        self.regulator.connect()
        data = parse_yaml(EXAMPLE.read_text())
        data['watchdog'] = {'register': {'address': 16}, 'timeout_s': TIMEOUT_S}
        self.modbus = SimulatedModbusDevice(RegisterMap.from_dict(data), self.regulator)
        self.server = Server(action=self.modbus.action)
        self.ticking = asyncio.run_coroutine_threadsafe(self.modbus.run(0.01),
                                                        self.server.loop)
        data['connection'].update(host='127.0.0.1', port=self.server.port)
        self.map_path = tmp_path / 'map.yaml'
        self.map_path.write_text(yaml.safe_dump(data))

    def at(self, pressure):
        return all(abs(self.regulator.setpoint(i) - pressure) < 500.0 for i in range(3))

    def close(self):
        self.ticking.cancel()
        self.server.close()


class Bridge:
    """`python -m fpc_gripper.nodes.regulator_bridge` on the device, its output collected."""

    def __init__(self, map_path, namespace):
        self.process = subprocess.Popen(
            [sys.executable, '-m', 'fpc_gripper.nodes.regulator_bridge', '--ros-args',
             '-r', f'__ns:={namespace}', '-p', 'backend:=modbus',
             '-p', f'modbus_config:={map_path}',
             # Its own watchdog would hold the last command for 30 s: only the device vents.
             '-p', 'command_timeout_s:=30.0', '-p', 'safe_state:=hold'],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines = []
        self.active = threading.Event()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.process.stdout:
            self.lines.append(line)
            if 'active:' in line:
                self.active.set()

    def log(self):
        return ''.join(self.lines)

    def stop(self):
        if self.process.poll() is None:
            os.kill(self.process.pid, signal.SIGCONT)
            self.process.kill()
        self.process.wait()
        self._reader.join(timeout=5.0)


def test_a_stopped_bridge_has_the_device_vent_and_a_resumed_one_takes_over(tmp_path):
    device = Device(tmp_path)
    bridge = Bridge(device.map_path, '/dw')
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('device_watchdog_probe', namespace='/dw', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    publishers = [node.create_publisher(FluidPressure, f'{name}/pressure_command',
                                        RELIABLE_QOS) for name in FINGERS]

    def command():
        for name, publisher in zip(FINGERS, publishers):
            msg = FluidPressure()
            msg.header.frame_id = name
            msg.fluid_pressure = STANDARD_ATMOSPHERE + COMMAND
            publisher.publish(msg)

    # Commands keep coming all along: the controller upstream is alive, the bridge is not.
    node.create_timer(0.05, command)
    try:
        assert bridge.active.wait(120.0), bridge.log()
        assert device.modbus.timeout_s == pytest.approx(TIMEOUT_S), bridge.log()
        assert 'device watchdog 0.5 s' in bridge.log()
        assert spin_until(executor, lambda: device.at(COMMAND), 60.0), bridge.log()
        # 5 Hz would write less often than the device's watchdog allows for.
        client = AsyncParameterClient(node, '/dw/regulator_bridge')
        assert client.wait_for_services(60.0)
        future = client.set_parameters([Parameter('publish_rate_hz', value=5.0)])
        assert spin_until(executor, future.done, 60.0)
        result = future.result().results[0]
        assert not result.successful
        assert "device watchdog's timeout_s 0.5 s is shorter than 3 control periods at " \
               '`publish_rate_hz` 5 Hz (0.6 s)' in result.reason
        before = len(device.modbus.trips)

        os.kill(bridge.process.pid, signal.SIGSTOP)
        assert spin_until(executor, lambda: len(device.modbus.trips) > before, 30.0)
        vented_at, last_write = device.modbus.trips[-1]
        assert vented_at - last_write > TIMEOUT_S
        assert device.at(0.0)
        # The outputs fall while the bridge stays stopped (0.1 s time constant).
        assert spin_until(executor, lambda: max(
            device.regulator.true_pressure(i) for i in range(3)) < 1.0e3, 30.0)
        assert len(device.modbus.trips) == before + 1 and bridge.process.poll() is None

        os.kill(bridge.process.pid, signal.SIGCONT)
        assert spin_until(executor, lambda: device.at(COMMAND), 60.0), bridge.log()
        bridge.process.send_signal(signal.SIGTERM)
        assert bridge.process.wait(timeout=60.0) == 0, bridge.log()
        assert 'Traceback' not in bridge.log()
    finally:
        bridge.stop()
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
        device.close()
