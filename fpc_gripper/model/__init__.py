"""ROS-free physics core: the chained composite model (CCM) of an FPC finger."""

import importlib

# Each public name from the module that defines it, imported at first use (PEP 562): a
# process that needs a design or an input check (the regulator bridge, a config tool) does
# not load numba and the compiled engine with them.
_HOMES = {
    '.analysis': ('CircleFit', 'fit_circle', 'flexural_rigidity'),
    '.design': ('ActuatorDesign', 'PAPER_MATERIALS'),
    '.discretisations.arc': ('ArcSolver',),
    '.discretisations.ccm': ('CCMSolver', 'SolverStatus'),
    '.discretisations.pcc': ('PCCSolver',),
    '.discretisations.rod': ('RodSolver',),
    '.result': ('Result', 'FINGER_FIELDS'),
    '.section.law': ('build_section_law', 'section_minimiser', 'SectionLaw', 'station_layout'),
    '.section.materials': ('default_emc_coefficients', 'fit_emc_polynomial', 'Material'),
    '.selection': ('AdaptiveSolver', 'choose_model', 'ModelChoice', 'RUNGS', 'Scene'),
    '.validation': ('PRESSURE_MODEL_NAMES', 'PRESSURE_MODELS'),
}
_HOME = {name: module for module, names in _HOMES.items() for name in names}

__all__ = sorted(_HOME)


def __getattr__(name):
    module = _HOME.get(name)
    if module is None:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
