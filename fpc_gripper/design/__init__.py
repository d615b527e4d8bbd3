"""Design studies: parametric sweeps, the paper's figures and inverse design (fpc-design)."""

from .grid import design_grid, parse_values
from .sweep import model_settings, sweep

__all__ = ['sweep', 'design_grid', 'model_settings', 'parse_values']
