"""Measurement files: formats, grouping into frames, and errors that name the file and row."""

from geometry_msgs.msg import Pose, PoseArray
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import FluidPressure

from fpc_gripper.calibration import (DataError, read_loading, read_markers, read_markers_mcap,
                                     read_tensile)
from fpc_gripper.io.mcap_writer import Rosbag2McapWriter
from fpc_gripper.model import ActuatorDesign

DESIGN = ActuatorDesign.paper(prestrain=0.25)
MARKERS = """pressure_pa,marker,s_m,x_m,z_m
0,0,0.01,0.0100,-0.0005
0,1,0.03,0.0290,-0.0040
0,2,0.05,0.0450,-0.0120
100000,0,0.01,0.0100,-0.0003
100000,1,0.03,0.0295,-0.0030
100000,2,0.05,0.0470,-0.0090
"""


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_markers_are_grouped_into_frames(tmp_path):
    data = read_markers(write(tmp_path, 'markers.csv', MARKERS), DESIGN)
    np.testing.assert_array_equal(data.pressure, [0.0, 100e3])
    np.testing.assert_array_equal(data.tip_force, np.zeros((2, 2)))
    np.testing.assert_array_equal(data.frame, [0, 0, 0, 1, 1, 1])
    np.testing.assert_array_equal(data.s, [0.01, 0.03, 0.05] * 2)
    np.testing.assert_array_equal(data.xz[4], [0.0295, -0.0030])
    assert data.rows[4].endswith('markers.csv, line 6')
    # The same pressure again after another: a new frame; a repeated label: a new frame.
    again = MARKERS + '0,0,0.01,0.0101,-0.0005\n0,0,0.01,0.0102,-0.0005\n'
    data = read_markers(write(tmp_path, 'again.csv', again))
    np.testing.assert_array_equal(data.frame[-2:], [2, 3])
    np.testing.assert_array_equal(data.pressure, [0.0, 100e3, 0.0, 0.0])


def test_markers_with_tip_forces(tmp_path):
    text = ('pressure_pa,marker,s_m,x_m,z_m,tip_force_x_n,tip_force_z_n\n'
            '5e4,a,0.02,0.02,0,0.1,-0.2\n5e4,b,0.04,0.04,0,0.1,-0.2\n5e4,a,0.02,0.02,0,0,0\n')
    data = read_markers(write(tmp_path, 'm.csv', text))
    np.testing.assert_array_equal(data.tip_force, [[0.1, -0.2], [0.0, 0.0]])
    np.testing.assert_array_equal(data.frame, [0, 0, 1])


@pytest.mark.parametrize('text, message', [
    ('pressure_pa,marker,s_m,x_m\n0,0,0.01,0.01\n', r'm.csv, line 1: missing column\(s\) z_m'),
    ('pressure_pa,marker,s_m,x_m,z_m,tip_force_x_n\n0,0,0.01,0.01,0,0\n',
     'tip_force_x_n, tip_force_z_n go together'),
    (MARKERS.replace('0.0290', 'nan'), r'm.csv, line 3: column x_m must be finite \[m\], '
                                       "got 'nan'"),
    (MARKERS.replace('0.0290', ''), 'line 3: column x_m must be a number'),
    (MARKERS.replace(',1,0.03', ',1,0.06'),
     'line 4: marker order is not monotonic in s_m: marker 2 has s_m = 0.05, not above the '
     '0.06 of marker 1'),
    (MARKERS.replace('100000,0,0.01', '100000,0,0.04').replace('0,0,0.01', '0,0,0.04'),
     'line 3: marker order is not monotonic in s_m'),
    (MARKERS.replace('100000,2,0.05', '100000,2,0.055'),
     'line 7: marker 2 has s_m = 0.055 here but 0.05 at line 4'),
    (MARKERS.replace('100000,0', '500000,0'),
     'line 5: pressure 500000 Pa is above the design limit max_pressure = 400000 Pa'),
    (MARKERS.replace('0,2,0.05', '0,2,0.095').replace('100000,2,0.05', '100000,2,0.095'),
     r'line 4: s_m = 0.095 lies outside the free length \[0, 0.09\] m'),
    (MARKERS.replace('100000,0', '-1,0'), 'line 5: pressure_pa must be a gauge pressure >= 0'),
    (MARKERS + '0,1,0.03\n', 'line 8: 3 values for the 5 columns'),
    ('pressure_pa,marker,s_m,x_m,z_m\n', 'no marker rows'),
    ('', 'empty file'),
])
def test_bad_markers_name_the_file_and_line(tmp_path, text, message):
    with pytest.raises(DataError, match=message):
        read_markers(write(tmp_path, 'm.csv', text), DESIGN)


def test_loading_and_tensile_files(tmp_path):
    loading = read_loading(write(tmp_path, 'loading.csv', 'pressure_pa,axis,displacement_m,'
                                 'force_n\n0,x,0.01,0.26\n27600,Z,0.01,0.5\n'), DESIGN)
    assert loading.axis == ('x', 'z')
    np.testing.assert_array_equal(loading.force, [0.26, 0.5])
    tensile = read_tensile(write(tmp_path, 't.csv', 'strain,stress_pa\n' + ''.join(
        f'{s},{1e6 * s}\n' for s in (0.1, 0.2, 0.3, 0.4))))
    np.testing.assert_array_equal(tensile.stress, [1e5, 2e5, 3e5, 4e5])


@pytest.mark.parametrize('name, text, message', [
    ('l.csv', 'pressure_pa,axis,displacement_m,force_n\n0,y,0.01,0.2\n',
     "l.csv, line 2: column axis must be 'x' or 'z', got 'y'"),
    ('l.csv', 'pressure_pa,axis,displacement_m,force_n\n0,x,0,0.2\n',
     r'line 2: displacement_m must be > 0 \[m\]'),
    ('l.csv', 'pressure_pa,axis,displacement_m,force_n\n0,x,0.01,0.2\n410000,x,0.01,0.2\n',
     'line 3: pressure 410000 Pa is above the design limit'),
    ('l.csv', 'pressure_pa,axis,force_n\n0,x,0.2\n', r'missing column\(s\) displacement_m'),
    ('t.csv', 'strain,stress_pa\n0.1,1e5\n0.2,inf\n', 'line 3: column stress_pa must be finite'),
    ('t.csv', 'strain,stress_pa\n0.1,1e5\n0.2,2e5\n', '2 tensile rows'),
])
def test_bad_loading_and_tensile_name_the_file_and_line(tmp_path, name, text, message):
    reader = read_loading if name == 'l.csv' else read_tensile
    with pytest.raises(DataError, match=message):
        reader(write(tmp_path, name, text), DESIGN)


def _pose_array(points):
    msg = PoseArray()
    msg.header.frame_id = 'mocap'
    for x, z in points:
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = float(x), 0.5, float(z)
        pose.orientation.w = 1.0
        msg.poses.append(pose)
    return msg


def test_markers_from_mcap_average_each_steady_hold(tmp_path):
    path = tmp_path / 'run.mcap'
    s = [0.02, 0.05, 0.08]
    base = np.array([[0.02, -0.001], [0.05, -0.008], [0.075, -0.02]])
    writer = Rosbag2McapWriter(path)
    writer.add_topic('/mocap/markers', 'geometry_msgs/msg/PoseArray')
    writer.add_topic('/finger_0/pressure', 'sensor_msgs/msg/FluidPressure')
    t = 1_000_000_000
    # Holds at 0 and 100 kPa (six samples each), a two-sample ramp between them.
    for gauge, count, shift in ((0.0, 6, 0.0), (50e3, 2, 1e-3), (100e3, 6, 2e-3)):
        for k in range(count):
            pressure = FluidPressure()
            pressure.fluid_pressure = 101325.0 + gauge + (-1) ** k * 100.0
            writer.write('/finger_0/pressure', serialize_message(pressure), t)
            jitter = (-1) ** k * 1e-5
            writer.write('/mocap/markers',
                         serialize_message(_pose_array(base + shift + jitter)), t + 1000)
            t += 10_000_000
    writer.close()
    data = read_markers_mcap(path, s, '/mocap/markers', '/finger_0/pressure', DESIGN)
    # Absolute pressures below atmospheric are 0 gauge, as model_node takes them.
    np.testing.assert_allclose(data.pressure, [50.0, 100e3], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(data.frame, [0, 0, 0, 1, 1, 1])
    np.testing.assert_array_equal(data.s, s * 2)
    np.testing.assert_allclose(data.xz, np.concatenate([base, base + 2e-3]), rtol=0,
                               atol=1e-15)
    assert 'hold of 6' in data.rows[0]
    with pytest.raises(DataError, match='3 poses for the 2 markers'):
        read_markers_mcap(path, s[:2], '/mocap/markers', '/finger_0/pressure')
    with pytest.raises(DataError, match='no hold of at least 10'):
        read_markers_mcap(path, s, '/mocap/markers', '/finger_0/pressure', min_samples=10)
    with pytest.raises(DataError, match='unknown topic'):
        read_markers_mcap(path, s, '/markers', '/finger_0/pressure')
