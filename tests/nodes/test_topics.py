"""The README's topic table against every publisher and subscription the nodes create."""

import pathlib
import re

import pytest
import rclpy
from rclpy.context import Context
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy
from rclpy.qos import HistoryPolicy
from rclpy.qos import ReliabilityPolicy

from fpc_gripper.io.qos import WRITER_HISTORY_ENV
from fpc_gripper.nodes.gripper_controller import GripperController
from fpc_gripper.nodes.model_node import ModelNode
from fpc_gripper.nodes.regulator_bridge import RegulatorBridge
from fpc_gripper.nodes.virtual_object import VirtualObjectNode

ROOT = pathlib.Path(__file__).resolve().parents[2]
# rclpy's own topics, not the package's.
INFRASTRUCTURE = re.compile(r'^/(rosout|parameter_events)$|/transition_event$')
_ROW = re.compile(r'^\| `(?P<topic>[^`]+)` \| (?P<type>[^|]+) \| (?P<nodes>[^|]+) \| '
                  r'(?P<qos>[^|]+) \|$')
_QOS = re.compile(r'^(reliable|best effort), (volatile|transient local), depth (\d+)')
_RELIABILITY = {'reliable': ReliabilityPolicy.RELIABLE,
                'best effort': ReliabilityPolicy.BEST_EFFORT}
_DURABILITY = {'volatile': DurabilityPolicy.VOLATILE,
               'transient local': DurabilityPolicy.TRANSIENT_LOCAL}


def readme_table():
    """Rows of the README's 'Topics and QoS' table: topic -> (type, nodes, QoS)."""
    text = (ROOT / 'README.md').read_text()
    section = text.split('### Topics and QoS\n', 1)[1].strip().split('\n\n', 1)[0]
    rows = {}
    for line in section.splitlines()[2:]:
        match = _ROW.match(line)
        assert match, f'not a table row: {line!r}'
        reliability, durability, depth = _QOS.match(match['qos']).groups()
        rows[match['topic']] = (match['type'].strip(), match['nodes'],
                                (_RELIABILITY[reliability], _DURABILITY[durability],
                                 int(depth)))
    return rows


@pytest.fixture(scope='module')
def nodes():
    # The table states the default: writers without a history of their own.
    with pytest.MonkeyPatch.context() as patch:
        patch.delenv(WRITER_HISTORY_ENV, raising=False)
        yield from _nodes()


def _nodes():
    context = Context()
    rclpy.init(context=context)
    built = [ModelNode(context=context, namespace='/cmd'),
             ModelNode(context=context, namespace='/meas', parameter_overrides=[
                 Parameter('pressure_input', value='measured')]),
             RegulatorBridge.create_active(context=context, namespace='/cmd'),
             GripperController(context=context, namespace='/cmd')]
    yield built
    for node in built:
        node.destroy_node()
    context.try_shutdown()


def _endpoints(node):
    for kind, entities in (('pub', node.publishers), ('sub', node.subscriptions)):
        for entity in entities:
            if not INFRASTRUCTURE.search(entity.topic_name):
                msg = entity.msg_type
                yield (kind, entity.topic_name, entity.qos_profile,
                       f'{msg.__module__.split(".")[0]}/{msg.__name__}')


@pytest.mark.ros
def test_every_topic_is_in_the_readme_table_with_its_qos(nodes):
    table = readme_table()
    seen = set()
    for node in nodes:
        namespace = node.get_namespace()
        for kind, topic, qos, msg_type in _endpoints(node):
            relative = topic[len(namespace) + 1:] if topic.startswith(namespace + '/') \
                else topic
            name = re.sub(r'^finger_\d+/', 'finger_<i>/', relative)
            assert name in table, f'{node.get_name()} {kind} {topic} is not in the README'
            type_name, names, (reliability, durability, depth) = table[name]
            where = f'{node.get_name()} {kind} {topic}'
            assert node.get_name() in names and msg_type == type_name, where
            assert (qos.reliability, qos.durability, qos.depth) == (
                reliability, durability, depth), where
            seen.add(name)
    # Every row belongs to a node here.
    assert set(table) - seen == set()


@pytest.mark.ros
@pytest.mark.parametrize('history, depth', [(None, 10), ('0.5', 500)])
def test_the_virtual_object_reads_shapes_best_effort_and_sizes_its_force_history(
        monkeypatch, history, depth):
    """The demo's node: no resends of shapes it does not use; forces' history at 1 kHz."""
    if history is None:
        monkeypatch.delenv(WRITER_HISTORY_ENV, raising=False)
    else:
        monkeypatch.setenv(WRITER_HISTORY_ENV, history)
    context = Context()
    rclpy.init(context=context)
    try:
        node = VirtualObjectNode(context=context, namespace='/vo')
        endpoints = list(_endpoints(node))
        node.destroy_node()
    finally:
        context.try_shutdown()
    shapes = [qos for kind, topic, qos, _ in endpoints if kind == 'sub' and
              topic.endswith('/shape')]
    forces = [qos for kind, topic, qos, _ in endpoints if kind == 'pub' and
              topic.endswith('/tip_force')]
    assert len(shapes) == len(forces) == 3
    for qos in shapes:
        assert (qos.reliability, qos.durability, qos.history, qos.depth) == (
            ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE, HistoryPolicy.KEEP_LAST,
            1)
    # Reliable and volatile, as the README's tip_force row that its readers follow.
    reliability, durability, _ = readme_table()['finger_<i>/tip_force'][2]
    for qos in forces:
        assert (qos.reliability, qos.durability, qos.depth) == (reliability, durability, depth)
