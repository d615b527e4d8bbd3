"""Total-Lagrangian plane-strain FE of a layered strip on 9-node quads (scikit-fem); Newton."""

from dataclasses import dataclass
import math

import numpy as np
from scipy.sparse.linalg import spsolve

from . import require_skfem
from .material import biot_response, stretch_response, volume_response

_skfem = require_skfem()
Basis, BilinearForm, LinearForm = _skfem.Basis, _skfem.BilinearForm, _skfem.LinearForm
ElementQuad2, ElementVector = _skfem.ElementQuad2, _skfem.ElementVector
FacetBasis, MeshQuad = _skfem.FacetBasis, _skfem.MeshQuad

__all__ = ['Strip', 'StripSolution', 'grid_lines']

#: Armijo constant of the energy line search.
_ARMIJO = 1e-4


def grid_lines(breaks, size):
    """
    Node lines of a tensor mesh: every break, and each interval cut evenly into pieces <= size.

    Parameters
    ----------
    breaks : array_like
        Increasing coordinates that must be element edges [m].
    size : float
        Largest element size [m].

    """
    breaks = np.asarray(breaks, dtype=float)
    out = [breaks[:1]]
    for lo, hi in zip(breaks, breaks[1:]):
        count = max(1, math.ceil((hi - lo) / size * (1.0 - 1e-9)))
        out.append(np.linspace(lo, hi, count + 1)[1:])
    return np.concatenate(out)


@dataclass(frozen=True)
class StripSolution:
    """
    Outcome of `Strip.solve`.

    Attributes
    ----------
    u : ndarray
        Displacement of every degree of freedom [m] (the last converged load level).
    success : bool
    message : str
    iterations : int
        Newton iterations over all load steps.
    steps : int
        Accepted load steps.
    fraction : float
        Load level reached, 1 on success [-].

    """

    u: np.ndarray
    success: bool
    message: str
    iterations: int
    steps: int
    fraction: float


class Strip:
    """
    A rectangle [0, length] x [z0, z1] of cells, each with its own law, solid and gas widths.

    The total potential per unit load level t in [0, 1] is

        Pi(u; t) = int w psi(F; t eig) dA - t k_p P int g J dA - t f.u,

    with w the solid width and g the gas width of each cell [m] (plane strain across the
    width Y), J = det F, eig the eigenstrains and f the nodal forces of the tip traction. The
    gas term is the exact potential of a follower pressure on the walls of the gas region
    (its volume is g times its deformed area).

    Parameters
    ----------
    x_breaks, z_breaks : array_like
        Cell edges [m]; x from 0 (the supported face) to the length.
    cell_law : ndarray of int, shape (len(x_breaks) - 1, len(z_breaks) - 1)
        Index into `laws` of every cell.
    laws : sequence of BiotMaterial
    width, gas_width : ndarray, shape of cell_law
        Solid and gas width of every cell [m].
    element_size : float
        Largest element edge [m].
    support : {'clamp', 'symmetry'} or callable
        'clamp' fixes the face x = 0; 'symmetry' holds it flat (u_x = 0) with u_z = 0 at
        z = 0 only; a callable (x, z) -> (u_x, u_z) prescribes the face's displacement
        [m], scaled with the load level.
    tip_profile : callable, optional
        Weight q(z) [1/m] of the tip traction over the face x = length, int q dz = 1; default
        uniform.
    gas_model : {'area', 'axial'}
        The gas volume per unit reference volume: J (a follower pressure on the walls) or
        the X-fibre stretch (the beam rungs' volume).

    """

    def __init__(self, x_breaks, z_breaks, cell_law, laws, width, gas_width, element_size,
                 support='clamp', tip_profile=None, gas_model='area'):
        if gas_model not in ('area', 'axial'):
            raise ValueError(f"`gas_model` must be 'area' or 'axial', got {gas_model!r}")
        self._volume = volume_response if gas_model == 'area' else stretch_response
        self.x_breaks = np.asarray(x_breaks, dtype=float)
        self.z_breaks = np.asarray(z_breaks, dtype=float)
        self.length = float(self.x_breaks[-1])
        self.height = float(self.z_breaks[-1] - self.z_breaks[0])
        xs = grid_lines(self.x_breaks, element_size)
        zs = grid_lines(self.z_breaks, element_size)
        self.mesh = MeshQuad.init_tensor(xs, zs)
        self.basis = Basis(self.mesh, ElementVector(ElementQuad2()))
        centre = self.mesh.p[:, self.mesh.t].mean(axis=1)
        ix = np.searchsorted(self.x_breaks, centre[0]) - 1
        iz = np.searchsorted(self.z_breaks, centre[1]) - 1
        cell = np.asarray(cell_law)[ix, iz]
        table = np.array([law.params for law in laws])
        # (8, elements, 1): broadcast against the quadrature points.
        self._params = table[cell].T[:, :, None]
        self._width = np.asarray(width, dtype=float)[ix, iz][:, None]
        self._gas = np.asarray(gas_width, dtype=float)[ix, iz][:, None]
        self.n_elements = self.mesh.t.shape[1]
        self.n_dofs = self.basis.N

        face = self.basis.get_dofs(lambda x: np.isclose(x[0], 0.0))
        locs = self.basis.doflocs
        self._prescribed = None
        if support == 'clamp':
            fixed = face.all()
        elif support == 'symmetry':
            centre = np.flatnonzero(np.isclose(self.mesh.p[0], 0.0)
                                    & np.isclose(self.mesh.p[1], 0.0))
            if centre.size != 1:
                raise ValueError("`support`='symmetry' needs a node at z = 0: put 0 in "
                                 '`z_breaks`')
            fixed = np.union1d(face.all('u^1'), self.basis.nodal_dofs[1, centre])
        elif callable(support):
            fixed = face.all()
            ux, uz = support(locs[0, fixed], locs[1, fixed])
            values = np.zeros(self.n_dofs)
            first = np.isin(fixed, face.all('u^1'))
            values[fixed] = np.where(first, ux, uz)
            self._prescribed = values
        else:
            raise ValueError(f"`support` must be 'clamp', 'symmetry' or a callable, got "
                             f'{support!r}')
        self.fixed = np.unique(fixed)
        self.free = np.setdiff1d(np.arange(self.n_dofs), self.fixed)

        tip = self.mesh.facets_satisfying(lambda x: np.isclose(x[0], self.length))
        fbasis = FacetBasis(self.mesh, self.basis.elem, facets=tip)
        profile = tip_profile or (lambda z: np.full_like(z, 1.0 / self.height))

        @LinearForm
        def along_x(v, w):
            return v[0] * profile(w.x[1])

        @LinearForm
        def along_z(v, w):
            return v[1] * profile(w.x[1])

        self._unit_loads = np.stack([along_x.assemble(fbasis), along_z.assemble(fbasis)])

    # -- points -------------------------------------------------------------------------
    def vertex_dofs(self, x, z):
        """
        Return the (u_x, u_z) degrees of freedom of the mesh vertex at (x, z), shape (2,).

        Raises
        ------
        ValueError
            If no vertex lies there.

        """
        hit = np.flatnonzero(np.isclose(self.mesh.p[0], x) & np.isclose(self.mesh.p[1], z))
        if hit.size != 1:
            raise ValueError(f'no mesh vertex at (x, z) = ({x}, {z}) [m]')
        return self.basis.nodal_dofs[:, hit[0]]

    def line_dofs(self, z):
        """Return the vertices on the line z (X order) and their dofs, shapes (K,), (2, K)."""
        hit = np.flatnonzero(np.isclose(self.mesh.p[1], z))
        hit = hit[np.argsort(self.mesh.p[0, hit])]
        return self.mesh.p[0, hit], self.basis.nodal_dofs[:, hit]

    # -- energy and derivatives -----------------------------------------------------------
    def _fields(self, u, level, pressure_work):
        """Return w psi - t k_p P g V at the quadrature points, with its stress and tangent."""
        grad = self.basis.interpolate(u).grad
        params = self._params.copy()
        params[6] = params[6] * level
        psi, stress, tangent = biot_response(grad, params)
        volume, first, second = self._volume(grad)
        gas = level * pressure_work * self._gas
        density = self._width * psi - gas * volume
        stress = self._width * stress - gas * first
        if second.ndim == 4:
            second = second[..., None, None]
        tangent = self._width * tangent - gas * second
        return density, stress, tangent

    def gas_volume(self, u):
        """Return the gas term's volume int g V dA [m^3] (g the gas width, V the gas model's)."""
        volume = self._volume(self.basis.interpolate(u).grad)[0]
        return float(np.sum(self._gas * volume * self.basis.dx))

    def load_vector(self, tip_force):
        """Nodal forces of a total tip force (f_x, f_z) [N] spread by the tip profile."""
        return tip_force[0] * self._unit_loads[0] + tip_force[1] * self._unit_loads[1]

    def energy(self, u, level=1.0, pressure_work=0.0, tip_force=(0.0, 0.0)):
        """Total potential Pi(u; t) [J]."""
        density = self._fields(u, level, pressure_work)[0]
        return float(np.sum(density * self.basis.dx)) \
            - level * float(self.load_vector(tip_force) @ u)

    def derivatives(self, u, level=1.0, pressure_work=0.0, tip_force=(0.0, 0.0)):
        """
        Total potential [J], its gradient [N] and its exact Hessian [N/m] (sparse CSR).

        Parameters
        ----------
        u : ndarray, shape (n_dofs,)
            Displacements [m].
        level : float
            Load level t [-] (eigenstrains, pressure and tip force scale with it).
        pressure_work : float
            k_p P [Pa].
        tip_force : (float, float)
            (f_x, f_z) [N].

        """
        density, stress, tangent = self._fields(u, level, pressure_work)

        @LinearForm
        def residual(v, w):
            return np.einsum('ij...,ij...->...', stress, v.grad)

        @BilinearForm
        def stiffness(du, v, w):
            return np.einsum('ijkl...,ij...,kl...->...', tangent, v.grad, du.grad)

        load = level * self.load_vector(tip_force)
        energy = float(np.sum(density * self.basis.dx)) - float(load @ u)
        return energy, residual.assemble(self.basis) - load, stiffness.assemble(self.basis)

    # -- Newton with load stepping --------------------------------------------------------
    def _newton(self, u, level, pressure_work, tip_force, max_iterations, xtol):
        """Damped Newton at one load level: (u, converged, iterations, message)."""
        free = self.free
        energy, grad, hess = self.derivatives(u, level, pressure_work, tip_force)
        for iteration in range(1, max_iterations + 1):
            if not np.isfinite(energy):
                return u, False, iteration, 'energy not finite'
            step = np.zeros_like(u)
            step[free] = spsolve(hess[free][:, free].tocsc(), -grad[free])
            size = float(np.abs(step).max())
            if not np.isfinite(size):
                return u, False, iteration, 'singular tangent'
            slope = float(grad @ step)
            if size <= xtol:
                return u + step, True, iteration, ''
            if not slope < 0.0:
                return u, False, iteration, 'tangent not positive along the Newton step'
            alpha = 1.0
            while True:
                trial = u + alpha * step
                e_trial = self.energy(trial, level, pressure_work, tip_force)
                if e_trial <= energy + _ARMIJO * alpha * slope:
                    break
                alpha *= 0.5
                if alpha < 1e-6:
                    return u, False, iteration, 'line search failed'
            u = trial
            energy, grad, hess = self.derivatives(u, level, pressure_work, tip_force)
        return u, False, max_iterations, f'no convergence in {max_iterations} iterations'

    def solve(self, pressure_work=0.0, tip_force=(0.0, 0.0), first_step=0.25,
              min_step=1.0 / 512, max_iterations=25, xtol=None):
        """
        Ramp every load from 0 to 1 (load stepping), each level by damped Newton.

        The step grows by 1.5 after a level converging in <= 6 iterations and halves after a
        failure; the start of each level is the secant extrapolation of the last two.

        Parameters
        ----------
        pressure_work : float
            k_p P [Pa].
        tip_force : (float, float)
            (f_x, f_z) [N].
        first_step, min_step : float
            First and smallest load increments [-].
        max_iterations : int
            Newton iterations per level.
        xtol : float, optional
            Largest displacement correction of a converged level [m]; default 1e-9 of
            the strip's height.

        Returns
        -------
        StripSolution

        """
        xtol = 1e-9 * self.height if xtol is None else float(xtol)
        u = np.zeros(self.n_dofs)
        previous, level, previous_level = None, 0.0, 0.0
        step, total, steps = float(first_step), 0, 0
        while level < 1.0:
            target = min(1.0, level + step)
            guess = u.copy()
            if previous is not None:
                guess += (u - previous) * (target - level) / (level - previous_level)
            if self._prescribed is not None:
                guess[self.fixed] = target * self._prescribed[self.fixed]
            trial, ok, its, why = self._newton(guess, target, pressure_work, tip_force,
                                               max_iterations, xtol)
            total += its
            if ok:
                previous, previous_level = u, level
                u, level = trial, target
                steps += 1
                if its <= 6:
                    step = min(1.5 * step, 1.0)
            else:
                step *= 0.5
                if step < min_step:
                    return StripSolution(u, False, f'load stepping stalled at level '
                                         f'{level:.4g} (increment below {min_step:.3g}; '
                                         f'last Newton: {why})', total, steps, level)
        return StripSolution(u, True, f'converged in {steps} load steps, {total} Newton '
                             'iterations', total, steps, 1.0)
