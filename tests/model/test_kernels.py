"""The compiled CCM kernels equal the numpy reference formulas and differentiate their energy."""

import ccm_reference as reference
from helpers import deviation
import numpy as np
import pytest
from scipy.optimize._numdiff import approx_derivative

from fpc_gripper.model import ActuatorDesign, CCMSolver
from fpc_gripper.model.kernels import ccm as kernels, chain, linear
from fpc_gripper.model.selection import aligned_edges

#: Kernels against the originals: the same formulas in the same order leave round-off
#: only (seen <= 3e-15), relative to the largest entry of the array.
RTOL = 1e-13
#: Newton steps: Cholesky (here) and LU (the original) agree to their forward error,
#: eps n kappa, with kappa the condition number of the Hessian (up to 9e4 for N = 1);
#: two eigensolvers (here LAPACK syevd, the original's dense path syevr) mix the
#: eigenvectors of close eigenvalues too (seen 1.6e-15 n kappa). The backward errors,
#: the residuals, must be round-off: RTOL.
STEP_RTOL = 1e-15
EIG_STEP_RTOL = 1e-14
PRESTRAINS = (0.1, 0.25, 0.4)
PRESSURES = (0.0, 50e3, 150e3)
# (N, edges aligned on the section changes, intermediate load point [m]).
CASES = [(1, False, None), (3, False, 0.05), (8, False, 0.05), (22, True, 0.048)]


def _solver(prestrain, n, aligned, point):
    design = ActuatorDesign.paper(prestrain=prestrain)
    edges = aligned_edges(design, n) if aligned else None
    return CCMSolver(design, n_segments=n, segment_edges=edges,
                     load_points=() if point is None else (point,))


@pytest.fixture(scope='module', params=CASES, ids=[f'N{c[0]}' for c in CASES])
def states(request):
    """
    Solver, state q, pressure and loads: equilibria and perturbations of them.

    Equilibria at several prestrains and pressures, unloaded and with a tip load
    plus (N > 1) an intermediate one, then each perturbed by 10 % plus 0.01. In each
    group of four: unloaded equilibrium, its perturbation, loaded, its perturbation.
    """
    n, aligned, point = request.param
    rng = np.random.default_rng(n)
    out = []
    for prestrain in PRESTRAINS:
        solver = _solver(prestrain, n, aligned, point)
        for pressure in PRESSURES:
            for tip, extra in (((0.0, 0.0), ()), ((0.1, 0.2), ((point, -0.05, 0.1),))):
                extra = extra if point is not None else ()
                result = solver.solve(pressure, tip, point_loads=extra)
                assert result.success, result.message
                loads = solver._loads(tip, extra)
                q = result.state
                out.append((solver, q, pressure, loads))
                jitter = rng.normal(size=q.shape) * (0.1 * np.abs(q) + 0.01)
                out.append((solver, q + jitter, pressure, loads))
    return out


def _params(solver, pressure):
    return solver.design.prestrain, solver.design.emc_coefficients, \
        solver.pressure_coefficient * pressure


def test_kernels_run_compiled():
    # Under NUMBA_DISABLE_JIT the kernels would be plain Python and prove nothing.
    solver = _solver(0.25, 3, False, 0.05)
    q = solver.solve(1e5).state
    kernels.segment_derivatives(q, solver.segments, *_params(solver, 1e5))
    chain.load_derivatives(q, solver.segments.lengths, [(3, np.array([0.1, 0.2]))])
    linear.newton_step(np.ones((3, 4)), np.tile(np.eye(4), (3, 1, 1)))
    linear.newton_step(np.ones((3, 4)), np.eye(12))
    chain.node_positions(q, solver.segments.lengths)
    for module, name in ((kernels, 'segment_derivatives_kernel'),
                         (chain, 'load_derivatives_kernel'), (linear, 'newton_step_blocks'),
                         (linear, 'newton_step_dense'), (chain, 'node_positions_kernel')):
        kernel = getattr(module, name)
        assert kernel.signatures and kernel.targetoptions['nopython'], name


def test_segment_kernels_equal_numpy(states):
    for solver, q, pressure, _ in states:
        args = (q, solver.segments, *_params(solver, pressure))
        assert deviation(kernels.segment_energy(*args), reference.segment_energy(*args)) <= RTOL
        compiled = kernels.segment_derivatives(*args)
        original = reference.segment_derivatives(*args)
        assert deviation(compiled[0], original[0]) <= RTOL
        # At an equilibrium the gradient is round-off: measure it on its terms' scale.
        assert deviation(compiled[1], original[1], solver.gradient_scale) <= RTOL
        assert deviation(compiled[2], original[2]) <= RTOL


def test_load_kernels_equal_numpy(states):
    for solver, q, _, loads in states:
        lengths = solver.segments.lengths
        compiled = chain.load_derivatives(q, lengths, loads)
        original = reference.load_derivatives(q, lengths, loads)
        assert isinstance(compiled[0], float) and isinstance(original[0], float)
        if not loads:
            assert compiled[0] == 0.0 and chain.load_energy(q, lengths, loads) == 0.0
            assert not compiled[1].any() and not compiled[2].any()
            assert compiled[2].shape == original[2].shape
            direct = chain.load_derivatives_kernel(q, lengths, *chain.load_arrays(loads))
            assert direct[0] == 0.0 and not direct[1].any() and not direct[2].any()
            assert direct[2].shape == original[2].shape
            continue
        # The energy scale: each load's |F| times the finger length.
        scale = sum(np.abs(f).sum() for _, f in loads) * lengths.sum()
        assert abs(compiled[0] - original[0]) <= RTOL * scale
        assert abs(chain.load_energy(q, lengths, loads)
                   - reference.load_energy(q, lengths, loads)) <= RTOL * scale
        assert deviation(compiled[1], original[1]) <= RTOL
        assert deviation(compiled[2], original[2]) <= RTOL


def test_kinematics_kernels_equal_numpy(states):
    for solver, q, _, _ in states:
        lengths = solver.segments.lengths
        for got, want in zip(chain.node_positions(q, lengths),
                             reference.node_positions(q, lengths)):
            assert deviation(got, want, max(np.abs(want).max(), 1e-3)) <= RTOL
        assert deviation(chain.end_rotation(q), reference.end_rotation(q), 1.0) <= RTOL
        for got, want in zip(chain.consistent_strain_map(q),
                             reference.consistent_strain_map(q)):
            assert deviation(got, want) <= RTOL


def _mirrored(hess):
    """Return V |Lambda| V^T, the matrix the step inverts, and its condition number."""
    lam, vec = np.linalg.eigh(hess)
    top = np.abs(lam).max(axis=-1, keepdims=True)
    floored = np.maximum(np.abs(lam), 1e-8 * top)
    matrix = np.matmul(vec * floored[..., None, :], np.swapaxes(vec, -1, -2))
    return matrix, float((top / floored).max()), float(lam.min())


def _check_step(solver, grad, hess):
    """Compare the compiled step with the solver's; return whether H was PD."""
    step, min_eig = linear.newton_step(grad, hess)
    want, want_eig = reference.newton_step(grad, hess)
    matrix, kappa, lowest = _mirrored(hess)
    if want_eig == 1.0:
        assert min_eig == 1.0
    else:
        assert min_eig == pytest.approx(want_eig, rel=0, abs=RTOL * np.abs(hess).max())
        assert min_eig == pytest.approx(lowest, rel=0, abs=RTOL * np.abs(hess).max())
    rtol = STEP_RTOL if want_eig == 1.0 else EIG_STEP_RTOL
    assert deviation(step, want) <= rtol * hess.shape[-1] * kappa
    flat = step[:, :, None] if hess.ndim == 3 else step.ravel()
    residual = np.matmul(matrix, flat).reshape(grad.shape) + grad
    assert np.abs(residual).max() <= RTOL * np.abs(hess).max() * np.abs(step).max()
    return min_eig == 1.0


def test_newton_step_equals_numpy(states):
    # Blocks (unloaded), dense (loaded), each shifted to be indefinite, and shifted onto
    # an eigenvalue: singular, so that the floor of |lambda| sets the step.
    paths = set()
    for solver, q, pressure, loads in states:
        _, grad, hess = solver.derivatives(q, pressure, loads)
        paths.add((hess.ndim, _check_step(solver, grad, hess)))
        lam = np.linalg.eigvalsh(hess)
        eye = np.eye(hess.shape[-1])
        paths.add((hess.ndim, _check_step(solver, grad, hess - np.median(lam) * eye)))
        singular = hess - (lam[..., 1, None, None] if hess.ndim == 3 else lam[1]) * eye
        assert not _check_step(solver, grad + 1e-3 * solver.gradient_scale, singular)
    assert paths == {(3, True), (3, False), (2, True), (2, False)}


def _compiled_total(solver, pressure, loads):
    """Energy, gradient and dense Hessian of the flat unknowns, all by the kernels."""
    n = solver.n_segments
    seg, lengths = solver.segments, solver.segments.lengths
    params = _params(solver, pressure)

    def total(x):
        q = x.reshape(n, 4)
        return kernels.segment_energy(q, seg, *params).sum() + chain.load_energy(
            q, lengths, loads)

    def derivatives(x):
        q = x.reshape(n, 4)
        _, g, blocks = kernels.segment_derivatives(q, seg, *params)
        _, g_load, hess = chain.load_derivatives(q, lengths, loads)
        for i in range(n):
            hess[4 * i:4 * i + 4, 4 * i:4 * i + 4] += blocks[i]
        return (g + g_load).ravel(), hess

    return total, derivatives


def test_compiled_derivatives_match_finite_differences(states):
    # The perturbed states: at an equilibrium the gradient is round-off.
    for solver, q, pressure, loads in states[1::2]:
        total, derivatives = _compiled_total(solver, pressure, loads)
        x = q.ravel()
        grad, hess = derivatives(x)
        g_fd = approx_derivative(total, x, method='3-point', abs_step=1e-6)
        h_fd = approx_derivative(lambda y: derivatives(y)[0], x, method='3-point',
                                 abs_step=1e-6)
        np.testing.assert_allclose(grad, g_fd, rtol=1e-6, atol=1e-7 * np.abs(grad).max())
        np.testing.assert_allclose(hess, h_fd, rtol=1e-6, atol=1e-7 * np.abs(hess).max())
        np.testing.assert_allclose(hess, hess.T, rtol=0, atol=1e-12 * np.abs(hess).max())


def test_compiled_load_derivatives_match_finite_differences(states):
    # On their own scale: beside the segments' stiffness a load term would hide in atol.
    # The loaded, perturbed states.
    for solver, q, _, loads in states[3::4]:
        n, lengths = solver.n_segments, solver.segments.lengths
        x = q.ravel()
        _, grad, hess = chain.load_derivatives(q, lengths, loads)
        g_fd = approx_derivative(
            lambda y: chain.load_energy(y.reshape(n, 4), lengths, loads), x,
            method='3-point', abs_step=1e-6)
        h_fd = approx_derivative(
            lambda y: chain.load_derivatives(y.reshape(n, 4), lengths, loads)[1].ravel(), x,
            method='3-point', abs_step=1e-6)
        # One segment's load Hessian is zero: p_0 is linear in q_0 and theta_0 = 0.
        scale = max(np.abs(hess).max(), np.abs(grad).max())
        np.testing.assert_allclose(grad.ravel(), g_fd, rtol=1e-6, atol=1e-8 * scale)
        np.testing.assert_allclose(hess, h_fd, rtol=1e-6, atol=1e-8 * scale)


def test_compiled_strain_map_derivatives_match_finite_differences(states):
    for _, q, _, _ in states[1::2]:
        n = q.shape[0]
        qs, jac, hess3 = chain.consistent_strain_map(q)
        for i in range(n):
            def row(x, i=i):
                q_i = q.copy()
                q_i[i] = x
                return chain.consistent_strain_map(q_i)[0][i]

            def row_jac(x, i=i):
                q_i = q.copy()
                q_i[i] = x
                return chain.consistent_strain_map(q_i)[1][i, 3]

            j_fd = approx_derivative(row, q[i], method='3-point', abs_step=1e-7)
            h_fd = approx_derivative(row_jac, q[i], method='3-point', abs_step=1e-7)
            np.testing.assert_allclose(jac[i], j_fd, rtol=1e-7, atol=1e-9)
            np.testing.assert_allclose(hess3[i], h_fd, rtol=1e-6, atol=1e-8)


def test_node_jacobian_is_the_derivative_of_the_node_position(states):
    """The compiled node Jacobian against central differences of the compiled node positions."""
    for solver, q, _, _ in states[::3]:
        lengths = solver.segments.lengths
        for node in sorted({solver.n_segments, max(1, solver.n_segments // 2)}):
            position, jac = chain.node_jacobian(q, lengths, node)
            np.testing.assert_allclose(position, chain.node_positions(q, lengths)[0][node],
                                       rtol=0, atol=1e-15)

            def at(x, node=node):
                return chain.node_positions(x.reshape(q.shape), lengths)[0][node]
            numeric = approx_derivative(at, q.ravel(), method='3-point')
            scale = np.abs(jac).max()
            assert np.abs(jac.reshape(2, -1) - numeric).max() <= 1e-7 * scale
            # Segments at and beyond the node do not move it.
            assert not jac[:, node:, :].any()


def test_block_step_at_a_zero_pivot_mirrors_every_block():
    # One block of eight has a zero pivot: the lockstep factorisation must stop before
    # dividing by it, and every block then takes the mirrored-eigenvalue step.
    rng = np.random.default_rng(3)
    a = rng.normal(size=(8, 4, 4))
    hess = a @ a.transpose(0, 2, 1) + np.eye(4)
    hess[5, 0, :] = hess[5, :, 0] = 0.0
    grad = rng.normal(size=(8, 4))
    step, min_eig = linear.newton_step(grad, hess)
    want, want_eig = reference.newton_step(grad, hess)
    assert want_eig < 1.0 and min_eig == pytest.approx(want_eig, rel=0, abs=1e-12)
    assert deviation(step, want) <= 1e-9
