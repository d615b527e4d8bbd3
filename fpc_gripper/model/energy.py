"""Total potential of the CCM and its exact gradient and Hessian: the compiled kernels."""

from .kernels import load_derivatives, load_energy, node_jacobian, segment_derivatives, \
    segment_energy

__all__ = ['segment_energy', 'segment_derivatives', 'load_energy', 'load_derivatives',
           'node_jacobian']
