"""The continuum rung: a 2-D finite-strain FE of the finger's side view (needs scikit-fem)."""

import importlib

__all__ = ['ChannelSection', 'ContinuumSolver', 'require_skfem']


def require_skfem():
    """Return the scikit-fem module, or raise ImportError saying how to install it."""
    try:
        return importlib.import_module('skfem')
    except ImportError as exc:
        raise ImportError('the continuum rung (fpc_gripper.model.continuum) needs scikit-fem, '
                          "an optional dependency: pip install 'fpc_gripper[continuum]' or "
                          'scikit-fem==12.0.2 (pinned in requirements.lock)') from exc


def __getattr__(name):
    if name == 'ContinuumSolver':
        require_skfem()
        from .solver import ContinuumSolver
        return ContinuumSolver
    if name == 'ChannelSection':
        require_skfem()
        from .section import ChannelSection
        return ChannelSection
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
