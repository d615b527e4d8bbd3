"""
The one equilibrium engine: damped Newton, continuation, the bordered Newton of constraints.

A discretisation registers its hooks (the top of `newton`) and hands the engine a
`CompiledProblem` of its data (`problems`); the loops are written once (`newton`,
`bordered`, `active_set`) and run compiled through the three entries (the top of `solves`:
solve, rigidity, contact) or interpreted on a Python object; the Python front (`solves`,
`contact_solves`, `batches`) packs the inputs, calls an entry and returns an outcome
(`outcomes`).
"""

from .batches import batch_key, BatchOutcome, BatchRigidity, rigidity_batch, solve_batch
from .bordered import ContactSet, NodeLine
from .contact_solves import contact_path, contact_solve, contact_step, ContactOutcome, next_anchors
from .newton import HOOKS, hooks_of, linear_solve, linear_step, POINT_HOOKS, register
from .outcomes import BorderedOutcome, Fields, NewtonOptions, NewtonOutcome, SolverStatus
from .problems import CompiledProblem
from .solves import ALL, newton, OUTPUTS, outputs, rigidity, sensitivity, SHAPE, solve, TIP

__all__ = ['CompiledProblem', 'register', 'hooks_of', 'HOOKS', 'POINT_HOOKS', 'SolverStatus',
           'NewtonOptions', 'NewtonOutcome', 'Fields', 'newton', 'solve', 'outputs', 'TIP',
           'SHAPE', 'ALL', 'OUTPUTS', 'rigidity', 'linear_step',
           'linear_solve',
           'BorderedOutcome', 'solve_batch', 'rigidity_batch', 'batch_key', 'BatchOutcome',
           'BatchRigidity',
           'sensitivity', 'ContactSet', 'NodeLine', 'ContactOutcome', 'contact_solve',
           'contact_step', 'contact_path', 'next_anchors']
