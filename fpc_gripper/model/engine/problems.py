"""What a discretisation hands the engine to run compiled: its data, flat state and scale."""

import numpy as np

from .newton import hooks_of
from ..kernels.chain import load_arrays


class CompiledProblem:
    """
    A discretisation as the engine runs it compiled; it never calls back into the solver.

    A discretisation builds one at construction and passes it to the engine's functions
    (`solve`, `rigidity`, `contact_solve`, the batches) in place of itself. Its methods
    are the interface an interpreted problem has (``energy``, ``derivatives``, ``step``,
    ``solve_linear``, ``node_jacobian``, the face points), answered by the hooks
    registered for the data's type (`register`), so the engine's Python code (sensitivities,
    contact's gaps) runs the same compiled kernels as its loops.

    Parameters
    ----------
    unloaded, loaded : namedtuple
        The compiled data of the unloaded and the loaded scenes, of registered types (the
        same object where one layout serves both).
    flat : ndarray
        The unstrained state in the engine's unknowns.
    gradient_scale : float
        [J] per unit of the unknowns: the scale of the convergence test.

    """

    def __init__(self, unloaded, loaded, flat, gradient_scale):
        self.data = (unloaded, loaded)
        # Writable, as every state the entries take (numba types a read-only array apart).
        self._flat = np.ascontiguousarray(flat, dtype=float)
        self.gradient_scale = float(gradient_scale)
        self._hooks = (hooks_of(type(unloaded)), hooks_of(type(loaded)))
        #: What the engine derives from it once (`engine.solves._derived`).
        self.derived = self.new_memo()

    @staticmethod
    def new_memo():
        """Return an empty memo of what the engine derives from a problem."""
        return {'flat': None, 'packed': {}, 'lists': {}, 'none': None, 'frames': {}}

    def flat(self):
        """Return the unstrained state (shared: copy it before writing)."""
        return self._flat

    def _call(self, name, loaded, *args):
        return self._hooks[loaded][name](self.data[loaded], *args)

    def energy(self, x, pressure, loads):
        """Total potential [J] at `x`."""
        return self._call('energy', bool(loads), _state(x), float(pressure),
                          *load_arrays(loads))

    def derivatives(self, x, pressure, loads):
        """Energy [J], gradient and the Hessian (opaque: the data's form, and which data)."""
        loaded = bool(loads)
        energy, grad, hess = self._call('derivatives', loaded, _state(x), float(pressure),
                                        *load_arrays(loads))
        return energy, grad, (loaded, hess)

    def step(self, grad, hess):
        """Newton step and smallest eigenvalue (1.0 if definite) for a `derivatives` Hessian."""
        loaded, matrix = hess
        return self._call('step', loaded, _state(grad), matrix)

    def solve_linear(self, hess, rhs):
        """Solve H x = rhs for a `derivatives` Hessian; LinAlgError where H is singular."""
        loaded, matrix = hess
        out, ok = self._call('solve_linear', loaded, matrix, _state(rhs))
        if not ok:
            raise np.linalg.LinAlgError('the Hessian is singular')
        return out

    def node_jacobian(self, x, node):
        """Position of a node [m] and its derivatives in the unknowns."""
        return self._call('node_jacobian', True, _state(x), int(node))

    def point_positions(self, x, pseg, poff, pz):
        """Positions [m] of face points (segment, offset [m], height [m])."""
        return self._call('point_positions', True, _state(x), pseg, poff, pz)

    def point_jacobian(self, x, seg, offset, z):
        """Position [m] of one face point and its derivatives in the unknowns."""
        return self._call('point_jacobian', True, _state(x), int(seg), float(offset),
                          float(z))

    def point_derivatives(self, x, pressure, loads, pseg, poff, pz, pforce):
        """Energy, gradient and Hessian (as `derivatives`') with dead forces at face points."""
        energy, grad, hess = self._call('point_derivatives', True, _state(x), float(pressure),
                                        *load_arrays(loads), pseg, poff, pz, pforce)
        return energy, grad, (True, hess)

    def has_points(self):
        """Whether the data has face points (contact)."""
        return 'point_positions' in self._hooks[True]


def _state(x):
    return np.ascontiguousarray(x, dtype=float)
