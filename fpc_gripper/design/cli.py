"""The ``fpc-design`` command: parametric sweeps, the paper's figures and inverse design."""

import argparse
import pathlib
import sys
import time

__all__ = ['build_parser', 'main']

_EPILOG = """\
examples:
  fpc-design sweep --vary prestrain=0.15,0.25,0.40 --vary Cy=22e-3:30e-3:5 --out out/sweep
  fpc-design sweep --vary prestrain=0.15:0.40:6 --pressure 0:400e3:5e3 --rigidity \\
      --scheduler local:2 --format parquet --out out/sweep
  fpc-design sweep --figure 7 --out out/figures
  fpc-design optimize --closed-aperture 0.03 --open-aperture 0.12 --pressure-budget 250e3 \\
      --kx 1.0e-3 --at-aperture 0.08 --max-strain 0.6 --out out/design

Ranges: start:stop:count when the third part is a plain integer (16e-3:30e-3:8, as
numpy.linspace), start:stop:step otherwise (0:400e3:5e3). SI units throughout.
Dask (--scheduler) is optional: pip install 'fpc_gripper[dask]'.
"""


def build_parser():
    """Return the argument parser of ``fpc-design``."""
    parser = argparse.ArgumentParser(
        prog='fpc-design', description=__doc__.split(':', 1)[1].strip().rstrip('.') + '.',
        formatter_class=argparse.RawDescriptionHelpFormatter, epilog=_EPILOG)
    commands = parser.add_subparsers(dest='command', required=True)
    sweep = commands.add_parser(
        'sweep', help='designs x pressures to a tidy table and charts, or a paper figure',
        formatter_class=argparse.RawDescriptionHelpFormatter, epilog=_EPILOG)
    sweep.add_argument('--design', metavar='FILE',
                       help='base actuator YAML (default: the paper finger, prestrain 0.25)')
    sweep.add_argument('--vary', action='append', default=[], metavar='FIELD=VALUES',
                       help='ActuatorDesign field and its values (repeatable; the last '
                            'varies fastest)')
    sweep.add_argument('--pressure', default='0:400e3:5e3', metavar='VALUES',
                       help='gauge pressures [Pa] (default 0:400e3:5e3)')
    _model_arguments(sweep)
    sweep.add_argument('--rigidity', action='store_true',
                       help='add K_x and K_z (eq. 22, displacement control)')
    sweep.add_argument('--displacement', type=float, default=0.010, metavar='M',
                       help='tip displacement of the rigidity protocol [m] (default 0.010)')
    sweep.add_argument('--scale-w1', action='store_true',
                       help='scale the rib width w1 with Cy (w1 = w1_base Cy / Cy_base); '
                            'without it a channel too narrow for the ribs is an invalid row')
    sweep.add_argument('--figure', type=int, choices=(4, 5, 7, 8, 9),
                       help="reproduce the paper's figure N (CCM-N, delta x = 10 mm) with "
                            'the default model overlaid; ignores --vary and --pressure')
    sweep.add_argument('--format', choices=('csv', 'parquet'), default='csv',
                       help='table format (parquet needs pyarrow)')
    sweep.add_argument('--no-charts', action='store_true', help='write the table only')
    _run_arguments(sweep)

    opt = commands.add_parser(
        'optimize', help='inverse design: search prestrain, Cy, h3a (w1, L) to meet targets',
        formatter_class=argparse.RawDescriptionHelpFormatter, epilog=_EPILOG)
    opt.add_argument('--design', metavar='FILE', help='base actuator YAML (default: paper)')
    opt.add_argument('--gripper', metavar='FILE',
                     help='gripper config for the palm radius (default: gripper_paper.yaml)')
    opt.add_argument('--closed-aperture', type=float, metavar='M',
                     help='largest aperture at 0 kPa [m]')
    opt.add_argument('--open-aperture', type=float, metavar='M',
                     help='smallest aperture reached at or below the pressure budget [m]')
    opt.add_argument('--pressure-budget', type=float, default=250e3, metavar='PA',
                     help='largest gauge pressure the design may use [Pa] (default 250e3)')
    opt.add_argument('--kx', type=float, metavar='NM2',
                     help='smallest K_x [N m^2] with the gripper opened to --at-aperture')
    opt.add_argument('--tip-force', type=float, metavar='N',
                     help='smallest force [N] a fingertip presses at 0 kPa on an object of '
                          'diameter --at-aperture')
    opt.add_argument('--at-aperture', type=float, metavar='M',
                     help='aperture of --kx or --tip-force [m]')
    opt.add_argument('--max-strain', type=float, metavar='STRAIN',
                     help='largest elastomer strain (prestrain included) up to the budget [-]')
    opt.add_argument('--vary', default='prestrain,Cy,h3a', metavar='FIELDS',
                     help='parameters searched, from prestrain, Cy, h3a, w1, L '
                          '(default prestrain,Cy,h3a)')
    opt.add_argument('--bounds', action='append', default=[], metavar='FIELD=LO:HI',
                     help='search interval of a parameter (SI; repeatable)')
    _model_arguments(opt)
    opt.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    opt.add_argument('--maxiter', type=int, default=30,
                     help='differential evolution generations (default 30)')
    opt.add_argument('--popsize', type=int, default=10,
                     help='population per parameter (default 10)')
    _run_arguments(opt, scheduler=False)
    return parser


def _model_arguments(parser):
    parser.add_argument('--model', choices=('default', 'paper'), default='default',
                        help='default: the rod-accurate default model (0.05 mm); paper: '
                             'the paper CCM (--segments, default 8)')
    parser.add_argument('--segments', type=int, default=None, metavar='N',
                        help='segments of the paper CCM (with --model paper)')
    parser.add_argument('--pressure-model', choices=('adiabatic', 'isobaric'),
                        help='pressure work model (default: the model default)')


def _run_arguments(parser, scheduler=True):
    parser.add_argument('--out', required=True, metavar='DIR', help='output directory')
    if scheduler:
        parser.add_argument('--scheduler', metavar='ADDRESS',
                            help="Dask: 'local:N' (a LocalCluster of N workers) or "
                                 "'tcp://host:port' (needs fpc_gripper[dask])")
        parser.add_argument('--chunk', type=int, default=None, metavar='DESIGNS',
                            help='designs per task (default: about 16 tasks on Dask or with '
                                 'a progress bar, else one batch); never changes a row')
    parser.add_argument('--progress', dest='progress', action='store_true', default=None,
                        help='always show the progress bar (default: on a terminal)')
    parser.add_argument('--no-progress', dest='progress', action='store_false')


def _settings(args):
    from fpc_gripper.model.pipeline import DEFAULT_N_SEGMENTS, ModelSettings
    from .parametric import model_settings
    if args.segments is not None and args.model != 'paper':
        raise ValueError('--segments applies to --model paper only')
    fields = {}
    if args.pressure_model is not None:
        fields['pressure_model'] = args.pressure_model
    if args.model == 'paper':
        fields.update(tolerance=0.0, n_segments=args.segments or DEFAULT_N_SEGMENTS)
    return ModelSettings(**fields) if fields else model_settings(args.model)


def _sweep(args, out, err):
    from .charts import sweep_charts, write_table
    from .grid import base_design, parse_assignment, parse_values
    from .runner import dask_available, DASK_HINT
    from .parametric import sweep
    out_dir = pathlib.Path(args.out)
    design = base_design(args.design)
    start = time.perf_counter()
    if args.figure is not None:
        from .figures import figure
        if args.vary:
            raise ValueError('--figure fixes its own axes: drop --vary')
        out_dir.mkdir(parents=True, exist_ok=True)
        frame = figure(args.figure, out_dir, design, args.scheduler, args.progress)
        print(f'figure {args.figure}: {len(frame)} rows in {time.perf_counter() - start:.2f} s '
              f'-> {out_dir}/figure_{args.figure}.png, .csv', file=out)
        return 0
    vary = dict(parse_assignment(v) for v in args.vary)
    pressures = parse_values(args.pressure, '--pressure')
    if args.scheduler is None and not dask_available():
        print(f'fpc-design sweep: running in this process; {DASK_HINT}', file=err)
    frame = sweep(vary, pressures, design, _settings(args), args.rigidity, args.displacement,
                  args.scale_w1, args.scheduler, args.chunk, args.progress)
    elapsed = time.perf_counter() - start
    out_dir.mkdir(parents=True, exist_ok=True)
    table = write_table(frame, out_dir / f'sweep.{args.format}', args.format)
    design.to_yaml(out_dir / 'base_design.yaml')
    charts = [] if args.no_charts else sweep_charts(frame, out_dir)
    bad = frame[frame['status'] != 'ok']
    print(f'{frame["design_id"].nunique()} designs x {len(pressures)} pressures = '
          f'{len(frame)} rows in {elapsed:.2f} s ({len(frame) / elapsed:.0f} rows/s); '
          f'{int(frame["success"].sum())} solved', file=out)
    for status, rows in bad.groupby('status'):
        example = rows['message'].iloc[0]
        print(f'  {status}: {len(rows)} rows ({rows["design_id"].nunique()} designs), '
              f'e.g. {example}', file=out)
    print(f'-> {table}' + ''.join(f', {c}' for c in charts), file=out)
    return 0


def _optimize(args, out, err):
    from .grid import base_design, parse_values
    from .inverse import optimize, Targets, write_outputs
    targets = Targets(closed_aperture=args.closed_aperture, open_aperture=args.open_aperture,
                      pressure_budget=args.pressure_budget, kx=args.kx,
                      tip_force=args.tip_force, at_aperture=args.at_aperture,
                      max_strain=args.max_strain)
    bounds = {}
    for text in args.bounds:
        field, sep, values = text.partition('=')
        interval = parse_values(values.replace(':', ','), field) if sep else []
        if len(interval) != 2:
            raise ValueError(f'--bounds must be FIELD=LO:HI, got {text!r}')
        bounds[field.strip()] = tuple(interval)
    result = optimize(targets, [f.strip() for f in args.vary.split(',') if f.strip()],
                      base_design(args.design), bounds, args.gripper, _settings(args),
                      seed=args.seed, maxiter=args.maxiter, popsize=args.popsize,
                      progress=args.progress)
    files = write_outputs(result, args.out)
    print(result.report(), file=out)
    print('-> ' + ', '.join(str(f) for f in files), file=out)
    return 0 if result.success else 3


def main(argv=None):
    """
    Run ``fpc-design``.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        0 on success, 1 for bad input (a message on stderr), 2 for bad usage, 3 when
        `optimize` cannot meet every target (it still writes its best design).

    """
    args = build_parser().parse_args(argv)
    try:
        run = _sweep if args.command == 'sweep' else _optimize
        return run(args, sys.stdout, sys.stderr)
    except (ValueError, TypeError, OSError) as error:
        print(f'fpc-design {args.command}: error: {error}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f'fpc-design {args.command}: interrupted', file=sys.stderr)
        return 130


if __name__ == '__main__':
    sys.exit(main())
