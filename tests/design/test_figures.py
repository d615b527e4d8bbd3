"""The paper's figures: files written, the paper model's values and trends, the overlay."""

import numpy as np
import pandas as pd
import pytest

from fpc_gripper.design import figure
from fpc_gripper.design.figures import PAPER_PRESSURES

#: SPEC's reference table at 0 kPa (CCM8), 1/m, to +-0.02.
SPEC_UNACTUATED = {0.15: 14.98, 0.25: 26.38, 0.40: 45.69}


@pytest.fixture(scope='module')
def figures(tmp_path_factory):
    out = tmp_path_factory.mktemp('figures')
    # Files for one figure of each drawing (8 and 9 are drawn as 7 is).
    return out, {n: figure(n, out if n in (4, 5, 7) else None) for n in (4, 5, 7, 8, 9)}


@pytest.mark.parametrize('number', [4, 5, 7])
def test_png_and_csv_are_written(figures, number):
    out, frames = figures
    png = out / f'figure_{number}.png'
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and png.stat().st_size > 20_000
    table = pd.read_csv(out / f'figure_{number}.csv')
    assert len(table) == len(frames[number])
    assert set(table['curve']) >= {'default model'}
    assert (table['figure'] == number).all()


def test_figure_7_is_the_paper_protocol(figures):
    frame = figures[1][7]
    paper = frame[frame['curve'] == 'paper CCM8']
    np.testing.assert_allclose(np.sort(paper['pressure_pa'].unique()), PAPER_PRESSURES)
    assert (paper['model'] == 'ccm N=8').all()
    for prestrain, kappa in SPEC_UNACTUATED.items():
        row = paper[(paper['prestrain'] == prestrain) & (paper['pressure_pa'] == 0.0)]
        assert float(row['curvature_per_m'].iloc[0]) == pytest.approx(kappa, abs=0.02)
    # SPEC's K_x: 1.636e-3 N m^2 at 0.25 and 0 kPa with delta x = 10 mm.
    first = paper[(paper['prestrain'] == 0.25) & (paper['pressure_pa'] == 0.0)]
    assert float(first['kx_nm2'].iloc[0]) == pytest.approx(1.636e-3, rel=1e-3)
    # The overlay is the rod-accurate default (0.25, 0 kPa: the rod's 24.07 1/m), which
    # the paper's reconstruction over-predicts by about 10 %.
    default = frame[(frame['curve'] == 'default model') & (frame['prestrain'] == 0.25)
                    & (frame['pressure_pa'] == 0.0)]
    assert float(default['curvature_per_m'].iloc[0]) == pytest.approx(24.07, abs=0.01)


@pytest.mark.parametrize('number, field', [(8, 'Cy'), (9, 'h3a')])
def test_channel_figures_curl_more_with_a_bigger_channel(figures, number, field):
    frame = figures[1][number]
    for curve, rows in frame.groupby('curve'):
        start = rows[rows['pressure_pa'] == 0.0].sort_values(field)['curvature_per_m']
        assert np.all(np.diff(start.to_numpy()) > 0.0), curve


def test_figure_4_converges_in_n(figures):
    frame = figures[1][4]
    kappa = frame[(frame['panel'] == 'b') & (frame['n_segments'] > 0)]
    for prestrain, rows in kappa.groupby('prestrain'):
        by_n = rows.set_index('n_segments')['curvature_per_m']
        assert by_n[8] == pytest.approx(SPEC_UNACTUATED[prestrain], abs=0.02)
        assert abs(by_n[8] - by_n[16]) < 0.01 * abs(by_n[16])
    shapes = frame[frame['panel'] == 'a']
    assert set(shapes['n_segments']) == {0, 1, 2, 4, 8}
    assert shapes[['x_m', 'z_m']].notna().all().all()


def test_figure_5_has_every_n_and_prestrain(figures):
    frame = figures[1][5]
    assert set(frame['n_segments']) == {0, 1, 4, 8, 16}
    assert set(frame['prestrain']) == {0.15, 0.25, 0.40}
    ccm8 = frame[frame['n_segments'] == 8]
    for _, rows in ccm8.groupby('prestrain'):
        assert np.all(np.diff(rows.sort_values('pressure_pa')['curvature_per_m']) < 0.0)


def test_unknown_figure():
    with pytest.raises(ValueError, match='figure'):
        figure(6)
