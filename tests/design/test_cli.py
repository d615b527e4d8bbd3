"""The fpc-design command: the sweep table's columns, formats, figures, bad input, optimize."""

import pandas as pd
import pytest

from fpc_gripper.design import cli
from fpc_gripper.model import ActuatorDesign

COLUMNS = ['design_id', 'prestrain', 'Cy', 'pressure_pa', 'curvature_per_m', 'tip_x_m',
           'tip_z_m', 'kx_nm2', 'kz_nm2', 'success', 'status', 'model', 'message']


def _run(capsys, *argv):
    code = cli.main([*argv, '--no-progress'])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_sweep_writes_the_tidy_table_and_charts(tmp_path, capsys):
    code, out, _ = _run(capsys, 'sweep', '--vary', 'prestrain=0.15,0.25', '--vary',
                        'Cy=16e-3:26e-3:2', '--pressure', '0:100e3:50e3', '--model', 'paper',
                        '--rigidity', '--out', str(tmp_path))
    assert code == 0
    table = pd.read_csv(tmp_path / 'sweep.csv', keep_default_na=False, na_values=[''])
    assert list(table.columns) == COLUMNS
    assert len(table) == 2 * 2 * 3
    assert set(table['Cy']) == {0.016, 0.026}
    invalid = table[table['Cy'] == 0.016]
    assert (invalid['status'] == 'invalid_design').all()
    assert 'invalid_design: 6 rows (2 designs)' in out
    assert (tmp_path / 'sweep.png').stat().st_size > 10_000
    assert ActuatorDesign.from_yaml(tmp_path / 'base_design.yaml') == ActuatorDesign.paper()


def test_parquet_equals_csv(tmp_path, capsys):
    args = ['sweep', '--vary', 'prestrain=0.25,0.40', '--pressure', '0,2e5', '--model',
            'paper', '--no-charts']
    assert _run(capsys, *args, '--out', str(tmp_path / 'c'))[0] == 0
    assert _run(capsys, *args, '--format', 'parquet', '--out', str(tmp_path / 'p'))[0] == 0
    # CSV has no empty string apart from a missing value: read those columns as text.
    csv = pd.read_csv(tmp_path / 'c' / 'sweep.csv', keep_default_na=False, na_values=[''],
                      dtype={'model': str, 'message': str}).fillna({'message': ''})
    parquet = pd.read_parquet(tmp_path / 'p' / 'sweep.parquet')
    pd.testing.assert_frame_equal(csv, parquet, check_dtype=False, check_exact=False,
                                  rtol=1e-15)


def test_figure(tmp_path, capsys):
    code, out, _ = _run(capsys, 'sweep', '--figure', '5', '--out', str(tmp_path))
    assert code == 0 and 'figure 5' in out
    assert (tmp_path / 'figure_5.png').is_file() and (tmp_path / 'figure_5.csv').is_file()


@pytest.mark.parametrize('argv, message', [
    (['--vary', 'Cz=0.02'], '`Cz` is not an ActuatorDesign field'),
    (['--vary', 'Cy'], 'FIELD=VALUES'),
    (['--pressure=-1e3'], '`pressures` must be finite and >= 0'),
    (['--pressure', '0:1e5'], 'start:stop:count'),
    (['--design', '/nonexistent.yaml'], 'cannot read actuator design'),
    (['--segments', '4'], '--segments applies to --model paper'),
    (['--scheduler', 'local:x'], "'local:N' needs an integer"),
])
def test_bad_input_exits_1_with_a_message(tmp_path, capsys, argv, message):
    code, _, err = _run(capsys, 'sweep', *argv, '--out', str(tmp_path))
    assert code == 1
    assert message in err and err.startswith('fpc-design sweep: error:')
    assert not (tmp_path / 'sweep.csv').exists()


def test_optimize_unreachable_exits_3_and_still_writes(tmp_path, capsys):
    code, out, _ = _run(capsys, 'optimize', '--open-aperture', '0.5', '--pressure-budget',
                        '50e3', '--vary', 'prestrain', '--model', 'paper', '--maxiter', '2',
                        '--popsize', '4', '--out', str(tmp_path))
    assert code == 3
    assert out.startswith('UNREACHABLE') and 'NOT MET' in out
    assert (tmp_path / 'actuator.yaml').is_file() and (tmp_path / 'margins.csv').is_file()
