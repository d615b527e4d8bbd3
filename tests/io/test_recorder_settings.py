"""The MCAP recorder's parameters without ROS: the table, the recording they open, the topics."""

import pytest

from fpc_gripper.io.config import default_gripper_config_path
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.io.mcap_writer import COMPRESSIONS
from fpc_gripper.io.messages import gripper_topics
from fpc_gripper.io.recorder_settings import apply_settings
from fpc_gripper.io.recorder_settings import compression_refusal
from fpc_gripper.io.recorder_settings import DEFAULT_FINGERS
from fpc_gripper.io.recorder_settings import default_topics
from fpc_gripper.io.recorder_settings import open_recording
from fpc_gripper.io.recorder_settings import PARAMETERS

DEFAULTS = {name: default for name, default, _, _ in PARAMETERS}


@pytest.mark.parametrize('row', PARAMETERS, ids=lambda row: row[0])
def test_every_default_is_inside_its_range(row):
    name, default, description, extra = row
    assert description
    if 'floating_point_range' in extra:
        low, high = extra['floating_point_range']
        assert low <= default <= high, name


def test_the_compressions_are_the_writers():
    assert DEFAULTS['compression'] in COMPRESSIONS
    for compression in COMPRESSIONS:
        assert compression_refusal(compression) is None
    assert compression_refusal('gzip') == \
        "`compression` must be one of zstd, lz4, none, got 'gzip'"


def test_the_recording_opened_has_the_parameters_in_writer_units(tmp_path):
    values = dict(DEFAULTS, output_path=str(tmp_path / 'r.mcap'), max_file_size_mb=2.0,
                  max_duration_s=1.5, flush_period_s=0.4, compression='none')
    background = open_recording(values)
    try:
        assert background.writer.path == tmp_path / 'r.mcap'
        assert background.writer.max_file_size == 2 * 1024 * 1024
        assert background.writer.max_duration == 1_500_000_000
        assert background.flush_period_s == pytest.approx(0.4)
        apply_settings(background, dict(values, max_file_size_mb=0.5, max_duration_s=0.0,
                                        flush_period_s=2.0))
        assert background.writer.max_file_size == 512 * 1024
        assert background.writer.max_duration == 0
        assert background.flush_period_s == pytest.approx(2.0)
    finally:
        background.close()
    assert (tmp_path / 'r.mcap').exists()


def test_the_default_topics_are_the_configured_fingers():
    topics, problem = default_topics()
    assert problem is None
    assert topics == gripper_topics(load_gripper_config(default_gripper_config_path()).names)


def test_an_unreadable_gripper_config_falls_back_to_three_fingers_and_says_why(tmp_path):
    topics, problem = default_topics(str(tmp_path / 'missing.yaml'))
    assert topics == gripper_topics(DEFAULT_FINGERS)
    assert problem.startswith('gripper configuration unavailable (')
    assert problem.endswith('recording fingers finger_0, finger_1, finger_2')
