"""Lifecycle node that drives one pressure-regulator channel per finger through a supervisor."""

import functools
import sys

from diagnostic_msgs.msg import DiagnosticArray
from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_msgs.msg import KeyValue
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.qos import qos_profile_sensor_data
from rclpy.time import Time
from sensor_msgs.msg import FluidPressure

from fpc_gripper.io.qos import RELIABLE_QOS
from fpc_gripper.nodes.guard import InputGuard
from fpc_gripper.nodes.lifecycle import SelfActivatingNode
from fpc_gripper.nodes.parameters import check_change
from fpc_gripper.nodes.parameters import declare_table
from fpc_gripper.nodes.parameters import input_bounds
from fpc_gripper.nodes.runner import run_node
from fpc_gripper.regulators.base import BackendFault
from fpc_gripper.regulators.bridge import BridgeSession
from fpc_gripper.regulators.bridge_parameters import BOUND_PARAMETERS
from fpc_gripper.regulators.bridge_parameters import LIMIT_PARAMETERS
from fpc_gripper.regulators.bridge_parameters import PARAMETERS
from fpc_gripper.regulators.bridge_parameters import refusal
from fpc_gripper.regulators.core import Level
from fpc_gripper.safe_yaml import ConfigError
from fpc_gripper.services.input_limits import input_bound_table
from fpc_gripper.services.logs import NodeLog
from fpc_gripper.services.logs import Severity

_LEVELS = {Level.OK: DiagnosticStatus.OK, Level.WARN: DiagnosticStatus.WARN,
           Level.ERROR: DiagnosticStatus.ERROR}
#: A line of the session or the core logs at the severity of its level (OK: info).
_SEVERITIES = {Level.OK: Severity.INFO, Level.WARN: Severity.WARN, Level.ERROR: Severity.ERROR}
#: What configure reads: every parameter of the table, and rclpy's use_sim_time.
_CONFIGURE_READS = tuple(row[0] for row in PARAMETERS) + ('use_sim_time',)


class RegulatorBridge(SelfActivatingNode):
    """
    Bridge ``finger_<i>/pressure_command`` to a regulator backend and publish what it measures.

    Each finger of the gripper config gets one backend channel guarded by a
    :class:`~fpc_gripper.regulators.safety.ChannelSupervisor` (clamp, rate
    limit, command watchdog, safe state). Commands and measurements on the
    topics are ABSOLUTE pressures [Pa]; the backend works in gauge pressure. A
    command is checked first (`RegulatorCore.offer_command`: a finite number at or
    above ``min_absolute_pressure``, a bounded frame_id and payload); a rejected one
    changes nothing and makes its channel WARN until the next good one. What configure
    builds and cleanup ends is a :class:`~fpc_gripper.regulators.bridge.BridgeSession`.

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
        declare_table(self, (*PARAMETERS, *input_bound_table(BOUND_PARAMETERS)),
                      defaults={'auto_activate': bool(auto_activate_default)})
        self._session = BridgeSession(backend)
        self._now_s = self._clock_s()
        self._configured = False
        self._active = False
        self._config_error = None
        self._pressure_pubs = ()
        self._command_subs = ()
        self._diag_pub = None
        self._timer = None
        self._log = NodeLog(self.get_logger())
        self._guard = InputGuard(self.get_parameter('max_payload_bytes').value)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        if self.get_parameter('auto_activate').value:
            self.configure_and_activate()

    # -- public helpers ---------------------------------------------------------------------

    @property
    def backend(self):
        """The backend in use (None while unconfigured)."""
        return self._session.backend

    @property
    def core(self):
        """The ROS-free control step (:class:`~fpc_gripper.regulators.core.RegulatorCore`)."""
        return self._session.core

    @property
    def supervisors(self):
        """The per-finger channel supervisors, in finger order."""
        return self.core.supervisors if self.core is not None else ()

    @property
    def finger_names(self):
        """Finger names of the gripper config, in channel order."""
        return self._session.finger_names

    @property
    def config_error(self):
        """The `ConfigError` of the last failed configure (None if it was not the config)."""
        return self._config_error

    def destroy_node(self):
        """Put every channel in its safe state, close the backend, then destroy the node."""
        self._release_backend('node destroyed')
        self._guard.close()
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
            # Nothing was commanded in this configuration: just let go of the device.
            self._session.abandon()
            self._destroy_entities()
            return TransitionCallbackReturn.FAILURE
        self._configured = True
        return super().on_configure(state)

    def on_activate(self, state):
        """Start the control timer."""
        # Activation acknowledges the latched faults (over-pressure, tracking).
        self.core.start(self._latch())
        self._active = True
        self._session.diagnostics.restart()
        self._start_timer()
        self.get_logger().info(
            f'active: {len(self.finger_names)} channels on backend {self._session.kind}, '
            f'max_pressure {self.supervisors[0].max_pressure:.0f} Pa gauge'
            f'{_device_watchdog_text(self._session.device_watchdog_s, self._session.kind)}')
        return super().on_activate(state)

    def on_deactivate(self, state):
        """Stop the timer and put every channel in its safe state."""
        self._stop_timer()
        self._active = False
        now = self._latch()
        self.core.stop(now)
        self._control_step(now, force_diagnostics=True)
        return super().on_deactivate(state)

    def on_cleanup(self, state):
        """Close the backend and destroy the topics."""
        self._release('cleanup')
        return super().on_cleanup(state)

    def on_shutdown(self, state):
        """Safe state, close the backend, destroy the topics."""
        self._release('shutdown')
        return super().on_shutdown(state)

    def on_error(self, state):
        """Safe state and release everything; the node returns to unconfigured."""
        self._release('error')
        return TransitionCallbackReturn.SUCCESS

    def _release(self, why):
        self._stop_timer()
        self._active = False
        self._release_backend(why)
        self._destroy_entities()
        self._configured = False

    # -- parameters -------------------------------------------------------------------------

    def _validate_parameters(self, parameters):
        return check_change(self, parameters, self._refusal)

    def _refusal(self, changes):
        return next(filter(None, (
            refusal(name, value, configured=self._configured, state=self.lifecycle_state,
                    backend_kind=self._session.kind,
                    device_watchdog_s=self._session.device_watchdog_s)
            for name, value in changes.items())), None)

    def _apply_parameters(self, parameters):
        names = {p.name for p in parameters}
        if names & set(LIMIT_PARAMETERS):
            limits = self._session.limits(self._values(LIMIT_PARAMETERS))
            if self.core is not None:
                self.core.configure(**limits)
            self.get_logger().info(
                f'limits now max_pressure {limits["max_pressure"]:.0f} Pa gauge, '
                f'rate_limit {limits["rate_limit_pa_s"]:.0f} Pa/s, command_timeout '
                f'{limits["command_timeout_s"]:.3f} s, safe_state {limits["safe_state"]}')
        if 'publish_rate_hz' in names and self._active:
            self._stop_timer()
            self._start_timer()
        if names & set(BOUND_PARAMETERS):
            bounds = input_bounds(self)
            self._guard.max_payload_bytes = bounds.max_payload_bytes
            if self.core is not None:
                self.core.bounds = bounds

    def _values(self, names):
        return {name: self.get_parameter(name).value for name in names}

    # -- configure helpers ------------------------------------------------------------------

    def _configure(self):
        values = self._values(_CONFIGURE_READS)
        bounds = input_bounds(self)
        for level, text in self._session.load(values):
            self._log.log(_SEVERITIES[level], text)
        # The simulated backend's model advances to the time latched at each control step,
        # so every published stamp is exactly the model time of its sample.
        self._session.connect(values, bounds, self._backend_time)
        self._pressure_pubs = tuple(
            self.create_lifecycle_publisher(FluidPressure, f'{name}/pressure',
                                            qos_profile_sensor_data)
            for name in self.finger_names)
        self._diag_pub = self.create_lifecycle_publisher(DiagnosticArray, '/diagnostics',
                                                         RELIABLE_QOS)
        self._command_subs = tuple(
            self._guard.subscribe(self, FluidPressure, f'{name}/pressure_command',
                                  RELIABLE_QOS, functools.partial(self._on_command, i),
                                  functools.partial(self._on_refused, i),
                                  functools.partial(self._on_lost, i))
            for i, name in enumerate(self.finger_names))

    def _destroy_entities(self):
        self._stop_timer()
        for sub in self._command_subs:
            self._guard.forget(sub)
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
        if self.backend is None:
            return
        for channel, error in self._session.release(self._latch()):
            self.get_logger().warning(
                f'{why}: could not send the safe state to channel {channel}: {error}')

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
        name = self.finger_names[index]
        if not self._active:
            self._log.info(f'{name}/pressure_command ignored: node is not active',
                           key=(index, 'inactive'))
            return
        check, result = self.core.offer_command(
            index, msg.fluid_pressure, self._latch(),
            atmospheric_pressure=self.get_parameter('atmospheric_pressure').value,
            frame_id=msg.header.frame_id)
        if result is None:
            self._rejected(index, check)
        elif not result.accepted:
            self._log.warning(
                f'{name}/pressure_command ignored: channel in safe state '
                f'({self.supervisors[index].mode.name.lower()})', key=(index, 'safe'))
        elif result.clamped:
            self._log.warning(
                f'{name}/pressure_command {check.value:.0f} Pa gauge clamped to '
                f'{result.target:.0f} Pa gauge (max_pressure '
                f'{self.supervisors[index].max_pressure:.0f} Pa)', key=(index, 'clamped'))

    def _on_refused(self, index, check):
        if self.core is not None:
            self._rejected(index, self.core.reject(index, check.rejection, check.detail))

    def _on_lost(self, index, count):
        """Report commands the middleware lost (see README: empty payloads)."""
        if self.core is not None:
            self._rejected(index, self.core.lost(index, count))

    def _rejected(self, index, check):
        self._log.warning(
            f'{check.headline(self.finger_names[index] + "/pressure_command")}: '
            f'{check.detail}', key=(index, check.rejection))

    def _on_timer(self):
        self._control_step(self._latch())

    def _control_step(self, now, force_diagnostics=False):
        """Run the core's step; publish what it measured and the channels' health."""
        if self.backend is None or self.core is None:
            return
        step = self.core.step(now)
        atmospheric = self.get_parameter('atmospheric_pressure').value
        stamp = Time(nanoseconds=int(round(now * 1e9))).to_msg()
        for sample in step.samples:
            msg = FluidPressure()
            msg.header.stamp = stamp
            msg.header.frame_id = self._session.frames[sample.channel]
            msg.fluid_pressure = sample.pressure + atmospheric
            msg.variance = sample.variance
            self._pressure_pubs[sample.channel].publish(msg)
        for level, text in step.events:
            self._log.log(_SEVERITIES[level], text)
        period = 1.0 / self.get_parameter('diagnostics_rate_hz').value
        if self._session.diagnostics.due(now, step.reports, period, force_diagnostics):
            array = DiagnosticArray()
            array.header.stamp = stamp
            array.status = [self._channel_status(i, r) for i, r in enumerate(step.reports)]
            self._diag_pub.publish(array)

    def _channel_status(self, index, report):
        kind = self._session.kind
        values = dict(report.values, backend=kind)
        return DiagnosticStatus(
            level=_LEVELS[report.level],
            name=f'{self.get_fully_qualified_name()}: {self.finger_names[index]}',
            message=report.message, hardware_id=f'{kind}:{index}',
            values=[KeyValue(key=k, value=v) for k, v in values.items()])


def _device_watchdog_text(timeout_s, kind):
    if timeout_s is not None:
        return f', device watchdog {timeout_s:g} s'
    return ', no device watchdog (the map names none)' if kind == 'modbus' else ''


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
