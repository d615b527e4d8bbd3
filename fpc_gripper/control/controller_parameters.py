"""The gripper controller's parameters without ROS: their table, and the control law they make."""

from fpc_gripper.control.controller import ControllerConfig
from fpc_gripper.control.controller import GripperControlLaw
from fpc_gripper.control.controller import SAFE_STATES
from fpc_gripper.control.geometry import PalmGeometry
from fpc_gripper.control.inverse import InverseModel
from fpc_gripper.grasp.finger import finger_grasps
from fpc_gripper.grasp.objects import make_object
from fpc_gripper.grasp.objects import OBJECTS
from fpc_gripper.model import PRESSURE_MODEL_NAMES
from fpc_gripper.model.pipeline import MAX_SEGMENTS
from fpc_gripper.model.pipeline import ModelSettings
from fpc_gripper.services.input_limits import atmospheric_pressure_row

__all__ = ['LAW_PARAMETERS', 'law_config', 'make_law', 'parameter_table']

#: Parameters copied into ControllerConfig (same names).
LAW_PARAMETERS = ('max_pressure', 'slew_rate_pa_s', 'approach_rate_pa_s', 'kp', 'ki',
                  'kp_force', 'ki_force', 'goal_tolerance_m',
                  'force_tolerance', 'settle_time_s', 'stall_timeout_s', 'feedback_timeout_s',
                  'safe_state', 'contact_threshold_n')


def parameter_table(config_max_pressure):
    """
    Return ``(name, default, description, descriptor fields)`` of every parameter.

    All but ``gripper_config`` (which gives `config_max_pressure`) and the input bounds;
    ranges as ``(low, high)``.

    Parameters
    ----------
    config_max_pressure : float
        The gripper config's limit: the default and the top of ``max_pressure`` [Pa gauge].

    """
    defaults = ControllerConfig()
    model = ModelSettings()
    return (
        ('tolerance', model.tolerance,
         "Finger model's tip-position tolerance against the rod [m], as model_node's "
         '(0: the paper CCM with n_segments); set both nodes alike.',
         {'read_only': True, 'floating_point_range': (0.0, 0.05)}),
        ('n_segments', model.n_segments, 'CCM segments of the finger model when tolerance '
         'is 0.', {'read_only': True, 'integer_range': (1, MAX_SEGMENTS)}),
        ('pressure_model', model.pressure_model,
         f"Pressure work model, one of {list(PRESSURE_MODEL_NAMES)} ('design': each finger "
         "design's pressure_work_factor).",
         {'read_only': True, 'additional_constraints': f'one of {list(PRESSURE_MODEL_NAMES)}'}),
        ('max_pressure', config_max_pressure,
         'Largest command [Pa gauge]; at most the gripper config max_pressure.',
         {'floating_point_range': (0.0, config_max_pressure)}),
        ('slew_rate_pa_s', defaults.slew_rate_pa_s, 'Command slew limit [Pa/s].',
         {'floating_point_range': (1.0e3, 1.0e8)}),
        ('approach_rate_pa_s', defaults.approach_rate_pa_s,
         'Slew limit while closing on an object and pressing it [Pa/s].',
         {'floating_point_range': (1.0e3, 1.0e8)}),
        ('kp', defaults.kp, 'Proportional gain on the aperture error in Pa [-].',
         {'floating_point_range': (0.0, 100.0)}),
        ('ki', defaults.ki, 'Integral gain on the aperture error in Pa [1/s].',
         {'floating_point_range': (0.0, 100.0)}),
        ('kp_force', defaults.kp_force, 'Proportional gain on the force error in Pa [-].',
         {'floating_point_range': (0.0, 100.0)}),
        ('ki_force', defaults.ki_force, 'Integral gain on the force error in Pa [1/s].',
         {'floating_point_range': (0.0, 100.0)}),
        ('control_rate_hz', 50.0, 'Control loop rate [Hz].',
         {'floating_point_range': (1.0, 1000.0)}),
        ('goal_tolerance_m', defaults.goal_tolerance_m, 'Aperture goal tolerance [m].',
         {'floating_point_range': (1.0e-5, 0.05)}),
        ('force_tolerance', defaults.force_tolerance,
         'Relative contact-force goal tolerance [-].',
         {'floating_point_range': (0.0, 1.0)}),
        ('settle_time_s', defaults.settle_time_s,
         'Time within tolerance before a goal is reached [s].',
         {'floating_point_range': (0.0, 60.0)}),
        ('stall_timeout_s', defaults.stall_timeout_s,
         'A goal not reached after this long is reported stalled [s].',
         {'floating_point_range': (0.1, 3600.0)}),
        ('feedback_timeout_s', defaults.feedback_timeout_s,
         'Pressure feedback older than this is lost: safe state and ERROR [s].',
         {'floating_point_range': (0.01, 60.0)}),
        ('safe_state', defaults.safe_state,
         "On lost feedback: 'vent' commands 0 Pa gauge, 'hold' keeps the last command.",
         {'additional_constraints': f'one of {list(SAFE_STATES)}'}),
        ('contact_threshold_n', defaults.contact_threshold_n,
         'Normal contact force above which a finger is in contact [N].',
         {'floating_point_range': (1.0e-4, 10.0)}),
        ('object', 'unknown',
         f'Object to grasp: unknown, or one of {list(OBJECTS)} (resting on the palm).',
         {'read_only': True, 'additional_constraints': f"one of {['unknown', *OBJECTS]}"}),
        ('object_diameter', 0.040, 'Size D of the object to grasp [m].',
         {'read_only': True, 'floating_point_range': (1.0e-3, 0.5)}),
        ('object_height', 0.0, "Height of the object's lowest point above the palm [m].",
         {'read_only': True, 'floating_point_range': (0.0, 0.5)}),
        atmospheric_pressure_row(),
        ('frame_prefix', '', 'Prefix of the finger frames (<prefix>finger_<i>) of the '
         "commands and of the tip forces accepted, as model_node's.", {'read_only': True}),
    )


def law_config(values, config_max_pressure):
    """
    Return the ControllerConfig of the parameter values.

    Parameters
    ----------
    values : mapping
        Parameter values by name; the `LAW_PARAMETERS` are read.
    config_max_pressure : float
        The gripper config's limit, which ``max_pressure`` may not exceed [Pa gauge].

    Raises
    ------
    ValueError
        A value above the gripper config's limit or one ControllerConfig refuses (naming
        it).

    """
    values = {name: values[name] for name in LAW_PARAMETERS}
    if values['max_pressure'] > config_max_pressure:
        raise ValueError(f'`max_pressure` must be <= the gripper config limit '
                         f'{config_max_pressure:.0f} [Pa], got {values["max_pressure"]}')
    return ControllerConfig(**values)


def make_law(config, values):
    """
    Build the control law of a gripper from the parameter values.

    One inverse model per distinct finger design, and for a declared object (not
    ``unknown``) every finger's `FingerGrasp` of it, on the finger model the
    ``tolerance``, ``n_segments`` and ``pressure_model`` parameters choose.

    Parameters
    ----------
    config : GripperConfig
    values : mapping
        Parameter values by name.

    Returns
    -------
    GripperControlLaw

    Raises
    ------
    ValueError
        An unknown object, or a value `law_config` refuses.

    """
    settings = ModelSettings(tolerance=values['tolerance'], n_segments=values['n_segments'],
                             pressure_model=values['pressure_model'])
    models = {}
    for finger in config.fingers:
        if finger.design not in models:
            models[finger.design] = InverseModel(
                finger.design, config.palm_radius, config.max_pressure, settings)
    return GripperControlLaw([models[f.design] for f in config.fingers],
                             PalmGeometry.from_config(config),
                             law_config(values, config.max_pressure),
                             _grasps(config, settings, values))


def _grasps(config, settings, values):
    """Every finger's FingerGrasp of the declared object (None for 'unknown')."""
    kind = values['object']
    if kind == 'unknown':
        return None
    if kind not in OBJECTS:
        raise ValueError(f"`object` must be 'unknown' or one of {list(OBJECTS)}, got "
                         f'{kind!r}')
    obj = make_object(kind, values['object_diameter'], values['object_height'])
    return finger_grasps(obj, config, settings)
