"""replay-model: outputs from recorded inputs equal direct solves of the node's finger model."""

import math

from helpers import assert_designs_close, read_with_rosbags
from mcap_test_utils import (assert_rosbags_reads, ATM, fluid_pressure, read_independently,
                             summary_of, wrench)
import numpy as np
from numpy.testing import assert_allclose
import pytest
from rclpy.serialization import serialize_message
import yaml

from fpc_gripper.io.cli import main
from fpc_gripper.io.config import default_gripper_config_path, load_gripper_config
from fpc_gripper.io.mcap_reader import McapFile
from fpc_gripper.io.mcap_writer import Rosbag2McapWriter
from fpc_gripper.model import AdaptiveSolver
from fpc_gripper.model.pipeline import ModelSettings

BASE = 1_700_000_000_000_000_000
PERIOD = 20_000_000
GAUGE = [0.0, 40e3, 80e3, 80e3, 120e3, 160e3, 200e3, 150e3]
FORCES = {2: (0.05, 0.0), 5: (0.0, -0.03)}


def write_inputs(path, namespace='/gripper', **kwargs):
    """finger_0: commanded pressure and tip forces; finger_1: measured pressure, one < 1 atm."""
    with Rosbag2McapWriter(path, **kwargs) as writer:
        writer.add_topic(f'{namespace}/finger_0/pressure_command',
                         'sensor_msgs/msg/FluidPressure')
        writer.add_topic(f'{namespace}/finger_0/tip_force', 'geometry_msgs/msg/WrenchStamped')
        writer.add_topic(f'{namespace}/finger_1/pressure', 'sensor_msgs/msg/FluidPressure')
        for i, gauge in enumerate(GAUGE):
            t = BASE + i * PERIOD
            writer.write(f'{namespace}/finger_0/pressure_command',
                         serialize_message(fluid_pressure(i, gauge)), t)
            if i in FORCES:
                writer.write(f'{namespace}/finger_0/tip_force',
                             serialize_message(wrench(i, *FORCES[i])), t + 1)
            measured = gauge * 0.5 if i else -150.0     # below atmospheric: clipped to 0
            writer.write(f'{namespace}/finger_1/pressure',
                         serialize_message(fluid_pressure(i, measured)), t + 2)
    return path


def expected_solves(design):
    """Direct solves in the replay's order, warm-started, on a new instance of the model."""
    defaults = ModelSettings()      # replay-model defaults to model_node's settings
    solver = AdaptiveSolver(design, tolerance=defaults.tolerance,
                            pressure_model=defaults.pressure_model)
    finger_0, finger_1 = [], []
    last, force = None, (0.0, 0.0)
    for i, gauge in enumerate(GAUGE):
        p = ATM + gauge - ATM
        last = solver.solve(p, force, initial=last)
        finger_0.append((p, last))
        if i in FORCES:
            force = FORCES[i]
            last = solver.solve(p, force, initial=last)
            finger_0.append((p, last))
    last = None
    for i, gauge in enumerate(GAUGE):
        p = max(ATM + (gauge * 0.5 if i else -150.0) - ATM, 0.0)
        last = solver.solve(p, (0.0, 0.0), initial=last)
        finger_1.append((p, last))
    return solver, finger_0, finger_1


@pytest.fixture(scope='module')
def replayed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('replay')
    source = write_inputs(tmp / 'in.mcap')
    out = tmp / 'out.mcap'
    assert main(['replay-model', str(source), str(out)]) == 0
    assert assert_rosbags_reads(out, tmp) == 3 * (len(GAUGE) + len(FORCES) + len(GAUGE))
    by_topic = {}
    for topic, type_name, log_time, publish_time, msg in read_independently(out):
        by_topic.setdefault(topic, []).append((log_time, publish_time, msg))
    return by_topic


def test_outputs_equal_direct_core_solves(replayed):
    config = load_gripper_config(default_gripper_config_path())
    designs = {f.name: f.design for f in config.fingers}
    assert_designs_close(designs['finger_1'], designs['finger_0'])
    solver, finger_0, finger_1 = expected_solves(designs['finger_0'])
    assert sorted(replayed) == sorted(
        f'/gripper/finger_{k}/{kind}' for k in (0, 1)
        for kind in ('shape', 'curvature', 'rigidity'))
    for k, solves in ((0, finger_0), (1, finger_1)):
        curvature = replayed[f'/gripper/finger_{k}/curvature']
        shapes = replayed[f'/gripper/finger_{k}/shape']
        rigidity = replayed[f'/gripper/finger_{k}/rigidity']
        assert len(curvature) == len(shapes) == len(rigidity) == len(solves)
        for (p, r), (_, _, kappa), (_, stamp, path), (_, _, k_msg) in zip(
                solves, curvature, shapes, rigidity):
            assert r.success
            # The circle fit stops at its own tolerance (~1e-10 relative), so inputs equal
            # to round-off may stop one iteration apart.
            assert_allclose(kappa.data, r.curvature, rtol=1e-9, atol=1e-9)
            xz = np.array([(q.pose.position.x, q.pose.position.z) for q in path.poses])
            assert_allclose(xz, r.points, rtol=0, atol=1e-9)
            y = np.array([q.pose.position.y for q in path.poses])
            assert not y.any()          # exact: the shape never sets y, it stays 0.0
            angle = np.array([-2.0 * math.atan2(q.pose.orientation.y, q.pose.orientation.w)
                              for q in path.poses])
            assert_allclose(angle, r.tangent, rtol=0, atol=1e-9)
            assert path.header.frame_id == f'finger_{k}'
            assert k_msg.header.frame_id == f'finger_{k}'
            assert_allclose(k_msg.vector.x, solver.rigidity(p, axis='x').value, atol=1e-9,
                            rtol=0)
            assert_allclose(k_msg.vector.z, solver.rigidity(p, axis='z').value, atol=1e-9,
                            rtol=0)
            assert k_msg.vector.y == 0.0            # exact: set to 0.0, not computed
            # A cold solve gives the same shape: warm starts do not change the answer.
            cold = solver.solve(p, r.tip_force)
            assert_allclose(xz, cold.points, rtol=0, atol=1e-9)


def test_times_follow_the_inputs(replayed):
    log_times = [log for log, _, _ in replayed['/gripper/finger_0/shape']]
    assert log_times[:4] == [BASE, BASE + PERIOD, BASE + 2 * PERIOD, BASE + 2 * PERIOD + 1]
    stamps = [msg.header.stamp for _, _, msg in replayed['/gripper/finger_1/shape']]
    assert [(s.sec, s.nanosec) for s in stamps[:2]] == [(1_700_000_000, 7),
                                                        (1_700_000_000, 10_000_007)]
    publish = [pub for _, pub, _ in replayed['/gripper/finger_1/shape']]
    assert publish[1] == 1_700_000_000 * 10**9 + 10_000_007


def test_progress_and_summary(tmp_path, capsys):
    source = write_inputs(tmp_path / 'in.mcap', namespace='')
    code = main(['replay-model', str(source), str(tmp_path / 'out.mcap'), '--no-rigidity',
                 '--source', 'pressure_command'])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert 'Traceback' not in err
    assert '10 solves, 0 not converged' in out
    topics = {t for t, *_ in read_independently(tmp_path / 'out.mcap')}
    assert topics == {'/finger_0/shape', '/finger_0/curvature', '/finger_0/rigidity'}
    k = [m for t, _, _, _, m in read_independently(tmp_path / 'out.mcap')
         if t == '/finger_0/rigidity']
    assert all(math.isnan(m.vector.x) and math.isnan(m.vector.z) for m in k)


def test_unknown_finger_is_an_error(tmp_path, capsys):
    path = tmp_path / 'in.mcap'
    with Rosbag2McapWriter(path) as writer:
        writer.add_topic('/finger_7/pressure', 'sensor_msgs/msg/FluidPressure')
        writer.write('/finger_7/pressure', serialize_message(fluid_pressure(0, 1e4)), 1)
    code = main(['replay-model', str(path), str(tmp_path / 'out.mcap'), '--quiet'])
    assert code == 2
    assert 'finger_7' in capsys.readouterr().err
    assert not (tmp_path / 'out.mcap').exists()


def test_rigidity_period_reuses_the_last_values(tmp_path):
    source = write_inputs(tmp_path / 'in.mcap', namespace='')
    out = tmp_path / 'out.mcap'
    assert main(['replay-model', str(source), str(out), '--quiet', '--source', 'pressure',
                 '--rigidity-period', '1.0']) == 0
    k = [m.vector.x for t, _, _, _, m in read_independently(out) if t.endswith('rigidity')]
    # All inputs fall within 1 s, so every message repeats the first value verbatim
    # (reused, not recomputed): exactly one distinct float.
    assert len(k) == len(GAUGE) and len(set(k)) == 1
    assert main(['replay-model', str(source), str(tmp_path / 'x.mcap'), '--quiet',
                 '--rigidity-period', '-1']) == 2


def test_inputs_the_node_rejects_are_rejected_in_replay(tmp_path, capsys):
    """Over the limit, non-finite, wrong frame and stale inputs are not solved, as in the node."""
    path = tmp_path / 'in.mcap'
    limit = load_gripper_config(default_gripper_config_path()).max_pressure
    with Rosbag2McapWriter(path) as writer:
        writer.add_topic('/finger_0/pressure_command', 'sensor_msgs/msg/FluidPressure')
        writer.add_topic('/finger_0/tip_force', 'geometry_msgs/msg/WrenchStamped')
        t = BASE
        for gauge in (50e3, limit + 1.0, math.nan, 60e3):
            writer.write('/finger_0/pressure_command',
                         serialize_message(fluid_pressure(0, gauge)), t)
            t += PERIOD
        foreign = wrench(0, 0.0, 0.1)
        foreign.header.frame_id = 'finger_1'
        writer.write('/finger_0/tip_force', serialize_message(foreign), t)
        # Stamped at BASE + 7 ns but logged 5 s later: older than stale_after_s = 1 s.
        writer.write('/finger_0/tip_force', serialize_message(wrench(0, 0.0, 0.1)),
                     t + 5_000_000_000)
    out = tmp_path / 'out.mcap'
    assert main(['replay-model', str(path), str(out), '--no-rigidity']) == 0
    assert '2 solves, 0 not converged, 4 rejected' in capsys.readouterr().out
    shapes = [m for t, _, _, _, m in read_independently(out) if t == '/finger_0/shape']
    defaults = ModelSettings()
    solver = AdaptiveSolver(load_gripper_config(default_gripper_config_path()).fingers[0]
                            .design, tolerance=defaults.tolerance)
    for msg, gauge in zip(shapes, (50e3, 60e3)):
        tip = msg.poses[-1].pose.position
        assert_allclose((tip.x, tip.z), solver.solve(gauge).tip, rtol=0, atol=1e-9)
    # With the stale check off the late force is taken.
    assert main(['replay-model', str(path), str(out), '--no-rigidity', '--stale-after',
                 '0', '--force']) == 0
    assert '3 solves, 0 not converged, 3 rejected' in capsys.readouterr().out


def test_a_bag_directory_replays_as_the_single_file(tmp_path):
    single = write_inputs(tmp_path / 'in.mcap')
    split = write_inputs(tmp_path / 'in_bag', max_duration=3 * PERIOD)
    assert len(list(split.glob('*.mcap'))) == 3
    outputs = []
    for source in (single, split):
        out = tmp_path / f'out_{source.stem}.mcap'
        assert main(['replay-model', str(source), str(out), '--quiet', '--no-rigidity']) == 0
        with McapFile(out) as recording:
            outputs.append([(m.topic, m.log_time, m.publish_time, m.data)
                            for m in recording.messages(decode=False)])
        assert len(read_with_rosbags(out)) == len(outputs[-1])
    assert outputs[0] == outputs[1] and len(outputs[0]) == 3 * 18
    # The outputs are offered as the node offers them: reliable, transient local, depth 1.
    _, summary, _ = summary_of(tmp_path / 'out_in.mcap')
    for channel in summary.channels.values():
        (qos,) = yaml.safe_load(channel.metadata['offered_qos_profiles'])
        assert (qos['reliability'], qos['durability'], qos['depth']) == (
            'reliable', 'transient_local', 1)


def test_frame_prefix_as_the_node(tmp_path, capsys):
    path = tmp_path / 'in.mcap'
    with Rosbag2McapWriter(path) as writer:
        writer.add_topic('/finger_0/pressure_command', 'sensor_msgs/msg/FluidPressure')
        writer.add_topic('/finger_0/tip_force', 'geometry_msgs/msg/WrenchStamped')
        writer.write('/finger_0/pressure_command', serialize_message(fluid_pressure(0, 9e4)),
                     BASE)
        force = wrench(1, 0.0, 0.2)
        force.header.frame_id = 'left/finger_0'
        writer.write('/finger_0/tip_force', serialize_message(force), BASE + PERIOD)
    out = tmp_path / 'out.mcap'
    assert main(['replay-model', str(path), str(out), '--no-rigidity', '--quiet']) == 0
    assert '1 solves, 0 not converged, 1 rejected' in capsys.readouterr().out
    assert main(['replay-model', str(path), str(out), '--no-rigidity', '--quiet', '--force',
                 '--frame-prefix', 'left/']) == 0
    assert '2 solves, 0 not converged, 0 rejected' in capsys.readouterr().out
    shapes = [m for t, _, _, _, m in read_independently(out) if t == '/finger_0/shape']
    assert [m.header.frame_id for m in shapes] == ['left/finger_0'] * 2
    solver = AdaptiveSolver(load_gripper_config(default_gripper_config_path()).fingers[0]
                            .design, tolerance=ModelSettings().tolerance)
    tip = shapes[-1].poses[-1].pose.position
    assert_allclose((tip.x, tip.z), solver.solve(9e4, (0.0, 0.2)).tip, rtol=0, atol=1e-9)
