"""The compiled rod equals its numpy reference and differentiates its own energy."""

from helpers import deviation, fd_derivative
import numpy as np
import pytest
from rod_reference import ReferenceRodSolver

from fpc_gripper.model import ActuatorDesign, RodSolver
from fpc_gripper.model.discretisations.rod import _INDEFINITE, _PointwiseLocal
from fpc_gripper.model.kernels import rod as rod_kernels

#: Kernels against the reference: the same formulas, summed in another order than
#: einsum and np.add.at, leave round-off only (seen <= 4e-15), relative to the largest
#: entry of the reference array or the scale of its terms.
RTOL = 1e-13
#: Steps and solves: the banded Cholesky and LAPACK's dense one differ in round-off,
#: which the solve amplifies by the condition number of the Hessian (up to 3e6 here;
#: seen 4e-12). At an equilibrium the step is itself round-off and only the backward
#: error, the residual on the scale |H| |dx| + |rhs|, is compared (seen 3e-16).
STEP_RTOL = 1e-9
BACKWARD_RTOL = 1e-14
#: Fourth-order differences of the compiled energy (step 1e-5, seen <= 4e-11 of the
#: largest entry) and gradient (along a direction v with max |h v| = 1e-3; the round-off
#: of the gradient over h dominates, seen <= 5e-9).
FD_RTOL = 1e-8
FD_HESSIAN_RTOL = 1e-7
PRESSURES = (0.0, 200e3)
FORCES = ((0.0, 0.0), (0.3, -0.5))


def uniform_design(prestrain):
    """No ribs, channel over the whole free length: every cross-section is the same."""
    return ActuatorDesign.paper(prestrain).replace(ribs=False, Cx=0.110)


SOLVERS = {
    'paper': (ActuatorDesign.paper(0.25), {}),
    'prestrain 0.40, p = 4': (ActuatorDesign.paper(0.40), {'degree': 4}),
    'uniform, p = 6': (uniform_design(0.15), {'degree': 6, 'max_element_length': 0.02}),
}


def loads_of(solver, force):
    return [(solver.tip_node, np.array(force))] if any(force) else []


def random_state(solver, seed, turning):
    """theta turning by about `turning` rad in all with a wiggle, eps and c1 near physical."""
    rng = np.random.default_rng(seed)
    nodes = np.linspace(0.0, 1.0, solver.n_theta)
    theta = -turning * nodes + 0.01 * np.sin(17.0 * nodes + rng.uniform(0, 6))
    theta[0] = 0.0
    shape = solver._qtypes.shape
    b = np.stack([-0.08 + 0.02 * rng.normal(size=shape), 1e-3 * rng.normal(size=shape)],
                 axis=-1)
    return solver._pack((theta, b))


@pytest.fixture(scope='module', params=list(SOLVERS))
def solvers(request):
    design, options = SOLVERS[request.param]
    return RodSolver(design, **options), ReferenceRodSolver(design, **options)


@pytest.fixture(scope='module')
def states(solvers):
    """(x, pressure, force, at an equilibrium) for every scene, solved and random."""
    solver, reference = solvers
    out = []
    for pressure in PRESSURES:
        for force in FORCES:
            result = reference.solve(pressure, force)
            assert result.success, result.message
            out.append((reference._pack(result.state), pressure, force, True))
            for seed, turning in enumerate((2.0, 0.0)):
                out.append((random_state(solver, seed, turning), pressure, force, False))
    return out


def test_kernels_run_compiled(solvers):
    # Under NUMBA_DISABLE_JIT the kernels would be plain Python and prove nothing.
    solver, _ = solvers
    result = solver.solve(1e5, (0.0, 0.5))
    result.points                                   # the outputs' kernels
    x = solver._pack(result.state)
    _, grad, hess = solver.derivatives(x, 1e5, [(solver.tip_node, np.array([0.0, 0.5]))])
    solver.energy(x, 1e5, [])
    solver.solve_linear(hess, grad)
    solver.node_jacobian(x, solver.tip_node)
    # The condensation's pieces, which the kernels above call compiled.
    blocks = (hess.haa, hess.hab, hess.hbb, solver._weights, solver._basis, solver._dbasis,
              solver._theta_scale)
    rod_kernels.newton_step_kernel(grad, *blocks)
    rod_kernels.condense_kernel(*blocks)
    reduced = rod_kernels.reduced_rhs_kernel(grad, hess.hab_inv, solver._basis,
                                             solver._dbasis, solver._theta_scale)
    rod_kernels.expand_kernel(reduced, grad, hess.inv, hess.hab, solver._weights,
                              solver._basis, solver._dbasis)
    # The outputs' local problem, whose energy only a line search calls.
    _, kap, along, start = rod_kernels.sample_fields_kernel(
        x, solver._xq.size, *solver._sample_at[1:5], np.array([0.0, 0.5]))
    local = _PointwiseLocal(solver, kap, along, solver._sample_at[4], 1e5)
    local.energy(start, 1e5, [])
    # And its derivatives and step: else only an earlier test's outputs had run them.
    _, local_grad, local_hess = local.derivatives(start, 1e5, [])
    local.step(local_grad, local_hess)
    names = [name for name in rod_kernels.__all__ if name.endswith('_kernel')]
    assert len(names) == len(rod_kernels.__all__) == 13
    for name in names:
        kernel = getattr(rod_kernels, name)
        assert kernel.signatures and kernel.targetoptions['nopython'], name


def test_derivatives_equal_reference(solvers, states):
    solver, reference = solvers
    for x, pressure, force, equilibrium in states:
        loads = loads_of(solver, force)
        energy, grad, hess = solver.derivatives(x, pressure, loads)
        want_energy, want_grad, want_hess = reference.derivatives(x, pressure, loads)
        assert isinstance(energy, float)
        # One formula for both: the line search compares them.
        assert solver.energy(x, pressure, loads) == energy
        scale = abs(want_energy) + solver._theta_scale
        assert abs(energy - want_energy) <= RTOL * scale
        assert abs(energy - reference.energy(x, pressure, loads)) <= RTOL * scale
        # At an equilibrium the gradient is round-off: measure it on its terms' scale,
        # |H| |x| (the linear part of every term).
        full = full_hessian(reference, want_hess)
        grad_scale = max(np.abs(want_grad).max(), (np.abs(full) @ np.abs(x)).max())
        assert deviation(grad, want_grad, grad_scale) <= RTOL
        assert deviation(hess.th, want_hess.th, max(np.abs(want_hess.th).max(), 1.0)) <= RTOL
        for name in ('haa', 'hab', 'hbb'):
            got, want = getattr(hess, name), getattr(want_hess, name)
            assert deviation(got, want) <= RTOL, name
        # The structural zeros of the blocks are exactly zero.
        assert not hess.haa[..., 0, 1].any() and not hess.haa[..., 1, 0].any()
        assert not hess.hab[..., 0, 1].any()


def test_condensed_band_equals_the_dense_reference(solvers, states):
    solver, reference = solvers
    degree, n = solver.degree, solver.n_theta - 1
    for x, pressure, force, _ in states:
        loads = loads_of(solver, force)
        _, _, hess = solver.derivatives(x, pressure, loads)
        dense, inv, hab_inv = reference.condensed_matrix(reference.derivatives(
            x, pressure, loads)[2])
        assert hess.local and hess.lower.shape == (degree + 1, n)
        assert deviation(hess.inv, inv) <= RTOL
        assert deviation(hess.hab_inv, hab_inv) <= RTOL
        # Every entry of the reference within the band, and nothing outside it.
        rows, cols = np.nonzero(dense)
        assert np.abs(rows - cols).max() == degree
        for d in range(degree + 1):
            k = np.arange(n - d)
            assert deviation(hess.lower[d, :n - d], dense[k + d, k],
                             np.abs(dense).max()) <= RTOL
            assert not hess.lower[d, n - d:].any()


def backward_error(full, dx, rhs):
    """Return max |H dx - rhs| / max(|H| |dx| + |rhs|)."""
    return float(np.abs(full @ dx - rhs).max() / (np.abs(full) @ np.abs(dx) + np.abs(rhs)).max())


def test_steps_and_solves_equal_reference(solvers, states):
    solver, reference = solvers
    rng = np.random.default_rng(7)
    for x, pressure, force, equilibrium in states:
        loads = loads_of(solver, force)
        _, grad, hess = solver.derivatives(x, pressure, loads)
        _, want_grad, want_hess = reference.derivatives(x, pressure, loads)
        assert hess.factor is not _INDEFINITE
        full = full_hessian(reference, want_hess)
        step, min_eig = solver.step(grad, hess)
        want_step, want_eig = reference.step(want_grad, want_hess)
        assert min_eig == want_eig == 1.0
        if not equilibrium:
            assert deviation(step, want_step) <= STEP_RTOL
        assert backward_error(full, step, -grad) <= BACKWARD_RTOL
        # The step `derivatives` kept is handed out once; the next is solved afresh.
        again, _ = solver.step(grad, hess)
        assert again is not step and backward_error(full, again, -grad) <= BACKWARD_RTOL
        rhs = rng.normal(size=x.size)
        got = solver.solve_linear(hess, rhs)
        assert deviation(got, reference.solve_linear(want_hess, rhs)) <= STEP_RTOL
        assert backward_error(full, got, rhs) <= BACKWARD_RTOL


def full_hessian(solver, hess):
    """Dense Hessian of the engine unknowns from the pointwise blocks (numpy)."""
    wt, nb, db = solver._weights, solver._basis, solver._dbasis
    n, size = solver.n_theta, solver.n_theta - 1 + 2 * wt.size
    bmat = np.stack([np.broadcast_to(nb, db.shape), db], axis=2)       # (E, Q, 2, a)
    dofs = solver._dofs
    big = np.zeros((n + 2 * wt.size, n + 2 * wt.size))
    kaa = np.einsum('eq,eqia,eqij,eqjb->eab', wt, bmat, hess.haa, bmat)
    np.add.at(big, (dofs[:, :, None], dofs[:, None, :]), kaa)
    bidx = n + np.arange(2 * wt.size).reshape(wt.shape + (2,))
    kab = np.einsum('eq,eqia,eqij->eqaj', wt, bmat, hess.hab)
    rows = np.broadcast_to(dofs[:, None, :, None], kab.shape)
    cols = np.broadcast_to(bidx[:, :, None, :], kab.shape)
    np.add.at(big, (rows, cols), kab)
    np.add.at(big, (cols, rows), kab)
    kbb = wt[..., None, None] * hess.hbb
    np.add.at(big, (np.broadcast_to(bidx[..., :, None], kbb.shape),
                    np.broadcast_to(bidx[..., None, :], kbb.shape)), kbb)
    assert big.shape[0] - 1 == size
    return big[1:, 1:]


def test_indefinite_steps_equal_reference(solvers):
    solver, reference = solvers
    x = reference._pack(reference.solve(1e5).state)
    nt = solver.n_theta
    # A compressive tip load makes the condensed system indefinite, a strain of 3 at a
    # few points (the PEMC softens) the pointwise blocks.
    stretched = x.copy()
    stretched[nt - 1:nt + 9:2] = 3.0
    cases = [(x, [(solver.tip_node, np.array([-20.0, 0.0]))], 'condensed'),
             (stretched, [], 'local')]
    for x, loads, kind in cases:
        _, grad, hess = solver.derivatives(x, 1e5, loads)
        _, want_grad, want_hess = reference.derivatives(x, 1e5, loads)
        assert hess.factor is _INDEFINITE and hess.local == (kind == 'condensed')
        step, min_eig = solver.step(grad, hess)
        want_step, want_eig = reference.step(want_grad, want_hess)
        assert min_eig == want_eig == -1.0
        assert deviation(step, want_step) <= STEP_RTOL
        # Mirrored eigenvalues: the step still descends.
        assert grad @ step < 0.0
        rhs = np.linspace(-1.0, 1.0, x.size)
        if kind == 'condensed':
            got = solver.solve_linear(hess, rhs)
            assert deviation(got, reference.solve_linear(want_hess, rhs)) <= STEP_RTOL
        else:
            with pytest.raises(np.linalg.LinAlgError):
                solver.solve_linear(hess, rhs)


def test_node_jacobian_equals_reference(solvers, states):
    solver, reference = solvers
    for x, _, _, _ in states:
        tip, jac = solver.node_jacobian(x, solver.tip_node)
        want_tip, want_jac = reference.node_jacobian(x, solver.tip_node)
        assert deviation(tip, want_tip) <= RTOL
        assert deviation(jac, want_jac) <= RTOL
    with pytest.raises(ValueError, match='tip'):
        solver.node_jacobian(x, 0)


def test_solves_and_outputs_equal_reference(solvers):
    solver, reference = solvers
    for pressure in PRESSURES:
        for force in FORCES + ((-1.0, 0.0),):
            got, want = solver.solve(pressure, force), reference.solve(pressure, force)
            assert got.success and want.success
            assert got.iterations == want.iterations
            assert deviation(got.tip, want.tip, solver.length) <= RTOL
            assert deviation(got.points, want.points, solver.length) <= RTOL
            assert deviation(got.nodes, want.nodes, solver.length) <= RTOL
            assert deviation(got.tangent, want.tangent, 1.0) <= RTOL
            assert deviation(got.beta, want.beta, 1.0) <= RTOL
            # eps and c1 of the local equilibrium: converged to 1e-15 from either start.
            for k in range(3):
                assert deviation(got.strains[:, k], want.strains[:, k]) <= 1e-12
            assert abs(got.energy - want.energy) <= RTOL * solver._theta_scale
    got, want = solver.rigidity(1e5), reference.rigidity(1e5)
    assert got.success and got.iterations == want.iterations
    assert abs(got.value - want.value) <= 1e-10 * abs(want.value)


# -- finite differences of the compiled path ------------------------------------------------
def test_gradient_is_the_derivative_of_the_energy(solvers, states):
    # Away from the equilibria, where the gradient is more than its differences' noise.
    solver, _ = solvers
    for x, pressure, force, _ in [state for state in states if not state[3]][::2]:
        loads = loads_of(solver, force)
        _, grad, _ = solver.derivatives(x, pressure, loads)
        fd = fd_derivative(lambda v: np.array(solver.energy(v, pressure, loads)), x, 1e-5)
        assert deviation(grad, fd, np.abs(fd).max()) <= FD_RTOL


def test_hessian_is_the_derivative_of_the_gradient(solvers, states):
    # Through the condensed solve: H (H^-1 r) = r with H v by differences of the gradient
    # along v, for the step and random right-hand sides.
    solver, _ = solvers
    rng = np.random.default_rng(3)
    for x, pressure, force, _ in [state for state in states if not state[3]]:
        loads = loads_of(solver, force)
        _, grad, hess = solver.derivatives(x, pressure, loads)
        step, _ = solver.step(grad, hess)
        pairs = [(-grad, step)] + [(r, solver.solve_linear(hess, r))
                                   for r in rng.normal(size=(2, x.size))]
        for rhs, v in pairs:
            h = 1e-3 / np.abs(v).max()
            hv = fd_derivative(lambda t: solver.derivatives(x + t[0] * v, pressure, loads)[1],
                               np.zeros(1), h)[:, 0]
            assert deviation(hv, rhs) <= FD_HESSIAN_RTOL


def test_pointwise_blocks_are_the_derivative_of_the_gradient(solvers, states):
    # The blocks themselves: the gradient's response to a change of (eps, c1) at one point,
    # and to one theta dof, is the block's column (times the weight).
    solver, _ = solvers
    x, pressure, force, _ = states[-1]
    loads = loads_of(solver, force)
    _, _, hess = solver.derivatives(x, pressure, loads)
    nt, nq = solver.n_theta, solver._xq.size
    for e, q in ((0, 0), (solver.n_elements // 2, nq - 1)):
        k = nt - 1 + 2 * (e * nq + q)
        for j in range(2):
            v = np.zeros(x.size)
            v[k + j] = 1.0
            col = fd_derivative(lambda t: solver.derivatives(x + t[0] * v, pressure,
                                                             loads)[1], np.zeros(1), 1e-5)[:, 0]
            want = solver._weights[e, q] * hess.hbb[e, q, :, j]
            assert deviation(col[k:k + 2], want) <= FD_RTOL
            # Coupling to theta and kappa: the weight times B^T hab at that point.
            bmat = np.stack([solver._basis[q], solver._dbasis[e, q]])     # (2, p + 1)
            coupling = solver._weights[e, q] * bmat.T @ hess.hab[e, q, :, j]
            dofs = solver._dofs[e]
            keep = dofs > 0
            assert deviation(col[dofs[keep] - 1], coupling[keep],
                             np.abs(coupling).max()) <= FD_RTOL


def test_node_jacobian_is_the_derivative_of_the_tip(solvers, states):
    solver, _ = solvers
    for x, _, _, _ in states[::4]:
        _, jac = solver.node_jacobian(x, solver.tip_node)
        fd = fd_derivative(lambda v: solver.node_jacobian(v, solver.tip_node)[0], x, 1e-5)
        assert deviation(jac, fd) <= FD_RTOL


def test_local_problem_derivatives_and_step(solvers, states):
    # The outputs' pointwise (eps, c1) problem: gradient and blocks by differences of the
    # compiled energy and gradient, and the block step solves the blocks.
    solver, _ = solvers
    x, pressure, force, _ = states[-2]
    fields = rod_kernels.sample_fields_kernel(
        x, solver._xq.size, *solver._sample_at[1:5], np.array(force, dtype=float))
    _, kap, along, start = fields
    problem = _PointwiseLocal(solver, kap, along, solver._sample_at[4], pressure)
    energy, grad, hess = problem.derivatives(start, pressure, [])
    assert problem.energy(start, pressure, []) == energy

    def local_energy(v):
        # (eps, c1) of the first 20 points vary; the energy is a sum over the points.
        b = start.copy()
        b[:20] = v.reshape(20, 2)
        return np.array(problem.energy(b, pressure, []))

    fd = fd_derivative(local_energy, start[:20].ravel(), 1e-6)
    assert deviation(grad[:20].ravel(), fd) <= FD_RTOL

    def local_gradient(t, j):
        b = start.copy()
        b[:, j] += t[0]
        return problem.derivatives(b, pressure, [])[1]

    for j in range(2):
        col = fd_derivative(lambda t: local_gradient(t, j), np.zeros(1), 1e-6)[..., 0]
        assert deviation(col, hess[:, :, j]) <= FD_RTOL
    step, min_eig = problem.step(grad, hess)
    assert min_eig == 1.0
    assert deviation(np.einsum('kij,kj->ki', hess, step), -grad) <= BACKWARD_RTOL
