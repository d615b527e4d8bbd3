"""The regulator bridge's parameters without ROS: their table and the checks made on a change."""

import math

from fpc_gripper.io.config import default_gripper_config_path
from fpc_gripper.regulators.factory import BACKEND_KINDS
from fpc_gripper.regulators.safety import SafeState
from fpc_gripper.services.input_limits import atmospheric_pressure_row

__all__ = ['BOUND_PARAMETERS', 'DEVICE_WATCHDOG_PERIODS', 'LIMIT_PARAMETERS', 'PARAMETERS',
           'SAFE_STATES', 'SIM_PARAMETERS', 'SIM_TIME_REFUSED', 'STRUCTURAL', 'limits',
           'refusal', 'watchdog_refusal']

SAFE_STATES = tuple(s.value for s in SafeState)

#: Parameters read only at configure: refused while the node is configured.
STRUCTURAL = ('gripper_config', 'backend', 'modbus_config', 'modbus_host', 'modbus_port',
              'sim_time_constant_s', 'sim_slew_rate_pa_s', 'sim_deadband_pa',
              'sim_noise_std_pa', 'sim_max_output_pa', 'sim_full_scale_pa', 'sim_adc_bits',
              'sim_seed', 'tracking_tolerance_pa', 'tracking_timeout_s',
              'overpressure_margin_pa')
#: Parameters of the simulated backend: ``sim_<name>`` is SimulatedRegulator's ``<name>``.
SIM_PARAMETERS = tuple(name for name in STRUCTURAL if name.startswith('sim_'))
#: The channel supervisors' limits: a change reaches every channel at once.
LIMIT_PARAMETERS = ('max_pressure', 'rate_limit_pa_s', 'command_timeout_s', 'safe_state')
#: The input bounds that apply to a pressure command.
BOUND_PARAMETERS = ('min_absolute_pressure', 'max_frame_id_length', 'max_payload_bytes')
#: A real regulator's watchdog, rate limit and safe state follow the node clock: on /clock
#: a stopped simulation would hold the device at its last pressure.
SIM_TIME_REFUSED = ('`use_sim_time` is true with backend modbus: a real regulator runs on '
                    'the wall clock (its watchdog, rate limit and safe state follow the node '
                    'clock, and a stopped /clock would hold its last pressure); use backend '
                    'sim on simulated time')

#: The fewest control periods a device's own watchdog may last: the bridge writes every
#: setpoint once a period, so a shorter one would vent the device at one late step.
DEVICE_WATCHDOG_PERIODS = 3

#: ``(name, default, description, descriptor fields)`` of every parameter but the input
#: bounds, ranges as ``(low, high)``.
PARAMETERS = (
    ('gripper_config', str(default_gripper_config_path()),
     'Gripper YAML: one regulator channel per finger, in finger order.', {}),
    ('backend', 'sim', f'Regulator backend, one of {list(BACKEND_KINDS)}.',
     {'additional_constraints': f'one of {list(BACKEND_KINDS)}'}),
    ('modbus_config', '', 'Modbus register-map YAML (backend modbus).', {}),
    ('modbus_host', '', 'Overrides connection.host of modbus_config; empty keeps it.', {}),
    ('modbus_port', 0, 'Overrides connection.port of modbus_config; 0 keeps it.',
     {'integer_range': (0, 65535)}),
    ('max_pressure', 4.0e5,
     'Largest setpoint [Pa gauge]; also capped by the gripper config max_pressure.',
     {'floating_point_range': (0.0, 1.0e6)}),
    ('rate_limit_pa_s', 1.0e6, 'Setpoint slew limit [Pa/s].',
     {'floating_point_range': (1.0e3, 1.0e9)}),
    ('command_timeout_s', 0.5, 'Command watchdog period [s].',
     {'floating_point_range': (0.01, 3600.0)}),
    ('safe_state', 'vent',
     "Watchdog/fault behaviour: 'hold' keeps the last setpoint, 'vent' goes to 0 gauge.",
     {'additional_constraints': f'one of {list(SAFE_STATES)}'}),
    ('publish_rate_hz', 50.0, 'Control and pressure publishing rate [Hz].',
     {'floating_point_range': (1.0, 1000.0)}),
    ('diagnostics_rate_hz', 2.0,
     'Diagnostics rate [Hz]; a change of state is published at once.',
     {'floating_point_range': (0.1, 100.0)}),
    atmospheric_pressure_row(),
    ('auto_activate', False, 'Configure and activate at start-up (main defaults it to '
     'true; gripper.launch.py sets false and drives the transitions).',
     {'read_only': True}),
    ('frame_prefix', '', 'Prefix of the frame id of the published pressures '
     "(<prefix>finger_<i>), as model_node's.", {'read_only': True}),
    ('tracking_tolerance_pa', 2.0e4,
     'Largest |measured - setpoint| that counts as following the setpoint [Pa].',
     {'floating_point_range': (1.0e2, 1.0e6)}),
    ('tracking_timeout_s', 2.0,
     'Time a measurement may stay off the setpoint before the channel is in fault '
     '(leak, blocked valve, stuck sensor) [s]; 0 disables.',
     {'floating_point_range': (0.0, 3600.0)}),
    ('overpressure_margin_pa', 5.0e4,
     'A measurement above max_pressure plus this vents the channel at once [Pa].',
     {'floating_point_range': (0.0, 1.0e6)}),
    ('sim_time_constant_s', 0.15, 'Simulated regulator first-order time constant [s].',
     {'floating_point_range': (1.0e-3, 100.0)}),
    ('sim_slew_rate_pa_s', 2.0e6, 'Simulated regulator slew limit [Pa/s].',
     {'floating_point_range': (1.0e3, 1.0e10)}),
    ('sim_deadband_pa', 500.0, 'Simulated regulator deadband [Pa].',
     {'floating_point_range': (0.0, 1.0e5)}),
    ('sim_noise_std_pa', 300.0, 'Simulated readback noise standard deviation [Pa].',
     {'floating_point_range': (0.0, 1.0e5)}),
    ('sim_max_output_pa', 7.0e5, 'Simulated supply-limited output [Pa gauge].',
     {'floating_point_range': (1.0e3, 1.0e7)}),
    ('sim_full_scale_pa', 1.0e6, 'Simulated readback full scale [Pa gauge].',
     {'floating_point_range': (1.0e3, 1.0e7)}),
    ('sim_adc_bits', 12, 'Simulated readback resolution [bit].',
     {'integer_range': (1, 32)}),
    ('sim_seed', 0, 'Seed of the simulated readback noise.',
     {'integer_range': (0, 2 ** 31 - 1)}),
)


def watchdog_refusal(device_watchdog_s, publish_rate_hz):
    """
    Return why a device watchdog of `device_watchdog_s` [s] is too short at `publish_rate_hz`.

    None when it lasts `DEVICE_WATCHDOG_PERIODS` control periods or more, or when the device
    has none (`device_watchdog_s` None).
    """
    if device_watchdog_s is None:
        return None
    least = DEVICE_WATCHDOG_PERIODS / float(publish_rate_hz)
    if device_watchdog_s >= least:
        return None
    return (f"the device watchdog's timeout_s {device_watchdog_s:g} s is shorter than "
            f'{DEVICE_WATCHDOG_PERIODS} control periods at `publish_rate_hz` '
            f'{float(publish_rate_hz):g} Hz ({least:g} s): the device would vent at one late '
            'step')


def refusal(name, value, *, configured=False, state='', backend_kind='',
            device_watchdog_s=None):
    """
    Return why the bridge refuses to set a parameter now, or None when it accepts it.

    Parameters
    ----------
    name : str
    value : object
        The value asked for.
    configured : bool
        Whether the node is configured (a structural parameter is then refused).
    state : str
        Label of the lifecycle state, for the reason.
    backend_kind : str
        The backend in use ('sim', 'modbus', 'injected', or '' before the first).
    device_watchdog_s : float or None
        The timeout of the connected device's own watchdog [s], if it has one.

    """
    if name in STRUCTURAL and configured:
        return (f'`{name}` is read at configure; the node is {state}: cleanup first, then '
                'configure')
    if name == 'backend' and value not in BACKEND_KINDS:
        return f'`backend` must be one of {list(BACKEND_KINDS)}, got {value!r}'
    if name == 'use_sim_time' and value and configured and backend_kind == 'modbus':
        return SIM_TIME_REFUSED
    if name == 'safe_state' and value not in SAFE_STATES:
        return f'`safe_state` must be one of {list(SAFE_STATES)}, got {value!r}'
    if name == 'publish_rate_hz':
        return watchdog_refusal(device_watchdog_s, value)
    return None


def limits(values, config_max_pressure=math.inf):
    """
    Return the channel supervisors' limits from the parameter values.

    Parameters
    ----------
    values : mapping
        Parameter values by name; the `LIMIT_PARAMETERS` are read.
    config_max_pressure : float
        The gripper config's limit, which caps ``max_pressure`` [Pa gauge].

    Returns
    -------
    dict
        ``ChannelSupervisor`` arguments.

    """
    return {
        'max_pressure': min(values['max_pressure'], config_max_pressure),
        'rate_limit_pa_s': values['rate_limit_pa_s'],
        'command_timeout_s': values['command_timeout_s'],
        'safe_state': values['safe_state'],
    }
