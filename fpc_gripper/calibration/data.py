"""Measurements of a finger: CSV and MCAP readers whose errors name the file and the row."""

import csv
from dataclasses import dataclass
import math
import pathlib

import numpy as np

from fpc_gripper.model.validation import STANDARD_ATMOSPHERE

__all__ = ['DataError', 'MarkerData', 'LoadingData', 'TensileData', 'read_markers',
           'read_loading', 'read_tensile', 'read_markers_mcap', 'MARKER_COLUMNS',
           'LOADING_COLUMNS', 'TENSILE_COLUMNS']

#: Required and optional columns of markers.csv.
MARKER_COLUMNS = ('pressure_pa', 'marker', 's_m', 'x_m', 'z_m')
MARKER_FORCE_COLUMNS = ('tip_force_x_n', 'tip_force_z_n')
LOADING_COLUMNS = ('pressure_pa', 'axis', 'displacement_m', 'force_n')
TENSILE_COLUMNS = ('strain', 'stress_pa')
#: Fewest tensile samples: the PEMC law has four coefficients.
_MIN_TENSILE = 4


class DataError(ValueError):
    """Measurement data that cannot be used; the message names the file and the row."""


@dataclass(frozen=True)
class MarkerData:
    """
    Marker positions in the motion-capture frame, grouped into shapes (frames).

    Attributes
    ----------
    pressure : ndarray, shape (F,)
        Gauge pressure of every frame [Pa].
    tip_force : ndarray, shape (F, 2)
        Tip force (f0, p0) of every frame [N].
    frame : ndarray of int, shape (K,)
        Frame of every marker observation.
    marker : tuple of str, shape (K,)
        Marker label of every observation.
    s : ndarray, shape (K,)
        Reference arc length of the marker from the clamp edge [m].
    xz : ndarray, shape (K, 2)
        Measured (x, z) in the motion-capture frame [m].
    rows : tuple of str, shape (K,)
        Where each observation came from (file and line, or message).
    source : str
        The file.

    """

    pressure: np.ndarray
    tip_force: np.ndarray
    frame: np.ndarray
    marker: tuple
    s: np.ndarray
    xz: np.ndarray
    rows: tuple
    source: str

    def check(self, design):
        """Raise DataError naming the row of any pressure or arc length the design refuses."""
        length = design.free_length
        for k in range(self.s.size):
            pressure = self.pressure[self.frame[k]]
            _limit(pressure, design, self.rows[k])
            if not 0.0 <= self.s[k] <= length:
                raise DataError(f'{self.rows[k]}: s_m = {float(self.s[k])!r} lies outside '
                                f'the free length [0, {length:g}] m of the design')


@dataclass(frozen=True)
class LoadingData:
    """
    Loading tests: the tip force that moves the tip by a displacement along X or Z.

    Attributes
    ----------
    pressure : ndarray, shape (L,)
        Gauge pressure [Pa].
    axis : tuple of str
        'x' or 'z' of every test.
    displacement : ndarray, shape (L,)
        Imposed tip displacement delta > 0 [m].
    force : ndarray, shape (L,)
        Measured force along the axis [N].
    rows : tuple of str
    source : str

    """

    pressure: np.ndarray
    axis: tuple
    displacement: np.ndarray
    force: np.ndarray
    rows: tuple
    source: str

    def check(self, design):
        """Raise DataError naming the row of any pressure above the design limit."""
        for pressure, row in zip(self.pressure, self.rows):
            _limit(pressure, design, row)


@dataclass(frozen=True)
class TensileData:
    """
    Tensile test of the EMC: stress against the mechanical strain of the PEMC law.

    Attributes
    ----------
    strain : ndarray, shape (T,)
        [-].
    stress : ndarray, shape (T,)
        [Pa].
    rows : tuple of str
    source : str

    """

    strain: np.ndarray
    stress: np.ndarray
    rows: tuple
    source: str

    def check(self, design):
        """Nothing in a tensile test depends on the design."""


def _limit(pressure, design, row):
    if pressure > design.max_pressure:
        raise DataError(f'{row}: pressure {pressure:g} Pa is above the design limit '
                        f'max_pressure = {design.max_pressure:g} Pa')


def _rows(path, required, optional=()):
    """Yield (line number, {column: text}) of a CSV file with a header; check the columns."""
    path = pathlib.Path(path)
    try:
        handle = open(path, newline='')
    except OSError as exc:
        raise DataError(f'{path}: cannot read: {exc.strerror or exc}') from None
    with handle:
        reader = csv.reader(handle, skipinitialspace=True)
        try:
            header = next(reader, None)
            if header is None:
                raise DataError(f'{path}: empty file; expected a header row with the columns '
                                f'{", ".join(required)}')
            header = [name.strip() for name in header]
            missing = [name for name in required if name not in header]
            if missing:
                raise DataError(f'{path}, line 1: missing column(s) {", ".join(missing)}; the '
                                f'header has {", ".join(header) or "nothing"}')
            if len(set(header)) != len(header):
                raise DataError(f'{path}, line 1: repeated column names in {header}')
            present = [name for name in optional if name in header]
            if present and len(present) != len(optional):
                raise DataError(f'{path}, line 1: columns {", ".join(optional)} go together; '
                                f'only {", ".join(present)} given')
            for row in reader:
                if not row or all(not cell.strip() for cell in row):
                    continue
                where = f'{path}, line {reader.line_num}'
                if len(row) != len(header):
                    raise DataError(f'{where}: {len(row)} values for the {len(header)} '
                                    'columns of the header')
                yield where, dict(zip(header, (cell.strip() for cell in row)))
        except csv.Error as exc:
            raise DataError(f'{path}, line {reader.line_num}: malformed CSV ({exc})') from None
        except UnicodeDecodeError:
            raise DataError(f'{path}: not a text (UTF-8) CSV file') from None


def _number(where, row, column, unit):
    text = row[column]
    try:
        value = float(text)
    except ValueError:
        raise DataError(f'{where}: column {column} must be a number {unit}, got '
                        f'{text!r}') from None
    if not math.isfinite(value):
        raise DataError(f'{where}: column {column} must be finite {unit}, got {text!r}')
    return value


def _gauge(where, row):
    value = _number(where, row, 'pressure_pa', '[Pa]')
    if value < 0.0:
        raise DataError(f'{where}: pressure_pa must be a gauge pressure >= 0 [Pa], got {value:g}')
    return value


def _sort_key(label):
    """Marker labels in their natural order: numbers by value, then text."""
    try:
        return (0, float(label), label)
    except ValueError:
        return (1, 0.0, label)


def _check_order(frame):
    """Raise naming the row where s_m does not increase with the marker label in a frame."""
    ordered = sorted(frame['labels'].items(), key=lambda item: _sort_key(item[0]))
    for (before, (s0, _)), (label, (s1, where)) in zip(ordered, ordered[1:]):
        if not s1 > s0:
            raise DataError(f'{where}: marker order is not monotonic in s_m: marker {label} '
                            f'has s_m = {s1!r}, not above the {s0!r} of marker {before}')


def read_markers(path, design=None):
    """
    Read markers.csv: marker positions of the finger in the motion-capture frame.

    Columns (a header row, SI units): ``pressure_pa`` (gauge), ``marker`` (a label,
    numbered from the root), ``s_m`` (the marker's reference arc length along the free
    length from the clamp edge), ``x_m``, ``z_m`` (motion-capture frame), and optionally
    ``tip_force_x_n``, ``tip_force_z_n`` together. Consecutive rows with the same pressure
    and tip force form one shape (a frame); a marker label seen again starts the next one.
    Within a frame, s_m must increase with the marker label (numeric labels by value), and
    a marker keeps its s_m in every frame.

    Parameters
    ----------
    path : str or path-like
    design : ActuatorDesign, optional
        When given, also refuse pressures above `max_pressure` and s_m outside [0, L].

    Returns
    -------
    MarkerData

    Raises
    ------
    DataError
        Naming the file and the line: missing columns, a value that is not a finite
        number, a negative pressure or s_m, an order not monotonic in s_m, a marker whose
        s_m changes, or (with `design`) a pressure above the design limit.

    """
    forces = False
    frames, frame_of, labels, s, xz, where_all = [], [], [], [], [], []
    seen = {}
    current = None
    for where, row in _rows(path, MARKER_COLUMNS, MARKER_FORCE_COLUMNS):
        forces = forces or MARKER_FORCE_COLUMNS[0] in row
        pressure = _gauge(where, row)
        force = tuple(_number(where, row, c, '[N]') for c in MARKER_FORCE_COLUMNS) \
            if MARKER_FORCE_COLUMNS[0] in row else (0.0, 0.0)
        label = row['marker']
        if not label:
            raise DataError(f'{where}: column marker is empty')
        arc = _number(where, row, 's_m', '[m]')
        if arc < 0.0:
            raise DataError(f'{where}: s_m must be >= 0 [m], got {arc:g}')
        point = (_number(where, row, 'x_m', '[m]'), _number(where, row, 'z_m', '[m]'))
        if current is None or current['key'] != (pressure, force) or label in current['labels']:
            if current is not None:
                _check_order(current)
            current = {'key': (pressure, force), 'labels': {}}
            frames.append(current)
        current['labels'][label] = (arc, where)
        if label in seen and seen[label][0] != arc:
            raise DataError(f'{where}: marker {label} has s_m = {arc!r} here but '
                            f'{seen[label][0]!r} at {seen[label][1].rsplit(", ", 1)[-1]}')
        seen.setdefault(label, (arc, where))
        frame_of.append(len(frames) - 1)
        labels.append(label)
        s.append(arc)
        xz.append(point)
        where_all.append(where)
    if not frames:
        raise DataError(f'{path}: no marker rows after the header')
    _check_order(current)
    data = MarkerData(
        pressure=np.array([f['key'][0] for f in frames]),
        tip_force=np.array([f['key'][1] for f in frames], dtype=float).reshape(-1, 2),
        frame=np.array(frame_of, dtype=np.int64), marker=tuple(labels), s=np.array(s),
        xz=np.array(xz, dtype=float).reshape(-1, 2), rows=tuple(where_all),
        source=str(path))
    if design is not None:
        data.check(design)
    return data


def read_loading(path, design=None):
    """
    Read loading.csv: the paper's loading tests (Section VI-B).

    Columns: ``pressure_pa`` (gauge), ``axis`` (``x`` or ``z``: the direction of the tip
    load and displacement), ``displacement_m`` (delta > 0 from the unloaded tip, 0.010 in
    the paper's protocol) and ``force_n`` (the measured force along the axis).

    Parameters
    ----------
    path : str or path-like
    design : ActuatorDesign, optional
        When given, also refuse pressures above `max_pressure`.

    Returns
    -------
    LoadingData

    Raises
    ------
    DataError
        Naming the file and the line.

    """
    pressure, axis, displacement, force, rows = [], [], [], [], []
    for where, row in _rows(path, LOADING_COLUMNS):
        pressure.append(_gauge(where, row))
        name = row['axis'].lower()
        if name not in ('x', 'z'):
            raise DataError(f"{where}: column axis must be 'x' or 'z', got {row['axis']!r}")
        axis.append(name)
        delta = _number(where, row, 'displacement_m', '[m]')
        if delta <= 0.0:
            raise DataError(f'{where}: displacement_m must be > 0 [m], got {delta:g}')
        displacement.append(delta)
        force.append(_number(where, row, 'force_n', '[N]'))
        rows.append(where)
    if not rows:
        raise DataError(f'{path}: no loading rows after the header')
    data = LoadingData(np.array(pressure), tuple(axis), np.array(displacement), np.array(force),
                       tuple(rows), str(path))
    if design is not None:
        data.check(design)
    return data


def read_tensile(path, design=None):
    """
    Read tensile.csv: the EMC's tensile test, ``strain`` [-] and ``stress_pa`` [Pa].

    Parameters
    ----------
    path : str or path-like
    design : ActuatorDesign, optional
        Unused (the test does not depend on the design); accepted for symmetry.

    Returns
    -------
    TensileData

    Raises
    ------
    DataError
        Naming the file and the line; also with fewer than four rows.

    """
    strain, stress, rows = [], [], []
    for where, row in _rows(path, TENSILE_COLUMNS):
        strain.append(_number(where, row, 'strain', '[-]'))
        stress.append(_number(where, row, 'stress_pa', '[Pa]'))
        rows.append(where)
    if len(rows) < _MIN_TENSILE:
        raise DataError(f'{path}: {len(rows)} tensile rows; the PEMC law has four '
                        f'coefficients, so at least {_MIN_TENSILE} are needed')
    return TensileData(np.array(strain), np.array(stress), tuple(rows), str(path))


def read_markers_mcap(path, marker_s, markers_topic, pressure_topic, design=None,
                      atmospheric_pressure=STANDARD_ATMOSPHERE, pressure_tolerance=1.0e3,
                      min_samples=5):
    """
    Read marker frames from an MCAP recording (rosbag2 profile, CDR).

    `markers_topic` carries geometry_msgs/PoseArray messages: one pose per marker, root
    to tip, the (x, z) of each position in the motion-capture frame. `pressure_topic`
    carries sensor_msgs/FluidPressure (absolute [Pa]). Each PoseArray takes the last
    pressure logged at or before it. Consecutive PoseArrays whose gauge pressure stays
    within `pressure_tolerance` of their run's first form a hold; a hold of at least
    `min_samples` messages becomes one frame with the mean positions and pressure (shorter
    runs, pressure ramps, are not quasi-static and are dropped). Tip forces are zero.

    Parameters
    ----------
    path : str or path-like
        The .mcap file.
    marker_s : sequence of float
        Reference arc length of every marker from the clamp edge, in PoseArray order [m].
    markers_topic, pressure_topic : str
    design : ActuatorDesign, optional
        When given, refuse pressures above its limit and s outside [0, L].
    atmospheric_pressure : float
        Gauge = absolute - atmospheric [Pa].
    pressure_tolerance : float
        Width of a hold [Pa].
    min_samples : int
        Fewest messages of a hold.

    Returns
    -------
    MarkerData

    Raises
    ------
    DataError
        Naming the file and the message (its log time), or the topics.

    """
    from ..io.mcap_reader import McapFile, McapInputError

    marker_s = np.asarray(marker_s, dtype=float).ravel()
    if marker_s.size < 1 or not np.all(np.isfinite(marker_s)) or np.any(np.diff(marker_s) <= 0):
        raise DataError(f'`marker_s` must be finite arc lengths increasing root to tip [m], '
                        f'got {marker_s.tolist()}')
    samples, pressure = [], None
    try:
        with McapFile(path) as bag:
            for message in bag.messages([markers_topic, pressure_topic]):
                where = f'{path}, {message.topic} message at log time {message.log_time} ns'
                if message.topic == pressure_topic:
                    value = float(message.ros_msg.fluid_pressure)
                    if not math.isfinite(value):
                        raise DataError(f'{where}: fluid_pressure is not finite')
                    pressure = max(value - atmospheric_pressure, 0.0)
                    continue
                poses = message.ros_msg.poses
                if len(poses) != marker_s.size:
                    raise DataError(f'{where}: {len(poses)} poses for the {marker_s.size} '
                                    'markers of `marker_s`')
                xz = np.array([(p.position.x, p.position.z) for p in poses], dtype=float)
                if not np.all(np.isfinite(xz)):
                    raise DataError(f'{where}: a marker position is not finite')
                if pressure is not None:
                    samples.append((where, pressure, xz))
    except McapInputError as exc:
        raise DataError(str(exc)) from None
    holds, run = [], []
    for sample in samples + [None]:
        if sample is not None and run and abs(sample[1] - run[0][1]) <= pressure_tolerance:
            run.append(sample)
            continue
        if len(run) >= min_samples:
            holds.append(run)
        run = [sample] if sample is not None else []
    if not holds:
        raise DataError(f'{path}: no hold of at least {min_samples} {markers_topic} messages '
                        f'within {pressure_tolerance:g} Pa on {pressure_topic} '
                        f'({len(samples)} marker messages with a pressure before them)')
    count = marker_s.size
    data = MarkerData(
        pressure=np.array([np.mean([p for _, p, _ in run]) for run in holds]),
        tip_force=np.zeros((len(holds), 2)),
        frame=np.repeat(np.arange(len(holds)), count),
        marker=tuple(str(k) for _ in holds for k in range(count)),
        s=np.tile(marker_s, len(holds)),
        xz=np.concatenate([np.mean([xz for _, _, xz in run], axis=0) for run in holds]),
        rows=tuple(f'{run[0][0]} (hold of {len(run)})' for run in holds for _ in range(count)),
        source=str(path))
    if design is not None:
        data.check(design)
    return data
