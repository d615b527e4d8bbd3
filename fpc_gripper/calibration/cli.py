"""fpc-calibrate: the command line over `fpc_gripper.calibration.calibrate`."""

import argparse
import sys

from fpc_gripper.model.validation import STANDARD_ATMOSPHERE
from fpc_gripper.progress import Progress
from fpc_gripper.tools import add_version, OutputDir, run
from .data import DataError, read_loading, read_markers, read_markers_mcap, read_tensile
from .fit import calibrate, DEFAULT_FIT, FIT_SEGMENTS
from .parameters import FIT_NAMES, parse_fit
from .report import write_outputs

__all__ = ['main']

_EPILOG = """\
CSV files have a header row and SI units (see the README, "Calibrating a finger"):
  markers.csv   pressure_pa, marker, s_m, x_m, z_m[, tip_force_x_n, tip_force_z_n]
  loading.csv   pressure_pa, axis, displacement_m, force_n
  tensile.csv   strain, stress_pa
Markers may also come from an MCAP recording (--markers run.mcap): a
geometry_msgs/PoseArray topic of marker positions (--markers-topic, one pose per
marker, root to tip, arc lengths in --marker-s) and the pressure topic
(sensor_msgs/FluidPressure, absolute Pa; --pressure-topic).
A calibration of the shipped example data (examples/calibration/README.md):
  fpc-calibrate --design msg_configs/actuator_paper.yaml \\
      --markers examples/calibration/markers.csv \\
      --loading examples/calibration/loading.csv \\
      --fit prestrain,fl_modulus,pressure_work_factor --out calibrated/
--out is written whole or not at all: a failed fit leaves report.json, report.png
and FAILED.txt there, and no actuator.yaml or gripper.yaml."""


def _arc_lengths(text):
    try:
        return [float(v) for v in text.split(',') if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f'--marker-s must be comma-separated arc lengths '
                                         f'[m], got {text!r}') from None


def _positive(kind):
    """Return an argparse type: a finite `kind` number > 0."""
    def convert(text):
        try:
            value = kind(text)
        except ValueError:
            value = None
        if value is None or not value > 0 or value != value or value == float('inf'):
            raise argparse.ArgumentTypeError(f'must be a finite {kind.__name__} > 0, got '
                                             f'{text!r}')
        return value
    convert.__name__ = kind.__name__
    return convert


def _fit(text):
    try:
        return parse_fit(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _parser():
    p = argparse.ArgumentParser(
        prog='fpc-calibrate', epilog=_EPILOG, formatter_class=argparse.RawTextHelpFormatter,
        description='Fit a finger design to its measurements: motion-capture markers, '
                    'loading tests and tensile data.')
    p.add_argument('--design', required=True, help='base design YAML (ActuatorDesign)')
    p.add_argument('--markers', help='markers.csv, or an .mcap recording')
    p.add_argument('--loading', help='loading.csv')
    p.add_argument('--tensile', help='tensile.csv (constrains emc)')
    p.add_argument('--out', required=True, help='output directory')
    p.add_argument('--force', action='store_true',
                   help='replace the outputs of an earlier run in --out')
    p.add_argument('--no-progress', dest='progress', action='store_false', default=None,
                   help='no progress on stderr (default: after a second, a bar on a '
                        'terminal, a line every few seconds otherwise)')
    p.add_argument('--fit', type=_fit, default=DEFAULT_FIT,
                   help=f'parameters to fit, comma-separated from {",".join(FIT_NAMES)} '
                        f'(default {",".join(DEFAULT_FIT)})')
    p.add_argument('--marker-noise', type=_positive(float), default=0.3e-3, metavar='M',
                   help='standard deviation of a marker coordinate [m] (default 0.3e-3)')
    p.add_argument('--force-noise', type=_positive(float), default=0.02, metavar='N',
                   help='standard deviation of a loading-test force [N] (default 0.02)')
    p.add_argument('--stress-noise', type=_positive(float), default=5e3, metavar='PA',
                   help='standard deviation of a tensile stress [Pa] (default 5e3)')
    p.add_argument('--segments', type=_positive(int), default=FIT_SEGMENTS,
                   help=f"segments of the fit's PCC model (default {FIT_SEGMENTS})")
    p.add_argument('--max-evaluations', type=_positive(int), default=100,
                   help='largest number of residual evaluations (default 100)')
    mcap = p.add_argument_group('markers from MCAP')
    mcap.add_argument('--marker-s', type=_arc_lengths,
                      help='arc length of every marker, root to tip [m], e.g. 0.01,0.023')
    mcap.add_argument('--markers-topic', default='/mocap/markers',
                      help='geometry_msgs/PoseArray topic (default /mocap/markers)')
    mcap.add_argument('--pressure-topic', default='/finger_0/pressure',
                      help='sensor_msgs/FluidPressure topic (default /finger_0/pressure)')
    mcap.add_argument('--atmospheric-pressure', type=float, default=STANDARD_ATMOSPHERE,
                      help='absolute - gauge [Pa] (default 101325)')
    return add_version(p)


def _markers(args, design):
    if args.markers is None:
        return None
    if not args.markers.endswith('.mcap'):
        return read_markers(args.markers, design)
    if not args.marker_s:
        raise DataError(f'{args.markers}: an MCAP recording needs --marker-s, the arc length '
                        'of every marker [m]')
    return read_markers_mcap(args.markers, args.marker_s, args.markers_topic,
                             args.pressure_topic, design=design,
                             atmospheric_pressure=args.atmospheric_pressure)


def _summary(result, paths):
    lines = [f'{"parameter":<22}{"estimate":>16}{"stderr":>14}']
    for name, value in result.estimates.items():
        error = result.stderr[name]
        values, errors = (value, error) if isinstance(value, list) else ([value], [error])
        for k, (v, e) in enumerate(zip(values, errors)):
            label = name if len(values) == 1 else f'{name}[{k}]'
            lines.append(f'{label:<22}{v:>16.6g}{e:>14.3g}')
    lines.append('residual RMS: ' + ', '.join(f'{k} {v:.3g}'
                                              for k, v in result.residual_rms.items()))
    lines.append(f'condition number {result.condition_number:.3g}; {result.nfev} '
                 f'evaluations; {result.status.name}: {result.message}')
    lines += [f'warning: {w}' for w in result.warnings]
    lines += [f'wrote {path}' for path in paths.values()]
    return '\n'.join(lines)


def _prepare(args):
    """Check the design, the data and --out; return the job (the fit and its files)."""
    from ..model import ActuatorDesign
    out = OutputDir(args.out, args.force).check()
    design = ActuatorDesign.from_yaml(args.design)
    markers = _markers(args, design)
    loading = read_loading(args.loading, design) if args.loading else None
    tensile = read_tensile(args.tensile, design) if args.tensile else None
    if markers is None and loading is None and tensile is None:
        raise DataError('give data to fit: --markers, --loading or --tensile')

    def job():
        with Progress(1, 'fit', 'fpc-calibrate', show=args.progress):
            result = calibrate(design, markers=markers, loading=loading, tensile=tensile,
                               fit=args.fit, marker_noise=args.marker_noise,
                               force_noise=args.force_noise, stress_noise=args.stress_noise,
                               n_segments=args.segments, max_nfev=args.max_evaluations)
        reason = None if result.success else f"{result.status.name}: {result.message.rstrip('.')}"
        with out:
            paths = write_outputs(result, out.tmp)
            out.commit(failed=reason)
        paths = {kind: out.final(path) for kind, path in paths.items()}
        print(_summary(result, paths))
        if out.replaced:
            print(out.replaced_note())
        if reason is not None:
            print(f'fpc-calibrate: failed: {reason}; {out.path} holds its report and '
                  'no design', file=sys.stderr)
            return 1
        return 0
    return job


def main(argv=None):
    """Run fpc-calibrate; return the exit status of `fpc_gripper.tools.EXIT_CODES`."""
    return run(_parser(), _prepare, argv, input_errors=(DataError,))


if __name__ == '__main__':
    sys.exit(main())
