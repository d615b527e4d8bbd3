"""The speed-accuracy chart against the continuum agrees with the FE table it was drawn from."""

import json
import pathlib

import pytest

from fpc_gripper.model.reference import CONTINUUM_FLOOR, CORRECTED_FLOOR

ROOT = pathlib.Path(__file__).resolve().parents[2]
CHART = json.loads((ROOT / 'bench' / 'results' / 'continuum_chart.json').read_text())['models']
TABLE = [row for row in json.loads((ROOT / 'bench' / 'results' / 'continuum.json').read_text())
         ['table']['rows'] if row['pressure_kpa'] == 0.0 and row['success']]


@pytest.mark.parametrize('chart, table', [('rod', 'rod'), ('default', 'default'),
                                          ('ccm-8 (paper)', 'ccm8'), ('arc', 'arc')])
def test_the_chart_errors_are_the_tables(chart, table):
    """The chart's solves (today's rungs) against bench_continuum's, stored with the FE."""
    stored = [row['rungs'][table]['error_mm'] for row in TABLE]
    assert CHART[chart]['fe_all_max_mm'] == pytest.approx(max(stored), abs=1e-6)
    assert CHART[chart]['fe_all_median_mm'] == pytest.approx(
        sorted(stored)[len(stored) // 2], abs=1e-6)


def test_the_floors_are_the_charts():
    assert CHART['rod']['fe_all_max_mm'] == pytest.approx(1e3 * CONTINUUM_FLOOR, abs=1e-3)
    assert CHART['corrected']['fe_all_max_mm'] <= 1e3 * CORRECTED_FLOOR + 1e-4
    # Every other rung is at or above the beam floor against the continuum.
    assert min(e['fe_all_max_mm'] for k, e in CHART.items() if k != 'corrected') \
        >= 1e3 * CONTINUUM_FLOOR - 0.01


def test_the_chart_is_drawn():
    png = ROOT / 'docs' / 'speed_accuracy_continuum.png'
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
