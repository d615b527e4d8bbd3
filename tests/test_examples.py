"""The shipped examples are what their scripts make: rerun, they rewrite the same data."""

import importlib.util
import pathlib

import numpy as np

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


def test_the_recordings_are_what_the_script_writes(tmp_path):
    make = _script(EXAMPLES / 'recording' / 'make_recording.py')
    for path in make.write_recordings(tmp_path):
        assert path.read_bytes() == (EXAMPLES / 'recording' / path.name).read_bytes()
