"""The fpc-design command: the sweep table's columns, formats, figures, bad input, optimize."""

import pandas as pd
import pytest

from fpc_gripper.design import cli
from fpc_gripper.model import ActuatorDesign

COLUMNS = ['design_id', 'prestrain', 'Cy', 'pressure_pa', 'curvature_per_m', 'tip_x_m',
           'tip_z_m', 'kx_nm2', 'kz_nm2', 'kx_direct_n_per_m', 'kz_direct_n_per_m', 'success',
           'status', 'model', 'message']


def _run(capsys, *argv):
    code = cli.main([*argv, '--no-progress'])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_sweep_writes_the_tidy_table_and_charts(tmp_path, capsys):
    code, out, _ = _run(capsys, 'sweep', '--vary', 'prestrain=0.15,0.25', '--vary',
                        'Cy=16e-3:26e-3/2', '--pressure', '0:100e3:50e3', '--model', 'paper',
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
    (['--pressure=-1e3'], '`--pressure` must be >= 0'),
    (['--pressure', '0:1e5'], 'start:stop:step or start:stop/count'),
    (['--pressure', '0:4e5:5000'], 'write 0:4e5/5000 for 5000 values, or 0:4e5:5000.0'),
    (['--vary', 'Cy=22e-3:30e-3:5'], 'write 22e-3:30e-3/5 for 5 values'),
    (['--vary', 'prestrain=0.2', '--vary', 'prestrain=0.3'], 'names prestrain twice'),
    (['--design', '/nonexistent.yaml'], 'cannot read actuator design'),
    (['--segments', '4'], '--segments applies to --model paper'),
    (['--scheduler', 'local:x'], "'local:N' needs an integer"),
])
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, argv, message):
    code, _, err = _run(capsys, 'sweep', *argv, '--out', str(tmp_path))
    assert code == 2
    assert message in err and err.startswith('fpc-design sweep: error:')
    assert len(err.strip().splitlines()) == 1
    assert not any(tmp_path.iterdir())


def test_optimize_unreachable_exits_1_and_writes_no_deployable_design(tmp_path, capsys):
    code, out, err = _run(capsys, 'optimize', '--open-aperture', '0.5', '--pressure-budget',
                          '50e3', '--vary', 'prestrain', '--model', 'paper', '--maxiter', '2',
                          '--popsize', '4', '--out', str(tmp_path))
    assert code == 1
    assert out.startswith('UNREACHABLE') and 'NOT MET' in out
    assert err.startswith('fpc-design optimize: failed:') and 'Traceback' not in err
    assert (tmp_path / 'closest_actuator.yaml').is_file()
    assert (tmp_path / 'margins.csv').is_file() and (tmp_path / 'FAILED.txt').is_file()
    assert not (tmp_path / 'actuator.yaml').exists() and not (tmp_path / 'gripper.yaml').exists()


@pytest.mark.parametrize('argv, message', [
    (['--pressure-budget=9e5', '--closed-aperture', '0.01'],
     '`--pressure-budget` must be <= 800000 [Pa]'),
    (['--closed-aperture', '-0.01'], '`--closed-aperture` must be > 0 [m]'),
    (['--closed-aperture', '0.01', '--bounds', 'prestrain=0.5:0.1'], 'low < high'),
])
def test_optimize_refuses_bad_targets_before_searching(tmp_path, capsys, argv, message):
    code, _, err = _run(capsys, 'optimize', *argv, '--out', str(tmp_path / 'o'))
    assert code == 2 and message in err
    assert len(err.strip().splitlines()) == 1 and err.startswith('fpc-design optimize: error:')
    assert not (tmp_path / 'o').exists()


def test_a_sweep_with_no_solved_row_exits_1_and_marks_its_outputs(tmp_path, capsys):
    code, out, err = _run(capsys, 'sweep', '--vary', 'prestrain=-0.5,5', '--pressure', '0,1e5',
                          '--out', str(tmp_path / 'x'))
    assert code == 1
    assert 'none of the 4 rows was solved' in err and 'invalid_design' in err
    assert len(err.strip().splitlines()) == 1
    assert (tmp_path / 'x' / 'FAILED.txt').is_file()


def test_outputs_need_force_and_are_replaced_whole(tmp_path, capsys):
    args = ['sweep', '--vary', 'prestrain=0.25', '--pressure', '0', '--no-charts',
            '--out', str(tmp_path / 'x')]
    assert _run(capsys, *args)[0] == 0
    (tmp_path / 'x' / 'stale.txt').write_text('an earlier file')
    code, _, err = _run(capsys, *args)
    assert code == 2 and '--force' in err
    assert (tmp_path / 'x' / 'stale.txt').is_file()
    code, out, _ = _run(capsys, *args, '--force')
    assert code == 0 and 'replaced the earlier outputs' in out
    names = sorted(p.name for p in (tmp_path / 'x').iterdir() if p.name[0] != '.')
    assert names == ['base_design.yaml', 'sweep.csv']
