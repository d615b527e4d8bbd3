"""Synthetic truth recovery: data from the rod, the calibrated design, fpc-calibrate's files."""

import dataclasses
import json
import math
import pathlib
import shutil
import subprocess
import sys
import threading
import time

from helpers import assert_designs_close, deviation, fd_derivative
import numpy as np
import pytest
import synthetic

from fpc_gripper.calibration import (calibrate, DataError, FitParameters, read_markers,
                                     TensileData)
from fpc_gripper.calibration.cli import main
from fpc_gripper.calibration.fit import _Problem
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.model import ActuatorDesign
from fpc_gripper.model.section.materials import DEFAULT_EMC_COEFFICIENTS, emc_stress

BASE = ActuatorDesign.paper(prestrain=0.25)
FIT = ('prestrain', 'cl_modulus', 'fl_modulus', 'pressure_work_factor')
MARKER_COLUMNS = ('pressure_pa', 'marker', 's_m', 'x_m', 'z_m')
LOADING_COLUMNS = ('pressure_pa', 'axis', 'displacement_m', 'force_n')
REQUIRED_KEYS = {'estimates', 'stderr', 'correlation', 'residual_rms', 'success', 'status',
                 'message', 'warnings'}


def truth_values(truth):
    return {'prestrain': truth.prestrain, 'cl_modulus': truth.constraining_layer.E1,
            'fl_modulus': truth.fluidic_layer.E1,
            'pressure_work_factor': truth.pressure_work_factor}


@pytest.fixture(scope='module')
def case(tmp_path_factory):
    """The rod's data of the true finger, and fpc-calibrate run on them."""
    root = tmp_path_factory.mktemp('calibration')
    truth = synthetic.truth_design(BASE)
    rows, loading, clean = synthetic.measurements(truth)
    markers = synthetic.write_csv(root / 'markers.csv', MARKER_COLUMNS, rows)
    loads = synthetic.write_csv(root / 'loading.csv', LOADING_COLUMNS, loading)
    force_noise = synthetic.FORCE_NOISE * float(np.mean(clean['forces']))
    base = root / 'base.yaml'
    BASE.to_yaml(base)
    out = root / 'calibrated'
    start = time.perf_counter()
    status = main(['--design', str(base), '--markers', str(markers), '--loading', str(loads),
                   '--fit', ','.join(FIT), '--marker-noise', str(synthetic.MARKER_NOISE),
                   '--force-noise', str(force_noise), '--out', str(out)])
    wall = time.perf_counter() - start
    report = json.loads((out / 'report.json').read_text())
    return {'truth': truth, 'status': status, 'out': out, 'report': report, 'rows': rows,
            'markers': markers, 'loading': loads, 'force_noise': force_noise, 'wall': wall}


def flagged(report):
    return {name for name in report['estimates']
            if any(w.startswith(f'{name} is not identifiable') for w in report['warnings'])}


def test_fpc_calibrate_writes_the_design_and_the_report(case, capsys):
    assert case['status'] == 0
    report = case['report']
    assert REQUIRED_KEYS <= set(report)
    assert report['success'] is True and report['status'] == 'SUCCESS'
    assert list(report['estimates']) == list(FIT) == list(report['stderr'])
    names = report['correlation']['names']
    assert names == [*FIT, 'frame_rotation', 'frame_offset_x', 'frame_offset_z']
    matrix = np.array(report['correlation']['matrix'])
    assert matrix.shape == (7, 7)
    np.testing.assert_allclose(np.diag(matrix), 1.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(matrix, matrix.T, rtol=0, atol=1e-12)
    assert set(report['residual_rms']) == {'markers', 'loading'}
    # The noise is what was put in: the residuals are about that size.
    assert 0.5 * synthetic.MARKER_NOISE < report['residual_rms']['markers'] \
        < 1.5 * synthetic.MARKER_NOISE
    png = (case['out'] / 'report.png').read_bytes()
    assert png[:8] == b'\x89PNG\r\n\x1a\n' and len(png) > 50_000
    # The gripper config holds the calibrated actuator on every finger.
    design = ActuatorDesign.from_yaml(case['out'] / 'actuator.yaml')
    config = load_gripper_config(case['out'] / 'gripper.yaml')
    assert len(config.fingers) == 3
    for finger in config.fingers:
        assert finger.design == design


def test_identifiable_parameters_are_recovered_within_three_standard_errors(case):
    report, truth = case['report'], truth_values(case['truth'])
    identifiable = [name for name in FIT if name not in flagged(report)]
    assert {'prestrain', 'fl_modulus', 'pressure_work_factor'} <= set(identifiable)
    for name in identifiable:
        error = abs(report['estimates'][name] - truth[name])
        assert error <= 3.0 * report['stderr'][name], (name, report['estimates'][name],
                                                       truth[name], report['stderr'][name])
        # The fit moved the parameter from the (wrong) base design towards the truth.
        base = FitParameters(BASE, [name]).initial[0]
        assert error < 0.5 * abs(base - truth[name]), name
    frame = report['frame']
    assert abs(frame['rotation'] - synthetic.ROTATION) <= 3.0 * frame['rotation_stderr']
    for k in range(2):
        assert abs(frame['offset'][k] - synthetic.OFFSET[k]) <= 3.0 * frame['offset_stderr'][k]


def test_an_unidentifiable_parameter_is_flagged(case):
    # The constraining layer is so much stiffer than the rest that the neutral axis sits
    # in it: its modulus barely changes the bending stiffness, the shapes or K_x.
    report = case['report']
    assert flagged(report) == {'cl_modulus'}
    assert report['stderr']['cl_modulus'] > 0.25 * report['estimates']['cl_modulus']


def test_one_gross_outlier_barely_moves_the_estimates(case):
    clean = case['report']
    markers = read_markers(case['markers'], BASE)
    xz = markers.xz.copy()
    xz[17] += (5e-3, -3e-3)          # 29 sigma and 17 sigma off: a swapped marker, say
    moved = calibrate(BASE, markers=dataclasses.replace(markers, xz=xz),
                      loading=case['loading'], fit=FIT, marker_noise=synthetic.MARKER_NOISE,
                      force_noise=case['force_noise'])
    assert moved.success
    for name in FIT:
        shift = abs(moved.estimates[name] - clean['estimates'][name])
        assert shift <= clean['stderr'][name], (name, shift, clean['stderr'][name])
    assert abs(moved.residuals['markers'][17]).max() > 4e-3


def test_the_calibrated_design_round_trips(case, tmp_path):
    report = case['report']
    design = ActuatorDesign.from_yaml(case['out'] / 'actuator.yaml')
    assert design.prestrain == report['estimates']['prestrain']
    assert design.pressure_work_factor == report['estimates']['pressure_work_factor']
    assert design.constraining_layer.E1 == design.constraining_layer.E2 \
        == report['estimates']['cl_modulus']
    assert design.fluidic_layer.E1 == report['estimates']['fl_modulus']
    # Everything not fitted is the base design.
    assert_designs_close(design.replace(
        prestrain=BASE.prestrain, pressure_work_factor=BASE.pressure_work_factor,
        constraining_layer=BASE.constraining_layer, fluidic_layer=BASE.fluidic_layer), BASE,
        rtol=0.0)
    again = tmp_path / 'again.yaml'
    design.to_yaml(again)
    assert ActuatorDesign.from_yaml(again) == design


def test_the_jacobian_is_exact():
    # Every parameter, every dataset: markers (one loaded frame), loading along X and Z and
    # tensile stresses, away from any optimum.
    truth = synthetic.truth_design(BASE)
    rows, loading, _ = synthetic.measurements(truth)
    markers = read_markers(synthetic.write_csv(
        pathlib.Path(__file__).parent / '.jacobian_markers.csv', MARKER_COLUMNS,
        rows[:7] + [(r[0], *r[1:]) for r in rows[21:28]]), BASE)
    markers = dataclasses.replace(markers, tip_force=np.array([[0.0, 0.0], [0.05, 0.1]]))
    (pathlib.Path(__file__).parent / '.jacobian_markers.csv').unlink()
    load = _loading([(20e3, 'x', 0.01, 0.3), (40e3, 'z', 0.008, 0.5)])
    strain = np.linspace(0.05, 0.5, 6)
    tensile = TensileData(strain, emc_stress(DEFAULT_EMC_COEFFICIENTS, strain) * 1.05,
                          ('t',) * 6, 't')
    params = FitParameters(BASE, ('prestrain', 'cl_modulus', 'fl_modulus',
                                  'pressure_work_factor', 'emc'))
    noise = {'markers': 2e-4, 'loading': 0.01, 'tensile': 5e3}
    problem = _Problem(params, markers, load, tensile, noise, 22)
    u = np.concatenate([params.initial / params.scale * 1.02, [0.3, 0.1, -0.1]])
    jac = problem.jacobian(u)
    fd = fd_derivative(problem.residuals, u, 1e-6)
    assert jac.shape == fd.shape == (7 * 2 * 2 + 2 + 6, 11)
    for k in range(u.size):
        assert deviation(jac[:, k], fd[:, k]) <= 1e-6, k


def _loading(rows):
    from fpc_gripper.calibration import LoadingData
    p, axis, delta, force = zip(*rows)
    return LoadingData(np.array(p), axis, np.array(delta), np.array(force),
                       tuple(f'row {k}' for k in range(len(rows))), 'loading')


def test_the_emc_law_from_tensile_data():
    rng = np.random.default_rng(3)
    strain = np.linspace(0.02, 0.6, 25)
    true_law = tuple(1.1 * a for a in DEFAULT_EMC_COEFFICIENTS)
    stress = emc_stress(true_law, strain) + rng.normal(0.0, 2e3, strain.size)
    result = calibrate(BASE, tensile=TensileData(strain, stress, ('t',) * 25, 't'), fit='emc',
                       stress_noise=2e3)
    assert result.success and not result.warnings
    for k in range(4):
        assert abs(result.estimates['emc'][k] - true_law[k]) <= 3 * result.stderr['emc'][k]
    assert result.design.emc_coefficients == tuple(result.estimates['emc'])


def test_an_invalid_estimate_fails_honestly(tmp_path, capsys):
    # Stresses that fall with strain: the fitted law makes no valid design.
    path = tmp_path / 'tensile.csv'
    path.write_text('strain,stress_pa\n' + ''.join(f'{s},{-1e6 * s * s}\n'
                                                   for s in (0.1, 0.2, 0.3, 0.4, 0.5)))
    base = tmp_path / 'base.yaml'
    BASE.to_yaml(base)
    out = tmp_path / 'out'
    status = main(['--design', str(base), '--tensile', str(path), '--fit', 'emc',
                   '--out', str(out)])
    assert status == 1
    report = json.loads((out / 'report.json').read_text())
    assert report['success'] is False and report['status'] == 'INVALID_DESIGN'
    assert 'increases on' in report['message']
    assert not (out / 'actuator.yaml').exists() and (out / 'report.png').exists()
    assert 'INVALID_DESIGN' in capsys.readouterr().out


def test_bad_input_is_refused_by_name(case, tmp_path, capsys):
    with pytest.raises(ValueError, match='needs data'):
        calibrate(BASE)
    with pytest.raises(ValueError, match="unknown parameter\\(s\\) 'stiffness'"):
        calibrate(BASE, loading=case['loading'], fit='prestrain,stiffness')
    with pytest.raises(ValueError, match='`marker_noise` must be finite and > 0'):
        calibrate(BASE, markers=case['markers'], marker_noise=0.0)
    bad = tmp_path / 'markers.csv'
    bad.write_text(case['markers'].read_text().replace('\n0.0,3,', '\nnan,3,', 1))
    with pytest.raises(DataError, match=r'markers.csv, line 5: column pressure_pa must be '
                                        'finite'):
        calibrate(BASE, markers=bad)
    status = main(['--design', str(tmp_path / 'none.yaml'), '--markers', str(bad),
                   '--out', str(tmp_path / 'out')])
    assert status == 2 and 'cannot read actuator design' in capsys.readouterr().err
    base = tmp_path / 'base.yaml'
    BASE.to_yaml(base)
    status = main(['--design', str(base), '--markers', str(bad), '--out', str(tmp_path / 'o')])
    assert status == 2 and 'line 5' in capsys.readouterr().err
    assert not (tmp_path / 'o').exists()


def _distance_to_path(points, path):
    """Shortest distance of every point to the polyline `path` [m]."""
    a, b = path[:-1], path[1:]
    ab = b - a
    t = np.clip(np.einsum('kij,ij->ki', points[:, None, :] - a[None], ab)
                / np.einsum('ij,ij->i', ab, ab), 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(points[:, None, :] - closest, axis=2).min(axis=1)


@pytest.mark.ros
def test_model_node_on_the_calibrated_design_passes_through_the_markers(case):
    import rclpy
    from nav_msgs.msg import Path
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import FluidPressure

    report = case['report']
    rows = np.array([r[:1] + r[2:] for r in case['rows']], dtype=float)
    frame = report['frame']
    c, s = math.cos(frame['rotation']), math.sin(frame['rotation'])
    seen = (rows[:, 2:4] - np.array(frame['offset'])) @ np.array([[c, -s], [s, c]])
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('calibration_probe', context=context)
    shapes = {}
    arrived = threading.Condition()

    def on_shape(msg):
        with arrived:
            stamp = msg.header.stamp.sec * 10 ** 9 + msg.header.stamp.nanosec
            shapes[stamp] = np.array([(p.pose.position.x, p.pose.position.z)
                                      for p in msg.poses])
            arrived.notify_all()

    node.create_subscription(Path, '/calib/finger_0/shape', on_shape, 10)
    publisher = node.create_publisher(FluidPressure, '/calib/finger_0/pressure_command', 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    process = subprocess.Popen(
        [sys.executable, '-m', 'fpc_gripper.nodes.model_node', '--ros-args',
         '-p', f'gripper_config:={case["out"] / "gripper.yaml"}', '-r', '__ns:=/calib'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        # A hang guard, not a timing: on a cold numba cache the node compiles first.
        deadline = time.monotonic() + 240.0
        for pressure in (0.0, synthetic.MARKER_PRESSURES[3], synthetic.MARKER_PRESSURES[5]):
            shape = None
            while shape is None:
                assert process.poll() is None, process.communicate()[0]
                assert time.monotonic() < deadline, 'no shape from model_node'
                msg = FluidPressure()
                now = time.time_ns()
                msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 10 ** 9)
                msg.header.frame_id = 'finger_0'
                msg.fluid_pressure = 101325.0 + pressure
                publisher.publish(msg)
                with arrived:
                    arrived.wait_for(lambda: now in shapes, timeout=0.5)
                    shape = shapes.get(now)
            mine = seen[rows[:, 0] == pressure]
            distance = _distance_to_path(mine, shape)
            assert np.sqrt(np.mean(distance ** 2)) < 1.5 * synthetic.MARKER_NOISE, distance
            assert distance.max() < 4.0 * synthetic.MARKER_NOISE, distance
    finally:
        process.terminate()
        process.communicate(timeout=30)
        executor.shutdown(timeout_sec=5.0)
        spinner.join(timeout=5.0)
        node.destroy_node()
        context.try_shutdown()


def test_markers_from_an_mcap_recording_calibrate_as_the_csv(case, tmp_path):
    from geometry_msgs.msg import Pose, PoseArray
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import FluidPressure

    from fpc_gripper.io.mcap_writer import Rosbag2McapWriter

    recording = tmp_path / 'session.mcap'
    writer = Rosbag2McapWriter(recording)
    writer.add_topic('/mocap/markers', 'geometry_msgs/msg/PoseArray')
    writer.add_topic('/finger_0/pressure', 'sensor_msgs/msg/FluidPressure')
    t = 10 ** 9
    rows = case['rows']
    for start in range(0, len(rows), 7):
        pressure = FluidPressure()
        pressure.fluid_pressure = 101325.0 + rows[start][0]
        poses = PoseArray()
        for _, _, _, x, z in rows[start:start + 7]:
            pose = Pose()
            pose.position.x, pose.position.z = float(x), float(z)
            poses.poses.append(pose)
        for _ in range(5):          # a steady hold of five frames at each pressure
            writer.write('/finger_0/pressure', serialize_message(pressure), t)
            writer.write('/mocap/markers', serialize_message(poses), t + 10 ** 6)
            t += 10 ** 8
    writer.close()
    base = tmp_path / 'base.yaml'
    BASE.to_yaml(base)
    out = tmp_path / 'from_mcap'
    status = main(['--design', str(base), '--markers', str(recording), '--marker-s',
                   ','.join(repr(s) for s in synthetic.MARKER_S), '--loading',
                   str(case['loading']), '--fit', ','.join(FIT), '--marker-noise',
                   str(synthetic.MARKER_NOISE), '--force-noise', str(case['force_noise']),
                   '--out', str(out)])
    assert status == 0
    report = json.loads((out / 'report.json').read_text())
    for name in FIT:
        assert report['estimates'][name] == pytest.approx(case['report']['estimates'][name],
                                                          rel=1e-6)
    assert main(['--design', str(base), '--markers', str(recording), '--out',
                 str(tmp_path / 'x')]) == 2


def test_a_failed_fit_over_an_earlier_success_leaves_nothing_that_looks_deployable(
        case, tmp_path, capsys):
    out = tmp_path / 'calibrated'
    shutil.copytree(case['out'], out)
    assert (out / 'actuator.yaml').is_file() and (out / 'gripper.yaml').is_file()
    argv = ['--design', str(tmp_path / 'base.yaml'), '--markers', str(case['markers']),
            '--loading', str(case['loading']), '--fit', ','.join(FIT), '--out', str(out)]
    BASE.to_yaml(tmp_path / 'base.yaml')
    # Without --force the earlier success is refused, before any fit.
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and '--force' in err
    assert (out / 'actuator.yaml').is_file()
    # Two evaluations cannot converge: the fit fails.
    assert main(argv + ['--force', '--max-evaluations', '2']) == 1
    captured = capsys.readouterr()
    assert 'MAX_EVALUATIONS' in captured.err and 'Traceback' not in captured.err
    assert 'replaced the earlier outputs' in captured.out
    names = sorted(p.name for p in out.iterdir())
    assert names == ['.fpc_gripper_output', 'FAILED.txt', 'report.json', 'report.png']
    assert json.loads((out / 'report.json').read_text())['success'] is False
    assert sorted(p.name for p in tmp_path.iterdir()) == ['base.yaml', 'calibrated']


def test_an_existing_file_as_out_is_bad_input_before_the_fit(case, tmp_path, capsys):
    target = tmp_path / 'taken'
    target.write_text('not a directory')
    status = main(['--design', str(case['out'] / 'actuator.yaml'), '--markers',
                   str(case['markers']), '--out', str(target)])
    err = capsys.readouterr().err
    assert status == 2 and err.count('\n') == 1
    assert err.startswith('fpc-calibrate: error: --out') and 'not a directory' in err
    assert target.read_text() == 'not a directory'
