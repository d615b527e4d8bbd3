"""Design studies: parametric sweeps, the paper's figures and inverse design (fpc-design)."""

import importlib

__all__ = ['sweep', 'figure', 'optimize', 'Targets', 'design_grid', 'model_settings',
           'parse_values']

# Imported on first use: a Dask worker that unpickles `runner`'s task, or `fpc-design
# --help`, does not load the model and its compiled kernels.
_LAZY = {'sweep': 'parametric', 'model_settings': 'parametric', 'figure': 'figures',
         'optimize': 'inverse', 'Targets': 'inverse', 'design_grid': 'grid',
         'parse_values': 'grid'}


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(f'.{_LAZY[name]}', __name__), name)
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')


def __dir__():
    return sorted(list(globals()) + list(_LAZY))
