"""ROS-free state of the regulator bridge from configure to cleanup: configs, backend and core."""

import math

from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.regulators.bridge_parameters import limits
from fpc_gripper.regulators.bridge_parameters import refusal
from fpc_gripper.regulators.bridge_parameters import SIM_PARAMETERS
from fpc_gripper.regulators.bridge_parameters import SIM_TIME_REFUSED
from fpc_gripper.regulators.bridge_parameters import watchdog_refusal
from fpc_gripper.regulators.core import Level
from fpc_gripper.regulators.core import MonitorSettings
from fpc_gripper.regulators.core import RegulatorCore
from fpc_gripper.regulators.factory import make_backend
from fpc_gripper.regulators.modbus import RegisterMap
from fpc_gripper.safe_yaml import ConfigError
from fpc_gripper.services.periods import period_passed

__all__ = ['RECONNECT_S', 'BridgeSession', 'DiagnosticsSchedule', 'load_bridge_config']

#: Least time between two reconnection attempts of a disconnected backend [s].
RECONNECT_S = 1.0


def load_bridge_config(gripper_config, backend, modbus_config):
    """
    Load and check every config file the bridge needs, before any device is touched.

    Parameters
    ----------
    gripper_config : str
        Gripper YAML path.
    backend : str
        'sim', 'modbus' or 'injected' (a backend object given to the node).
    modbus_config : str
        Register-map YAML path (backend 'modbus').

    Returns
    -------
    (GripperConfig, RegisterMap or None)

    Raises
    ------
    ConfigError
        One line naming the file, the key path and the problem.

    """
    config = load_gripper_config(gripper_config)
    if backend != 'modbus':
        return config, None
    if not modbus_config:
        raise ConfigError('modbus_config', '', 'is empty: backend modbus needs a register map '
                                               '(see msg_configs/modbus_example.yaml)')
    return config, RegisterMap.from_yaml(modbus_config)


class DiagnosticsSchedule:
    """When the channels' health is due: on request, at a change of level or mode, or a period."""

    def __init__(self):
        self._last_time = None
        self._last_levels = None

    def restart(self):
        """Make the next report due at once (activation)."""
        self._last_time = None

    def due(self, now, reports, period_s, force=False):
        """
        Return whether to publish `reports` at `now` [s]; if so, remember them as published.

        Parameters
        ----------
        now : float
            Node clock [s].
        reports : sequence of ChannelReport
            This step's, one per channel.
        period_s : float
            Longest time between two reports [s].
        force : bool
            Due whatever else holds.

        """
        levels = [(r.level, r.mode) for r in reports]
        periodic = period_passed(self._last_time, now, period_s)
        if not (force or periodic or levels != self._last_levels):
            return False
        self._last_time = now
        self._last_levels = levels
        return True


class BridgeSession:
    """
    The regulator bridge's configuration, free of ROS: what configure builds, cleanup ends.

    Configure runs in two steps: `load` reads and checks the config files (nothing is
    touched yet), `connect` builds and connects the backend and the
    :class:`~fpc_gripper.regulators.core.RegulatorCore` over it. `release` sends every
    channel its safe setpoint and closes the backend; `abandon` closes it after a failed
    configure, in which nothing was commanded.

    Parameters
    ----------
    backend : RegulatorBackend, optional
        Use this backend instead of building one from the parameters.

    Attributes
    ----------
    kind : str
        The backend's kind ('sim', 'modbus', 'injected'; '' before the first is built).
    backend : RegulatorBackend or None
        The connected backend (None when released).
    core : RegulatorCore or None
        The control step (None until connected; kept after a release).
    finger_names, frames : tuple of str
        Per channel: the finger's name, and the frame id of its pressures.
    diagnostics : DiagnosticsSchedule

    """

    def __init__(self, backend=None):
        self._injected = backend
        self.kind = 'injected' if backend is not None else ''
        self.backend = None
        self.core = None
        self.finger_names = ()
        self.frames = ()
        self.config_max_pressure = math.inf
        self._register_map = None
        self.diagnostics = DiagnosticsSchedule()

    @property
    def device_watchdog_s(self):
        """The timeout of the connected device's own watchdog [s], or None if it has none."""
        return getattr(self.backend, 'device_watchdog_s', None)

    def limits(self, values):
        """Return the supervisors' limits of the parameter `values`, capped by the config."""
        return limits(values, self.config_max_pressure)

    def load(self, values):
        """
        Check the parameters that configure reads, and load the config files.

        Parameters
        ----------
        values : mapping
            Parameter values by name (`PARAMETERS` and ``use_sim_time``).

        Returns
        -------
        list of (Level, str)
            What is worth a log line: a parameter the gripper config overrides.

        Raises
        ------
        ConfigError
            A config file, or simulated time with a real regulator.
        ValueError
            An unknown backend or safe state.

        """
        for name in ('backend', 'safe_state'):
            reason = refusal(name, values[name])
            if reason is not None:
                raise ValueError(reason)
        if values['backend'] == 'modbus' and self._injected is None and values['use_sim_time']:
            raise ConfigError('parameters', 'use_sim_time', SIM_TIME_REFUSED)
        config, self._register_map = load_bridge_config(
            values['gripper_config'], values['backend'] if self._injected is None
            else 'injected', values['modbus_config'])
        watchdog = None if self._register_map is None else self._register_map.watchdog
        reason = watchdog_refusal(None if watchdog is None else watchdog.timeout_s,
                                  values['publish_rate_hz'])
        if reason is not None:
            raise ConfigError(values['modbus_config'], 'watchdog.timeout_s', reason)
        self.finger_names = tuple(f.name for f in config.fingers)
        self.frames = tuple(values['frame_prefix'] + name for name in self.finger_names)
        self.config_max_pressure = float(config.max_pressure)
        notes = []
        if values['max_pressure'] > self.config_max_pressure:
            notes.append((Level.WARN, f'max_pressure {values["max_pressure"]:.0f} Pa exceeds '
                                      f'the gripper config limit {self.config_max_pressure:.0f} '
                                      'Pa gauge; using the latter'))
        if abs(values['atmospheric_pressure'] - config.atmospheric_pressure) > 1.0:
            notes.append((Level.OK, f'atmospheric_pressure parameter '
                                    f'{values["atmospheric_pressure"]:.0f} Pa differs from the '
                                    f'gripper config {config.atmospheric_pressure:.0f} Pa; the '
                                    'parameter is used'))
        return notes

    def connect(self, values, bounds, clock):
        """
        Build the backend (or take the given one), connect it, and build the core over it.

        Parameters
        ----------
        values : mapping
            Parameter values by name, as for `load` (which must have run).
        bounds : InputBounds
            What a command must meet.
        clock : callable
            Seconds of the simulated backend's model time.

        Raises
        ------
        BackendFault
            The device cannot be reached.
        ValueError
            A backend parameter out of range, or too few channels.

        """
        n_channels = len(self.finger_names)
        if self._injected is not None:
            self.backend = self._injected
        else:
            self.backend = self._build_backend(values, n_channels, clock)
        if self.backend.n_channels < n_channels:
            raise ValueError(f'backend has {self.backend.n_channels} channels, the gripper '
                             f'config needs {n_channels}')
        self.backend.connect()
        self.core = RegulatorCore(self.backend, n_channels, self.limits(values), MonitorSettings(
            tracking_tolerance_pa=values['tracking_tolerance_pa'],
            tracking_timeout_s=values['tracking_timeout_s'],
            overpressure_margin_pa=values['overpressure_margin_pa'],
            reconnect_interval_s=RECONNECT_S,
            atmospheric_pressure=values['atmospheric_pressure']), bounds)
        self.diagnostics = DiagnosticsSchedule()

    def _build_backend(self, values, n_channels, clock):
        self.kind = kind = values['backend']
        if kind == 'sim':
            return make_backend('sim', n_channels=n_channels, clock=clock,
                                **{name[len('sim_'):]: values[name] for name in SIM_PARAMETERS})
        return make_backend('modbus', register_map=self._register_map,
                            host=values['modbus_host'] or None,
                            port=values['modbus_port'] or None)

    def abandon(self):
        """Close the backend of a failed configure (nothing was commanded) and drop the core."""
        if self.backend is not None:
            self.backend.close()
            self.backend = None
        self.core = None

    def release(self, now):
        """
        Send every channel's safe setpoint (best effort), then close the backend.

        Returns
        -------
        list of (int, str)
            The channels the safe setpoint could not be sent to, and why.

        """
        failed = self.core.release(now) if self.core is not None else []
        self.backend.close()
        self.backend = None
        return failed
