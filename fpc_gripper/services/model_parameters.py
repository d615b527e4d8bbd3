"""The model node's parameters without ROS: their table and the checks made on a change."""

import math

from fpc_gripper.model import PRESSURE_MODEL_NAMES
from fpc_gripper.model.pipeline import MAX_SEGMENTS
from fpc_gripper.model.pipeline import ModelSettings
from fpc_gripper.services.input_limits import atmospheric_pressure_row
from fpc_gripper.services.input_limits import input_bound_table
from fpc_gripper.services.model_core import DEFAULT_STALE_AFTER_S

__all__ = ['PRESSURE_INPUTS', 'SOLVER_PARAMETERS', 'parameter_table', 'refusal']

PRESSURE_INPUTS = ('command', 'measured')
#: Parameters whose change rebuilds the solvers.
SOLVER_PARAMETERS = ('n_segments', 'pressure_model', 'tolerance')
# The model settings every consumer of the finger pipeline defaults to.
_DEFAULTS = ModelSettings()
_CHOICES = {'pressure_model': PRESSURE_MODEL_NAMES, 'pressure_input': PRESSURE_INPUTS}


def parameter_table(gripper_config):
    """
    Return ``(name, default, description, descriptor fields)`` of every parameter.

    Parameters
    ----------
    gripper_config : str
        The default gripper YAML (the shipped one; `fpc_gripper.io` is not imported here).

    """
    return (
        ('gripper_config', gripper_config,
         'Gripper YAML: one set of topics per finger, named and framed finger_<i>.',
         {'read_only': True}),
        ('tolerance', _DEFAULTS.tolerance,
         'Tip-position tolerance against the geometrically exact rod [m]: per scene the node '
         'uses the cheapest model that meets it (fpc_gripper.model.AdaptiveSolver), refining '
         'when a segment passes 45 degrees. 0 uses the paper CCM with a fixed n_segments.',
         {'floating_point_range': (0.0, 0.05)}),
        ('n_segments', _DEFAULTS.n_segments, 'Number N of CCM segments per finger when '
         'tolerance is 0; a change rebuilds the solvers.',
         {'integer_range': (1, MAX_SEGMENTS)}),
        ('pressure_model', _DEFAULTS.pressure_model,
         "Pressure work: 'design' (each finger design's pressure_work_factor k_p), "
         "'adiabatic' (k_p = 1/(gamma - 1) = 2.5, paper eq. 20) or 'isobaric' (k_p = 1); a "
         'change rebuilds the solvers.',
         {'additional_constraints': f'one of {list(PRESSURE_MODEL_NAMES)}'}),
        ('max_rate_hz', 200.0,
         'Solve-rate cap per finger [Hz]; newer input replaces pending input (latest wins).',
         {'floating_point_range': (1.0, 10000.0)}),
        ('pressure_input', 'command',
         "'command': finger_<i>/pressure_command (reliable); 'measured': finger_<i>/pressure "
         '(sensor data QoS). Both absolute [Pa].',
         {'read_only': True, 'additional_constraints': f'one of {list(PRESSURE_INPUTS)}'}),
        atmospheric_pressure_row(),
        ('stale_after_s', DEFAULT_STALE_AFTER_S,
         'Inputs whose header stamp is older than this against the node clock are rejected '
         '[s]; 0 disables. Unstamped (zero) headers are never stale.',
         {'floating_point_range': (0.0, 3600.0)}),
        ('future_limit_s', 1.0,
         'Inputs whose header stamp is more than this ahead of the node clock are rejected '
         '[s]; 0 disables. Stamps that are no time (sec < 0, nanosec >= 1e9) always are.',
         {'floating_point_range': (0.0, 3600.0)}),
        ('rigidity_rate_hz', 10.0,
         "Largest rate of each finger's rigidity output [Hz]: K_x and K_z take two "
         "displacement-controlled solves at the state's pressure; 0 publishes none.",
         {'floating_point_range': (0.0, 100.0)}),
        ('frame_prefix', '',
         'Prefix of every frame id published or expected (<prefix>palm, <prefix>finger_<i>), '
         'so that two grippers can share a tf tree, e.g. "left/".',
         {'read_only': True}),
        ('publish_tf', True,
         'Send tf: the mounts palm -> finger_<i> on /tf_static, and finger_<i> -> '
         'finger_<i>_tip on /tf with every shape.',
         {'read_only': True}),
        *input_bound_table(),
    )


def refusal(changes):
    """
    Return why the model node refuses a change of parameters, or None when it accepts it.

    The choices and finite floats, by name; the node checks the input bounds after.

    Parameters
    ----------
    changes : mapping
        The changed values by name.

    """
    for name, value in changes.items():
        if name in _CHOICES and value not in _CHOICES[name]:
            return f'`{name}` must be one of {list(_CHOICES[name])}, got {value!r}'
        if isinstance(value, float) and not math.isfinite(value):
            return f'`{name}` must be finite, got {value}'
    return None
