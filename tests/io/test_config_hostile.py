"""
Every config loader against hostile files: a valid result or one clear line, nothing else.

"Clear" means: a `ConfigError` (a ValueError) whose message is one line that starts with
the file's path, is at most 300 characters longer than it, and, where one key is at fault,
names its key path. Two explicit corpora (the actuator design and the gripper config, each
case with the words its message must hold) and hypothesis properties over generated files
(fixed seeds, no example database, so every run tries the same files) for the design,
gripper, Modbus register map and bare YAML loaders.
"""

import math
import pathlib

from hypothesis import event
from hypothesis import given
from hypothesis import HealthCheck
from hypothesis import seed
from hypothesis import settings
from hypothesis import strategies as st
import pytest
import yaml

from fpc_gripper.io.config import GripperConfig, load_gripper_config
from fpc_gripper.model import ActuatorDesign
from fpc_gripper.model.validation import DESIGN_BOUNDS
from fpc_gripper.regulators.modbus import RegisterMap
from fpc_gripper.safe_yaml import ConfigError, load_yaml

ROOT = pathlib.Path(__file__).resolve().parents[2] / 'msg_configs'
ACTUATOR = (ROOT / 'actuator_paper.yaml').read_text()
GRIPPER = (ROOT / 'gripper_paper.yaml').read_text().replace(
    'actuator: actuator_paper.yaml', f'actuator: {ROOT / "actuator_paper.yaml"}')
MODBUS = (ROOT / 'modbus_example.yaml').read_text()
MAX_MESSAGE = 300


def _bomb(levels=9, width=10, key='lol'):
    lines = [f'{key}0: &{key}0 [' + ', '.join(['lol'] * width) + ']']
    for i in range(1, levels):
        lines.append(f'{key}{i}: &{key}{i} [' + ', '.join([f'*{key}{i - 1}'] * width) + ']')
    return lines


BOMB = '\n'.join(_bomb()) + '\n'
BOMB_IN_LX = '\n'.join(_bomb(6, 9)) + '\nLx: *lol5\n'


def _set(text, key, value):
    """Return `text` with the top-level line of `key` replaced by ``key: value``."""
    lines = [line for line in text.splitlines() if not line.startswith(f'{key}:')]
    return '\n'.join(lines + [f'{key}: {value}']) + '\n'


def assert_clear(error, path, *words):
    """The message of `error` is one short line about `path` holding every word."""
    message = str(error.value)
    assert isinstance(error.value, ConfigError) and isinstance(error.value, ValueError)
    assert '\n' not in message and len(message) <= len(str(path)) + MAX_MESSAGE, message
    assert message.startswith(str(path)), message
    for word in words:
        assert word in message, (word, message)


# -- the actuator design: (case, file text or bytes, words the message must hold) --------
ACTUATOR_CASES = [
    ('duplicate key', ACTUATOR + 'prestrain: 0.6\n', 'prestrain: line', 'duplicate key'),
    ('hex', _set(ACTUATOR, 'Lx', '0x6E'), 'Lx:', 'not a plain decimal'),
    ('octal 0o', _set(ACTUATOR, 'Lx', '0o156'), 'Lx:', 'not a plain decimal'),
    ('binary', _set(ACTUATOR, 'Lx', '0b1101110'), 'Lx:', 'not a plain decimal'),
    ('underscores', _set(ACTUATOR, 'Lx', '1_000'), 'Lx:', 'not a plain decimal'),
    ('sexagesimal', _set(ACTUATOR, 'Lx', '1:50'), 'Lx:', 'not a plain decimal'),
    ('sexagesimal float', _set(ACTUATOR, 'Lx', '1:30.5'), 'Lx:', 'not a plain decimal'),
    ('leading zero', _set(ACTUATOR, 'Lx', '010'), 'Lx:', 'not a plain decimal'),
    ('explicit int tag', _set(ACTUATOR, 'Lx', '!!int "0x6E"'), 'Lx:', 'not a plain decimal'),
    ('huge', _set(ACTUATOR, 'Lx', '1e30'), 'Lx: must be in [0.001, 2] [m], got 1e+30'),
    ('negative', _set(ACTUATOR, 'Lx', '-0.11'), 'Lx: must be > 0 [m], got -0.11'),
    ('zero', _set(ACTUATOR, 'Lx', '0'), 'Lx: must be > 0 [m]'),
    ('nan', _set(ACTUATOR, 'Lx', '.nan'), 'Lx: must be a finite number [m], got nan'),
    ('inf', _set(ACTUATOR, 'Lx', '.inf'), 'Lx: must be a finite number'),
    ('overflow', _set(ACTUATOR, 'Lx', '1e400'), 'Lx: must be a finite number'),
    ('too many digits', _set(ACTUATOR, 'Lx', '1' * 60), 'Lx:', 'not a plain decimal'),
    ('quoted number', _set(ACTUATOR, 'Lx', "'0.11'"), 'Lx: must be a number [m], got string'),
    ('word', _set(ACTUATOR, 'Lx', 'abc'), 'Lx: must be a number [m]'),
    ('list', _set(ACTUATOR, 'Lx', '[0.11]'), 'Lx: must be a number [m], got list'),
    ('mapping', _set(ACTUATOR, 'Lx', '{a: 1}'), 'Lx: must be a number [m], got mapping'),
    ('null', _set(ACTUATOR, 'Lx', 'null'), 'Lx: must be a number [m], got null'),
    ('bool', _set(ACTUATOR, 'Lx', 'true'), 'Lx: must be a number [m], got boolean'),
    ('date', _set(ACTUATOR, 'Lx', '2001-12-14'), 'Lx: must be a number [m], got string'),
    ('ribs 1e-12', _set(_set(ACTUATOR, 'w2', '1e-12'), 't', '1e-12'), 'w2: gives a feature'),
    ('850 ribs', _set(_set(ACTUATOR, 'w2', '5e-5'), 't', '5e-5'), 'w2:', '850 ribs'),
    ('max_pressure 1e30', _set(ACTUATOR, 'max_pressure', '1e30'), 'max_pressure: must be in'),
    ('max_pressure < 0', _set(ACTUATOR, 'max_pressure', '-1'), 'max_pressure: must be > 0'),
    ('prestrain 1.5', _set(ACTUATOR, 'prestrain', '1.5'), 'prestrain: must be in [0, 1)'),
    ('prestrain < 0', _set(ACTUATOR, 'prestrain', '-0.1'), 'prestrain: must be in [0, 1)'),
    ('emc 1e308', ACTUATOR.split('emc_coefficients:')[0] + 'emc_coefficients: [1e308, 1e308, '
     '1e308, 1e308]\n', 'emc_coefficients[0]: must be in [-1e+10, 1e+10] [Pa]'),
    ('emc two numbers', ACTUATOR.split('emc_coefficients:')[0] + 'emc_coefficients: [1, 2]\n',
     'emc_coefficients: must hold 4'),
    ('emc words', ACTUATOR.split('emc_coefficients:')[0] + 'emc_coefficients: [a, b, c, d]\n',
     'emc_coefficients[0]: must be a number'),
    ('emc not monotonic', ACTUATOR.split('emc_coefficients:')[0]
     + 'emc_coefficients: [1.0e6, 0, 0, -1.0e5]\n', 'emc_coefficients:', 'increases'),
    ('emc zero', ACTUATOR.split('emc_coefficients:')[0] + 'emc_coefficients: [0, 0, 0, 0]\n',
     'emc_coefficients:', 'increases'),
    ('material missing nu', ACTUATOR.replace('  nu: 0.48\n', ''), 'fluidic_layer: needs',
     'missing nu'),
    ('nu 0.95', ACTUATOR.replace('nu: 0.48', 'nu: 0.95'), 'fluidic_layer.nu: must be in'),
    ('modulus 1e30', ACTUATOR.replace('E1: 1200000.0', 'E1: 1.0e30'),
     'fluidic_layer.E1: must be in'),
    ('modulus < 0', ACTUATOR.replace('E2: 170000000.0', 'E2: -1.0'), 'emc:', 'E2'),
    ('material scalar', ACTUATOR.split('fluidic_layer:')[0] + 'fluidic_layer: 5\n',
     'fluidic_layer: expected a mapping'),
    ('ribs yes', _set(ACTUATOR, 'ribs', 'yes'), 'ribs: must be true or false'),
    ('ribs 1', _set(ACTUATOR, 'ribs', '1'), 'ribs: must be true or false'),
    ('unknown key', ACTUATOR + 'width: 0.03\n', "unknown key(s) 'width'"),
    ('Cx > Lx', _set(ACTUATOR, 'Cx', '0.2'), 'Cx: must be in (Lc, Lx]'),
    ('Cy > Ly', _set(ACTUATOR, 'Cy', '0.05'), 'Cy: must be < `Ly`'),
    ('layers', _set(ACTUATOR, 'h1', '0.005'), 'h1: breaks the layers'),
    ('Lc >= Lx', _set(ACTUATOR, 'Lc', '0.2'), 'Lc: must be in [0, Lx)'),
    ('H 1e-9', _set(ACTUATOR, 'H', '1e-9'), 'H: must be in'),
    ('top-level list', '- 1\n- 2\n', 'expected a mapping of ActuatorDesign fields'),
    ('top-level scalar', '42\n', 'expected a mapping'),
    ('empty', '', 'expected a mapping', 'got null'),
    ('two documents', ACTUATOR + '---\nLx: 0.1\n', 'malformed YAML', 'single document'),
    ('malformed', 'Lx: [0.11\n', 'malformed YAML'),
    ('tab indent', 'Lx:\n\t- 1\n', 'malformed YAML'),
    ('alias bomb', BOMB, 'aliases'),
    ('alias bomb in Lx', BOMB_IN_LX, 'values (aliases expanded)'),
    ('recursive alias', 'Lx: &a [*a]\n', 'Lx[0]:', 'recursive alias'),
    ('deep nesting', 'Lx: ' + '[' * 1000 + ']' * 1000 + '\n', 'nested deeper than 32'),
    ('python tag', 'Lx: !!python/object/apply:os.system ["true"]\n', 'Lx:', 'tag'),
    ('binary tag', 'Lx: !!binary aGVsbG8=\n', 'Lx:', 'tag'),
    ('local tag', 'Lx: !metres 0.11\n', 'Lx:', 'tag'),
    ('set tag', 'Lx: !!set {a, b}\n', 'Lx:', 'tag'),
    ('integer key', '1: 2\n', 'keys must be strings'),
    ('complex key', '? [a, b]\n: 1\n', 'keys must be strings'),
    ('bad merge', '<<: 5\n', 'malformed YAML'),
    ('undefined alias', 'Lx: *nowhere\n', 'malformed YAML', 'undefined alias'),
    ('NUL character', 'Lx: "\x00"\n', 'character #x0000'),
    ('non-UTF-8', b'Lx: 0.11\n# \xff\xfe\xfa\n', 'not UTF-8', '0xff'),
    ('UTF-16', 'Lx: 0.11\n'.encode('utf-16'), 'not UTF-8'),
    ('too large', ACTUATOR + '#' * (130 << 10) + '\n', 'larger than 131072 bytes'),
]


def _write(path, content):
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, errors='surrogateescape')
    return path


def _cases(cases):
    return pytest.mark.parametrize('content, words', [(c[1], c[2:]) for c in cases],
                                   ids=[c[0] for c in cases])


@_cases(ACTUATOR_CASES)
def test_hostile_actuator_files_give_one_clear_line(tmp_path, content, words):
    path = _write(tmp_path / 'actuator.yaml', content)
    with pytest.raises(ValueError) as error:
        ActuatorDesign.from_yaml(path)
    assert_clear(error, path, *words)


def test_paths_that_are_not_regular_files_are_refused(tmp_path):
    cases = ((tmp_path, 'is not a regular file'), (tmp_path / 'absent.yaml', 'does not exist'),
             (pathlib.Path('/dev/zero'), 'is not a regular file'))
    for path, words in cases:
        with pytest.raises(ValueError) as error:
            ActuatorDesign.from_yaml(path)
        assert_clear(error, path, 'cannot read actuator design', words)


def test_a_real_design_far_from_the_paper_still_loads(tmp_path):
    # A 25 cm finger, 5 cm wide, 2 mm ribs every 3 mm over 22 cm (73 ribs), stiffer
    # laminae, 1 MPa rating: a finger one could cast.
    text = ('Lx: 0.25\nLy: 0.05\nLc: 0.03\nCx: 0.25\nCy: 0.04\nH: 0.012\nh1: 0.0055\n'
            'h2: 0.0025\nh3: 0.003\nh3a: 0.0012\nh3b: 0.0015\nw1: 0.01\nw2: 0.001\nt: 0.002\n'
            'prestrain: 0.6\nmax_pressure: 1.0e6\n'
            'constraining_layer: {E1: 2.0e9, E2: 2.0e9, nu: 0.35}\n')
    path = tmp_path / 'big.yaml'
    path.write_text(text)
    design = ActuatorDesign.from_yaml(path)
    assert design.transverse_ribs().shape == (73, 2)
    assert design.max_pressure == 1.0e6 and design.constraining_layer.E1 == 2.0e9


# -- the gripper config ----------------------------------------------------------------------
def _finger(name='finger_0', extra=''):
    return f'  - name: {name}\n    mount_angle: 0.0\n{extra}'


def _gripper(fingers=None, top=''):
    head = GRIPPER.split('fingers:')[0]
    return head + top + 'fingers:\n' + (fingers if fingers is not None else _finger())


GRIPPER_CASES = [
    ('200 fingers', _gripper(''.join(_finger(f'f{i}') for i in range(200))),
     'fingers: must hold 1 to 16 finger mappings, got 200'),
    ('17 fingers', _gripper(''.join(_finger(f'f{i}') for i in range(17))), 'got 17'),
    ('no fingers', _gripper('  []\n'), 'fingers: must hold 1 to 16'),
    ('fingers missing', GRIPPER.split('fingers:')[0], 'fingers: must be a list'),
    ('fingers mapping', _gripper('  {a: 1}\n'), 'fingers: must be a list'),
    ('finger scalar', _gripper('  - 5\n'), 'fingers[0]: expected a mapping'),
    ('mount angle 1e300', _gripper(_finger().replace('0.0', '1.0e300')),
     'fingers[0].mount_angle: must be in [-6.28319, 6.28319] [rad], got 1e+300'),
    ('mount angle nan', _gripper(_finger().replace('0.0', '.nan')),
     'fingers[0].mount_angle: must be a finite number'),
    ('atmosphere 1 Pa', _gripper(top='').replace('atmospheric_pressure: 101325.0',
                                                 'atmospheric_pressure: 1'),
     'atmospheric_pressure: must be in [30000, 120000] [Pa], got 1.0'),
    ('atmosphere 1e30', _gripper().replace('atmospheric_pressure: 101325.0',
                                           'atmospheric_pressure: 1.0e30'),
     'atmospheric_pressure: must be in [30000, 120000]'),
    ('300-character name', _gripper(_finger('f' * 300)),
     'fingers[0].name: must be at most 64 characters, got 300'),
    ('name with digit first', _gripper(_finger('0bad')), 'fingers[0].name: must be a valid ROS'),
    ('name with slash', _gripper(_finger('a/b')), 'fingers[0].name: must be a valid ROS'),
    ('name with dash', _gripper(_finger('a-b')), 'fingers[0].name: must be a valid ROS'),
    ('name with space', _gripper(_finger("'a b'")), 'fingers[0].name: must be a valid ROS'),
    ('name number', _gripper(_finger('123')), 'fingers[0].name: must be a valid ROS'),
    ('name null', _gripper(_finger('null')), 'fingers[0].name: must be a valid ROS'),
    ('name list', _gripper(_finger('[a]')), 'fingers[0].name: must be a valid ROS'),
    ('duplicate names', _gripper(_finger('a') + _finger('a')),
     "fingers[1].name: finger names must be unique: 'a' is also fingers[0].name"),
    ('duplicate key', _gripper() + 'palm_radius: 0.05\n', 'palm_radius: line', 'duplicate'),
    ('design Lx < 0', _gripper(_finger() + _finger('finger_1', '    design: {Lx: -0.11}\n')),
     'fingers[1].design.Lx: must be > 0 [m], got -0.11'),
    ('design scalar', _gripper(_finger(extra='    design: 5\n')),
     'fingers[0].design: expected a mapping'),
    ('design unknown key', _gripper(_finger(extra='    design: {Cq: 1}\n')),
     "fingers[0].design: unknown key(s) 'Cq'"),
    ('design hex', _gripper(_finger(extra='    design: {prestrain: 0x1}\n')),
     'fingers[0].design.prestrain:', 'not a plain decimal'),
    ('finger unknown key', _gripper(_finger(extra='    colour: red\n')),
     "fingers[0]: unknown key(s) 'colour'"),
    ('actuator number', _gripper().replace('actuator: ', 'actuator: 5 #'),
     'actuator: must be a file name or a mapping'),
    ('actuator inline bad', _gripper().replace('actuator: ', 'actuator: {Lx: 1.0e30} #'),
     'actuator.Lx: must be in'),
    ('palm radius 0', _gripper().replace('palm_radius: 0.062', 'palm_radius: 0'),
     'palm_radius: must be in (0, 1] [m], got 0.0'),
    ('palm radius 1e9', _gripper().replace('palm_radius: 0.062', 'palm_radius: 1.0e9'),
     'palm_radius: must be in (0, 1]'),
    ('palm radius word', _gripper().replace('palm_radius: 0.062', 'palm_radius: wide'),
     'palm_radius: must be a number'),
    ('max_pressure 1e30', _gripper().replace('max_pressure: 400000.0', 'max_pressure: 1e30'),
     'max_pressure: must be in [1000, 2e+06] [Pa]'),
    ('max_pressure 0', _gripper().replace('max_pressure: 400000.0', 'max_pressure: 0'),
     'max_pressure: must be in'),
    ('unknown top key', _gripper(top='colour: red\n'), "unknown key(s) 'colour'"),
    ('top-level list', '- 1\n', 'expected a mapping of gripper config keys'),
    ('empty', '', 'expected a mapping', 'got null'),
    ('alias bomb', BOMB + 'fingers: *lol8\n', 'aliases'),
    ('alias bomb in fingers', '\n'.join(_bomb(6, 9)) + '\nfingers: *lol5\n',
     'values (aliases expanded)'),
    ('recursive alias', 'fingers: &f [*f]\n', 'recursive alias'),
    ('deep nesting', 'fingers: ' + '[' * 500 + ']' * 500 + '\n', 'nested deeper'),
    ('python tag', 'fingers: !!python/object/new:list []\n', 'fingers:', 'tag'),
    ('non-UTF-8', b'fingers:\n  - name: \xc3\x28\n', 'not UTF-8'),
    ('too large', _gripper() + '#' * (130 << 10) + '\n', 'larger than'),
]


@_cases(GRIPPER_CASES)
def test_hostile_gripper_files_give_one_clear_line(tmp_path, content, words):
    path = _write(tmp_path / 'gripper.yaml', content)
    with pytest.raises(ValueError) as error:
        load_gripper_config(path)
    assert_clear(error, path, *words)


def test_an_actuator_file_at_fault_is_named_itself(tmp_path):
    bad = tmp_path / 'finger.yaml'
    bad.write_text(_set(ACTUATOR, 'Lx', '0x6E'))
    path = tmp_path / 'gripper.yaml'
    path.write_text(_gripper().replace(str(ROOT / 'actuator_paper.yaml'), 'finger.yaml'))
    with pytest.raises(ValueError) as error:
        load_gripper_config(path)
    assert_clear(error, bad, 'Lx:', 'not a plain decimal')


# -- generated files ------------------------------------------------------------------------
#: Hypothesis settings of every property: fixed seed (per test), no example database.
PROPERTY = settings(max_examples=100, database=None, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture,
                                           HealthCheck.too_slow])
#: Raw YAML that a careless or hostile hand might put anywhere.
SNIPPETS = ['0x6E', '0o17', '1_000', '1:30', '010', '1e30', '-1e-12', '.nan', '.inf', '~',
            'yes', 'no', '2001-12-14', '!!binary aGk=', '!!python/name:os.system', '!x 1',
            '&a [*a]', '*missing', '[' * 40, '{a: [b, {c: d}]}', "'quoted'", '"\\x00"', '|-\n  x',
            '1' * 50, '-', '? [k]', '<<: 5', '[1e308, 1e308, 1e308, 1e308]', '- - -']


def _documents(shipped):
    """Documents derived from a shipped file by a generated edit, and raw junk."""
    data = yaml.safe_load(shipped)
    lines = shipped.splitlines()
    scalars = st.one_of(st.floats(), st.integers(min_value=-10 ** 60, max_value=10 ** 60),
                        st.booleans(), st.none(), st.text(max_size=20))
    values = st.recursive(scalars, lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)),
        max_leaves=12)
    keys = st.sampled_from(sorted(data))

    def replace(pair):
        key, value = pair
        return yaml.safe_dump({**data, key: value}, sort_keys=False)

    def splice(args):
        index, snippet, key = args
        cut = index % (len(lines) + 1)
        return '\n'.join(lines[:cut] + [f'{key}: {snippet}'] + lines[cut:]) + '\n'

    edits = st.one_of(
        st.tuples(keys, values).map(replace),
        st.tuples(st.integers(0, 200), st.sampled_from(SNIPPETS),
                  st.one_of(keys, st.sampled_from(['fingers', 'Lx', 'channels']))).map(splice),
        st.tuples(st.integers(0, 200), st.integers(0, 200)).map(
            lambda ab: '\n'.join(lines[:ab[0]] + lines[ab[1]:]) + '\n'),
    )
    junk = st.one_of(st.binary(max_size=300), st.text(alphabet='[]{}:,-&*!|>\'"#%@ \n\tab01.',
                                                      max_size=300))
    return st.one_of(edits, edits, junk)


def _try(tmp_path, content, loader):
    path = _write(tmp_path / 'generated.yaml', content)
    try:
        result = loader(path)
        event('loaded')
        return result
    except ValueError as exc:
        assert isinstance(exc, ConfigError), repr(exc)
        event('refused')
        message = str(exc)
        assert '\n' not in message and len(message) <= len(str(path)) + MAX_MESSAGE, message
        assert message.startswith(str(path)) or message.startswith(str(ROOT)), message
        return None


@seed(20261201)
@PROPERTY
@given(content=_documents(ACTUATOR))
def test_property_actuator_loader(tmp_path, content):
    design = _try(tmp_path, content, ActuatorDesign.from_yaml)
    if design is not None:
        assert isinstance(design, ActuatorDesign)
        low, high = DESIGN_BOUNDS.length
        assert low <= design.Lx <= high and math.isfinite(design.max_pressure)


@seed(20261202)
@PROPERTY
@given(content=_documents(GRIPPER))
def test_property_gripper_loader(tmp_path, content):
    config = _try(tmp_path, content, load_gripper_config)
    if config is not None:
        assert isinstance(config, GripperConfig) and 1 <= len(config.fingers) <= 16
        assert all(len(name) <= 64 for name in config.names)


@seed(20261203)
@PROPERTY
@given(content=_documents(MODBUS))
def test_property_modbus_map_loader(tmp_path, content):
    rmap = _try(tmp_path, content, RegisterMap.from_yaml)
    if rmap is not None:
        assert isinstance(rmap, RegisterMap) and 1 <= len(rmap.channels) <= 64


@seed(20261204)
@PROPERTY
@given(content=st.one_of(_documents(GRIPPER), st.text(max_size=400)))
def test_property_bare_yaml_gives_plain_data(tmp_path, content):
    data = _try(tmp_path, content, load_yaml)

    def plain(value, depth=0):
        assert depth <= 33
        if isinstance(value, dict):
            return all(isinstance(k, str) and plain(v, depth + 1) for k, v in value.items())
        if isinstance(value, list):
            return all(plain(v, depth + 1) for v in value)
        return value is None or isinstance(value, (str, int, float, bool))

    assert plain(data)
