"""The compiled PCC rod equals its numpy reference and differentiates its own energy."""

from helpers import deviation, fd_derivative
import numpy as np
from pcc_reference import half_angle_sinc as reference_sinc, random_state, ReferencePCCSolver
import pytest

from fpc_gripper.model import ActuatorDesign, engine
from fpc_gripper.model.discretisations.pcc import half_angle_sinc, PCCSolver
from fpc_gripper.model.engine.newton import OUTPUT_FIELDS
from fpc_gripper.model.kernels import linear, pcc as pcc_kernels, pcc_section

#: Kernels against the reference: the same formulas, in the same order but for dot
#: products and einsum, leave round-off only (seen <= 1.9e-15), relative to the largest
#: entry of the reference array or the scale of its terms.
RTOL = 1e-13
#: Newton steps: the compiled banded Cholesky and LAPACK's (OpenBLAS) differ in
#: round-off, which the solve amplifies by the condition number kappa of H (up to 3e5
#: here); seen 2e-17 kappa. The backward error, the residual, must be round-off: RTOL.
STEP_RTOL = 1e-15
PRESTRAINS = (0.15, 0.40)
PRESSURES = (0.0, 200e3)
N_VALUES = (1, 24, 64)
# States: the reference's equilibrium, then random ones turning by 3 rad, by 60 rad (most
# segments beyond |Delta| = 2, the closed forms of S) and not at all.
TURNINGS = (3.0, 60.0, 0.0)


def load_cases(n):
    """Unloaded, a tip load, and loads at the tip, an inner node and the clamp [N]."""
    return {'none': [], 'tip': [(n, np.array([0.0, 1.0]))],
            'inner': [(n, np.array([-0.4, 0.9])), (max(n // 3, 1), np.array([1.1, 0.6])),
                      (0, np.array([5.0, 5.0]))]}


@pytest.fixture(scope='module')
def states():
    """(compiled solver, reference solver, x, pressure, loads, near an equilibrium)."""
    out = []
    for prestrain in PRESTRAINS:
        design = ActuatorDesign.paper(prestrain)
        for n in N_VALUES:
            solver, reference = PCCSolver(design, n), ReferencePCCSolver(design, n)
            for pressure in PRESSURES:
                for name, loads in load_cases(solver.n_segments).items():
                    tip = loads[0][1] if name == 'tip' else (0.0, 0.0)
                    result = reference.solve(pressure, tip)
                    assert result.success, result.message
                    # Near equilibrium under the inner loads too: they are small.
                    out.append((solver, reference, reference._pack(result.state), pressure,
                                loads, True))
                    for seed, turning in enumerate(TURNINGS):
                        out.append((solver, reference, random_state(solver, seed, turning),
                                    pressure, loads, False))
    return out


def test_kernels_run_compiled():
    # Under NUMBA_DISABLE_JIT the kernels would be plain Python and prove nothing.
    solver = PCCSolver(ActuatorDesign.paper(0.25), 24)
    result = solver.solve(1e5, (0.0, 0.5))
    x = solver._pack(result.state)
    _, grad, hess = solver.derivatives(x, 1e5, [(24, np.array([0.0, 0.5]))])
    solver.energy(x, 1e5, [])
    data = solver.engine_problem.data[True]
    pcc_kernels.energy_kernel(x, data.lengths, data.stiffness, data.gas, data.pemc, 1e5,
                              *solver._load_arrays([]))
    pcc_kernels.derivatives_kernel(x, data.lengths, data.stiffness, data.gas, data.pemc, 1e5,
                                   *solver._load_arrays([]))
    solver.solve_linear(hess, grad)
    solver.step(grad, hess)
    linear.banded_cholesky(hess.lower)
    linear.banded_step(hess.lower, grad)
    solver.node_jacobian(x, 24)
    solver.nodes(x)
    pcc_kernels.pcc_outputs(data, x, 1e5, *solver._load_arrays([]), True)
    half_angle_sinc(np.array([0.5]))
    for module, name in ((pcc_section, 'half_angle_sinc_kernel'), (pcc_kernels, 'energy_kernel'),
                         (pcc_kernels, 'derivatives_kernel'), (linear, 'banded_cholesky'),
                         (linear, 'cholesky_solve'), (linear, 'banded_step'),
                         (pcc_kernels, 'nodes_kernel'), (pcc_kernels, 'node_jacobian_kernel'),
                         (pcc_kernels, 'pcc_outputs'), (pcc_kernels, 'pcc_derivatives'),
                         (pcc_kernels, 'pcc_energy'), (pcc_kernels, 'pcc_solve_linear')):
        kernel = getattr(module, name)
        assert kernel.signatures and kernel.targetoptions['nopython'], name


def test_half_angle_sinc_equals_numpy():
    # Both branches, their seam at |delta| = 2, zero and large turns.
    delta = np.concatenate([np.linspace(-50.0, 50.0, 20001), [0.0, 2.0, -2.0, 2.0 - 1e-13]])
    for order in (0, 1, 2):
        got, want = half_angle_sinc(delta, order), reference_sinc(delta, order)
        assert len(got) == len(want) == order + 1
        for g, w in zip(got, want):
            assert deviation(g, w, 1.0) <= RTOL
    # Shapes as numpy: a scalar stays 0-d, a matrix keeps its shape.
    assert half_angle_sinc(0.3)[0].shape == ()
    assert half_angle_sinc(np.ones((2, 3)))[2].shape == (2, 3)
    assert half_angle_sinc([0.0])[0][0] == 1.0


def test_derivatives_equal_numpy(states):
    for solver, reference, x, pressure, loads, equilibrium in states:
        energy, grad, hess = solver.derivatives(x, pressure, loads)
        want_energy, want_grad, want_hess = reference.derivatives(x, pressure, loads)
        assert isinstance(energy, float)
        # One formula for both: the line search compares them.
        assert solver.energy(x, pressure, loads) == energy
        assert abs(energy - want_energy) <= RTOL * abs(want_energy)
        assert abs(energy - reference.energy(x, pressure, loads)) <= RTOL * abs(want_energy)
        # At an equilibrium the gradient is round-off: measure it on its terms' scale,
        # |H| |x| (the linear part of every term).
        scale = np.abs(want_grad).max()
        if equilibrium:
            scale = max(scale, (np.abs(want_hess.dense()) @ np.abs(x)).max())
        assert deviation(grad, want_grad, scale) <= RTOL
        assert deviation(hess.lower, want_hess.lower) <= RTOL
        # The band's unused corner (beyond the last unknown) is exactly zero.
        m = x.size
        for d in range(1, 4):
            assert not hess.lower[d, m - d:].any()


def _check_step(solver, reference, grad, hess, want_hess):
    """Compare the compiled step with the reference's for one gradient; return it PD."""
    step, min_eig = solver.step(grad, hess)
    want, want_eig = reference.step(grad, want_hess)
    dense = want_hess.dense()
    if want_eig == 1.0:
        assert min_eig == 1.0
        kappa = np.linalg.cond(dense)
        assert deviation(step, want) <= STEP_RTOL * kappa
        residual = dense @ step + grad
        assert np.abs(residual).max() <= RTOL * np.abs(dense).max() * np.abs(step).max()
        return True
    # The indefinite path is the reference's own code (scipy) on the compiled band.
    assert min_eig < 0.0
    assert min_eig == pytest.approx(want_eig, rel=1e-10)
    d = np.sqrt(np.abs(dense.diagonal()))
    shifted = dense + 2.0 * abs(want_eig) * np.diag(d ** 2)
    assert deviation(step, want) <= STEP_RTOL * np.linalg.cond(shifted)
    assert grad @ step < 0.0
    return False


def test_steps_equal_numpy(states):
    paths = set()
    for solver, reference, x, pressure, loads, _ in states:
        _, grad, hess = solver.derivatives(x, pressure, loads)
        _, want_grad, want_hess = reference.derivatives(x, pressure, loads)
        # Every step is the caller's own array.
        first, _ = solver.step(grad, hess)
        again, _ = solver.step(grad, hess)
        assert again is not first
        np.testing.assert_array_equal(first, again)
        # Against the reference with the same gradient: near an equilibrium the two
        # gradients differ by round-off, which is all of the step.
        paths.add(_check_step(solver, reference, want_grad, hess, want_hess))
    # A compressive tip load far beyond the flat finger's buckling load: indefinite.
    for solver, reference, _, _, _, _ in states[::len(states) // 6]:
        load = [(solver.tip_node, np.array([-200.0, 0.0]))]
        x = solver.flat() + 1e-3
        _, grad, hess = solver.derivatives(x, 0.0, load)
        want_hess = reference.derivatives(x, 0.0, load)[2]
        paths.add(_check_step(solver, reference, grad, hess, want_hess))
    assert paths == {True, False}


def test_linear_solves_equal_numpy(states):
    rng = np.random.default_rng(7)
    for solver, reference, x, pressure, loads, _ in states[::5]:
        _, _, hess = solver.derivatives(x, pressure, loads)
        want_hess = reference.derivatives(x, pressure, loads)[2]
        dense = want_hess.dense()
        kappa = np.linalg.cond(dense)
        for rhs in (rng.normal(size=x.size), rng.normal(size=(x.size, 2))):
            got = solver.solve_linear(hess, rhs)
            assert got.shape == rhs.shape
            assert deviation(got, reference.solve_linear(want_hess, rhs)) <= STEP_RTOL * kappa
    # Indefinite: the banded LU of scipy, as the reference.
    solver, reference = states[0][:2]
    load = [(solver.tip_node, np.array([-200.0, 0.0]))]
    x = solver.flat() + 1e-3
    hess, want_hess = solver.derivatives(x, 0.0, load)[2], reference.derivatives(x, 0.0, load)[2]
    rhs = rng.normal(size=x.size)
    kappa = np.linalg.cond(want_hess.dense())
    assert deviation(solver.solve_linear(hess, rhs),
                     reference.solve_linear(want_hess, rhs)) <= STEP_RTOL * kappa


def test_kinematics_equal_numpy(states):
    for solver, reference, x, _, _, _ in states:
        n = solver.n_segments
        # Positions on the finger's scale, 0.1 m: the root nodes are near zero.
        assert deviation(solver.nodes(x), reference.nodes(x), 0.1) <= RTOL
        for node in {1, n // 3, n - 1, n} - {0}:
            position, jac = solver.node_jacobian(x, node)
            want_position, want_jac = reference.node_jacobian(x, node)
            assert deviation(position, want_position, 0.1) <= RTOL
            assert deviation(jac, want_jac) <= RTOL
        position, jac = solver.node_jacobian(x, 0)
        assert not position.any() and not jac.any()


def test_outputs_equal_numpy(states):
    # The compiled `outputs` hook against the numpy reference's, field by field.
    for solver, reference, x, pressure, loads, _ in states[::3]:
        state = solver._unpack(x)
        force = loads[0][1] if len(loads) == 1 else np.zeros(2)
        data = solver.engine_problem.data[True]
        hook = engine.hooks_of(type(data))['outputs']
        out = dict(zip(OUTPUT_FIELDS, hook(data, np.ascontiguousarray(x), pressure,
                                           np.array([solver.n_segments]), force[None], True)))
        want = reference._outputs(state, pressure, force)
        assert out['valid'] is True
        assert deviation(out['nodes'][-1], want['tip']) <= RTOL
        for key in ('points', 'tangent', 'strains', 'beta', 'coefficients', 'nodes', 'energy'):
            scale = abs(want[key]) if key == 'energy' else None
            assert deviation(out[key], want[key], scale) <= RTOL, key


@pytest.mark.parametrize('prestrain, pressure, force, n', [
    (0.40, 200e3, (0.0, 0.0), 24), (0.40, 200e3, (0.0, 1.0), 32), (0.25, 100e3, (0.0, 1.0), 24),
    (0.25, 0.0, (-1.0, 0.5), 64), (0.15, 200e3, (-5.0, 0.0), 24)])
def test_solves_equal_numpy(prestrain, pressure, force, n):
    # The same Newton path: iterations equal, states to round-off (the last -5 N scene
    # buckles through indefinite Hessians).
    design = ActuatorDesign.paper(prestrain)
    solver, reference = PCCSolver(design, n), ReferencePCCSolver(design, n)
    got, want = solver.solve(pressure, force), reference.solve(pressure, force)
    assert got.success and want.success, (got.message, want.message)
    assert got.iterations == want.iterations
    assert deviation(got.state, want.state) <= 1e-12
    assert deviation(got.tip, want.tip) <= 1e-12
    warm = solver.solve(pressure + 1e3, force, initial=got)
    want_warm = reference.solve(pressure + 1e3, force, initial=want)
    assert warm.iterations == want_warm.iterations
    assert deviation(warm.state, want_warm.state) <= 1e-12


def test_rigidity_equals_numpy():
    design = ActuatorDesign.paper(0.25)
    solver, reference = PCCSolver(design, 24), ReferencePCCSolver(design, 24)
    for pressure, axis in ((0.0, 'x'), (55.2e3, 'x'), (0.0, 'z')):
        got, want = solver.rigidity(pressure, axis), reference.rigidity(pressure, axis)
        assert got.success and want.success
        assert got.iterations == want.iterations
        assert got.value == pytest.approx(want.value, rel=1e-12)


# -- the compiled path differentiates itself ---------------------------------------------
@pytest.mark.parametrize('design, n, turning, loads', [
    (ActuatorDesign.paper(0.25).replace(ribs=False, Cx=0.110), 1, 3.0, 'tip'),
    (ActuatorDesign.paper(0.40), 22, 60.0, 'inner'),
    (ActuatorDesign.paper(0.15), 64, 3.0, 'inner'),
    (ActuatorDesign.paper(0.40).replace(ribs=False, Cx=0.110), 2, 5.0, 'inner'),
], ids=['N1-arc', 'N22-wide', 'N64', 'N2'])
def test_compiled_derivatives_match_finite_differences(design, n, turning, loads):
    # One segment turning by 3 rad and 22 by 60 rad in all use the closed forms of S;
    # N = 2 puts the inner load on the first segment's end.
    solver = PCCSolver(design, n)
    x = random_state(solver, 11, turning)
    load = load_cases(solver.n_segments)[loads]
    pressure = 150e3
    energy, grad, hess = solver.derivatives(x, pressure, load)
    # h = 1e-3 (rad, or strain): truncation and round-off below 1e-10 of the largest entry.
    g_fd = fd_derivative(lambda v: np.array(solver.energy(v, pressure, load)), x, 1e-3)
    np.testing.assert_allclose(grad, g_fd, rtol=0, atol=1e-10 * np.abs(grad).max())
    dense = hess.dense()
    h_fd = fd_derivative(lambda v: solver.derivatives(v, pressure, load)[1], x, 1e-3)
    np.testing.assert_allclose(dense, h_fd, rtol=0, atol=1e-10 * np.abs(dense).max())
    far = np.abs(np.subtract.outer(np.arange(x.size), np.arange(x.size))) > 3
    assert np.abs(h_fd[far]).max(initial=0.0) <= 1e-12 * np.abs(dense).max()
    for node in {1, solver.n_segments // 2, solver.n_segments} - {0}:
        position, jac = solver.node_jacobian(x, node)
        np.testing.assert_array_equal(position, solver.nodes(x)[node])
        j_fd = fd_derivative(lambda v: solver.nodes(v)[node], x, 1e-3)
        np.testing.assert_allclose(jac, j_fd, rtol=0, atol=1e-10 * np.abs(jac).max())
    # The banded Cholesky of the compiled path solves the dense system.
    _, min_eig = solver.step(grad, hess)
    rhs = np.random.default_rng(3).normal(size=x.size)
    if min_eig == 1.0:
        np.testing.assert_allclose(dense @ solver.solve_linear(hess, rhs), rhs,
                                   atol=1e-12 * np.linalg.cond(dense))


def test_load_and_node_errors():
    solver = PCCSolver(ActuatorDesign.paper(0.25), 24)
    x = solver.flat()
    for node in (25, -1, 2.0, True):
        with pytest.raises(ValueError, match='node'):
            solver.energy(x, 0.0, [(node, np.array([1.0, 0.0]))])
        with pytest.raises(ValueError, match='node'):
            solver.derivatives(x, 0.0, [(node, np.array([1.0, 0.0]))])
        with pytest.raises(ValueError, match='node'):
            solver.node_jacobian(x, node)
