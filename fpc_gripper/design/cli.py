"""The ``fpc-design`` command: parametric sweeps, the paper's figures and inverse design."""

import argparse
import sys
import time

from fpc_gripper.ranges import RANGE_HELP
from fpc_gripper.tools import add_version, JobFailed, OutputDir, run

__all__ = ['build_parser', 'main']

_EPILOG = f"""\
examples:
  fpc-design sweep --vary prestrain=0.15,0.25,0.40 --vary Cy=22e-3:30e-3/3 --out out/sweep
  fpc-design sweep --vary prestrain=0.15:0.40/6 --pressure 0:400e3:20e3 --rigidity \\
      --format parquet --out out/sweep2
  fpc-design sweep --figure 7 --out out/figures
  fpc-design optimize --closed-aperture 0.010 --open-aperture 0.09 \\
      --pressure-budget 250e3 --tip-force 0.05 --at-aperture 0.03 --max-strain 0.6 \\
      --maxiter 4 --out out/design

{RANGE_HELP}
Dask (--scheduler local:N or tcp://host:port) is optional: pip install 'fpc_gripper[dask]'.
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
                       help='ActuatorDesign field and its values (repeatable for other '
                            'fields; the last varies fastest)')
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
    for sub in (parser, sweep, opt):
        add_version(sub)
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
    parser.add_argument('--force', action='store_true',
                        help='replace the outputs of an earlier run in --out')
    if scheduler:
        parser.add_argument('--scheduler', metavar='ADDRESS',
                            help="Dask: 'local:N' (a LocalCluster of N workers) or "
                                 "'tcp://host:port' (needs fpc_gripper[dask])")
        parser.add_argument('--chunk', type=int, default=None, metavar='DESIGNS',
                            help='designs per task (default: about 16 tasks on Dask or with '
                                 'a progress bar, else one batch); never changes a row')
    parser.add_argument('--progress', dest='progress', action='store_true', default=None,
                        help='show progress on stderr (the default: after a second, a bar '
                             'on a terminal, a line every few seconds otherwise)')
    parser.add_argument('--no-progress', dest='progress', action='store_false',
                        help='no progress on stderr')


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


def _prepare_sweep(args):
    """Check the sweep's inputs and --out; return its job."""
    from fpc_gripper.model import batch
    from .grid import base_design, parse_assignment, parse_values
    from .runner import _parse, dask_available, DASK_HINT
    out = OutputDir(args.out, args.force).check()
    design = base_design(args.design)
    if args.scheduler is not None:
        _parse(args.scheduler)
        if not dask_available():
            raise ValueError(f'`scheduler` {args.scheduler!r} needs dask.distributed: '
                             f'{DASK_HINT}')
    if args.figure is not None:
        if args.vary:
            raise ValueError('`figure` fixes its own axes: drop `vary`')
        return lambda: _figure(args, design, out)
    vary = {}
    for text in args.vary:
        field, values = parse_assignment(text)
        if field in vary:
            raise ValueError(f'`vary` names {field} twice; give all its values once '
                             f'({field}=a,b,c)')
        vary[field] = values
    pressures = parse_values(args.pressure, '--pressure')
    if pressures.min() < 0.0:
        raise ValueError(f'`pressure` must be >= 0 (gauge) [Pa], got {args.pressure!r}')
    pressures = batch.check_pressures(pressures)
    if not (0.0 < args.displacement < float('inf')):
        raise ValueError(f'`displacement` must be finite and > 0 [m], got {args.displacement}')
    if args.chunk is not None and args.chunk < 1:
        raise ValueError(f'`chunk` must be >= 1, got {args.chunk}')
    settings = _settings(args)
    return lambda: _sweep(args, design, vary, pressures, settings, out)


def _figure(args, design, out):
    from fpc_gripper.progress import Progress
    from .figures import figure
    start = time.perf_counter()
    # One unit: off a terminal its heartbeat is the line every few seconds.
    with out, Progress(1, 'figure', 'fpc-design sweep', show=args.progress) as progress:
        frame = figure(args.figure, out.tmp, design, args.scheduler, False)
        progress.update()
        solved = int(frame['success'].sum())
        out.commit(failed=None if solved else 'no row of the figure was solved')
    print(f'figure {args.figure}: {len(frame)} rows ({solved} solved) in '
          f'{time.perf_counter() - start:.2f} s -> {out.path}/figure_{args.figure}.png, .csv')
    if not solved:
        raise JobFailed(f'no row of figure {args.figure} was solved')
    return 0


def _sweep(args, design, vary, pressures, settings, out):
    from .charts import sweep_charts, write_table
    from .parametric import sweep
    from .runner import dask_available, DASK_HINT
    start = time.perf_counter()
    if args.scheduler is None and not dask_available():
        print(f'fpc-design sweep: running in this process; {DASK_HINT}', file=sys.stderr)
    frame = sweep(vary, pressures, design, settings, args.rigidity, args.displacement,
                  args.scale_w1, args.scheduler, args.chunk, args.progress)
    elapsed = time.perf_counter() - start
    solved = int(frame['success'].sum())
    bad = frame[frame['status'] != 'ok']
    why = [f'{status}: {len(rows)} rows ({rows["design_id"].nunique()} designs), e.g. '
           f'{rows["message"].iloc[0]}' for status, rows in bad.groupby('status')]
    with out:
        table = write_table(frame, out.file(f'sweep.{args.format}'), args.format)
        design.to_yaml(out.file('base_design.yaml'))
        charts = [] if args.no_charts else sweep_charts(frame, out.tmp)
        out.commit(failed=None if solved else 'no row solved; ' + '; '.join(why))
    print(f'{frame["design_id"].nunique()} designs x {len(pressures)} pressures = '
          f'{len(frame)} rows in {elapsed:.2f} s ({len(frame) / elapsed:.0f} rows/s); '
          f'{solved} solved')
    for line in why:
        print(f'  {line}')
    print(f'-> {out.final(table)}' + ''.join(f', {out.final(c)}' for c in charts))
    if out.replaced:
        print(out.replaced_note())
    if not solved:
        raise JobFailed(f'none of the {len(frame)} rows was solved ({"; ".join(why)}); '
                        f'{out.path} holds the table and FAILED.txt')
    return 0


def _prepare_optimize(args):
    """Check the targets, the search and --out; return the search's job."""
    from .grid import base_design, parse_values
    from .inverse import check_search, palm_radius, PARAMETERS, Targets
    out = OutputDir(args.out, args.force).check()
    targets = Targets(closed_aperture=args.closed_aperture, open_aperture=args.open_aperture,
                      pressure_budget=args.pressure_budget, kx=args.kx,
                      tip_force=args.tip_force, at_aperture=args.at_aperture,
                      max_strain=args.max_strain)
    bounds = {}
    for text in args.bounds:
        field, sep, values = text.partition('=')
        interval = parse_values(values.replace(':', ','), '--bounds') if sep else []
        if len(interval) != 2:
            raise ValueError(f'`bounds` must be FIELD=LO:HI, got {text!r}')
        bounds[field.strip()] = tuple(interval)
    parameters = [f.strip() for f in args.vary.split(',') if f.strip()]
    if not parameters or len(set(parameters)) != len(parameters) \
            or not set(parameters) <= set(PARAMETERS):
        raise ValueError(f'`vary` must be distinct names from {", ".join(PARAMETERS)}, got '
                         f'{args.vary!r}')
    design = base_design(args.design)
    check_search(targets, parameters, design, bounds)
    palm_radius(args.gripper)
    for name in ('maxiter', 'popsize'):
        if getattr(args, name) < 1:
            raise ValueError(f'`{name}` must be >= 1, got {getattr(args, name)}')
    settings = _settings(args)
    return lambda: _optimize(args, targets, parameters, design, bounds, settings, out)


def _optimize(args, targets, parameters, design, bounds, settings, out):
    from .inverse import optimize, write_outputs
    result = optimize(targets, parameters, design, bounds, args.gripper, settings,
                      seed=args.seed, maxiter=args.maxiter, popsize=args.popsize,
                      progress=args.progress)
    with out:
        files = write_outputs(result, out.tmp)
        out.commit(failed=None if result.success else result.message)
    print(result.report())
    print('-> ' + ', '.join(str(out.final(f)) for f in files))
    if out.replaced:
        print(out.replaced_note())
    if not result.success:
        raise JobFailed(f'{result.status}: {result.message}; {out.path} holds the closest '
                        'design as closest_actuator.yaml and FAILED.txt')
    return 0


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
        The exit status of `fpc_gripper.tools.EXIT_CODES`: 1 when a sweep solved no row or
        `optimize` met not every target (it still writes the closest design).

    """
    parser = build_parser()

    def prepare(args):
        return (_prepare_sweep if args.command == 'sweep' else _prepare_optimize)(args)
    return run(parser, prepare, argv)


if __name__ == '__main__':
    sys.exit(main())
