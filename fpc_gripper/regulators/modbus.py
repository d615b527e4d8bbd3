"""A Modbus TCP pressure-regulator backend configured by a YAML register map."""

import dataclasses
import inspect
import math
import os
import time
import typing

from fpc_gripper.regulators.base import BackendFault
from fpc_gripper.regulators.base import BackendStatus
from fpc_gripper.regulators.base import check_channel
from fpc_gripper.regulators.base import check_pressure
from fpc_gripper.safe_yaml import load_yaml
from fpc_gripper.safe_yaml import Where
from fpc_gripper.services.periods import period_passed

REGISTER_TYPES = ('holding', 'input')

_TOP_KEYS = ('connection', 'scaling', 'noise_std_pa', 'channels', 'watchdog')
_CONNECTION_KEYS = ('host', 'port', 'device_id', 'unit', 'timeout_s')
_CHANNEL_KEYS = ('name', 'setpoint', 'readback', 'scaling')
_REGISTER_KEYS = ('address', 'type')
_WATCHDOG_KEYS = ('register', 'timeout_s', 'counts_per_s')
_SCALING_KEYS = ('counts_per_pa', 'full_scale_counts', 'full_scale_pa', 'offset_counts',
                 'signed')
#: Bounds of a register map: channels, name and host lengths, request timeout [s] and the
#: largest pressure a scale or a noise figure may name [Pa].
MAX_CHANNELS = 64
MAX_NAME_CHARS = 64
MAX_HOST_CHARS = 253
MAX_TIMEOUT_S = 60.0
MAX_PRESSURE_PA = 1.0e8


@dataclasses.dataclass(frozen=True)
class Register:
    """
    One 16-bit register.

    Attributes
    ----------
    address : int
        Zero-based protocol address, 0..65535.
    kind : {'holding', 'input'}
        Register table.
    """

    address: int
    kind: str = 'holding'


@dataclasses.dataclass(frozen=True)
class Scaling:
    """
    Linear map between register counts and gauge pressure.

    counts = offset_counts + counts_per_pa · pressure [Pa gauge], rounded and
    limited to [min_counts, max_counts].

    Attributes
    ----------
    counts_per_pa : float
        Gain [count/Pa], > 0.
    offset_counts : float
        Counts at 0 Pa gauge.
    min_counts, max_counts : int
        Representable range (the device's full scale, or the 16-bit range).
    signed : bool
        True when registers hold two's-complement int16.
    """

    counts_per_pa: float
    offset_counts: float = 0.0
    min_counts: int = 0
    max_counts: int = 0xFFFF
    signed: bool = False

    def to_counts(self, pressure_pa_gauge):
        """Return the register word for a pressure [Pa gauge], saturated to the range."""
        counts = round(self.offset_counts + self.counts_per_pa * float(pressure_pa_gauge))
        counts = min(max(counts, self.min_counts), self.max_counts)
        return counts & 0xFFFF

    def to_pressure(self, word):
        """Return the pressure [Pa gauge] of a raw 16-bit register word."""
        counts = int(word)
        if self.signed and counts >= 0x8000:
            counts -= 0x10000
        return (counts - self.offset_counts) / self.counts_per_pa

    @property
    def resolution_pa(self):
        """Pressure of one count [Pa]."""
        return 1.0 / self.counts_per_pa


@dataclasses.dataclass(frozen=True)
class ChannelMap:
    """Setpoint register, readback register and scaling of one channel."""

    setpoint: Register
    readback: Register
    scaling: Scaling
    name: str = ''


@dataclasses.dataclass(frozen=True)
class DeviceWatchdog:
    """
    The device's own communication watchdog: the register that arms it, and its timeout.

    The contract a device must meet (the simulated one does, `modbus_sim`): a write of
    ``word`` to `register` arms it with a timeout of ``word / counts_per_s`` seconds (0
    disarms it); when no setpoint register is written for longer than that, every channel
    vents to 0 Pa gauge until the next setpoint write. The bridge writes every setpoint at
    each control step, so only a bridge that has died, hung or lost its link lets it expire.

    Attributes
    ----------
    register : Register
        The holding register that takes the timeout.
    timeout_s : float
        Timeout the backend arms at each connection [s].
    counts_per_s : float
        The register's unit [count/s]: 1000 for milliseconds, 10 for tenths of a second.
    """

    register: Register
    timeout_s: float
    counts_per_s: float = 1000.0

    @property
    def word(self):
        """The register word for `timeout_s`."""
        return round(self.timeout_s * self.counts_per_s)


@dataclasses.dataclass(frozen=True)
class RegisterMap:
    """
    Connection settings and per-channel registers of a Modbus TCP regulator.

    Attributes
    ----------
    channels : tuple of ChannelMap
        One entry per channel, in channel order.
    host : str
        Device address.
    port : int
        TCP port.
    device_id : int
        Modbus unit / device id, 0..255.
    timeout_s : float
        Request timeout [s].
    noise_std_pa : float
        Standard deviation of the readback noise [Pa], for the reported variance.
    watchdog : DeviceWatchdog or None
        The device's communication watchdog, armed at every connection (None: the device
        has none, and only the bridge's own watchdog guards the outputs).
    """

    channels: typing.Tuple[ChannelMap, ...]
    host: str = '127.0.0.1'
    port: int = 502
    device_id: int = 1
    timeout_s: float = 0.5
    noise_std_pa: float = 0.0
    watchdog: typing.Optional[DeviceWatchdog] = None

    @classmethod
    def from_yaml(cls, path):
        """
        Load a register map from YAML (see ``msg_configs/modbus_example.yaml``).

        The file is read with `fpc_gripper.safe_yaml.load_yaml` (size, depth and alias
        limits, no duplicate keys, decimal numbers only).

        Raises
        ------
        ValueError
            A `safe_yaml.ConfigError`, one line naming the file, the key path and the
            problem, for anything wrong with the file.
        """
        return cls.from_dict(load_yaml(path, what='Modbus register map'),
                             source=os.fspath(path))

    @classmethod
    def from_dict(cls, data, source='<dict>'):
        """Build a register map from the parsed YAML structure (see :meth:`from_yaml`)."""
        where = Where(source)
        top = where.mapping(data, _TOP_KEYS, what='a mapping of register-map keys')
        at = where / 'connection'
        conn = at.mapping(top.get('connection', {}), _CONNECTION_KEYS)
        if 'device_id' in conn and 'unit' in conn:
            raise at.error("give 'device_id' or its alias 'unit', not both")
        host = (at / 'host').string(conn.get('host', '127.0.0.1'), MAX_HOST_CHARS,
                                    what='a host name or address')
        port = (at / 'port').integer(conn.get('port', 502), 1, 65535)
        device_key = 'unit' if 'unit' in conn else 'device_id'
        device_id = (at / device_key).integer(conn.get(device_key, 1), 0, 255)
        timeout = (at / 'timeout_s').number(conn.get('timeout_s', 0.5), '[s]', 0.0,
                                            MAX_TIMEOUT_S, low_open=True)
        noise = (where / 'noise_std_pa').number(top.get('noise_std_pa', 0.0), '[Pa]', 0.0,
                                                MAX_PRESSURE_PA)
        default_scaling = top.get('scaling')
        channels = (where / 'channels').sequence(top.get('channels'), 1, MAX_CHANNELS,
                                                 what='channel mappings')
        parsed = []
        for i, entry in enumerate(channels):
            at = where / 'channels' / i
            entry = at.mapping(entry, _CHANNEL_KEYS)
            for required in ('setpoint', 'readback'):
                if required not in entry:
                    raise (at / required).error('is missing')
            setpoint = _register(entry['setpoint'], at / 'setpoint')
            if setpoint.kind != 'holding':
                raise (at / 'setpoint' / 'type').error(
                    f"must be 'holding' (input registers are read-only), got {setpoint.kind!r}")
            readback = _register(entry['readback'], at / 'readback')
            if 'scaling' in entry:
                scaling = _scaling(entry['scaling'], at / 'scaling')
            elif default_scaling is None:
                raise (at / 'scaling').error('is missing and there is no top-level scaling')
            else:
                scaling = _scaling(default_scaling, where / 'scaling')
            name = (at / 'name').string(entry.get('name', f'channel_{i}'), MAX_NAME_CHARS)
            parsed.append(ChannelMap(setpoint=setpoint, readback=readback, scaling=scaling,
                                     name=name))
        watchdog = None
        if 'watchdog' in top:
            watchdog = _watchdog(top['watchdog'], where / 'watchdog', parsed)
        return cls(channels=tuple(parsed), host=host, port=port, device_id=device_id,
                   timeout_s=timeout, noise_std_pa=noise, watchdog=watchdog)


class ModbusRegulator:
    """
    A pressure regulator reached over Modbus TCP (pymodbus 3.x, imported in :meth:`connect`).

    Parameters
    ----------
    register_map : RegisterMap or str or pathlib.Path
        The map, or a YAML file to load it from.
    host, port, device_id, timeout_s : optional
        Override the connection settings of the map.
    reconnect_interval_s : float
        Least time between two reconnection attempts after a failure [s].
    clock : callable
        Returns the current time [s], for the reconnection interval.
    """

    def __init__(self, register_map, host=None, port=None, device_id=None, timeout_s=None,
                 reconnect_interval_s=1.0, clock=time.monotonic):
        if not isinstance(register_map, RegisterMap):
            register_map = RegisterMap.from_yaml(register_map)
        overrides = {}
        if host is not None:
            if not isinstance(host, str) or not host:
                raise ValueError(f'`host` must be a non-empty string, got {host!r}')
            overrides['host'] = host
        if port is not None:
            overrides['port'] = _integer(port, 'port', 1, 65535)
        if device_id is not None:
            overrides['device_id'] = _integer(device_id, 'device_id', 0, 255)
        if timeout_s is not None:
            if not float(timeout_s) > 0.0:
                raise ValueError(f'`timeout_s` must be > 0 [s], got {timeout_s!r}')
            overrides['timeout_s'] = float(timeout_s)
        if not float(reconnect_interval_s) >= 0.0:
            raise ValueError(
                f'`reconnect_interval_s` must be >= 0 [s], got {reconnect_interval_s!r}')
        self.register_map = dataclasses.replace(register_map, **overrides)
        self.n_channels = len(self.register_map.channels)
        self._reconnect_interval = float(reconnect_interval_s)
        self._clock = clock
        self._client = None
        self._exceptions = (OSError,)
        self._device_kw = 'device_id'
        self._fault = None
        self._last_attempt = None

    @property
    def device_watchdog_s(self):
        """The timeout of the device's own watchdog [s], or None if the map gives none."""
        watchdog = self.register_map.watchdog
        return None if watchdog is None else watchdog.timeout_s

    def connect(self):
        """
        Open the TCP connection and arm the device's watchdog; a no-op while connected.

        The watchdog is armed at every connection, because a device that lost power or
        was replaced comes back disarmed.

        Raises
        ------
        BackendFault
            If pymodbus is missing, the device cannot be reached, or it refuses its
            watchdog's timeout.
        """
        if self._client is None:
            try:
                from pymodbus.client import ModbusTcpClient
                from pymodbus.exceptions import ModbusException
            except ImportError as exc:
                raise self._failed(
                    f'pymodbus >= 3 is required for the Modbus backend: {exc}') from exc
            rmap = self.register_map
            self._client = ModbusTcpClient(rmap.host, port=rmap.port, timeout=rmap.timeout_s,
                                           retries=0)
            self._exceptions = (ModbusException, OSError)
            params = inspect.signature(self._client.read_holding_registers).parameters
            # pymodbus < 3.9 names the unit id `slave`.
            self._device_kw = 'device_id' if 'device_id' in params else 'slave'
        self._last_attempt = self._clock()
        if not self._client.connected:
            if not self._client.connect():
                rmap = self.register_map
                raise self._failed(f'cannot connect to {rmap.host}:{rmap.port}')
            self._arm_watchdog()
        self._fault = None

    def _arm_watchdog(self):
        watchdog = self.register_map.watchdog
        if watchdog is None:
            return
        try:
            self._request('write_register', watchdog.register.address, watchdog.word)
        except BackendFault as exc:
            # Not connected: the next attempt arms it again, before any setpoint goes out.
            self._client.close()
            raise self._failed(f'cannot arm the device watchdog (register '
                               f'{watchdog.register.address}, {watchdog.timeout_s:g} s): '
                               f'{exc}') from exc

    def close(self):
        """Close the connection; safe to call more than once."""
        if self._client is not None:
            self._client.close()
            self._client = None

    def set_pressure(self, channel, pressure_pa_gauge):
        """
        Write the setpoint register of one channel.

        Parameters
        ----------
        channel : int
            Channel index.
        pressure_pa_gauge : float
            Setpoint [Pa gauge], saturated to the register's range.

        Raises
        ------
        BackendFault
            On a connection error or an exception response.
        """
        index = check_channel(channel, self.n_channels)
        value = check_pressure(pressure_pa_gauge)
        cmap = self.register_map.channels[index]
        word = cmap.scaling.to_counts(value)
        self._request('write_register', cmap.setpoint.address, word)

    def read_pressure(self, channel):
        """
        Read the readback register of one channel.

        Returns
        -------
        value : float
            Pressure [Pa gauge].
        variance : float
            noise_std_pa² + resolution²/12 [Pa²].

        Raises
        ------
        BackendFault
            On a connection error or an exception response.
        """
        index = check_channel(channel, self.n_channels)
        cmap = self.register_map.channels[index]
        method = ('read_holding_registers' if cmap.readback.kind == 'holding'
                  else 'read_input_registers')
        response = self._request(method, cmap.readback.address, count=1)
        registers = getattr(response, 'registers', None) or ()
        if len(registers) != 1:
            raise self._failed(f'{method}({cmap.readback.address}) returned '
                               f'{len(registers)} registers, not 1')
        variance = self.register_map.noise_std_pa ** 2 + cmap.scaling.resolution_pa ** 2 / 12.0
        return cmap.scaling.to_pressure(registers[0]), variance

    def readback_range(self, channel):
        """Return the (low, high) pressures the readback register can represent [Pa gauge]."""
        scaling = self.register_map.channels[check_channel(channel, self.n_channels)].scaling
        return (scaling.to_pressure(scaling.min_counts & 0xFFFF),
                scaling.to_pressure(scaling.max_counts & 0xFFFF))

    def status(self):
        """Return the connection state and the last error, without any traffic."""
        connected = self._client is not None and self._client.connected
        fault = self._fault
        if fault is None and not connected:
            fault = 'not connected'
        return BackendStatus(ok=fault is None, fault=fault, connected=connected,
                             n_channels=self.n_channels)

    def _request(self, method, address, *args, **kwargs):
        if self._client is None:
            raise BackendFault('Modbus regulator not connected: call connect() first')
        if not self._client.connected:
            now = self._clock()
            # A clock that stepped back must not hold off reconnection until it catches up.
            if not period_passed(self._last_attempt, now, self._reconnect_interval):
                raise BackendFault(self._fault or 'Modbus connection lost')
            self.connect()
        kwargs[self._device_kw] = self.register_map.device_id
        try:
            response = getattr(self._client, method)(address, *args, **kwargs)
        except self._exceptions as exc:
            self._client.close()
            raise self._failed(f'{method}({address}) failed: {exc}') from exc
        if response.isError():
            raise self._failed(f'{method}({address}) returned an exception response: '
                               f'{response}')
        self._fault = None
        return response

    def _failed(self, message):
        self._fault = message
        return BackendFault(message)


def word_range(signed):
    """Return the (low, high) counts a 16-bit register holds, as int16 if `signed`."""
    return (-0x8000, 0x7FFF) if signed else (0, 0xFFFF)


def _integer(value, name, low, high):
    if isinstance(value, bool) or not hasattr(value, '__index__') \
            or not low <= int(value) <= high:
        raise ValueError(f'`{name}` must be an integer in [{low}, {high}], got {value!r}')
    return int(value)


def _register(value, where):
    entry = where.mapping(value, _REGISTER_KEYS)
    if 'address' not in entry:
        raise (where / 'address').error('is missing')
    address = (where / 'address').integer(entry['address'], 0, 0xFFFF)
    kind = (where / 'type').choice(entry.get('type', 'holding'), REGISTER_TYPES)
    return Register(address=address, kind=kind)


def _watchdog(value, where, channels):
    entry = where.mapping(value, _WATCHDOG_KEYS)
    for required in ('register', 'timeout_s'):
        if required not in entry:
            raise (where / required).error('is missing')
    register = _register(entry['register'], where / 'register')
    if register.kind != 'holding':
        raise (where / 'register' / 'type').error(
            f"must be 'holding' (the backend writes the timeout), got {register.kind!r}")
    taken = {c.setpoint.address: c.name for c in channels}
    taken.update({c.readback.address: c.name for c in channels if c.readback.kind == 'holding'})
    if register.address in taken:
        raise (where / 'register' / 'address').error(
            f'{register.address} is a register of channel {taken[register.address]!r}')
    rate = (where / 'counts_per_s').number(entry.get('counts_per_s', 1000.0), '[count/s]',
                                           0.0, 1.0e6, low_open=True)
    # At least one count, and no more than a 16-bit word holds.
    timeout = (where / 'timeout_s').number(entry['timeout_s'], '[s]', 1.0 / rate,
                                           0xFFFF / rate)
    return DeviceWatchdog(register=register, timeout_s=timeout, counts_per_s=rate)


def _scaling(value, where):
    entry = where.mapping(value, _SCALING_KEYS)
    signed = (where / 'signed').boolean(entry.get('signed', False))
    low, high = word_range(signed)
    offset = (where / 'offset_counts').number(entry.get('offset_counts', 0), '[count]', low,
                                              high)
    has_gain = 'counts_per_pa' in entry
    has_full_scale = 'full_scale_counts' in entry or 'full_scale_pa' in entry
    if has_gain == has_full_scale:
        raise where.error("needs either 'counts_per_pa' or both 'full_scale_counts' and "
                          f"'full_scale_pa', got keys {', '.join(sorted(entry))}")
    if has_gain:
        # At least one count per MAX_PRESSURE_PA: a gain below that cannot be a regulator.
        gain = (where / 'counts_per_pa').number(entry['counts_per_pa'], '[count/Pa]',
                                                1.0 / MAX_PRESSURE_PA, 0xFFFF)
        return Scaling(counts_per_pa=gain, offset_counts=offset, min_counts=low,
                       max_counts=high, signed=signed)
    for required in ('full_scale_counts', 'full_scale_pa'):
        if required not in entry:
            raise (where / required).error('is missing (full-scale scaling needs both '
                                           "'full_scale_counts' and 'full_scale_pa')")
    counts = (where / 'full_scale_counts').integer(entry['full_scale_counts'], low, high)
    span = (where / 'full_scale_pa').number(entry['full_scale_pa'], '[Pa]', 0.0,
                                            MAX_PRESSURE_PA, low_open=True)
    if counts <= offset:
        raise (where / 'full_scale_counts').error(f'must be > offset_counts ({offset:g}), '
                                                  f'got {counts}')
    return Scaling(counts_per_pa=(counts - offset) / span, offset_counts=offset,
                   min_counts=int(math.ceil(offset)), max_counts=counts, signed=signed)
