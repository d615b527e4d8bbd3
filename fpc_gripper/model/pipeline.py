"""The one finger pipeline: model settings to the solver every consumer of a finger uses."""

from dataclasses import dataclass
import functools
import math

import numpy as np

from .corrected import CONTINUUM_FIT, CorrectedSolver
from .design import ActuatorDesign
from .result import rung_label
from .selection import AdaptiveSolver, make_solver, RUNGS
from .validation import check_pressure_model, integer

__all__ = ['PHYSICS',
           'DEFAULT_TOLERANCE', 'DEFAULT_N_SEGMENTS', 'MAX_SEGMENTS', 'MAX_RUNG_SEGMENTS',
           'ModelSettings', 'finger_model', 'contact_model', 'contact_segments', 'model_label',
           'rung_label', 'solver_label']

#: The physics a finger can be modelled with: the paper's plane sections, or the fast rung
#: corrected to the 2-D continuum (`corrected.CorrectedSolver`, docs/physics.md 18.1).
PHYSICS = ('paper', 'continuum')
#: Default tip-position tolerance against the geometrically exact rod [m].
DEFAULT_TOLERANCE = 5e-5
#: Segments of the fixed paper CCM that tolerance 0 selects.
DEFAULT_N_SEGMENTS = 8
#: Largest N of the paper CCM a setting may ask for (the nodes' `n_segments` range).
MAX_SEGMENTS = 64
#: Largest N of a rung named in the settings: the ladder's finest PCC (contact, 0.94 um).
MAX_RUNG_SEGMENTS = 128


@dataclass(frozen=True)
class ModelSettings:
    """
    How a finger is modelled: the settings `model_node`, replay and the controller share.

    Parameters
    ----------
    tolerance : float
        Tip-position tolerance against the rod [m]; > 0 selects, per scene, the
        cheapest model that meets it (`AdaptiveSolver`); 0 selects the paper CCM
        with `n_segments` segments.
    n_segments : int
        Segments of the fixed paper CCM (used when `tolerance` is 0), 1 to 64.
    pressure_model : {'design', 'adiabatic', 'isobaric'}
        Pressure work: 'design' (or None; the default) uses the design's
        `pressure_work_factor`, the others fix k_p (2.5, 1).
    rung : {'auto'} or one of `selection.RUNGS`
        'auto' (the default): the model `tolerance` selects, as above. A rung name fixes
        that rung with `n_segments` segments (the arc and the rod ignore N), whatever
        the tolerance: what calibration, contact and the benchmarks ask for.
    physics : {'paper', 'continuum'}
        'paper' (the default): the paper's plane-section physics, as above. 'continuum':
        the fast rung corrected to the 2-D FE (`CorrectedSolver` with `CONTINUUM_FIT`, the
        PCC with `corrected.CORRECTED_SEGMENTS` segments), whatever `tolerance`, `rung`
        and `n_segments` say; fitted to unpressurised scenes only.

    """

    tolerance: float = DEFAULT_TOLERANCE
    n_segments: int = DEFAULT_N_SEGMENTS
    pressure_model: str = 'design'
    rung: str = 'auto'
    physics: str = 'paper'

    def __post_init__(self):
        if self.physics not in PHYSICS:
            raise ValueError(f'`physics` must be one of {list(PHYSICS)}, got {self.physics!r}')
        tolerance = self.tolerance
        if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float, np.integer,
                                                                     np.floating)):
            raise TypeError(f'`tolerance` must be a real number [m], got {tolerance!r}')
        if not (math.isfinite(tolerance) and tolerance >= 0.0):
            raise ValueError(f'`tolerance` must be finite and >= 0 [m], got {tolerance}')
        object.__setattr__(self, 'tolerance', float(tolerance))
        if self.rung != 'auto' and self.rung not in RUNGS:
            raise ValueError(f"`rung` must be 'auto' or one of {list(RUNGS)}, "
                             f'got {self.rung!r}')
        top = MAX_SEGMENTS if self.rung == 'auto' else MAX_RUNG_SEGMENTS
        object.__setattr__(self, 'n_segments', integer('n_segments', self.n_segments, 1, top))
        object.__setattr__(self, 'pressure_model', check_pressure_model(self.pressure_model))

    @property
    def fixed(self):
        """The (rung, N) these settings fix, or None where the tolerance selects per scene."""
        if self.rung != 'auto':
            return self.rung, self.n_segments
        return None if self.tolerance > 0.0 else ('ccm', self.n_segments)


@functools.lru_cache(maxsize=32)
def finger_model(design, settings=ModelSettings()):
    """
    Return the solver of a finger: the only way the package builds one for a consumer.

    The node, `fpc-mcap replay-model`, the controller's inverse, the virtual object,
    `fpc-design`, `fpc-grasp` (through `contact_model`) and calibration all call this, so
    that they compute the same finger. The solver is a pure function
    of its inputs (warm starts change iteration counts, never answers), so one instance
    per (design, settings) is shared.

    Parameters
    ----------
    design : ActuatorDesign
    settings : ModelSettings

    Returns
    -------
    AdaptiveSolver or the solver of one rung
        `AdaptiveSolver(design, tolerance)` when the settings fix no rung
        (`ModelSettings.fixed` is None), else that rung's solver: the paper
        `CCMSolver(design, n_segments)` for tolerance 0.

    """
    if not isinstance(design, ActuatorDesign):
        raise TypeError(f'`design` must be an ActuatorDesign, got {type(design).__name__}')
    if not isinstance(settings, ModelSettings):
        raise TypeError(f'`settings` must be a ModelSettings, got {type(settings).__name__}')
    if settings.physics == 'continuum':
        return CorrectedSolver(design, CONTINUUM_FIT, pressure_model=settings.pressure_model)
    fixed = settings.fixed
    if fixed is None:
        return AdaptiveSolver(design, tolerance=settings.tolerance,
                              pressure_model=settings.pressure_model)
    return make_solver(*fixed, design, settings.pressure_model)


#: PCC segment counts for contact, with their worst tip error against the rod over the loaded
#: ladder scenes (docs/physics.md, section 11.6) [m].
_CONTACT_LADDER = ((32, 17.8e-6), (64, 4.07e-6), (128, 0.944e-6))
#: Safety factor on those errors, as the error model's.
_CONTACT_SAFETY = 1.5


def contact_segments(tolerance):
    """
    PCC segments of the contact model for a tip tolerance [m] (0: the paper CCM setting).

    The fewest of 32, 64, 128 whose worst loaded tip error, times 1.5, meets the tolerance;
    32 for tolerance 0 (the paper CCM has no face kinematics, so contact always runs on
    the PCC) and 128 below what 128 meets.
    """
    for n, error in _CONTACT_LADDER:
        if tolerance == 0.0 or error * _CONTACT_SAFETY <= tolerance:
            return n
    return _CONTACT_LADDER[-1][0]


@functools.lru_cache(maxsize=32)
def contact_model(design, settings=ModelSettings()):
    """
    Return the finger solver for contact scenes: the PCC rod, with face points.

    A grasp loads the finger along its faces, not at the tip, and a friction path must
    keep one discretisation from step to step, so contact scenes do not go through the
    per-scene model choice: they use the PCC with `contact_segments(settings.tolerance)`
    segments (32 for the default 0.05 mm: its worst loaded tip error is 18 um). The
    controller's inverse, the demo's virtual object and `fpc-grasp` all call this.

    Parameters
    ----------
    design : ActuatorDesign
    settings : ModelSettings

    Returns
    -------
    PCCSolver

    """
    if not isinstance(settings, ModelSettings):
        raise TypeError(f'`settings` must be a ModelSettings, got {type(settings).__name__}')
    return finger_model(design, ModelSettings(
        tolerance=settings.tolerance, n_segments=contact_segments(settings.tolerance),
        pressure_model=settings.pressure_model, rung='pcc'))


def model_label(result):
    """Rung and N of the model behind a result, e.g. 'ccm_aligned N=22' or 'ccm N=8'."""
    return 'none' if result is None else result.model


def solver_label(solver):
    """Return the `model` label of a solver's results, e.g. 'pcc N=22', 'ccm N=8' or 'rod'."""
    return solver._constants['model']
