"""Lifecycle node that drives one pressure-regulator channel per finger through a supervisor."""

import functools
import math
import sys

from diagnostic_msgs.msg import DiagnosticArray
from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_msgs.msg import KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.lifecycle import LifecycleNode
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.qos import HistoryPolicy
from rclpy.qos import qos_profile_sensor_data
from rclpy.qos import QoSProfile
from rclpy.qos import ReliabilityPolicy
from rclpy.time import Time
from sensor_msgs.msg import FluidPressure

from fpc_gripper.io.config import default_gripper_config_path
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.nodes.guard import InputGuard
from fpc_gripper.nodes.parameters import declare_table
from fpc_gripper.nodes.parameters import float_range
from fpc_gripper.nodes.parameters import input_bound_table
from fpc_gripper.nodes.parameters import input_bounds
from fpc_gripper.nodes.parameters import int_range
from fpc_gripper.nodes.runner import run_node
from fpc_gripper.regulators.base import BackendFault
from fpc_gripper.regulators.core import Level
from fpc_gripper.regulators.core import MonitorSettings
from fpc_gripper.regulators.core import RegulatorCore
from fpc_gripper.regulators.factory import BACKEND_KINDS
from fpc_gripper.regulators.factory import make_backend
from fpc_gripper.regulators.modbus import RegisterMap
from fpc_gripper.regulators.safety import SafeState
from fpc_gripper.safe_yaml import ConfigError
from fpc_gripper.services.logs import NodeLog

SAFE_STATES = tuple(s.value for s in SafeState)

# Parameters read only at configure: refused while the node is configured.
_STRUCTURAL = ('gripper_config', 'backend', 'modbus_config', 'modbus_host', 'modbus_port',
               'sim_time_constant_s', 'sim_slew_rate_pa_s', 'sim_deadband_pa',
               'sim_noise_std_pa', 'sim_max_output_pa', 'sim_full_scale_pa', 'sim_adc_bits',
               'sim_seed', 'tracking_tolerance_pa', 'tracking_timeout_s',
               'overpressure_margin_pa')

_COMMAND_QOS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                          reliability=ReliabilityPolicy.RELIABLE)
_RECONNECT_S = 1.0
#: A real regulator's watchdog, rate limit and safe state follow the node clock: on /clock
#: a stopped simulation would hold the device at its last pressure.
_SIM_TIME_REFUSED = ('`use_sim_time` is true with backend modbus: a real regulator runs on '
                     'the wall clock (its watchdog, rate limit and safe state follow the node '
                     'clock, and a stopped /clock would hold its last pressure); use backend '
                     'sim on simulated time')
# The bounds that apply to a pressure command.
_BOUNDS = ('min_absolute_pressure', 'max_frame_id_length', 'max_payload_bytes')
_LEVELS = {Level.OK: DiagnosticStatus.OK, Level.WARN: DiagnosticStatus.WARN,
           Level.ERROR: DiagnosticStatus.ERROR}


def _parameter_table():
    """Return ``(name, default, description, extra descriptor fields)`` of every parameter."""
    return (
        ('gripper_config', str(default_gripper_config_path()),
         'Gripper YAML: one regulator channel per finger, in finger order.', {}),
        ('backend', 'sim', f'Regulator backend, one of {list(BACKEND_KINDS)}.',
         {'additional_constraints': f'one of {list(BACKEND_KINDS)}'}),
        ('modbus_config', '', 'Modbus register-map YAML (backend modbus).', {}),
        ('modbus_host', '', 'Overrides connection.host of modbus_config; empty keeps it.', {}),
        ('modbus_port', 0, 'Overrides connection.port of modbus_config; 0 keeps it.',
         {'integer_range': int_range(0, 65535)}),
        ('max_pressure', 4.0e5,
         'Largest setpoint [Pa gauge]; also capped by the gripper config max_pressure.',
         {'floating_point_range': float_range(0.0, 1.0e6)}),
        ('rate_limit_pa_s', 1.0e6, 'Setpoint slew limit [Pa/s].',
         {'floating_point_range': float_range(1.0e3, 1.0e9)}),
        ('command_timeout_s', 0.5, 'Command watchdog period [s].',
         {'floating_point_range': float_range(0.01, 3600.0)}),
        ('safe_state', 'vent',
         "Watchdog/fault behaviour: 'hold' keeps the last setpoint, 'vent' goes to 0 gauge.",
         {'additional_constraints': f'one of {list(SAFE_STATES)}'}),
        ('publish_rate_hz', 50.0, 'Control and pressure publishing rate [Hz].',
         {'floating_point_range': float_range(1.0, 1000.0)}),
        ('diagnostics_rate_hz', 2.0,
         'Diagnostics rate [Hz]; a change of state is published at once.',
         {'floating_point_range': float_range(0.1, 100.0)}),
        ('atmospheric_pressure', 101325.0,
         'Atmospheric pressure [Pa]: gauge = absolute - atmospheric_pressure.',
         {'floating_point_range': float_range(3.0e4, 1.2e5)}),
        ('auto_activate', False, 'Configure and activate at start-up (main defaults it to '
         'true; gripper.launch.py sets false and drives the transitions).',
         {'read_only': True}),
        ('frame_prefix', '', 'Prefix of the frame id of the published pressures '
         "(<prefix>finger_<i>), as model_node's.", {'read_only': True}),
        ('tracking_tolerance_pa', 2.0e4,
         'Largest |measured - setpoint| that counts as following the setpoint [Pa].',
         {'floating_point_range': float_range(1.0e2, 1.0e6)}),
        ('tracking_timeout_s', 2.0,
         'Time a measurement may stay off the setpoint before the channel is in fault '
         '(leak, blocked valve, stuck sensor) [s]; 0 disables.',
         {'floating_point_range': float_range(0.0, 3600.0)}),
        ('overpressure_margin_pa', 5.0e4,
         'A measurement above max_pressure plus this vents the channel at once [Pa].',
         {'floating_point_range': float_range(0.0, 1.0e6)}),
        ('sim_time_constant_s', 0.15, 'Simulated regulator first-order time constant [s].',
         {'floating_point_range': float_range(1.0e-3, 100.0)}),
        ('sim_slew_rate_pa_s', 2.0e6, 'Simulated regulator slew limit [Pa/s].',
         {'floating_point_range': float_range(1.0e3, 1.0e10)}),
        ('sim_deadband_pa', 500.0, 'Simulated regulator deadband [Pa].',
         {'floating_point_range': float_range(0.0, 1.0e5)}),
        ('sim_noise_std_pa', 300.0, 'Simulated readback noise standard deviation [Pa].',
         {'floating_point_range': float_range(0.0, 1.0e5)}),
        ('sim_max_output_pa', 7.0e5, 'Simulated supply-limited output [Pa gauge].',
         {'floating_point_range': float_range(1.0e3, 1.0e7)}),
        ('sim_full_scale_pa', 1.0e6, 'Simulated readback full scale [Pa gauge].',
         {'floating_point_range': float_range(1.0e3, 1.0e7)}),
        ('sim_adc_bits', 12, 'Simulated readback resolution [bit].',
         {'integer_range': int_range(1, 32)}),
        ('sim_seed', 0, 'Seed of the simulated readback noise.',
         {'integer_range': int_range(0, 2 ** 31 - 1)}),
        *input_bound_table(_BOUNDS),
    )


class RegulatorBridge(LifecycleNode):
    """
    Bridge ``finger_<i>/pressure_command`` to a regulator backend and publish what it measures.

    Each finger of the gripper config gets one backend channel guarded by a
    :class:`~fpc_gripper.regulators.safety.ChannelSupervisor` (clamp, rate
    limit, command watchdog, safe state). Commands and measurements on the
    topics are ABSOLUTE pressures [Pa]; the backend works in gauge pressure. A
    command is checked first (`RegulatorCore.offer_command`: a finite number at or
    above ``min_absolute_pressure``, a bounded frame_id and payload); a rejected one
    changes nothing and makes its channel WARN until the next good one.

    Parameters
    ----------
    node_name : str
        Node name.
    backend : RegulatorBackend, optional
        Use this backend instead of building one from the parameters at configure.
    auto_activate_default : bool
        Default of the ``auto_activate`` parameter (``main`` passes True).
    **kwargs
        Passed to :class:`rclpy.lifecycle.LifecycleNode` (namespace,
        parameter_overrides, context, ...).
    """

    def __init__(self, node_name='regulator_bridge', *, backend=None,
                 auto_activate_default=False, **kwargs):
        super().__init__(node_name, **kwargs)
        declare_table(self, _parameter_table(),
                      defaults={'auto_activate': bool(auto_activate_default)})
        self._injected_backend = backend
        self._backend = None
        self._backend_kind = 'injected' if backend is not None else ''
        self._now_s = self._clock_s()
        self._configured = False
        self._active = False
        self._finger_names = ()
        self._core = None
        self._supervisors = ()
        self._config_error = None
        self._pressure_pubs = ()
        self._command_subs = ()
        self._diag_pub = None
        self._timer = None
        self._last_diag_time = None
        self._last_levels = None
        self._config_max_pressure = math.inf
        self._log = NodeLog(self.get_logger())
        self._guard = InputGuard(self.get_parameter('max_payload_bytes').value)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        if self.get_parameter('auto_activate').value:
            self.configure_and_activate()

    # -- public helpers ---------------------------------------------------------------------

    @classmethod
    def create_active(cls, node_name='regulator_bridge', *, backend=None, **kwargs):
        """
        Build a bridge, configure it and activate it (for single-process executors).

        Parameters
        ----------
        node_name : str
            Node name.
        backend : RegulatorBackend, optional
            See :class:`RegulatorBridge`.
        **kwargs
            Passed to the constructor (namespace, parameter_overrides, context, ...).

        Raises
        ------
        RuntimeError
            If configure or activate does not succeed (the node is destroyed).
        """
        node = cls(node_name, backend=backend, **kwargs)
        try:
            node.configure_and_activate(raise_on_failure=True)
        except Exception:
            node.destroy_node()
            raise
        return node

    def configure_and_activate(self, raise_on_failure=False):
        """Run the configure and activate transitions that are still needed; return success."""
        for wanted, trigger in (('unconfigured', self.trigger_configure),
                                ('inactive', self.trigger_activate)):
            if self.lifecycle_state != wanted:
                continue
            result = trigger()
            if result != TransitionCallbackReturn.SUCCESS:
                message = (f'{trigger.__name__} of {self.get_name()} returned {result.name}; '
                           f'now {self.lifecycle_state}')
                if raise_on_failure:
                    raise RuntimeError(message)
                if trigger != self.trigger_configure:
                    # on_configure has logged its reason already: one line per failure.
                    self.get_logger().error(message)
                return False
        return self.lifecycle_state == 'active'

    @property
    def lifecycle_state(self):
        """Label of the current lifecycle state ('unconfigured', 'inactive', 'active', ...)."""
        return self._state_machine.current_state[1]

    @property
    def backend(self):
        """The backend in use (None while unconfigured)."""
        return self._backend

    @property
    def supervisors(self):
        """The per-finger channel supervisors, in finger order."""
        return self._supervisors

    @property
    def finger_names(self):
        """Finger names of the gripper config, in channel order."""
        return self._finger_names

    @property
    def config_error(self):
        """The `ConfigError` of the last failed configure (None if it was not the config)."""
        return self._config_error

    def destroy_node(self):
        """Put every channel in its safe state, close the backend, then destroy the node."""
        self._release_backend('node destroyed')
        super().destroy_node()

    # -- lifecycle --------------------------------------------------------------------------

    def on_configure(self, state):
        """Load the gripper config, build and connect the backend, create the topics."""
        self._config_error = None
        try:
            self._configure()
        except (BackendFault, ImportError, KeyError, OSError, TypeError, ValueError) as exc:
            if isinstance(exc, ConfigError):
                self._config_error = exc
            self.get_logger().error(f'configure failed: {exc}')
            if self._backend is not None:
                # Nothing was commanded in this configuration: just let go of the device.
                self._backend.close()
                self._backend = None
            self._destroy_entities()
            self._core = None
            self._supervisors = ()
            return TransitionCallbackReturn.FAILURE
        self._configured = True
        return super().on_configure(state)

    def on_activate(self, state):
        """Start the control timer."""
        # Activation acknowledges the latched faults (over-pressure, tracking).
        self._core.start(self._latch())
        self._active = True
        self._last_diag_time = None
        self._start_timer()
        self.get_logger().info(
            f'active: {len(self._finger_names)} channels on backend {self._backend_kind}, '
            f'max_pressure {self._supervisors[0].max_pressure:.0f} Pa gauge')
        return super().on_activate(state)

    def on_deactivate(self, state):
        """Stop the timer and put every channel in its safe state."""
        self._stop_timer()
        self._active = False
        now = self._latch()
        self._core.stop(now)
        self._control_step(now, force_diagnostics=True)
        return super().on_deactivate(state)

    def on_cleanup(self, state):
        """Close the backend and destroy the topics."""
        self._release_backend('cleanup')
        self._destroy_entities()
        self._configured = False
        return super().on_cleanup(state)

    def on_shutdown(self, state):
        """Safe state, close the backend, destroy the topics."""
        self._stop_timer()
        self._active = False
        self._release_backend('shutdown')
        self._destroy_entities()
        self._configured = False
        return super().on_shutdown(state)

    def on_error(self, state):
        """Safe state and release everything; the node returns to unconfigured."""
        self._stop_timer()
        self._active = False
        self._release_backend('error')
        self._destroy_entities()
        self._configured = False
        return TransitionCallbackReturn.SUCCESS

    # -- parameters -------------------------------------------------------------------------

    def _validate_parameters(self, parameters):
        try:
            input_bounds(self, {p.name: p.value for p in parameters})
        except (TypeError, ValueError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        for param in parameters:
            if param.name in _STRUCTURAL and self._configured:
                return SetParametersResult(
                    successful=False,
                    reason=f'`{param.name}` is read at configure; the node is '
                           f'{self.lifecycle_state}: cleanup first, then configure')
            if param.name == 'backend' and param.value not in BACKEND_KINDS:
                return SetParametersResult(
                    successful=False,
                    reason=f'`backend` must be one of {list(BACKEND_KINDS)}, '
                           f'got {param.value!r}')
            if param.name == 'use_sim_time' and param.value and self._configured \
                    and self._backend_kind == 'modbus':
                return SetParametersResult(successful=False, reason=_SIM_TIME_REFUSED)
            if param.name == 'safe_state' and param.value not in SAFE_STATES:
                return SetParametersResult(
                    successful=False,
                    reason=f'`safe_state` must be one of {list(SAFE_STATES)}, '
                           f'got {param.value!r}')
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters):
        names = {p.name for p in parameters}
        if names & {'max_pressure', 'rate_limit_pa_s', 'command_timeout_s', 'safe_state'}:
            limits = self._limits()
            if self._core is not None:
                self._core.configure(**limits)
            self.get_logger().info(
                f'limits now max_pressure {limits["max_pressure"]:.0f} Pa gauge, '
                f'rate_limit {limits["rate_limit_pa_s"]:.0f} Pa/s, command_timeout '
                f'{limits["command_timeout_s"]:.3f} s, safe_state {limits["safe_state"]}')
        if 'publish_rate_hz' in names and self._active:
            self._stop_timer()
            self._start_timer()
        if names & set(_BOUNDS):
            bounds = input_bounds(self)
            self._guard.max_payload_bytes = bounds.max_payload_bytes
            if self._core is not None:
                self._core.bounds = bounds

    def _limits(self):
        requested = self.get_parameter('max_pressure').value
        return {
            'max_pressure': min(requested, self._config_max_pressure),
            'rate_limit_pa_s': self.get_parameter('rate_limit_pa_s').value,
            'command_timeout_s': self.get_parameter('command_timeout_s').value,
            'safe_state': self.get_parameter('safe_state').value,
        }

    # -- configure helpers ------------------------------------------------------------------

    def _configure(self):
        param = self.get_parameter
        for name in ('backend', 'safe_state'):
            result = self._validate_parameters([param(name)])
            if not result.successful:
                raise ValueError(result.reason)
        if param('backend').value == 'modbus' and self._injected_backend is None \
                and param('use_sim_time').value:
            raise ConfigError('parameters', 'use_sim_time', _SIM_TIME_REFUSED)
        config, register_map = load_bridge_config(
            param('gripper_config').value,
            param('backend').value if self._injected_backend is None else 'injected',
            param('modbus_config').value)
        self._finger_names = tuple(f.name for f in config.fingers)
        self._frames = tuple(param('frame_prefix').value + name for name in self._finger_names)
        n_channels = len(self._finger_names)
        self._config_max_pressure = float(config.max_pressure)
        if param('max_pressure').value > self._config_max_pressure:
            self.get_logger().warning(
                f'max_pressure {param("max_pressure").value:.0f} Pa exceeds the gripper '
                f'config limit {self._config_max_pressure:.0f} Pa gauge; using the latter')
        if abs(param('atmospheric_pressure').value - config.atmospheric_pressure) > 1.0:
            self.get_logger().info(
                f'atmospheric_pressure parameter {param("atmospheric_pressure").value:.0f} Pa '
                f'differs from the gripper config {config.atmospheric_pressure:.0f} Pa; '
                'the parameter is used')
        if self._injected_backend is not None:
            self._backend = self._injected_backend
        else:
            self._backend = self._build_backend(n_channels, register_map)
        if self._backend.n_channels < n_channels:
            raise ValueError(f'backend has {self._backend.n_channels} channels, the gripper '
                             f'config needs {n_channels}')
        self._backend.connect()
        self._core = RegulatorCore(self._backend, n_channels, self._limits(), MonitorSettings(
            tracking_tolerance_pa=param('tracking_tolerance_pa').value,
            tracking_timeout_s=param('tracking_timeout_s').value,
            overpressure_margin_pa=param('overpressure_margin_pa').value,
            reconnect_interval_s=_RECONNECT_S,
            atmospheric_pressure=param('atmospheric_pressure').value), input_bounds(self))
        self._supervisors = self._core.supervisors
        self._last_levels = None
        self._pressure_pubs = tuple(
            self.create_lifecycle_publisher(FluidPressure, f'{name}/pressure',
                                            qos_profile_sensor_data)
            for name in self._finger_names)
        self._diag_pub = self.create_lifecycle_publisher(DiagnosticArray, '/diagnostics',
                                                         _COMMAND_QOS)
        self._command_subs = tuple(
            self._guard.subscribe(self, FluidPressure, f'{name}/pressure_command',
                                  _COMMAND_QOS, functools.partial(self._on_command, i),
                                  functools.partial(self._on_refused, i))
            for i, name in enumerate(self._finger_names))

    def _build_backend(self, n_channels, register_map):
        param = self.get_parameter
        kind = param('backend').value
        self._backend_kind = kind
        if kind == 'sim':
            return make_backend(
                'sim', n_channels=n_channels,
                time_constant_s=param('sim_time_constant_s').value,
                slew_rate_pa_s=param('sim_slew_rate_pa_s').value,
                deadband_pa=param('sim_deadband_pa').value,
                max_output_pa=param('sim_max_output_pa').value,
                adc_bits=param('sim_adc_bits').value,
                full_scale_pa=param('sim_full_scale_pa').value,
                noise_std_pa=param('sim_noise_std_pa').value,
                seed=param('sim_seed').value,
                # The model advances to the time latched at each control step, so every
                # published stamp is exactly the model time of its sample.
                clock=self._backend_time)
        return make_backend('modbus', register_map=register_map,
                            host=param('modbus_host').value or None,
                            port=param('modbus_port').value or None)

    def _destroy_entities(self):
        self._stop_timer()
        for sub in self._command_subs:
            self.destroy_subscription(sub)
        for pub in self._pressure_pubs:
            self.destroy_lifecycle_publisher(pub)
        if self._diag_pub is not None:
            self.destroy_lifecycle_publisher(self._diag_pub)
        self._command_subs = ()
        self._pressure_pubs = ()
        self._diag_pub = None

    def _release_backend(self, why):
        """Send every channel's safe setpoint (best effort), then close the backend."""
        if self._backend is None:
            return
        if self._core is not None:
            for channel, error in self._core.release(self._latch()):
                self.get_logger().warning(
                    f'{why}: could not send the safe state to channel {channel}: {error}')
        self._backend.close()
        self._backend = None

    # -- run time ---------------------------------------------------------------------------

    def _start_timer(self):
        self._timer = self.create_timer(1.0 / self.get_parameter('publish_rate_hz').value,
                                        self._on_timer)

    def _stop_timer(self):
        if self._timer is not None:
            self.destroy_timer(self._timer)
            self._timer = None

    def _clock_s(self):
        return self.get_clock().now().nanoseconds * 1e-9

    def _latch(self):
        self._now_s = self._clock_s()
        return self._now_s

    def _backend_time(self):
        return self._now_s

    def _on_command(self, index, msg):
        name = self._finger_names[index]
        if not self._active:
            self._log.info(f'{name}/pressure_command ignored: node is not active',
                           key=(index, 'inactive'))
            return
        check, result = self._core.offer_command(
            index, msg.fluid_pressure, self._latch(),
            atmospheric_pressure=self.get_parameter('atmospheric_pressure').value,
            frame_id=msg.header.frame_id)
        if result is None:
            self._rejected(index, check)
        elif not result.accepted:
            self._log.warning(
                f'{name}/pressure_command ignored: channel in safe state '
                f'({self._supervisors[index].mode.name.lower()})', key=(index, 'safe'))
        elif result.clamped:
            self._log.warning(
                f'{name}/pressure_command {check.value:.0f} Pa gauge clamped to '
                f'{result.target:.0f} Pa gauge (max_pressure '
                f'{self._supervisors[index].max_pressure:.0f} Pa)', key=(index, 'clamped'))

    def _on_refused(self, index, check):
        if self._core is not None:
            self._rejected(index, self._core.reject(index, check.rejection, check.detail))

    def _rejected(self, index, check):
        self._log.warning(
            f'{self._finger_names[index]}/pressure_command rejected ({check.rejection.value}): '
            f'{check.detail}', key=(index, check.rejection))

    def _on_timer(self):
        self._control_step(self._latch())

    def _control_step(self, now, force_diagnostics=False):
        """Run the core's step; publish what it measured and the channels' health."""
        if self._backend is None or self._core is None:
            return
        step = self._core.step(now)
        atmospheric = self.get_parameter('atmospheric_pressure').value
        stamp = Time(nanoseconds=int(round(now * 1e9))).to_msg()
        for sample in step.samples:
            msg = FluidPressure()
            msg.header.stamp = stamp
            msg.header.frame_id = self._frames[sample.channel]
            msg.fluid_pressure = sample.pressure + atmospheric
            msg.variance = sample.variance
            self._pressure_pubs[sample.channel].publish(msg)
        for level, text in step.events:
            if level == Level.ERROR:
                self._log.error(text)
            else:
                self._log.info(text)
        self._publish_diagnostics(now, step.reports, force_diagnostics)

    def _publish_diagnostics(self, now, reports, force):
        levels = [(r.level, r.mode) for r in reports]
        period = 1.0 / self.get_parameter('diagnostics_rate_hz').value
        # A clock that stepped back must not silence the periodic diagnostics.
        due = self._last_diag_time is None or not 0.0 <= now - self._last_diag_time < period
        if not (force or due or levels != self._last_levels):
            return
        self._last_diag_time = now
        self._last_levels = levels
        array = DiagnosticArray()
        array.header.stamp = Time(nanoseconds=int(round(now * 1e9))).to_msg()
        array.status = [self._channel_status(i, r) for i, r in enumerate(reports)]
        self._diag_pub.publish(array)

    def _channel_status(self, index, report):
        values = dict(report.values, backend=self._backend_kind)
        return DiagnosticStatus(
            level=_LEVELS[report.level],
            name=f'{self.get_fully_qualified_name()}: {self._finger_names[index]}',
            message=report.message, hardware_id=f'{self._backend_kind}:{index}',
            values=[KeyValue(key=k, value=v) for k, v in values.items()])


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


def main(args=None):
    """
    Run the bridge until SIGINT or SIGTERM: 0 then, 2 on a bad config, else 1.

    It configures and activates itself unless ``auto_activate`` is false; when that
    activation fails, it exits (2 when the configuration is invalid, 1 when the device
    cannot be reached, after the one log line that says why) rather than stay up
    half-configured.
    """
    return run_node(functools.partial(RegulatorBridge, auto_activate_default=True),
                    'regulator_bridge', args, check=activation_exit_code)


def activation_exit_code(node):
    """Exit code for a bridge whose auto-activation failed (2 invalid, 1 else), or None."""
    if node.get_parameter('auto_activate').value and node.lifecycle_state != 'active':
        return 2 if node.config_error is not None else 1
    return None


if __name__ == '__main__':
    sys.exit(main())
