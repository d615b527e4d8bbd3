"""The health level every node reports, with the values of diagnostic_msgs/DiagnosticStatus."""

import enum

__all__ = ['Level']


class Level(enum.IntEnum):
    """Health of a finger, a channel or the controller; ordered, worst last."""

    OK = 0
    WARN = 1
    ERROR = 2
