"""Gripper configuration: fingers, their designs and the palm geometry, loaded from YAML."""

from dataclasses import dataclass
import math
import os
import pathlib
import re

from fpc_gripper.model import ActuatorDesign
from fpc_gripper.model.validation import ATMOSPHERIC_RANGE
from fpc_gripper.model.validation import DESIGN_BOUNDS
from fpc_gripper.model.validation import STANDARD_ATMOSPHERE
from fpc_gripper.safe_yaml import load_yaml
from fpc_gripper.safe_yaml import Where

__all__ = ['FingerConfig', 'GripperConfig', 'load_gripper_config',
           'default_gripper_config_path', 'config_dir', 'MAX_FINGERS', 'MAX_NAME_CHARS']

#: Most fingers a gripper config may have.
MAX_FINGERS = 16
#: Longest finger name: it becomes a topic prefix and a TF frame, and the full topic name
#: (namespace, finger, 'pressure_command') must stay within ROS's 247 characters.
MAX_NAME_CHARS = 64
#: A ROS name token (rcl's topic-name rule for one token, which TF frames satisfy too).
_NAME = re.compile(r'[A-Za-z][A-Za-z0-9_]*\Z')
_TOP_KEYS = {'actuator', 'palm_radius', 'atmospheric_pressure', 'max_pressure', 'fingers'}
_FINGER_KEYS = {'name', 'mount_angle', 'design'}
#: Largest palm radius [m].
MAX_PALM_RADIUS = 1.0


@dataclass(frozen=True)
class FingerConfig:
    """
    One finger of the gripper.

    Attributes
    ----------
    name : str
        Topic prefix and TF frame, e.g. ``finger_0``.
    design : ActuatorDesign
        The finger's design.
    mount_angle : float
        Azimuth of the finger around the palm axis [rad].

    """

    name: str
    design: ActuatorDesign
    mount_angle: float


@dataclass(frozen=True)
class GripperConfig:
    """
    Gripper of several fingers on a round palm.

    Attributes
    ----------
    fingers : tuple of FingerConfig
    palm_radius : float
        Palm centre to each finger's clamp edge [m].
    max_pressure : float
        Gauge pressure limit of every channel [Pa].
    atmospheric_pressure : float
        Ambient pressure for absolute-to-gauge conversion [Pa].
    source : str
        File the configuration came from.

    """

    fingers: tuple
    palm_radius: float
    max_pressure: float
    atmospheric_pressure: float
    source: str = ''

    @property
    def names(self):
        """Finger names in order."""
        return tuple(f.name for f in self.fingers)


def config_dir():
    """Return the msg_configs directory: the source tree's, else the installed share/."""
    here = pathlib.Path(__file__).resolve().parents[2] / 'msg_configs'
    if here.is_dir():
        return here
    try:
        from ament_index_python.packages import get_package_share_directory
        return pathlib.Path(get_package_share_directory('fpc_gripper')) / 'msg_configs'
    except Exception:  # noqa: BLE001 - ament index absent or package not installed
        import sys
        return pathlib.Path(sys.prefix) / 'share' / 'fpc_gripper' / 'msg_configs'


def default_gripper_config_path():
    """Path of the shipped three-finger configuration, gripper_paper.yaml."""
    return config_dir() / 'gripper_paper.yaml'


def load_gripper_config(path=None):
    """
    Load and validate a gripper configuration.

    Parameters
    ----------
    path : str or path-like, optional
        YAML file; default `default_gripper_config_path()`. It is read with
        `fpc_gripper.safe_yaml.load_yaml` (size, depth and alias limits, no duplicate
        keys, decimal numbers only). `actuator` may name another YAML file, relative to
        this one, read the same way.

    Returns
    -------
    GripperConfig

    Raises
    ------
    ValueError
        A `safe_yaml.ConfigError`, one line naming the file, the key path and the
        problem with its value and unit, e.g. ``g.yaml: fingers[1].design.Lx: must be
        > 0 [m], got -0.11``. Nothing else escapes, whatever the file holds.

    """
    path = pathlib.Path(path) if path is not None else default_gripper_config_path()
    source = os.fspath(path)
    where = Where(source)
    data = where.mapping(load_yaml(path, what='gripper config'), _TOP_KEYS,
                         what='a mapping of gripper config keys (fingers, actuator, ...)')
    actuator = data.get('actuator')
    if actuator is None:
        base = ActuatorDesign.paper().to_dict()
    elif isinstance(actuator, str):
        name = (where / 'actuator').string(actuator, 4096, what='a file name')
        base = ActuatorDesign.from_yaml(path.parent / name).to_dict()
    elif isinstance(actuator, dict):
        base = ActuatorDesign.from_dict(actuator, source, 'actuator').to_dict()
    else:
        raise (where / 'actuator').error('must be a file name or a mapping of ActuatorDesign '
                                         f'fields, got {type(actuator).__name__}')
    fingers = (where / 'fingers').sequence(data.get('fingers'), 1, MAX_FINGERS,
                                           what='finger mappings')
    out, first = [], {}
    for i, item in enumerate(fingers):
        at = where / 'fingers' / i
        item = at.mapping(item, _FINGER_KEYS)
        name = (at / 'name').string(
            item.get('name', f'finger_{i}'), MAX_NAME_CHARS, _NAME,
            what='a valid ROS name token (a letter, then letters, digits or _)')
        if name in first:
            raise (at / 'name').error(f'finger names must be unique: {name!r} is also '
                                      f'fingers[{first[name]}].name')
        first[name] = i
        overrides = item.get('design')
        overrides = {} if overrides is None else (at / 'design').mapping(overrides)
        design = ActuatorDesign.from_dict({**base, **overrides}, source, (at / 'design').path)
        angle = (at / 'mount_angle').number(item.get('mount_angle', 0.0), '[rad]',
                                            -2.0 * math.pi, 2.0 * math.pi)
        out.append(FingerConfig(name=name, design=design, mount_angle=angle))
    return GripperConfig(
        fingers=tuple(out),
        palm_radius=(where / 'palm_radius').number(
            data.get('palm_radius', 0.035), '[m]', 0.0, MAX_PALM_RADIUS, low_open=True),
        max_pressure=(where / 'max_pressure').number(
            data.get('max_pressure', 400e3), '[Pa]', *DESIGN_BOUNDS.max_pressure),
        atmospheric_pressure=(where / 'atmospheric_pressure').number(
            data.get('atmospheric_pressure', STANDARD_ATMOSPHERE), '[Pa]', *ATMOSPHERIC_RANGE),
        source=source)
