"""
The regulator fault matrix: each fault on the sim and on Modbus, with its safe state and level.

Every case drives `RegulatorCore` (the bridge's control step) at 20 Hz on a hand-driven
clock, with a controller commanding 200 kPa on both channels, injects one fault into the
device, and states: the safe state the faulted channel must reach, the most simulated time
it may take, and the diagnostic level it must show then. The Modbus cases talk to a
pymodbus server on loopback whose device is a `SimulatedRegulator` on the same clock, and
inject the faults there (an exception response to writes, an over-range word, the server
going away). Throughout, every pressure the core hands out for publishing must be one the
backend read in that very step, finite and inside the sensor range.
"""

import dataclasses
import math

import pytest
from regulator_test_utils import FakeClock
from regulator_test_utils import Server

from fpc_gripper.regulators.base import BackendFault
from fpc_gripper.regulators.core import Level
from fpc_gripper.regulators.core import MonitorSettings
from fpc_gripper.regulators.core import RegulatorCore
from fpc_gripper.regulators.modbus import ModbusRegulator
from fpc_gripper.regulators.modbus import RegisterMap
from fpc_gripper.regulators.modbus_sim import SimulatedModbusDevice
from fpc_gripper.regulators.safety import SupervisorMode
from fpc_gripper.regulators.sim import SimulatedRegulator

DT = 0.05
COMMAND = 2.0e5
LIMITS = dict(max_pressure=4.0e5, rate_limit_pa_s=1.0e6, command_timeout_s=0.5,
              safe_state='vent')
MONITOR = MonitorSettings(tracking_tolerance_pa=2.0e4, tracking_timeout_s=2.0,
                          overpressure_margin_pa=5.0e4, reconnect_interval_s=1.0)
# 4-20 mA style map: 819 counts at 0 Pa, 4095 at 1 MPa, so a word of 0 is a broken wire.
OFFSET, FULL_COUNTS, FULL_PA = 819, 4095, 1.0e6
SAFE_MODES = (SupervisorMode.FAULT, SupervisorMode.WATCHDOG)


class Recorder:
    """A backend wrapper that records every readback and can refuse every write."""

    def __init__(self, backend):
        self.backend = backend
        self.n_channels = backend.n_channels
        self.reads = []
        self.fail_writes = False

    def connect(self):
        self.backend.connect()

    def close(self):
        self.backend.close()

    def set_pressure(self, channel, pressure):
        if self.fail_writes:
            raise BackendFault(f'write to channel {channel} refused (injected)')
        self.backend.set_pressure(channel, pressure)

    def read_pressure(self, channel):
        value = self.backend.read_pressure(channel)
        self.reads.append((channel,) + tuple(value))
        return value

    def readback_range(self, channel):
        return self.backend.readback_range(channel)

    def status(self):
        return self.backend.status()


def _device(clock):
    device = SimulatedRegulator(2, time_constant_s=0.15, noise_std_pa=300.0, seed=3,
                                clock=clock)
    device.connect()
    return device


class Rig:
    """What both rigs share: the simulated device on a hand-driven clock and its faults."""

    def __init__(self):
        self.clock = FakeClock()
        self.device = _device(self.clock)

    def inject_device(self, fault):
        """Inject a fault of the device itself; return whether `fault` was one."""
        if fault == 'leak':
            self.device.inject_fault('leak', 0, rate=3.0e6)
        elif fault == 'stuck_sensor':
            self.device.inject_fault('stuck_sensor', 0)
        else:
            return False
        return True

    def device_setpoint(self, channel):
        return self.device.setpoint(channel)


class SimRig(Rig):
    """The core on the simulated regulator."""

    name = 'sim'

    def __init__(self):
        super().__init__()
        self.backend = Recorder(self.device)
        self.backend.connect()

    def inject(self, fault):
        if self.inject_device(fault):
            return
        if fault in ('over_range', 'nan'):
            self.device.inject_fault('bad_readback', 0,
                                     value=5.0e6 if fault == 'over_range' else math.nan)
        elif fault == 'disconnect':
            self.device.inject_fault('disconnect')
        elif fault == 'write_fails':
            self.backend.fail_writes = True

    def clear(self):
        self.device.clear_faults()
        self.backend.fail_writes = False

    def close(self):
        self.backend.close()


class ModbusRig(Rig):
    """The core on the Modbus backend; the device behind a pymodbus server on loopback."""

    name = 'modbus'

    def __init__(self):
        super().__init__()
        self.stopped = False
        scaling = {'full_scale_counts': FULL_COUNTS, 'full_scale_pa': FULL_PA,
                   'offset_counts': OFFSET}
        rmap = RegisterMap.from_dict({
            'connection': {'host': '127.0.0.1', 'timeout_s': 0.5},
            'scaling': scaling,
            'channels': [{'setpoint': {'address': i}, 'readback': {'address': i,
                                                                   'type': 'input'}}
                         for i in range(2)]})
        self.modbus = SimulatedModbusDevice(rmap, self.device, self.clock)
        self.server = Server(action=self.modbus.action)
        self.backend = Recorder(ModbusRegulator(rmap, port=self.server.port,
                                                reconnect_interval_s=0.5, clock=self.clock))
        self.backend.connect()

    def inject(self, fault):
        if self.inject_device(fault):
            return
        if fault in ('over_range', 'under_range'):
            self.modbus.readback_words[0] = 0xFFFF if fault == 'over_range' else 0
        elif fault == 'disconnect':
            self.server.stop()
            self.stopped = True
        elif fault == 'write_fails':
            self.modbus.fail_writes = True

    def clear(self):
        self.device.clear_faults()
        self.modbus.readback_words.clear()
        self.modbus.fail_writes = False
        if self.stopped:
            self.server.start()
            self.stopped = False

    def close(self):
        self.backend.close()
        if self.stopped:
            self.server.start()
        self.server.close()


@dataclasses.dataclass
class Case:
    """One row of the matrix: what the faulted channel 0 must do, and how fast."""

    fault: str
    safe_state: str
    level: Level
    words: str
    within_s: float
    not_before_s: float = 0.0
    on_device: bool = True


#: The matrix. `within_s` counts simulated time from the injection to the first step at
#: which channel 0 is in its safe state (setpoint 0 Pa, vented) with that level, and,
#: where `on_device`, the device holds the vent setpoint too.
CASES = {
    'leak': Case('leak', 'vent, latched', Level.ERROR, 'off the setpoint', 2.2,
                 not_before_s=2.0),
    'stuck_sensor': Case('stuck_sensor', 'vent, latched', Level.ERROR, 'off the setpoint', 2.2,
                         not_before_s=2.0),
    'disconnect': Case('disconnect', 'vent (written on reconnection)', Level.ERROR,
                       'fault: backend', DT, on_device=False),
    'over_range': Case('over_range', 'vent, readback not published', Level.ERROR,
                       'outside the sensor range', 2 * DT),
    'nan': Case('nan', 'vent, readback not published', Level.ERROR, 'not finite', 2 * DT),
    'under_range': Case('under_range', 'vent, readback not published', Level.ERROR,
                        'outside the sensor range', 2 * DT),
    'write_fails': Case('write_fails', 'vent commanded, device keeps its setpoint', Level.ERROR,
                        'fault: backend', DT, on_device=False),
    'clock_back': Case('clock_back', 'vent (watchdog)', Level.WARN, 'watchdog', 0.5 + 2 * DT,
                       not_before_s=0.5),
    'clock_forward': Case('clock_forward', 'vent (watchdog)', Level.WARN, 'watchdog', DT),
}
MATRIX = [('sim', f) for f in CASES if f != 'under_range'] + \
    [('modbus', f) for f in CASES if f != 'nan']
RIGS = {'sim': SimRig, 'modbus': ModbusRig}


class Run:
    """Step the core on a rig, checking what it would publish at every step."""

    def __init__(self, rig):
        self.rig = rig
        self.core = RegulatorCore(rig.backend, 2, LIMITS, MONITOR)
        self.published = 0
        self.command = COMMAND

    def step(self, commanding=True, dt=DT):
        clock = self.rig.clock
        clock.now = round(clock.now + dt, 9)
        if commanding:
            for channel in range(2):
                self.core.command(channel, self.command, clock.now)
        self.rig.backend.reads.clear()
        out = self.core.step(clock.now)
        reads = self.rig.backend.reads
        for sample in out.samples:
            # Published only what was read at this step, exactly, and only a measurement.
            assert (sample.channel, sample.pressure, sample.variance) in reads
            assert math.isfinite(sample.pressure) and -1.0 <= sample.pressure <= FULL_PA
        self.published += len(out.samples)
        return out

    def until(self, condition, seconds, commanding=True):
        """Step until `condition(out)`; return (elapsed [s], out), or fail after `seconds`."""
        start = self.rig.clock.now
        while self.rig.clock.now - start < seconds + 1e-9:
            out = self.step(commanding)
            if condition(out):
                return self.rig.clock.now - start, out
        pytest.fail(f'condition not met within {seconds} s of simulated time')


@pytest.fixture
def run(request):
    rig = RIGS[request.param]()
    yield Run(rig)
    rig.close()


def _safe(run, case):
    def condition(out):
        report = out.reports[0]
        vented = (report.mode in SAFE_MODES and report.values['setpoint_pa_gauge'] == '0.0'
                  and report.level == case.level)
        return vented and (not case.on_device or run.rig.device_setpoint(0) == 0.0)
    return condition


@pytest.mark.parametrize('run, fault', MATRIX, indirect=['run'],
                         ids=[f'{b}-{f}' for b, f in MATRIX])
def test_fault_reaches_its_safe_state_in_time_at_its_level(run, fault):
    case = CASES[fault]
    settled = run.until(lambda out: all(r.level == Level.OK and r.mode == SupervisorMode.TRACKING
                                        for r in out.reports)
                        and abs(run.core.measured[0] - COMMAND) < 2e3, 3.0)[1]
    assert all(r.level == Level.OK for r in settled.reports)
    commanding = not fault.startswith('clock')
    if fault == 'clock_back':
        run.rig.clock.now -= 3600.0
    elif fault == 'clock_forward':
        run.rig.clock.now += 3600.0
    else:
        run.rig.inject(fault)
    if fault == 'stuck_sensor':
        run.command = 1.0e5          # the setpoint moves; the frozen reading does not
    elapsed, out = run.until(_safe(run, case), case.within_s + 1e-6, commanding)
    assert elapsed >= case.not_before_s - 1e-9
    report = out.reports[0]
    assert report.level == case.level and case.words in report.message, report.message
    print(f'\nFAULT-MATRIX | {fault} | {run.rig.name} | {case.safe_state} | {elapsed:.2f} s | '
          f'{case.level.name} | {report.message[:90]}')
    if fault in ('over_range', 'nan', 'under_range'):
        # The bad channel publishes nothing while its readback is bad; the other one goes on.
        out = run.step()
        assert [s.channel for s in out.samples] == [1]
    if fault == 'disconnect':
        # Nothing is published while the device is away; the vent reaches it on reconnection.
        for _ in range(10):
            assert not run.step().samples
        run.rig.clear()
        elapsed, out = run.until(lambda o: o.samples and run.rig.device_setpoint(0) == 0.0,
                                 MONITOR.reconnect_interval_s + 2 * DT)
        assert out.reports[0].level == Level.WARN        # healthy, safe until commanded
    if fault == 'write_fails':
        # Reads still work and are published; the diagnostics say the vent is not written.
        assert out.samples and out.reports[0].values['setpoint_written'] == 'False'
        assert run.rig.device_setpoint(0) == pytest.approx(COMMAND, abs=1e3)
        run.rig.clear()
        run.until(lambda o: run.rig.device_setpoint(0) == 0.0, 2 * DT)
    if case.safe_state.endswith('latched'):
        run.rig.clear()
        for _ in range(int(1.0 / DT)):
            assert run.step().reports[0].level == Level.ERROR     # until reactivated
        run.core.start(run.rig.clock.now)
    # Once the cause is gone the channel follows commands again, at level OK.
    run.rig.clear()
    run.command = COMMAND
    run.until(lambda o: o.reports[0].level == Level.OK
              and abs(run.core.measured[0] - COMMAND) < 5e3, 3.0)
    assert run.published > 0


@pytest.mark.parametrize('run', ['sim'], indirect=True)
def test_over_pressure_vents_even_with_safe_state_hold(run):
    run.core.configure(safe_state='hold')
    run.until(lambda out: abs(run.core.measured[0] - COMMAND) < 2e3, 3.0)
    # A valve stuck open: the device goes to 600 kPa whatever it is told.
    run.rig.backend.set_pressure = lambda channel, p: run.rig.device.set_pressure(
        channel, 6.0e5 if channel == 0 else p)
    elapsed, out = run.until(lambda o: o.reports[0].level == Level.ERROR, 1.0)
    report = out.reports[0]
    assert 'over-pressure' in report.message and report.values['setpoint_pa_gauge'] == '0.0'
    # Detected at the first reading above 450 kPa: 250 kPa of rise at the sim's slew rate.
    assert elapsed <= 0.25 / 2.0 + 3 * DT
    assert out.reports[1].level == Level.OK


@pytest.mark.parametrize('run', ['modbus'], indirect=True)
def test_reconnection_is_not_held_off_by_a_clock_that_steps_back(run):
    run.until(lambda out: out.reports[0].level == Level.OK, 3.0)
    run.rig.inject('disconnect')
    run.until(lambda out: out.reports[0].level == Level.ERROR, 2 * DT)
    run.rig.clock.now -= 3600.0
    run.rig.clear()
    elapsed, _ = run.until(lambda o: bool(o.samples), MONITOR.reconnect_interval_s + 2 * DT)
    assert elapsed <= MONITOR.reconnect_interval_s + 2 * DT


@pytest.mark.parametrize('run', ['sim'], indirect=True)
def test_a_starved_control_loop_is_not_mistaken_for_a_leak(run):
    # Steps 2.1 s apart (a busy executor) on a 10 kPa/s ramp: each reading answers the
    # setpoint written a step earlier, which the regulator has long reached, and lies 21 kPa
    # below the one written now, for longer than the 2 s timeout.
    run.core.configure(rate_limit_pa_s=1.0e4)
    for _ in range(5):
        out = run.step(dt=2.1)
        assert all(r.level == Level.OK for r in out.reports), out.reports[0].message
        run.core.command(0, COMMAND, run.rig.clock.now)
