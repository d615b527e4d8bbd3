"""The MCAP recorder's parameters without ROS: their table, and the recording they open."""

import time

from .background_writer import BackgroundWriter
from .mcap_writer import COMPRESSIONS
from .mcap_writer import Rosbag2McapWriter
from .messages import gripper_topics

__all__ = ['DEFAULT_FINGERS', 'LIBRARY', 'PARAMETERS', 'apply_settings', 'compression_refusal',
           'default_topics', 'open_recording']

#: Fingers recorded when the gripper config cannot be read.
DEFAULT_FINGERS = ('finger_0', 'finger_1', 'finger_2')
#: The writing library, as the MCAP header names it.
LIBRARY = 'fpc_gripper mcap_recorder (mcap-python)'
_MIB = 1024 * 1024
_POSITIVE = (0.001, 3600.0)
_NON_NEGATIVE = (0.0, 1.0e9)

#: ``(name, default, description, descriptor fields)`` of every parameter, ranges as
#: ``(low, high)``.
PARAMETERS = (
    ('output_path', '', 'MCAP file (*.mcap), or a directory for split files (default: '
     'fpc_gripper_<date>.mcap in the working directory)', {'read_only': True}),
    ('topics', [''], 'Topics to record, relative to the node namespace; empty for every '
     'fpc_gripper input and output of the configured fingers', {'read_only': True}),
    ('flush_period_s', 1.0, 'Longest time a received message waits before it is on disk in a '
     'completed chunk [s]', {'floating_point_range': _POSITIVE}),
    ('max_file_size_mb', 0.0, 'Split to a new file at this size [MiB]; 0 never splits',
     {'floating_point_range': _NON_NEGATIVE}),
    ('max_duration_s', 0.0, 'Split to a new file after this much recording time [s]; 0 never',
     {'floating_point_range': _NON_NEGATIVE}),
    ('compression', 'zstd', 'Chunk compression: zstd, lz4 or none', {'read_only': True}),
    ('discovery_period_s', 0.5, 'Period of the search for publishers of topics not yet '
     'recorded [s]', {'floating_point_range': _POSITIVE, 'read_only': True}),
    ('gripper_config', '', 'Gripper configuration YAML whose fingers give the default topics '
     '(default: the package default)', {'read_only': True}),
    ('overwrite', False, 'Replace an existing output file', {'read_only': True}),
    ('diagnostics_period_s', 1.0, 'Period of the status on /diagnostics (recorded too if '
     '/diagnostics is among the topics) [s]; 0 publishes none',
     {'floating_point_range': (0.0, 3600.0), 'read_only': True}),
    ('max_queue_mb', 100.0, 'Bound of the messages received but not yet written [MiB]; a '
     'message that finds it full is dropped and counted',
     {'floating_point_range': (1.0, 1.0e6), 'read_only': True}),
)


def compression_refusal(value):
    """Return why `value` is no chunk compression, or None when it is one."""
    if value in COMPRESSIONS:
        return None
    return f'`compression` must be one of {", ".join(COMPRESSIONS)}, got {value!r}'


def open_recording(values, on_error=None):
    """
    Open the recording the parameter values describe, written from a thread of its own.

    Parameters
    ----------
    values : mapping
        Parameter values by name (`PARAMETERS`).
    on_error : callable, optional
        ``on_error(exception)`` for each failed write (see `BackgroundWriter`).

    Returns
    -------
    BackgroundWriter
        Its ``writer`` is the `Rosbag2McapWriter`.

    """
    output = values['output_path'] or time.strftime('fpc_gripper_%Y_%m_%d-%H_%M_%S.mcap')
    writer = Rosbag2McapWriter(
        output, compression=values['compression'],
        max_file_size=int(values['max_file_size_mb'] * _MIB),
        max_duration=int(values['max_duration_s'] * 1e9), overwrite=values['overwrite'],
        library=LIBRARY)
    return BackgroundWriter(writer, flush_period_s=values['flush_period_s'],
                            max_queue_bytes=int(values['max_queue_mb'] * _MIB),
                            on_error=on_error)


def apply_settings(background, values):
    """Apply the parameters that may change while recording: splits and the flush period."""
    background.writer.max_file_size = int(values['max_file_size_mb'] * _MIB)
    background.writer.max_duration = int(values['max_duration_s'] * 1e9)
    background.flush_period_s = values['flush_period_s']


def default_topics(gripper_config=''):
    """
    Return every input and output topic of the gripper's fingers, and why not if it fell back.

    Parameters
    ----------
    gripper_config : str
        Gripper YAML ('' for the package default).

    Returns
    -------
    topics : list of str
        Relative to the node namespace (`gripper_topics`).
    problem : str or None
        Why the config's fingers are not the ones recorded (then `DEFAULT_FINGERS` are).

    """
    try:
        # Imported here: the config brings the finger model and its compiled engine, which
        # a recorder given its topics never loads.
        from .config import default_gripper_config_path, load_gripper_config
        path = gripper_config or default_gripper_config_path()
        fingers, problem = [f.name for f in load_gripper_config(path).fingers], None
    except (ImportError, OSError, ValueError) as error:
        fingers, problem = list(DEFAULT_FINGERS), (
            f'gripper configuration unavailable ({error}); recording fingers '
            f'{", ".join(DEFAULT_FINGERS)}')
    return gripper_topics(fingers), problem
