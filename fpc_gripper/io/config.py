"""Gripper configuration: fingers, their designs and the palm geometry, loaded from YAML."""

from dataclasses import dataclass
import math
import pathlib
import re

from fpc_gripper.model import ActuatorDesign
from fpc_gripper.model.design import safe_load_yaml

__all__ = ['FingerConfig', 'GripperConfig', 'load_gripper_config',
           'default_gripper_config_path', 'config_dir']

_NAME = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')
_TOP_KEYS = {'actuator', 'palm_radius', 'atmospheric_pressure', 'max_pressure', 'fingers'}
_FINGER_KEYS = {'name', 'mount_angle', 'design'}


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


def _number(source, name, value, unit, positive=True):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f'{source}: `{name}` must be a number {unit}, got {value!r}')
    value = float(value)
    if not math.isfinite(value) or (positive and value <= 0.0):
        raise ValueError(f'{source}: `{name}` must be finite{" and > 0" if positive else ""} '
                         f'{unit}, got {value}')
    return value


def load_gripper_config(path=None):
    """
    Load and validate a gripper configuration.

    Parameters
    ----------
    path : str or path-like, optional
        YAML file; default `default_gripper_config_path()`.

    Returns
    -------
    GripperConfig

    Raises
    ------
    ValueError
        On malformed YAML, unknown keys, bad values or invalid designs, naming the
        file and the key.

    """
    import yaml
    path = pathlib.Path(path) if path is not None else default_gripper_config_path()
    source = str(path)
    try:
        data = safe_load_yaml(path.read_text())
    except OSError as exc:
        raise ValueError(f'{source}: cannot read gripper config: {exc}') from exc
    except yaml.YAMLError as exc:
        raise ValueError(f'{source}: malformed YAML: {exc}') from exc
    if not isinstance(data, dict):
        raise ValueError(f'{source}: expected a mapping at top level')
    unknown = sorted(set(map(str, data)) - _TOP_KEYS)
    if unknown:
        raise ValueError(f'{source}: unknown key(s): {", ".join(unknown)}')
    actuator = data.get('actuator')
    if actuator is None:
        base = ActuatorDesign.paper().to_dict()
    elif isinstance(actuator, str):
        actuator_path = (path.parent / actuator)
        base = ActuatorDesign.from_yaml(actuator_path).to_dict()
    elif isinstance(actuator, dict):
        base = ActuatorDesign.from_dict(actuator, source=f'{source}: actuator').to_dict()
    else:
        raise ValueError(f'{source}: `actuator` must be a file name or a mapping')
    fingers = data.get('fingers')
    if not isinstance(fingers, list) or not fingers:
        raise ValueError(f'{source}: `fingers` must be a non-empty list')
    out = []
    for i, item in enumerate(fingers):
        where = f'{source}: fingers[{i}]'
        if not isinstance(item, dict):
            raise ValueError(f'{where} must be a mapping')
        bad = sorted(set(map(str, item)) - _FINGER_KEYS)
        if bad:
            raise ValueError(f'{where}: unknown key(s): {", ".join(bad)}')
        name = item.get('name', f'finger_{i}')
        if not isinstance(name, str) or not _NAME.match(name):
            raise ValueError(f'{where}: `name` must be a valid ROS name token, got {name!r}')
        overrides = item.get('design') or {}
        if not isinstance(overrides, dict):
            raise ValueError(f'{where}: `design` must be a mapping of ActuatorDesign fields')
        design = ActuatorDesign.from_dict({**base, **overrides}, source=f'{where}: design')
        angle = _number(where, 'mount_angle', item.get('mount_angle', 0.0), '[rad]',
                        positive=False)
        out.append(FingerConfig(name=name, design=design, mount_angle=angle))
    names = [f.name for f in out]
    if len(set(names)) != len(names):
        raise ValueError(f'{source}: finger names must be unique, got {names}')
    return GripperConfig(
        fingers=tuple(out),
        palm_radius=_number(source, 'palm_radius', data.get('palm_radius', 0.035), '[m]'),
        max_pressure=_number(source, 'max_pressure', data.get('max_pressure', 400e3), '[Pa]'),
        atmospheric_pressure=_number(source, 'atmospheric_pressure',
                                     data.get('atmospheric_pressure', 101325.0), '[Pa]'),
        source=source)
