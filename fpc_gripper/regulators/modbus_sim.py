"""A simulated Modbus regulator: the device a register map describes, over a SimulatedRegulator."""

import asyncio
import dataclasses
import time

from fpc_gripper.regulators.modbus import word_range

__all__ = ['SimulatedModbusDevice']

#: The Modbus function code of a read of input registers.
READ_INPUT = 4


class SimulatedModbusDevice:
    """
    The device a `RegisterMap` describes, as a pymodbus simulator action.

    A write to a channel's setpoint register commands the regulator; a read of its readback
    register answers the regulator's pressure in counts, and a read of its setpoint
    register the setpoint the device holds. With a ``watchdog`` in the map the device keeps
    the map's contract (`modbus.DeviceWatchdog`): a write to the watchdog register arms it
    (0 disarms), and when no setpoint is written for longer than its timeout, every channel
    vents to 0 Pa gauge until the next setpoint write. The watchdog runs on the device's
    clock, in `tick`: at every register access, and every `tick_period_s` under `run`, so
    it expires while nobody talks to the device.

    Parameters
    ----------
    register_map : RegisterMap
        Registers and scaling (its connection settings are not used).
    regulator : SimulatedRegulator
        The connected regulator behind the registers, one channel per map channel or more.
    clock : callable
        The device's time [s] (the regulator's, for a simulated clock).

    Attributes
    ----------
    timeout_s : float or None
        The armed watchdog timeout [s] (None while disarmed).
    trips : list of (float, float)
        Each time the watchdog vented: (the time it did, the last setpoint write before) [s].
    fail_writes : bool
        Answer every write with an exception response (a fault to inject).
    readback_words : dict
        Channel → the raw word its readback register answers instead of the pressure.

    """

    def __init__(self, register_map, regulator, clock=time.monotonic):
        if regulator.n_channels < len(register_map.channels):
            raise ValueError(f'`regulator` has {regulator.n_channels} channels, the map '
                             f'{len(register_map.channels)}')
        self.map = register_map
        self.regulator = regulator
        self.clock = clock
        self._setpoints = {c.setpoint.address: i for i, c in enumerate(register_map.channels)}
        self._readbacks = {(c.readback.kind, c.readback.address): i
                           for i, c in enumerate(register_map.channels)}
        self.timeout_s = None
        self.trips = []
        self.fail_writes = False
        self.readback_words = {}
        self._last_write = None
        self._vented = False

    def tick(self):
        """Vent every channel if the armed watchdog expired; return whether it did now."""
        now = self.clock()
        if self.timeout_s is None or self._vented or self._last_write is None \
                or now - self._last_write <= self.timeout_s:
            return False
        for i in range(len(self.map.channels)):
            self.regulator.set_pressure(i, 0.0)
        self._vented = True
        self.trips.append((now, self._last_write))
        return True

    async def run(self, tick_period_s=0.01):
        """Tick forever, every `tick_period_s` [s] (schedule it on the server's loop)."""
        while True:
            self.tick()
            await asyncio.sleep(tick_period_s)

    async def action(self, function_code, start, address, count, registers, values):
        """Serve one register access as pymodbus's SimDevice ``action`` (see `access`)."""
        return self.access(function_code, start, address, count, registers, values)

    def access(self, function_code, start, address, count, registers, values):
        """
        Serve one register access; return an exception code or None.

        The arguments are pymodbus's: the function code, the address of ``registers[0]``,
        the request's address and count, the registers (answers are written into them),
        and the words a write carries (None for a read).
        """
        self.tick()
        if values is not None:
            if self.fail_writes:
                from pymodbus.constants import ExcCodes
                return ExcCodes.DEVICE_FAILURE
            for k, word in enumerate(values):
                self._write(address + k, int(word))
            return None
        kind = 'input' if function_code == READ_INPUT else 'holding'
        for k in range(count):
            word = self._read(kind, address + k)
            if word is not None:
                registers[address - start + k] = word
        return None

    def _write(self, address, word):
        watchdog = self.map.watchdog
        if watchdog is not None and address == watchdog.register.address:
            self.timeout_s = word / watchdog.counts_per_s if word else None
            self._last_write = self.clock()
            return
        channel = self._setpoints.get(address)
        if channel is None:
            return
        scaling = self.map.channels[channel].scaling
        self.regulator.set_pressure(channel, scaling.to_pressure(word))
        self._last_write = self.clock()
        self._vented = False

    def _read(self, kind, address):
        channel = self._readbacks.get((kind, address))
        if channel is not None:
            word = self.readback_words.get(channel)
            if word is not None:
                return word
            return _word(self.map.channels[channel].scaling,
                         self.regulator.read_pressure(channel)[0])
        channel = self._setpoints.get(address) if kind == 'holding' else None
        if channel is not None:
            return _word(self.map.channels[channel].scaling, self.regulator.setpoint(channel))
        return None


def _word(scaling, pressure):
    """Return the 16-bit word of `pressure` [Pa gauge], limited to what the word can hold."""
    # A sensor's word may leave the setpoint's full scale (an over- or under-range reading).
    low, high = word_range(scaling.signed)
    return dataclasses.replace(scaling, min_counts=low, max_counts=high).to_counts(pressure)
