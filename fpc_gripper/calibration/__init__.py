"""Calibration of a finger design from its measurements, with uncertainties (ROS-free)."""

from .data import (DataError, LoadingData, MarkerData, read_loading, read_markers,
                   read_markers_mcap, read_tensile, TensileData)
from .fit import (calibrate, CalibrationResult, CalibrationStatus, DEFAULT_FIT, FIT_SEGMENTS,
                  IDENTIFIABLE_RSE)
from .parameters import FIT_NAMES, FitParameters
from .report import plot_report, write_outputs

__all__ = [
    'CalibrationResult', 'CalibrationStatus', 'DataError', 'DEFAULT_FIT', 'FIT_NAMES',
    'FIT_SEGMENTS', 'FitParameters', 'IDENTIFIABLE_RSE', 'LoadingData', 'MarkerData',
    'TensileData', 'calibrate', 'plot_report', 'read_loading', 'read_markers',
    'read_markers_mcap', 'read_tensile', 'write_outputs',
]
