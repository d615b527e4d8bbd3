"""The virtual object node's parameters without ROS: their table."""

from fpc_gripper.grasp.objects import OBJECTS
from fpc_gripper.io.config import default_gripper_config_path
from fpc_gripper.services.input_limits import atmospheric_pressure_row

__all__ = ['METHODS', 'PARAMETERS']

#: Contact methods: rigid, or compliant with the surface stiffness ``stiffness_n_m``.
METHODS = ('exact', 'penalty')

#: ``(name, default, description, descriptor fields)`` of every parameter, ranges as
#: ``(low, high)``.
PARAMETERS = (
    ('gripper_config', str(default_gripper_config_path()), 'Gripper YAML.',
     {'read_only': True}),
    ('object', 'cylinder',
     'cylinder (coaxial with the palm axis), sphere (centred on it) or box (D x D section, '
     'across the palm).',
     {'read_only': True, 'additional_constraints': f'one of {list(OBJECTS)}'}),
    ('object_diameter', 0.040, 'Object size D [m].',
     {'read_only': True, 'floating_point_range': (1e-3, 0.5)}),
    ('object_height', 0.0, "Height of the object's lowest point above the palm [m].",
     {'read_only': True, 'floating_point_range': (0.0, 0.5)}),
    ('method', 'exact', "'exact' (rigid) or 'penalty' (compliant, stiffness_n_m).",
     {'read_only': True, 'additional_constraints': f'one of {list(METHODS)}'}),
    ('stiffness_n_m', 200.0, 'Surface stiffness of the penalty method [N/m].',
     {'read_only': True, 'floating_point_range': (1.0, 1e6)}),
    atmospheric_pressure_row(),
)
