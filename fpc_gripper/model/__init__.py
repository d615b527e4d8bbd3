"""ROS-free physics core: the chained composite model (CCM) of an FPC finger."""

from .analysis import CircleFit, fit_circle, flexural_rigidity
from .design import ActuatorDesign, PAPER_MATERIALS
from .discretisations.arc import ArcSolver
from .discretisations.ccm import CCMResult, CCMSolver, RigidityResult, SolverStatus
from .discretisations.pcc import PCCResult, PCCSolver
from .discretisations.rod import RodSolver
from .discretisations.rung import ArcResult, LadderResult, RodResult
from .section.law import build_section_law, section_minimiser, SectionLaw, station_layout
from .section.materials import default_emc_coefficients, fit_emc_polynomial, Material
from .selection import AdaptiveSolver, choose_model, ModelChoice, RUNGS, Scene
from .validation import PRESSURE_MODEL_NAMES, PRESSURE_MODELS

__all__ = [
    'ActuatorDesign', 'AdaptiveSolver', 'ArcResult', 'ArcSolver', 'CCMResult', 'CCMSolver',
    'CircleFit', 'LadderResult', 'Material', 'ModelChoice', 'PAPER_MATERIALS', 'PCCResult',
    'PCCSolver', 'PRESSURE_MODEL_NAMES', 'PRESSURE_MODELS', 'RUNGS', 'RigidityResult',
    'RodResult', 'RodSolver', 'Scene', 'SectionLaw', 'SolverStatus', 'build_section_law',
    'choose_model', 'default_emc_coefficients', 'fit_circle', 'fit_emc_polynomial',
    'flexural_rigidity', 'section_minimiser', 'station_layout',
]
