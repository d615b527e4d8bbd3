"""ROS-free physics core: the chained composite model (CCM) of an FPC finger."""

from .analysis import CircleFit, fit_circle, flexural_rigidity
from .design import ActuatorDesign, PAPER_MATERIALS
from .materials import default_emc_coefficients, fit_emc_polynomial, Material
from .solver import CCMResult, CCMSolver, PRESSURE_MODELS, RigidityResult, SolverStatus

__all__ = [
    'ActuatorDesign', 'CCMResult', 'CCMSolver', 'CircleFit', 'Material', 'PAPER_MATERIALS',
    'PRESSURE_MODELS', 'RigidityResult', 'SolverStatus', 'default_emc_coefficients',
    'fit_circle', 'fit_emc_polynomial', 'flexural_rigidity',
]
