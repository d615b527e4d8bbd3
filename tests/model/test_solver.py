"""Solver behaviour: warm starts, no hidden state, limits, loads, failures and bad input."""

import numpy as np
import pytest

from fpc_gripper.model import ActuatorDesign, CCMSolver, SolverStatus


@pytest.fixture(scope='module')
def solver():
    return CCMSolver(ActuatorDesign.paper(prestrain=0.25), n_segments=8)


def test_zero_prestrain_and_pressure_is_flat():
    result = CCMSolver(ActuatorDesign.paper(prestrain=0.0), 4).solve(0.0)
    assert result.success
    np.testing.assert_allclose(result.coefficients, 0.0, atol=1e-14)
    np.testing.assert_allclose(result.tip, (0.090, 0.0), atol=1e-14)
    assert abs(result.curvature) < 1e-9


def test_warm_start_and_cold_start_agree(solver):
    cold = solver.solve(120e3, tip_force=(0.1, -0.2))
    warm = solver.solve(120e3, tip_force=(0.1, -0.2), initial=solver.solve(110e3))
    from_array = solver.solve(120e3, tip_force=(0.1, -0.2), initial=cold.coefficients)
    for other in (warm, from_array):
        assert other.success
        np.testing.assert_allclose(other.coefficients, cold.coefficients, rtol=1e-7,
                                   atol=1e-9)
    assert from_array.iterations <= 2


def test_no_hidden_state(solver):
    first = solver.solve(80e3)
    solver.solve(300e3, tip_force=(0.5, 0.5))
    again = solver.solve(80e3)
    # A hidden warm start (from the 300 kPa state, or from 79 kPa) moves the converged
    # coefficients by only ~6e-15 relative, too little to tell from round-off, but it
    # changes the Newton iteration count (5 cold, 6 and 3 warm): an integer, exact.
    # The coefficients then agree to round-off, which is not bitwise on BLAS builds that
    # are not reproducible between calls (e.g. MKL without CNR).
    assert again.iterations == first.iterations
    np.testing.assert_allclose(again.coefficients, first.coefficients, rtol=1e-12,
                               atol=1e-12 * np.abs(first.coefficients).max())


def test_isobaric_is_adiabatic_at_scaled_pressure():
    # k_p = 2.5 (adiabatic) against 1 (isobaric): the same work at 2.5 times the pressure.
    d = ActuatorDesign.paper(prestrain=0.25)
    a = CCMSolver(d, 8, pressure_model='adiabatic').solve(100e3)
    b = CCMSolver(d, 8, pressure_model='isobaric').solve(250e3)
    np.testing.assert_allclose(a.coefficients, b.coefficients, rtol=1e-9, atol=1e-12)


def test_tip_force_directions(solver):
    free = solver.solve(100e3)
    pushed = solver.solve(100e3, tip_force=(0.0, 0.3))
    pulled = solver.solve(100e3, tip_force=(0.3, 0.0))
    assert pushed.tip[1] > free.tip[1]
    assert pulled.tip[0] > free.tip[0]
    # Work balance: the loaded state has lower total potential than the free state does
    # under the same load (free state is not an equilibrium of the loaded problem).
    assert pushed.energy < solver.energy(free.state, 100e3,
                                         solver._loads(pushed.tip_force, pushed.point_loads))


def test_point_load_at_tip_equals_tip_force():
    d = ActuatorDesign.paper(prestrain=0.25)
    s = CCMSolver(d, 8, load_points=(0.090,))
    a = s.solve(50e3, tip_force=(0.2, 0.1))
    b = s.solve(50e3, point_loads=[(0.090, 0.2, 0.1)])
    np.testing.assert_allclose(a.coefficients, b.coefficients, rtol=1e-10, atol=1e-13)


def test_intermediate_load_leaves_distal_segments_unloaded():
    d = ActuatorDesign.paper(prestrain=0.25)
    s = CCMSolver(d, 9, load_points=(0.030,))
    assert np.any(np.isclose(s.segments.edges, 0.030, atol=1e-15))
    loaded = s.solve(0.0, point_loads=[(0.030, 0.3, -0.4)])
    free = s.solve(0.0)
    node = int(np.argmin(np.abs(s.segments.edges - 0.030)))
    np.testing.assert_allclose(loaded.coefficients[node:], free.coefficients[node:],
                               rtol=1e-8, atol=1e-10)
    assert not np.allclose(loaded.coefficients[:node], free.coefficients[:node])


def test_small_rotation_rule_is_flagged():
    result = CCMSolver(ActuatorDesign.paper(prestrain=0.40), 2).solve(0.0)
    assert result.success
    assert not result.valid
    assert 'small-rotation' in result.message
    assert CCMSolver(ActuatorDesign.paper(prestrain=0.40), 8).solve(0.0).valid


def test_non_convergence_is_reported(solver):
    strict = CCMSolver(ActuatorDesign.paper(prestrain=0.40), 8, max_iterations=2)
    result = strict.solve(0.0)
    assert not result.success
    assert result.status is not SolverStatus.SUCCESS
    assert result.message


def test_buckling_load_reports_failure_or_an_honest_state():
    # A large compressive tip load along -X: whatever comes back must be self-consistent.
    s = CCMSolver(ActuatorDesign.paper(prestrain=0.05), 4)
    result = s.solve(0.0, tip_force=(-5.0, 0.0))
    if result.success:
        _, grad, _ = s.derivatives(result.state, 0.0, s._loads(result.tip_force, ()))
        assert np.abs(grad).max() / s.gradient_scale < 1e-8
    else:
        assert result.message


def test_samples_layout(solver):
    r = solver.solve(0.0)
    assert r.points.shape == (8 * 16 + 1, 2)
    np.testing.assert_allclose(r.points[0], 0.0)
    np.testing.assert_allclose(r.points[-1], r.tip)
    np.testing.assert_allclose(r.points[::16][:-1], r.nodes[:-1])
    assert r.tangent[0] == pytest.approx(0.0)
    np.testing.assert_allclose(np.cumsum(r.beta)[-1], r.tangent[-1], atol=1e-12)


@pytest.mark.parametrize('kwargs, exc, message', [
    ({'pressure': float('nan')}, ValueError, '`pressure` must be finite'),
    ({'pressure': float('inf')}, ValueError, '`pressure` must be finite'),
    ({'pressure': -1.0}, ValueError, '`pressure` must be >= 0'),
    ({'pressure': '1e5'}, TypeError, '`pressure` must be a real number'),
    ({'pressure': 0.0, 'tip_force': (np.nan, 0.0)}, ValueError, 'tip_force'),
    ({'pressure': 0.0, 'tip_force': (1.0,)}, ValueError, 'tip_force'),
    ({'pressure': 0.0, 'initial': np.zeros((3, 4))}, ValueError, 'initial'),
    ({'pressure': 0.0, 'point_loads': [(0.031, 1.0, 0.0)]}, ValueError, 'segment edge'),
])
def test_bad_input_raises_clear_errors(solver, kwargs, exc, message):
    with pytest.raises(exc, match=message):
        solver.solve(**kwargs)


def test_bad_constructor_arguments():
    d = ActuatorDesign.paper()
    with pytest.raises(ValueError, match='pressure_model'):
        CCMSolver(d, pressure_model='isothermal')
    with pytest.raises(ValueError, match='n_segments'):
        CCMSolver(d, n_segments=0)
    with pytest.raises(TypeError, match='ActuatorDesign'):
        CCMSolver({'Lx': 0.1})
    with pytest.raises(ValueError, match='segment_edges'):
        CCMSolver(d, segment_edges=[0.0, 0.05, 0.04, 0.09])
    with pytest.raises(ValueError, match='axis'):
        CCMSolver(d).rigidity(0.0, axis='y')


def test_explicit_segment_edges():
    d = ActuatorDesign.paper(prestrain=0.25)
    edges = np.array([0.0, 0.01, 0.025, 0.05, 0.07, 0.09])
    s = CCMSolver(d, segment_edges=edges)
    r = s.solve(0.0)
    assert r.success and r.coefficients.shape == (5, 4)
    np.testing.assert_allclose(s.segments.lengths, np.diff(edges))
