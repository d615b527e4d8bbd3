"""The shipped examples are what their scripts make: rerun, they write the same data."""

import importlib.util
import pathlib

import numpy as np

from fpc_gripper.io.mcap_reader import Recording, recover

EXAMPLES = pathlib.Path(__file__).resolve().parents[1] / 'examples'


def _script(path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _table(path):
    lines = path.read_text().splitlines()
    rows = [line.split(',') for line in lines[1:]]
    return lines[0], rows


def test_the_calibration_data_are_the_documented_truth_measured(tmp_path):
    make = _script(EXAMPLES / 'calibration' / 'make_data.py')
    truth = make.truth()
    assert truth.prestrain == 0.30 and truth.pressure_work_factor == 1.8
    for path in make.write_data(tmp_path):
        shipped = EXAMPLES / 'calibration' / path.name
        header, rows = _table(path)
        assert (header, len(rows)) == _table(shipped)[:1] + (len(_table(shipped)[1]),)
        for made, ship in zip(rows, _table(shipped)[1]):
            numbers = [(float(a), float(b)) for a, b in zip(made, ship) if a not in 'xz']
            np.testing.assert_allclose(*zip(*numbers), rtol=1e-7, atol=1e-12)


def _messages(path):
    """Every message of a recording, the cut-off one too (through `recover`)."""
    fixed = path.with_suffix('.fixed.mcap')
    recover(path, fixed, overwrite=True)
    # Decoded: rclpy's serializer leaves its alignment padding uninitialised.
    with Recording(fixed) as recording:
        return [(m.topic, m.log_time, m.publish_time, repr(m.ros_msg))
                for m in recording.messages()]


def test_the_recordings_are_what_the_script_writes(tmp_path):
    make = _script(EXAMPLES / 'recording' / 'make_recording.py')
    (tmp_path / 'made').mkdir()
    for path in make.write_recordings(tmp_path / 'made'):
        shipped = EXAMPLES / 'recording' / path.name
        copy = tmp_path / 'shipped' / path.name
        copy.parent.mkdir(exist_ok=True)
        copy.write_bytes(shipped.read_bytes())
        made, ship = _messages(path), _messages(copy)
        assert len(made) > 100 and made == ship
        assert 'FluidPressure(header=' in made[0][3]
