"""ROS-free physics core: the chained composite model (CCM) of an FPC finger."""

from .analysis import CircleFit, fit_circle, flexural_rigidity
from .design import ActuatorDesign, PAPER_MATERIALS
from .ladder import ArcResult, ArcSolver, LadderResult, RodResult, RodSolver
from .materials import default_emc_coefficients, fit_emc_polynomial, Material
from .pcc import PCCResult, PCCSolver
from .section_law import build_section_law, section_minimiser, SectionLaw, station_layout
from .selection import AdaptiveSolver, choose_model, ModelChoice, RUNGS, Scene
from .solver import (CCMResult, CCMSolver, PRESSURE_MODEL_NAMES, PRESSURE_MODELS,
                     RigidityResult, SolverStatus)

__all__ = [
    'ActuatorDesign', 'AdaptiveSolver', 'ArcResult', 'ArcSolver', 'CCMResult', 'CCMSolver',
    'CircleFit', 'LadderResult', 'Material', 'ModelChoice', 'PAPER_MATERIALS', 'PCCResult',
    'PCCSolver', 'PRESSURE_MODEL_NAMES', 'PRESSURE_MODELS', 'RUNGS', 'RigidityResult',
    'RodResult', 'RodSolver', 'Scene', 'SectionLaw', 'SolverStatus', 'build_section_law',
    'choose_model', 'default_emc_coefficients', 'fit_circle', 'fit_emc_polynomial',
    'flexural_rigidity', 'section_minimiser', 'station_layout',
]
