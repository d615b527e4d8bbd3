"""PNG plots of recorded gripper topics: curvature and pressure against time, finger shapes."""

import re

import numpy as np

from .mcap_reader import McapInputError, UnknownTopicError
from .mcap_writer import atomic_output
from .messages import DEFAULT_ATMOSPHERIC_PRESSURE

__all__ = ['PlotSeries', 'extract_series', 'make_plots']

_FINGER_TOPIC = re.compile(r'^(?P<ns>(?:.*/)?)(?P<finger>finger_\d+)/'
                           r'(?P<kind>curvature|pressure|pressure_command|shape)$')


class PlotSeries:
    """
    Time series of the plotted topics, by finger.

    Attributes
    ----------
    start : int
        Log time that is t = 0 [ns].
    curvature : dict
        Finger to (t [s], kappa [1/m]) arrays.
    pressure : dict
        (finger, topic kind) to (t [s], gauge pressure [Pa]) arrays.
    shapes : dict
        Finger to (t [s] array, list of (M, 2) point arrays [m]).

    """

    def __init__(self, start):
        self.start = int(start)
        self.curvature = {}
        self.pressure = {}
        self.shapes = {}


def _label(ns, finger):
    return f'{ns}{finger}' if ns not in ('', '/') else finger


def extract_series(mcap_file, atmospheric_pressure=DEFAULT_ATMOSPHERIC_PRESSURE):
    """
    Read curvature, pressure and shape topics of every finger from an open file.

    Parameters
    ----------
    mcap_file : McapFile
        The recording.
    atmospheric_pressure : float
        Subtracted from the absolute FluidPressure readings [Pa].

    Returns
    -------
    PlotSeries

    """
    wanted = {}
    for topic in mcap_file.topics:
        match = _FINGER_TOPIC.match(topic)
        if match:
            wanted[topic] = (_label(match['ns'], match['finger']), match['kind'])
    series = PlotSeries(mcap_file.start_time)
    if not wanted:
        return series
    raw = {}
    for msg in mcap_file.messages(topics=sorted(wanted)):
        finger, kind = wanted[msg.topic]
        t = (msg.log_time - series.start) * 1e-9
        if kind == 'curvature':
            value = float(msg.ros_msg.data)
        elif kind == 'shape':
            value = np.array([(p.pose.position.x, p.pose.position.z)
                              for p in msg.ros_msg.poses], dtype=float).reshape(-1, 2)
        else:
            value = float(msg.ros_msg.fluid_pressure) - atmospheric_pressure
        raw.setdefault((finger, kind), ([], []))
        raw[(finger, kind)][0].append(t)
        raw[(finger, kind)][1].append(value)
    for (finger, kind), (times, values) in sorted(raw.items()):
        times = np.asarray(times)
        if kind == 'curvature':
            series.curvature[finger] = (times, np.asarray(values))
        elif kind == 'shape':
            series.shapes[finger] = (times, values)
        else:
            series.pressure[(finger, kind)] = (times, np.asarray(values))
    return series


def _figure(size, dpi):
    import matplotlib
    matplotlib.use('Agg', force=True)
    from matplotlib.figure import Figure
    width, height = size
    return Figure(figsize=(width / dpi, height / dpi), dpi=dpi)


def _save(fig, path, dpi):
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format='png')
    return path


def _plot_curvature(series, path, size, dpi):
    fig = _figure(size, dpi)
    ax = fig.add_subplot()
    for finger, (t, k) in series.curvature.items():
        ax.plot(t, k, label=finger)
    ax.set_xlabel('time [s]')
    ax.set_ylabel('curvature [1/m]')
    ax.set_title('Finger curvature')
    ax.grid(True, alpha=0.3)
    ax.legend(loc='best')
    fig.tight_layout()
    return _save(fig, path, dpi)


def _plot_pressure(series, path, size, dpi):
    fig = _figure(size, dpi)
    ax = fig.add_subplot()
    for (finger, kind), (t, p) in series.pressure.items():
        style = '--' if kind == 'pressure_command' else '-'
        ax.plot(t, p * 1e-3, style, label=f'{finger} {kind}')
    ax.set_xlabel('time [s]')
    ax.set_ylabel('gauge pressure [kPa]')
    ax.set_title('Finger pressure')
    ax.grid(True, alpha=0.3)
    ax.legend(loc='best')
    fig.tight_layout()
    return _save(fig, path, dpi)


def _shape_at(times, shapes, t):
    index = int(np.searchsorted(times, t, side='right')) - 1
    return shapes[max(index, 0)], times[max(index, 0)]


def _plot_shapes(series, times, path, size, dpi):
    import matplotlib
    fig = _figure(size, dpi)
    fingers = list(series.shapes)
    axes = fig.subplots(1, len(fingers), squeeze=False)[0]
    cmap = matplotlib.colormaps['viridis']
    for ax, finger in zip(axes, fingers):
        stamps, shapes = series.shapes[finger]
        for i, t in enumerate(times):
            points, t_msg = _shape_at(stamps, shapes, t)
            color = cmap(i / max(len(times) - 1, 1))
            ax.plot(points[:, 0] * 1e3, points[:, 1] * 1e3, color=color,
                    label=f't = {t:.2f} s (msg {t_msg:.2f} s)')
        ax.set_aspect('equal', adjustable='datalim')
        ax.set_xlabel('X [mm]')
        ax.set_ylabel('Z [mm]')
        ax.set_title(f'{finger} shape')
        ax.grid(True, alpha=0.3)
        ax.legend(loc='best', fontsize='small')
    fig.tight_layout()
    return _save(fig, path, dpi)


def make_plots(mcap_file, out_dir, times=None, size=(1280, 720), dpi=100,
               atmospheric_pressure=DEFAULT_ATMOSPHERIC_PRESSURE):
    """
    Write ``curvature.png``, ``pressure.png`` and ``shapes.png`` for a recording.

    A plot whose topics are absent is not written. Each PNG is written to a temporary file
    and moved into place, so a failure leaves earlier files as they were.

    Parameters
    ----------
    mcap_file : McapFile
        The recording.
    out_dir : pathlib.Path
        Existing output directory.
    times : sequence of float, optional
        Times of the overlaid shapes, from the first message [s]; five evenly spaced times
        over the shape messages when omitted.
    size : (int, int)
        Image width and height [px].
    dpi : int
        Resolution [px/inch].
    atmospheric_pressure : float
        For gauge pressure [Pa].

    Returns
    -------
    list of pathlib.Path
        The files written.

    Raises
    ------
    UnknownTopicError
        If the file has none of the plotted topics, or `times` is given without shapes.
    McapInputError
        If a time is outside the recording.

    """
    width, height = (int(v) for v in size)
    if width < 100 or height < 100:
        raise ValueError(f'`size` must be at least 100x100 [px], got {width}x{height}')
    series = extract_series(mcap_file, atmospheric_pressure)
    if not (series.curvature or series.pressure or series.shapes):
        raise UnknownTopicError(
            f'{mcap_file.path}: no finger_<i>/curvature, pressure, pressure_command or shape '
            f'topics to plot; the file has {", ".join(sorted(mcap_file.topics)) or "none"}')
    if times is not None and not series.shapes:
        raise UnknownTopicError(f'{mcap_file.path}: --times needs finger_<i>/shape topics')
    if series.shapes:
        first = min(s[0][0] for s in series.shapes.values())
        last = max(s[0][-1] for s in series.shapes.values())
        if times is None:
            times = list(np.linspace(first, last, 5)) if last > first else [first]
        duration = (mcap_file.end_time - mcap_file.start_time) * 1e-9
        bad = [t for t in times if t < 0.0 or t > duration + 1e-9]
        if bad:
            raise McapInputError(
                f'--times {", ".join(f"{t:g}" for t in bad)} s outside the recording '
                f'(0 to {duration:.3f} s)')
    written = []
    if series.curvature:
        written.append(_plot_curvature(series, out_dir / 'curvature.png', (width, height),
                                       dpi))
    if series.pressure:
        written.append(_plot_pressure(series, out_dir / 'pressure.png', (width, height), dpi))
    if series.shapes:
        written.append(_plot_shapes(series, list(times), out_dir / 'shapes.png',
                                    (width, height), dpi))
    return written
