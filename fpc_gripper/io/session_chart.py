"""The scripted session's chart: aperture, pressures, curvatures, contact forces from its MCAP."""

import math

from fpc_gripper.model.validation import STANDARD_ATMOSPHERE

__all__ = ['make_chart', 'message_count']


def message_count(path):
    """Message count of a closed MCAP file (0 if it cannot be read)."""
    from fpc_gripper.io.mcap_reader import McapFile
    try:
        with McapFile(path) as mcap:
            return mcap.message_count
    except Exception:  # noqa: BLE001 - reported as 0 messages in the summary
        return 0


def _series(mcap_path, atmospheric):
    """Read the charted topics from the recording: dict of name -> (t [s], values)."""
    from fpc_gripper.io.mcap_reader import McapFile
    data = {}
    start = None
    with McapFile(mcap_path) as mcap:
        wanted = [t for t in mcap.topics if t.endswith(
            ('/pressure', '/pressure_command', '/curvature', '/tip_force', '/aperture'))]
        for rec in mcap.messages(topics=wanted):
            start = rec.log_time if start is None else start
            msg = rec.ros_msg
            if rec.topic.endswith('/tip_force'):
                value = math.hypot(msg.wrench.force.x, msg.wrench.force.z)
            elif rec.topic.endswith(('/pressure', '/pressure_command')):
                value = (msg.fluid_pressure - atmospheric) * 1e-3
            else:
                value = msg.data
            t, v = data.setdefault(rec.topic, ([], []))
            t.append(rec.log_time * 1e-9)
            v.append(value)
    return data


def make_chart(mcap_path, png_path, phases, grasp_force, atmospheric=STANDARD_ATMOSPHERE):
    """
    Chart aperture, pressures, curvatures and contact forces against time from the MCAP.

    Parameters
    ----------
    mcap_path : path-like
        The session recording.
    png_path : path-like
        The chart to write.
    phases : list of Phase
        Drawn as shaded spans.
    grasp_force : float
        Total normal force goal [N]; its share per finger is drawn as a reference line.
    atmospheric : float
        Subtracted from the absolute pressures [Pa].

    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    data = _series(mcap_path, atmospheric)
    t0 = min((t[0] for t, _ in data.values() if t), default=0.0)
    fig, axes = plt.subplots(4, 1, figsize=(11, 11), sharex=True)
    rows = [('/aperture', 'aperture [mm]', 1e3), ('pressure', 'pressure [kPa gauge]', 1.0),
            ('/curvature', 'curvature [1/m]', 1.0), ('/tip_force', 'contact force |F| [N]', 1.0)]
    for ax, (suffix, label, scale) in zip(axes, rows):
        for topic in sorted(data):
            t, v = data[topic]
            if suffix == 'pressure':
                if not topic.endswith(('/pressure', '/pressure_command')):
                    continue
                style = '--' if topic.endswith('command') else '-'
                name = topic.strip('/').replace('/pressure_command', ' command').replace(
                    '/pressure', ' measured')
                ax.plot([x - t0 for x in t], v, style, lw=1.0, label=name)
            elif topic.endswith(suffix):
                ax.plot([x - t0 for x in t], [x * scale for x in v], lw=1.2,
                        label=topic.strip('/').split('/')[0] if suffix != '/aperture'
                        else 'model estimate')
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    share = grasp_force / max(1, sum(t.endswith('/tip_force') for t in data))
    axes[3].axhline(share, color='k', ls=':', lw=1, label=f'goal per finger {share:.3g} N')
    for phase in phases:
        if math.isfinite(phase.start):
            end = phase.end if math.isfinite(phase.end) else phase.start
            for ax in axes:
                ax.axvspan(phase.start - t0, end - t0, alpha=0.06,
                           color='tab:green' if phase.reached else 'tab:red')
            axes[0].text(phase.start - t0, axes[0].get_ylim()[1], f' {phase.name}',
                         va='top', fontsize=9)
            if phase.kind == 'aperture':
                axes[0].hlines(phase.value * 1e3, phase.start - t0, end - t0, colors='k',
                               linestyles=':', lw=1)
    for ax in axes:
        ax.legend(fontsize=7, ncol=3, loc='upper right')
    axes[-1].set_xlabel('time [s]')
    fig.suptitle('fpc_gripper scripted session (simulated regulator, virtual object)')
    fig.tight_layout()
    fig.savefig(png_path, dpi=90)
    plt.close(fig)
