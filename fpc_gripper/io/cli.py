"""The ``fpc-mcap`` command: inspect, plot, export, recover and replay gripper recordings."""

import argparse
import csv
import dataclasses
import json
import math
import os
import pathlib
import re
import shutil
import sys

from fpc_gripper.progress import Progress
from fpc_gripper.tools import add_version, EXIT_SKIPPED, InputError, OutputDir, run
from .mcap_reader import McapInputError, Recording, recover, UnknownTopicError
from .mcap_writer import atomic_mcap_writer, SchemaNotFoundError
from .messages import (curvature_message, DEFAULT_ATMOSPHERIC_PRESSURE, finger_topic,
                       MODEL_OUTPUT_TYPES, rigidity_message, serialized_shape, STATE_QOS,
                       time_to_ns)

__all__ = ['ReplayReport', 'build_parser', 'exact_seconds', 'export_csv', 'file_info', 'main',
           'replay_model']

_INPUT_TOPIC = re.compile(
    r'^(?P<ns>(?:.*/)?)(?P<finger>finger_\d+)/(?P<kind>pressure_command|pressure|tip_force)$')


def exact_seconds(nanoseconds):
    """
    Format a time in integer nanoseconds as seconds with all nine decimals, exactly.

    A float holds some 16 significant digits, so ``t * 1e-9`` of a time since the epoch
    (19 digits) invents its last nanoseconds; this is integer arithmetic.

    Parameters
    ----------
    nanoseconds : int
        [ns].

    Returns
    -------
    str
        For instance ``'1700000000.000000007'``.

    """
    sign = '-' if nanoseconds < 0 else ''
    sec, nsec = divmod(abs(int(nanoseconds)), 1_000_000_000)
    return f'{sign}{sec}.{nsec:09d}'


# -- info ---------------------------------------------------------------------------------

def file_info(mcap_file):
    """
    Summarise a recording: topics, counts, duration and rates.

    Parameters
    ----------
    mcap_file : Recording or McapFile
        The recording.

    Returns
    -------
    dict
        ``path, files, profile, library, message_count, chunk_count, compression,
        start_ns, end_ns, duration_ns, duration_s, topics`` (each topic: ``type, count,
        rate_hz``, the rate over that topic's own first-to-last span [Hz]); times are
        integer nanoseconds, ``duration_s`` their float difference in seconds.

    """
    spans = {}
    for msg in mcap_file.messages(decode=False):
        first, _ = spans.get(msg.topic, (msg.log_time, msg.log_time))
        spans[msg.topic] = (first, msg.log_time)
    topics = {}
    for name, info in sorted(mcap_file.topics.items()):
        first, last = spans.get(name, (0, 0))
        span = (last - first) * 1e-9
        rate = (info.message_count - 1) / span if info.message_count > 1 and span > 0 else 0.0
        topics[name] = {'type': info.type_name or '(no schema)', 'count': info.message_count,
                        'rate_hz': rate}
    return {
        'path': str(mcap_file.path),
        'files': [str(f) for f in getattr(mcap_file, 'files', [mcap_file.path])],
        'profile': mcap_file.header.profile,
        'library': mcap_file.header.library,
        'message_count': mcap_file.message_count,
        'chunk_count': mcap_file.chunk_count,
        'compression': sorted(c or 'none' for c in mcap_file.compressions),
        'start_ns': mcap_file.start_time,
        'end_ns': mcap_file.end_time,
        'duration_ns': mcap_file.end_time - mcap_file.start_time,
        'duration_s': (mcap_file.end_time - mcap_file.start_time) * 1e-9,
        'topics': topics,
    }


def _print_info(info, out):
    files = info['files']
    if files == [info['path']]:
        print(f"file:      {info['path']}", file=out)
    else:
        print(f"bag:       {info['path']} ({len(files)} files: "
              f"{', '.join(pathlib.Path(f).name for f in files)})", file=out)
    print(f"profile:   {info['profile'] or '(none)'}  library: {info['library']}", file=out)
    print(f"messages:  {info['message_count']} in {info['chunk_count']} chunks "
          f"({', '.join(info['compression']) or 'no chunks'})", file=out)
    print(f"start:     {exact_seconds(info['start_ns'])} s", file=out)
    print(f"end:       {exact_seconds(info['end_ns'])} s", file=out)
    print(f"duration:  {exact_seconds(info['duration_ns'])} s", file=out)
    print('topics:', file=out)
    width = max((len(t) for t in info['topics']), default=0)
    for name, topic in info['topics'].items():
        print(f"  {name:<{width}}  {topic['type']:<36} {topic['count']:>8} msgs "
              f"{topic['rate_hz']:>9.2f} Hz", file=out)


# -- export-csv ---------------------------------------------------------------------------

def _plain(value):
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, '__slots__') and not isinstance(value, (str, int, float, bool)):
        return {name: _plain(getattr(value, name)) for name in value.__slots__}
    if hasattr(value, 'tolist'):
        return value.tolist()
    return value


def _flatten(value, prefix, row):
    if hasattr(value, '__slots__') and not isinstance(value, (str, int, float, bool)):
        for name in value.__slots__:
            _flatten(getattr(value, name), f'{prefix}.{name}' if prefix else name, row)
    elif isinstance(value, (list, tuple, bytes, bytearray)) or hasattr(value, 'tolist'):
        row[prefix] = json.dumps(_plain(value))
    else:
        row[prefix] = value
    return row


def _csv_name(topic):
    return (topic.strip('/').replace('/', '__') or 'root') + '.csv'


def export_csv(mcap_file, out_dir, topics=None):
    """
    Write one CSV per topic: times, then every field flattened with dotted names.

    Scalars get a column each; arrays and sequences (a Path's poses, for instance) go into
    one JSON-encoded column. Files are written in a temporary directory beside `out_dir`
    and moved into place only after the whole file was read.

    Parameters
    ----------
    mcap_file : Recording or McapFile
        The recording.
    out_dir : pathlib.Path
        Output directory (created if missing).
    topics : list of str, optional
        Topics to export (all when omitted).

    Returns
    -------
    dict of str to pathlib.Path
        Topic to CSV file.

    """
    topics = sorted(mcap_file.topics) if not topics else list(topics)
    mcap_file.check_topics(topics)
    mcap_file.check_decodable(topics)
    out_dir = pathlib.Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise McapInputError(f'{out_dir}: exists and is not a directory')
    parent = out_dir.parent
    if not parent.is_dir():
        raise McapInputError(f'{parent}: no such directory')
    tmp_dir = parent / f'.{out_dir.name}.{os.getpid()}.tmp'
    shutil.rmtree(tmp_dir, ignore_errors=True)
    tmp_dir.mkdir()
    try:
        writers, files = {}, {}
        for msg in mcap_file.messages(topics=topics):
            row = _flatten(msg.ros_msg, '', {'log_time_ns': msg.log_time,
                                             'publish_time_ns': msg.publish_time})
            writer = writers.get(msg.topic)
            if writer is None:
                files[msg.topic] = open(tmp_dir / _csv_name(msg.topic), 'w', newline='',
                                        encoding='utf-8')
                writer = csv.DictWriter(files[msg.topic], fieldnames=list(row))
                writer.writeheader()
                writers[msg.topic] = writer
            writer.writerow(row)
        for handle in files.values():
            handle.close()
        for topic in topics:
            if topic not in files:
                empty = tmp_dir / _csv_name(topic)
                empty.write_text('log_time_ns,publish_time_ns\n', encoding='utf-8')
        if not out_dir.exists():
            os.replace(tmp_dir, out_dir)
        else:
            for topic in topics:
                os.replace(tmp_dir / _csv_name(topic), out_dir / _csv_name(topic))
        return {topic: out_dir / _csv_name(topic) for topic in topics}
    finally:
        shutil.rmtree(tmp_dir, ignore_errors=True)


# -- replay-model -------------------------------------------------------------------------

@dataclasses.dataclass
class ReplayReport:
    """
    Counts of a `replay_model` run.

    Attributes
    ----------
    inputs : int
        Input messages read.
    solves : int
        Equilibria written.
    failures : int
        Solves that did not converge (nothing written for them).
    rejected : int
        Inputs the model node would reject (non-finite, over the limit, wrong frame,
        stale): nothing is solved for them.
    clipped : int
        Inputs below atmospheric pressure, solved at 0 Pa gauge.
    rigidity_solves : int
        Rigidity evaluations (one per distinct pressure and axis).
    fingers : list of str
        Finger topic prefixes replayed.
    outputs : dict of str to int
        Messages written per topic.
    undecodable : list of Undecodable
        Input messages whose payload could not be decoded, skipped (with
        ``skip_undecodable``).

    """

    inputs: int = 0
    solves: int = 0
    failures: int = 0
    rejected: int = 0
    clipped: int = 0
    rigidity_solves: int = 0
    fingers: list = dataclasses.field(default_factory=list)
    outputs: dict = dataclasses.field(default_factory=dict)
    undecodable: list = dataclasses.field(default_factory=list)


class _Finger:
    """Replay state of one finger: its index in the model core and its topics."""

    def __init__(self, index, prefix, name, pressure_topic, force_topic):
        self.index = index
        self.prefix = prefix
        self.name = name
        self.pressure_topic = pressure_topic
        self.force_topic = force_topic
        self.last_rigidity = None
        self.last_rigidity_time = None


def _load_config(config_path):
    try:
        from .config import default_gripper_config_path, load_gripper_config
    except ImportError as err:
        raise McapInputError(f'gripper configuration loader unavailable ({err})') from None
    path = config_path or default_gripper_config_path()
    return load_gripper_config(path)


def _select_inputs(mcap_file, source):
    fingers = {}
    for topic in mcap_file.topics:
        match = _INPUT_TOPIC.match(topic)
        if match:
            key = (match['ns'], match['finger'])
            fingers.setdefault(key, {})[match['kind']] = topic
    if not fingers:
        raise UnknownTopicError(
            f'{mcap_file.path}: no finger_<i>/pressure_command, pressure or tip_force topic; '
            f'the file has {", ".join(sorted(mcap_file.topics)) or "no topics"}')
    chosen = {}
    for key, kinds in sorted(fingers.items()):
        order = {'auto': ('pressure', 'pressure_command'), 'pressure': ('pressure',),
                 'pressure_command': ('pressure_command',)}[source]
        pressure = next((kinds[k] for k in order if k in kinds), None)
        if pressure is not None:
            chosen[key] = (pressure, kinds.get('tip_force'))
    if not chosen:
        raise UnknownTopicError(
            f'{mcap_file.path}: no finger has a {source.replace("auto", "pressure")} topic '
            f'(found {", ".join(sorted(t for k in fingers.values() for t in k.values()))})')
    return chosen


def replay_model(in_path, out_path, *, config=None, settings=None, source='auto',
                 rigidity=True, rigidity_period=0.0, stale_after_s=None, frame_prefix='',
                 copy_inputs=False, compression='zstd', overwrite=False, progress=None,
                 skip_undecodable=False):
    """
    Run the model node's finger pipeline over recorded inputs; write its outputs.

    The recorded ``finger_<i>/pressure`` (or ``pressure_command``) and
    ``finger_<i>/tip_force`` messages go, in log-time order, through the same
    :class:`~fpc_gripper.services.model_core.ModelCore` and finger model that
    ``model_node`` runs with the same settings: the same checks (non-finite, below
    vacuum, over the design or gripper limit, wrong frame, stale against the log time),
    the same gauge conversion (the configuration's atmospheric pressure, clipped at 0),
    the same warm starts and model choice. Every accepted input, once the finger has a
    pressure, is solved (replay has no rate limit), and each converged solve writes
    ``shape``, ``curvature`` and ``rigidity`` under the input's namespace, with the
    input's log time, the stamp the node would give it and the node's offered QoS. A
    recording of ``model_node`` with default settings therefore replays to the shapes it
    published.

    Parameters
    ----------
    in_path : str or os.PathLike
        Input recording: an MCAP file or a bag directory (see `Recording`).
    out_path : str or os.PathLike
        Output file (written to a temporary file, then moved into place).
    config : str or os.PathLike, optional
        Gripper configuration (default: the package's default configuration).
    settings : ModelSettings, optional
        Finger model settings (default: ``model_node``'s defaults).
    source : {'auto', 'pressure', 'pressure_command'}
        Which pressure topic to replay; ``auto`` prefers the measured ``pressure``.
    rigidity : bool
        Solve the rigidities (else the rigidity messages carry NaN).
    rigidity_period : float
        Reuse a finger's last rigidities for this long [s]; 0 solves for every new
        pressure.
    stale_after_s : float, optional
        Inputs whose header stamp is older than this against their log time are
        rejected [s], as ``model_node``'s parameter (default: its default); 0 disables.
    frame_prefix : str
        As ``model_node``'s parameter: tip forces must be in ``<frame_prefix>finger_<i>``,
        the frame the outputs carry.
    copy_inputs : bool
        Also copy the replayed input messages into the output.
    compression : {'zstd', 'lz4', 'none'}
        Chunk compression of the output.
    overwrite : bool
        Replace an existing `out_path`; otherwise it is refused.
    progress : callable, optional
        ``progress(done, total, final=False)``, called after each input message.

    Returns
    -------
    ReplayReport

    """
    from rclpy.serialization import serialize_message

    from ..model.pipeline import finger_model, ModelSettings
    from ..services.model_core import DEFAULT_STALE_AFTER_S, ModelCore

    settings = ModelSettings() if settings is None else settings
    stale_after_s = DEFAULT_STALE_AFTER_S if stale_after_s is None else stale_after_s
    if not (math.isfinite(rigidity_period) and rigidity_period >= 0.0):
        raise ValueError(f'`rigidity_period` must be >= 0 [s], got {rigidity_period}')
    gripper = _load_config(config)
    designs = {f.name: f.design for f in gripper.fingers}
    atmospheric = float(getattr(gripper, 'atmospheric_pressure', DEFAULT_ATMOSPHERIC_PRESSURE))
    report = ReplayReport()
    with Recording(in_path, skip_undecodable=skip_undecodable) as mcap_file:
        chosen = _select_inputs(mcap_file, source)
        unknown = sorted({name for _, name in chosen} - set(designs))
        if unknown:
            raise UnknownTopicError(
                f'{mcap_file.path}: finger(s) {", ".join(unknown)} not in the gripper '
                f'configuration (which has {", ".join(sorted(designs))})')
        by_topic = {}
        fingers = []
        for (prefix, name), (pressure_topic, force_topic) in chosen.items():
            finger = _Finger(len(fingers), prefix, name, pressure_topic, force_topic)
            fingers.append(finger)
            by_topic[pressure_topic] = finger
            if force_topic:
                by_topic[force_topic] = finger
        core = ModelCore([(f.name, designs[f.name]) for f in fingers],
                         lambda design: finger_model(design, settings),
                         max_pressure=gripper.max_pressure, atmospheric_pressure=atmospheric,
                         stale_after_s=stale_after_s, frame_prefix=frame_prefix)
        inputs = sorted(by_topic)
        mcap_file.check_decodable(inputs)
        total = sum(mcap_file.topics[t].message_count for t in inputs)
        report.fingers = [f.prefix + f.name for f in fingers]
        with atomic_mcap_writer(out_path, overwrite=overwrite, compression=compression,
                                library='fpc-mcap replay-model (mcap-python)') as writer:
            if copy_inputs:
                for topic in inputs:
                    schema = mcap_file.schema(topic)
                    writer.add_topic(
                        topic, schema.name, definition=schema.data.decode(),
                        offered_qos_profiles=mcap_file.topics[topic].offered_qos_profiles)
            for f in fingers:
                for kind, type_name in MODEL_OUTPUT_TYPES.items():
                    writer.add_topic(f.prefix + finger_topic(f.name, kind), type_name,
                                     offered_qos_profiles=[STATE_QOS])
            for msg in mcap_file.messages(topics=inputs):
                report.inputs += 1
                if copy_inputs:
                    writer.write(msg.topic, msg.data, msg.log_time, msg.publish_time)
                finger = by_topic[msg.topic]
                _replay_one(core, finger, msg, frame_prefix + finger.name,
                            float(rigidity_period) if rigidity else None, writer,
                            serialize_message, report)
                if progress is not None:
                    progress(report.inputs, total)
        if progress is not None:
            progress(report.inputs, total, final=True)
        report.clipped = sum(state.clamped for state in core.fingers)
        report.undecodable = mcap_file.undecodable
    report.outputs = dict(sorted(report.outputs.items()))
    return report


def _replay_one(core, finger, msg, frame, rigidity_period, writer, serialize, report):
    """Offer one input to the core, write what it answers in `frame`; no rigidity for None."""
    stamp = time_to_ns(msg.ros_msg.header.stamp)
    if msg.topic == finger.pressure_topic:
        kind = finger.pressure_topic.rsplit('/', 1)[-1]
        check = core.offer_pressure(finger.index, msg.ros_msg.fluid_pressure, stamp,
                                    msg.log_time, source=kind)
    else:
        force = msg.ros_msg.wrench.force
        check = core.offer_tip_force(finger.index, force.x, force.z,
                                     msg.ros_msg.header.frame_id, stamp, msg.log_time)
    if not check.accepted:
        report.rejected += 1
        return
    # Nothing before the finger's first pressure, as in the node.
    updates = core.process([finger.index], msg.log_time)
    if not updates:
        return
    (update,) = updates
    if update.result is None:
        report.failures += 1
        return
    report.solves += 1
    k = (None, None)
    if rigidity_period is not None:
        recent = (finger.last_rigidity is not None and rigidity_period > 0.0
                  and msg.log_time - finger.last_rigidity_time < rigidity_period * 1e9)
        if recent:
            k = finger.last_rigidity
        else:
            k = (core.rigidity(finger.index, 'x'), core.rigidity(finger.index, 'z'))
            finger.last_rigidity, finger.last_rigidity_time = k, msg.log_time
            report.rigidity_solves += 2
    outputs = {
        'shape': serialized_shape(update.result, frame, update.stamp_ns),
        'curvature': serialize(curvature_message(update.result)),
        'rigidity': serialize(rigidity_message(k[0], k[1], frame, update.stamp_ns)),
    }
    for kind, data in outputs.items():
        topic = finger.prefix + finger_topic(finger.name, kind)
        writer.write(topic, data, msg.log_time, update.stamp_ns)
        report.outputs[topic] = report.outputs.get(topic, 0) + 1


# -- command line -------------------------------------------------------------------------

def _times(text):
    try:
        values = [float(v) for v in text.replace(',', ' ').split()]
    except ValueError:
        raise argparse.ArgumentTypeError(f'--times must be numbers in seconds, got {text!r}')
    if not values or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f'--times must be finite seconds, got {text!r}')
    return values


def _size(text):
    match = re.fullmatch(r'(\d+)[xX](\d+)', text.strip())
    if not match:
        raise argparse.ArgumentTypeError(f'--size must be WIDTHxHEIGHT in pixels, got {text!r}')
    return int(match[1]), int(match[2])


def _model_settings(args):
    from ..model.pipeline import ModelSettings
    try:
        return ModelSettings(tolerance=args.tolerance, n_segments=args.segments,
                             pressure_model=args.pressure_model)
    except (TypeError, ValueError) as exc:
        raise McapInputError(str(exc)) from None


_IN_HELP = 'MCAP file, or rosbag2 bag directory (metadata.yaml and split .mcap files)'
_FORCE_HELP = 'replace the outputs of an earlier run'
_EXAMPLES = """\
examples, on the recordings in examples/recording/ (any recording of mcap_recorder or
`ros2 bag record -s mcap` alike):
  fpc-mcap info examples/recording/run.mcap
  fpc-mcap plot examples/recording/run.mcap plots/ --times 0,1.5,3
  fpc-mcap export-csv examples/recording/run.mcap csv/
  fpc-mcap replay-model examples/recording/run.mcap modelled.mcap
  fpc-mcap recover examples/recording/crashed.mcap fixed.mcap"""


def build_parser():
    """Build the argparse parser of ``fpc-mcap``."""
    parser = argparse.ArgumentParser(
        prog='fpc-mcap', formatter_class=argparse.RawDescriptionHelpFormatter,
        description='Inspect, plot, export, recover and replay fpc_gripper MCAP recordings '
                    '(rosbag2 form: profile ros2, cdr messages, ros2msg schemas).',
        epilog=_EXAMPLES)
    sub = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')

    p = sub.add_parser('info', help='topics, message counts, duration and rates',
                       description='Print the topics, message counts, exact start and end '
                                   'times [s], duration and rates of a recording.')
    p.add_argument('input', type=pathlib.Path, metavar='IN', help=_IN_HELP)
    p.add_argument('--json', action='store_true', help='print JSON instead of a table')

    p = sub.add_parser('plot', help='PNG plots of curvature, pressure and finger shapes',
                       description='Write curvature.png and pressure.png (against time from '
                                   'the first message) and shapes.png (finger shapes '
                                   'overlaid at --times) into OUTDIR.')
    p.add_argument('input', type=pathlib.Path, metavar='IN', help=_IN_HELP)
    p.add_argument('output', type=pathlib.Path, metavar='OUTDIR',
                   help='output directory (created if missing)')
    p.add_argument('--times', type=_times, default=None,
                   help='comma-separated shape times from the first message [s] '
                        '(default: five evenly spaced)')
    p.add_argument('--size', type=_size, default=(1280, 720),
                   help='image size WIDTHxHEIGHT [px] (default 1280x720)')
    p.add_argument('--dpi', type=int, default=100, help='resolution [px/inch] (default 100)')
    p.add_argument('--atmospheric-pressure', type=float, default=DEFAULT_ATMOSPHERIC_PRESSURE,
                   help='subtracted from absolute pressure readings [Pa] (default 101325)')
    p.add_argument('--force', action='store_true', help=_FORCE_HELP + ' in OUTDIR')

    p = sub.add_parser('export-csv', help='one CSV per topic',
                       description='Write one CSV per topic into OUTDIR: log and publish '
                                   'times [ns], then every field (arrays as JSON).')
    p.add_argument('input', type=pathlib.Path, metavar='IN', help=_IN_HELP)
    p.add_argument('output', type=pathlib.Path, metavar='OUTDIR',
                   help='output directory (created if missing)')
    p.add_argument('--topics', nargs='+', default=None, metavar='TOPIC',
                   help='topics to export (default: all)')
    p.add_argument('--force', action='store_true', help=_FORCE_HELP + ' in OUTDIR')

    p = sub.add_parser('recover', help='rebuild a truncated file (e.g. after kill -9)',
                       description='Copy every readable message of a truncated or damaged '
                                   'MCAP file, or of the split files of a bag directory, into '
                                   'one complete, indexed MCAP file.')
    p.add_argument('input', type=pathlib.Path, metavar='IN',
                   help='damaged MCAP file, or a bag directory (with or without metadata.yaml)')
    p.add_argument('output', type=pathlib.Path, metavar='OUT', help='recovered MCAP file')
    p.add_argument('--compression', choices=('zstd', 'lz4', 'none'), default='zstd',
                   help='chunk compression of OUT (default zstd)')
    p.add_argument('--force', action='store_true', help='replace OUT if it exists')

    p = sub.add_parser('replay-model', help="run model_node's finger model on recorded inputs",
                       description="Solve model_node's finger model (by default the adaptive "
                                   'model, the PCC rod model within 0.05 mm; --tolerance 0: '
                                   'the paper CCM) for every recorded finger_<i>/pressure '
                                   '(or pressure_command) and tip_force message, warm-started, '
                                   'and write finger_<i>/shape, curvature and rigidity to OUT.')
    p.add_argument('input', type=pathlib.Path, metavar='IN', help=_IN_HELP)
    p.add_argument('output', type=pathlib.Path, metavar='OUT', help='output MCAP file')
    p.add_argument('--config', type=pathlib.Path, default=None,
                   help='gripper configuration YAML (default: the package default)')
    from ..model import PRESSURE_MODEL_NAMES
    from ..model.pipeline import ModelSettings
    from ..services.model_core import DEFAULT_STALE_AFTER_S
    defaults = ModelSettings()
    p.add_argument('--tolerance', type=float, default=defaults.tolerance, metavar='M',
                   help='tip-position tolerance of the finger model against the rod [m], as '
                        f"model_node's parameter (default {defaults.tolerance:g}; 0: the "
                        'paper CCM with --segments)')
    p.add_argument('--segments', type=int, default=defaults.n_segments,
                   help=f'CCM segments with --tolerance 0 (default {defaults.n_segments})')
    p.add_argument('--pressure-model', choices=PRESSURE_MODEL_NAMES,
                   default=defaults.pressure_model,
                   help=f'pressure work model (default {defaults.pressure_model})')
    p.add_argument('--stale-after', type=float, default=DEFAULT_STALE_AFTER_S, metavar='S',
                   help='reject inputs whose stamp is older than S against their log time, '
                        f"as model_node's stale_after_s (default {DEFAULT_STALE_AFTER_S:g}; "
                        '0 disables)')
    p.add_argument('--frame-prefix', default='', metavar='PREFIX',
                   help="frame prefix, as model_node's frame_prefix: tip forces in "
                        'PREFIXfinger_<i>, outputs framed so (default none)')
    p.add_argument('--source', choices=('auto', 'pressure', 'pressure_command'),
                   default='auto', help='pressure topic to replay (default: measured '
                                        'pressure if recorded, else pressure_command)')
    p.add_argument('--no-rigidity', action='store_true',
                   help='skip the rigidity solves (rigidity messages carry NaN)')
    p.add_argument('--rigidity-period', type=float, default=0.0, metavar='S',
                   help='reuse the last K_x, K_z of a finger for S seconds of log time '
                        '(default 0: solve for every new pressure)')
    p.add_argument('--copy-inputs', action='store_true',
                   help='also copy the replayed input messages into OUT')
    p.add_argument('--compression', choices=('zstd', 'lz4', 'none'), default='zstd',
                   help='chunk compression of OUT (default zstd)')
    p.add_argument('--force', action='store_true', help='replace OUT if it exists')
    p.add_argument('--quiet', action='store_true', help='no progress on stderr')
    for sub_parser in [parser, *sub.choices.values()]:
        add_version(sub_parser)
    return parser


def _run(args, out, err):
    skipped = []
    if args.command in ('recover', 'replay-model') and args.output.exists() and not args.force:
        raise InputError(f'{args.output}: exists; pass --force to replace it')
    if args.command == 'info':
        with Recording(args.input) as f:
            info = file_info(f)
        if args.json:
            print(json.dumps(info, indent=2), file=out)
        else:
            _print_info(info, out)
    elif args.command == 'plot':
        from .plots import make_plots
        target = OutputDir(args.output, args.force, 'OUTDIR')
        with Recording(args.input, skip_undecodable=True) as f, target, \
                Progress(1, 'recording', 'fpc-mcap plot', stream=err):
            written = make_plots(f, target.tmp, times=args.times, size=args.size,
                                 dpi=args.dpi, atmospheric_pressure=args.atmospheric_pressure)
            target.commit()
            skipped = f.undecodable
        for path in written:
            print(target.final(path), file=out)
    elif args.command == 'export-csv':
        target = OutputDir(args.output, args.force, 'OUTDIR')
        with Recording(args.input, skip_undecodable=True) as f, target, \
                Progress(1, 'recording', 'fpc-mcap export-csv', stream=err):
            written = export_csv(f, target.tmp, topics=args.topics)
            target.commit()
            skipped = f.undecodable
        for path in written.values():
            print(target.final(path), file=out)
    elif args.command == 'recover':
        with Progress(1, 'recording', 'fpc-mcap recover', stream=err):
            report = recover(args.input, args.output, compression=args.compression,
                             overwrite=args.force)
        if not report.complete:
            state = f'cut off or damaged ({report.dropped_bytes} bytes unreadable)'
        elif report.indexed_chunks:
            state = f'damaged ({report.indexed_chunks} chunks read through its index)'
        else:
            state = 'complete'
        lost = f'{report.lost_messages} messages lost' + (
            f', and those of {report.uncounted_chunks} chunks without a readable message index'
            if report.uncounted_chunks else '')
        print(f'recovered {report.messages} messages from {report.chunks} chunks of '
              f'{report.files} file{"s" * (report.files != 1)}; input was {state}; '
              f'{report.corrupt_chunks} damaged chunks skipped ({lost}), '
              f'{report.skipped_messages} messages without schema skipped -> {args.output}',
              file=out)
    elif args.command == 'replay-model':
        settings = _model_settings(args)
        with Progress(0, 'input', 'fpc-mcap replay-model', show=not args.quiet,
                      stream=err) as progress:
            report = replay_model(args.input, args.output, config=args.config,
                                  settings=settings, source=args.source,
                                  rigidity=not args.no_rigidity,
                                  rigidity_period=args.rigidity_period,
                                  stale_after_s=args.stale_after,
                                  frame_prefix=args.frame_prefix,
                                  copy_inputs=args.copy_inputs, compression=args.compression,
                                  overwrite=args.force, progress=progress,
                                  skip_undecodable=True)
        skipped = report.undecodable
        print(f'replayed {report.inputs} inputs of {", ".join(report.fingers)}: '
              f'{report.solves} solves, {report.failures} not converged, '
              f'{report.rejected} rejected, {report.clipped} below atmospheric '
              f'-> {args.output}', file=out)
    return _report_skipped(args.command, skipped, err)


#: Undecodable messages named one by one on stderr; the rest are counted.
_NAMED_SKIPS = 20


def _report_skipped(command, skipped, err):
    """Name the messages a command skipped as undecodable; its exit code (0, or 3)."""
    # EXIT_SKIPPED: the job was done, but not on every input message.
    if not skipped:
        return 0
    print(f'fpc-mcap {command}: warning: skipped {len(skipped)} undecodable '
          f'message{"s" * (len(skipped) != 1)}, every other one was read:', file=err)
    for bad in skipped[:_NAMED_SKIPS]:
        print(f'  {bad}', file=err)
    if len(skipped) > _NAMED_SKIPS:
        print(f'  ... and {len(skipped) - _NAMED_SKIPS} more', file=err)
    return EXIT_SKIPPED


def main(argv=None):
    """
    Run ``fpc-mcap``.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        The exit status of `fpc_gripper.tools.EXIT_CODES`: 2 for a missing, empty,
        damaged or wrong input (one line names it) and for bad values, 3 when ``plot``,
        ``export-csv`` or ``replay-model`` finished but skipped messages whose payload
        could not be decoded (each named on stderr, by topic and log time).

    """
    def prepare(args):
        return lambda: _run(args, sys.stdout, sys.stderr)
    return run(build_parser(), prepare, argv,
               input_errors=(McapInputError, SchemaNotFoundError, ValueError, TypeError))


if __name__ == '__main__':
    sys.exit(main())
