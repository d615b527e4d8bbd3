"""Contact: exact derivatives, closed forms, determinism and bad input of finger-object contact."""

from helpers import fd_derivative
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

from fpc_gripper.model import ActuatorDesign, engine, PCCSolver, SolverStatus
from fpc_gripper.model import contact as C
from fpc_gripper.model.kernels import contact as ck
from fpc_gripper.model.obstacles import obstacle_params
from fpc_gripper.model.pipeline import contact_model
from fpc_gripper.model.section.law import station_layout

DESIGN = ActuatorDesign.paper(0.25)
INNER = C.ContactSettings(faces=('inner',))
#: One of each obstacle, placed so that the random finger states below meet their faces,
#: curved parts and (polygon) corner blends.
OBSTACLES = (
    C.Circle((0.05, -0.05), 0.02),
    C.HalfPlane((0.0, -0.04), (0.3, 1.0)),
    C.ConvexPolygon([(0.03, -0.06), (0.05, -0.06), (0.05, -0.03), (0.03, -0.03)], 0.003),
    C.Ellipse((0.05, -0.05), (0.02, 0.01), 0.3),
)


@pytest.fixture(scope='module')
def solver():
    return PCCSolver(DESIGN, 22)


def random_state(solver, seed, spread=0.02, pressure=50e3):
    x = solver._pack(solver.solve(pressure).state)
    return x + spread * np.random.default_rng(seed).standard_normal(x.size)


# -- the obstacles' gap functions -----------------------------------------------------------
@pytest.mark.parametrize('obstacle', OBSTACLES, ids=lambda o: type(o).__name__)
def test_gap_function_derivatives_against_differences(obstacle):
    kind, params = obstacle_params((obstacle,))
    rng = np.random.default_rng(3)
    points = np.array([0.05, -0.05]) + 0.03 * rng.standard_normal((40, 2))
    if isinstance(obstacle, C.ConvexPolygon):
        # Points in the corner blends: around every vertex, outside and inside.
        corners = np.array(obstacle.vertices)
        points = np.concatenate([points, corners + 0.002 * rng.standard_normal((4, 2)),
                                 corners + 0.0015 * rng.standard_normal((4, 2))])

    def gap(p):
        return np.array([ck.signed_distance(int(kind[0]), params[0], *p)[0]])

    def gradient(p):
        return np.array(ck.signed_distance(int(kind[0]), params[0], *p)[1:3])

    for p in points:
        g, gx, gz, curvature, vx, vz = ck.signed_distance(int(kind[0]), params[0], *p)
        np.testing.assert_allclose([gx, gz], fd_derivative(gap, p, 1e-6)[0], atol=1e-8)
        hessian = curvature * np.outer([vx, vz], [vx, vz])
        np.testing.assert_allclose(hessian, fd_derivative(gradient, p, 1e-6), atol=1e-5,
                                   rtol=1e-6)
        assert abs(np.hypot(vx, vz) - 1.0) < 1e-12


def test_gap_is_the_distance_where_it_claims_to_be():
    """Circle, half-plane and ellipse: g equals the distance to sampled boundary points."""
    rng = np.random.default_rng(5)
    for obstacle, boundary in [
            (OBSTACLES[0], lambda t: np.stack([0.05 + 0.02 * np.cos(t),
                                               -0.05 + 0.02 * np.sin(t)], 1)),
            (OBSTACLES[3], lambda t: np.array([0.05, -0.05]) + np.stack(
                [0.02 * np.cos(t) * np.cos(0.3) - 0.01 * np.sin(t) * np.sin(0.3),
                 0.02 * np.cos(t) * np.sin(0.3) + 0.01 * np.sin(t) * np.cos(0.3)], 1))]:
        kind, params = obstacle_params((obstacle,))
        curve = boundary(np.linspace(0, 2 * np.pi, 200001))
        for p in np.array([0.05, -0.05]) + 0.04 * rng.standard_normal((10, 2)):
            g = ck.signed_distance(int(kind[0]), params[0], *p)[0]
            distance = np.hypot(*(curve - p).T).min()
            assert abs(abs(g) - distance) < 1e-9


@pytest.mark.parametrize('seed', [0, 1])
def test_face_point_kinematics_and_loads_against_differences(solver, seed):
    x = random_state(solver, seed)
    rng = np.random.default_rng(seed)
    seg = np.array([0, 3, 10, 21, 21])
    off = np.array([0.5, 1.0, 0.3, 1.0, 0.5]) * solver.lengths[seg]
    z = np.array([-1, 1, -1, -1, 0.5]) * DESIGN.H / 2
    force = rng.standard_normal((5, 2))
    loads = [(solver.tip_node, np.array([0.1, 0.3]))]

    def energy(v):
        return np.array([solver.point_derivatives(v, 50e3, loads, seg, off, z, force)[0]])

    def gradient(v):
        return solver.point_derivatives(v, 50e3, loads, seg, off, z, force)[1]

    e, g, hess = solver.point_derivatives(x, 50e3, loads, seg, off, z, force)
    np.testing.assert_allclose(g, fd_derivative(energy, x, 1e-5)[0], atol=1e-8)
    np.testing.assert_allclose(hess.dense(), fd_derivative(gradient, x, 1e-5), atol=1e-6)
    # The potential of the point loads is -F . p: against the positions themselves.
    positions = solver.point_positions(x, seg, off, z)
    assert e == pytest.approx(solver.energy(x, 50e3, loads) - np.sum(force * positions),
                              abs=1e-14)
    for k in range(seg.size):
        p, jac = solver.point_jacobian(x, seg[k], off[k], z[k])
        np.testing.assert_allclose(p, positions[k], atol=1e-15)
        np.testing.assert_allclose(
            jac, fd_derivative(lambda v: solver.point_jacobian(v, seg[k], off[k], z[k])[0],
                               x, 1e-6), atol=1e-10)
    # A point at the tip's end on the midplane is the tip node.
    np.testing.assert_allclose(solver.point_jacobian(x, 21, solver.lengths[21], 0.0)[1],
                               solver.node_jacobian(x, 22)[1], atol=1e-15)


def kkt(solver, con, x, lam, offset=0.0):
    """The bordered system's residual (r, c + E lam) and its Jacobian, from the engine."""
    nodes, forces = np.zeros(0, dtype=np.int64), np.zeros((0, 2))
    c, comp, brow, grow, urow, vrow, coef, residual, hess = engine.bordered._kkt(
        con, solver, x, lam, 40e3, nodes, forces, offset)
    n = x.size
    jac = np.zeros((n + c.size, n + c.size))
    jac[:n, :n] = hess.dense() - urow.T @ np.diag(coef) @ vrow
    jac[:n, n:] = -brow.T
    jac[n:, :n] = grow
    jac[n:, n:] = np.diag(comp)
    return np.concatenate([residual, c + comp * lam]), jac


@pytest.mark.parametrize('obstacle', OBSTACLES, ids=lambda o: type(o).__name__)
def test_contact_rows_are_exact_derivatives(solver, obstacle):
    """The Newton system of every pair status (frictionless, stick, slip both ways)."""
    x = random_state(solver, 2)
    con = C._contact_set(solver, C.finger_points(solver), (obstacle,), 0.4, 0.0)
    status = np.zeros(con.status.size, dtype=np.int64)
    picks = [10, 30, 50, 70, 80]
    status[picks] = [ck.NORMAL, ck.STICK, ck.SLIP_POS, ck.SLIP_NEG, ck.NORMAL]
    anchors = solver.point_positions(x, con.pseg, con.poff, con.pz)[con.pair_point] + 1e-3
    con = con._replace(status=status, anchor=anchors, compliance=1e-3)
    lam = np.random.default_rng(4).standard_normal(engine.bordered._row_count(status))
    values, jac = kkt(solver, con, x, lam)
    state = np.concatenate([x, lam])

    def residual(v):
        return kkt(solver, con, v[:x.size], v[x.size:])[0]

    numeric = fd_derivative(residual, state, 1e-6)
    assert np.abs(jac - numeric).max() <= 1e-7 * np.abs(jac).max()


# -- closed forms ------------------------------------------------------------------------------
def cantilever_compliance(solver, free, pressure):
    """delta / F of the linear cantilever: int (L - s)^2 / EI(s) ds, EI with eps, c1 condensed."""
    breaks, types, law = station_layout(solver.design, ribs='exact')
    prev = np.concatenate([[0.0], free.state[:-1, 0]])
    length = solver.design.free_length
    work = solver.pressure_coefficient * pressure
    total = 0.0
    for a, b, kind in zip(breaks, breaks[1:], types):
        i = int(np.searchsorted(solver.edges, 0.5 * (a + b))) - 1
        y = np.array([free.state[i, 1], (free.state[i, 0] - prev[i]) / solver.lengths[i],
                      free.state[i, 2]])
        hess = law.derivatives(y, work, kind)[2]
        rest = [0, 2]
        bending = hess[1, 1] - hess[1, rest] @ np.linalg.solve(hess[np.ix_(rest, rest)],
                                                               hess[rest, 1])
        total += ((length - a) ** 3 - (length - b) ** 3) / 3.0 / bending
    return total


@pytest.mark.parametrize('delta', [0.05e-3, 0.1e-3])
def test_flat_finger_pressed_at_its_tip_is_a_linear_cantilever(delta):
    """
    A finger without prestrain at 2 kPa is nearly flat, its tip a little above its root;
    a half-plane above it pushes the CL-face tip corner down by delta.
    """
    design = ActuatorDesign.paper(0.0)
    solver = contact_model(design)
    pressure = 2e3
    free = solver.solve(pressure)
    x = solver._pack(free.state)
    corner = solver.point_positions(x, [solver.n_segments - 1], [solver.lengths[-1]],
                                    [design.H / 2])[0]
    wall = C.HalfPlane((0.0, corner[1] - delta), (0.0, -1.0))
    result = C.solve_contact(solver, pressure, wall, settings=C.ContactSettings(
        faces=('outer',)))
    assert result.success, result.message
    (arc,) = result.arcs
    assert (arc.face, arc.points) == ('outer', 1)
    assert arc.start == pytest.approx(design.free_length, abs=1e-15)
    linear = delta / cantilever_compliance(solver, free, pressure)
    assert result.normal_force_total == pytest.approx(linear, rel=2e-3)


def uniform_finger():
    """No ribs, channel over the whole free length: unloaded, an exact arc."""
    design = DESIGN.replace(ribs=False, Cx=0.110)
    solver = PCCSolver(design, 32)
    free = solver.solve(100e3)
    eps, kappa = free.strains[0, 0], free.strains[0, 1]
    radius = (1.0 + eps) / abs(kappa)
    # The PEMC face is an arc of radius R - H/2 about (0, -R).
    return solver, C.Circle((0.0, -radius), radius - design.H / 2)


def test_finger_on_a_cylinder_of_its_own_curvature_touches_along_an_arc_without_force():
    solver, cylinder = uniform_finger()
    result = C.solve_contact(solver, 100e3, cylinder, settings=INNER)
    assert result.success, result.message
    points = C.finger_points(solver, INNER)
    (arc,) = result.arcs
    assert arc.points == points.s.size            # every point of the face touches
    assert (arc.start, arc.end) == pytest.approx((points.s[0], solver.design.free_length),
                                                 abs=1e-15)
    assert np.abs(result.gap).max() < 1e-12
    assert result.normal_force_total < 1e-9
    # Curled a little more (less pressure), it presses: force proportional to the change.
    pressed = [C.solve_contact(solver, 100e3 - dp, cylinder, settings=INNER)
               for dp in (10.0, 100.0)]
    assert all(r.success for r in pressed), [r.message for r in pressed]
    forces = [r.normal_force_total for r in pressed]
    assert 0.0 < forces[0] < 1e-3
    assert forces[1] / forces[0] == pytest.approx(10.0, rel=2e-3)


# -- equilibrium, complementarity, determinism --------------------------------------------------
SPHERE = C.Circle((0.045, -0.062), 0.025)


@pytest.mark.parametrize('pressure', [0.0, 40e3])
def test_constrained_state_satisfies_the_kkt_conditions(pressure):
    """Force balance by the finger's own derivatives, and complementarity, checked afresh."""
    solver = contact_model(DESIGN)
    result = C.solve_contact(solver, pressure, SPHERE)
    assert result.success, result.message
    points = result.points
    x = result.state[0]
    forces = np.zeros((points.s.size, 2))
    np.add.at(forces, np.arange(points.s.size), result.force)     # one obstacle: pair = point
    grad = solver.point_derivatives(x, pressure, [], points.segment, points.offset,
                                    points.height, forces)[1]
    assert np.abs(grad).max() <= 1e-10 * solver.gradient_scale
    assert result.gap.min() >= -1e-13
    assert result.normal_force.min() >= 0.0
    assert np.abs(result.gap[result.in_contact]).max() <= 1e-13
    # Forces on the object balance the finger's: total force and moment.
    np.testing.assert_allclose(result.total_force[0], -result.force.sum(axis=0), atol=1e-15)
    assert result.normal_force_total > 0.1


def test_compiled_and_interpreted_loops_agree():
    solver = contact_model(DESIGN)

    class Interpreted:
        """The PCC handing the engine itself: the engine runs its contact loops in Python."""

        def __init__(self, inner):
            self._inner = inner
            for name in ('gradient_scale', 'length', 'edges', 'design', 'tip_node', 'rung',
                         '_options', 'n_segments', 'lengths'):
                setattr(self, name, getattr(inner, name))

        @property
        def engine_problem(self):
            return self

        def __getattr__(self, name):
            return getattr(self._inner, name)

    compiled = C.solve_contact(solver, 0.0, SPHERE)
    interpreted = C.solve_contact(Interpreted(solver), 0.0, SPHERE)
    assert compiled.iterations == interpreted.iterations
    np.testing.assert_allclose(interpreted.state[0], compiled.state[0], atol=1e-12)
    np.testing.assert_allclose(interpreted.normal_force, compiled.normal_force, atol=1e-10)


@settings(max_examples=8, deadline=None, derandomize=True)
@given(st.lists(st.sampled_from([0.0, 20e3, 40e3, 55e3, 80e3]), min_size=1, max_size=4))
def test_answer_does_not_depend_on_the_warm_start(history):
    """Any history of warm-started solves ends where a cold solve does."""
    solver = contact_model(DESIGN)
    previous = None
    for pressure in history:
        previous = C.solve_contact(solver, pressure, SPHERE, initial=previous)
    cold = C.solve_contact(solver, history[-1], SPHERE)
    np.testing.assert_allclose(previous.state[0], cold.state[0], atol=1e-10)
    assert np.array_equal(previous.in_contact, cold.in_contact)
    assert previous.normal_force_total == pytest.approx(cold.normal_force_total, abs=1e-9)


def test_friction_path_closes_and_the_tip_slides():
    """Closing on a flat face, the tip slides at the Coulomb limit: |F_t| = mu F_n."""
    solver = contact_model(DESIGN)
    face = C.HalfPlane((0.0, -0.042), (0.0, 1.0))
    path = C.contact_path(solver, np.arange(200e3, 59e3, -10e3), face, mu=0.5)
    assert all(r.success for r in path), [r.message for r in path]
    last = path[-1]
    touching = last.in_contact
    assert touching.sum() == 1 and last.s[touching][0] == DESIGN.free_length
    assert abs(last.tangential_force[touching][0]) == pytest.approx(
        0.5 * last.normal_force[touching][0], rel=1e-9)
    # Without friction the same pressure presses harder: friction holds the tip back.
    frictionless = C.solve_contact(solver, last.pressure, face)
    assert frictionless.normal_force_total > last.normal_force_total


# -- bad input -----------------------------------------------------------------------------------
@pytest.mark.parametrize('make, word', [
    (lambda: C.Circle((0.0, 0.0), -0.01), 'radius'),
    (lambda: C.Circle((float('nan'), 0.0), 0.01), 'center'),
    (lambda: C.HalfPlane((0.0, 0.0), (0.0, 0.0)), 'normal'),
    (lambda: C.ConvexPolygon([(0, 0), (1, 0), (0.2, 0.2), (0, 1)]), 'convex'),
    (lambda: C.ConvexPolygon([(0, 0), (0.001, 0), (0, 0.001)]), 'corner_radius'),
    (lambda: C.ConvexPolygon([(0, 0), (1, 0)]), 'vertices'),
    (lambda: C.Ellipse((0.0, 0.0), (0.01, -0.02)), 'semi_axes'),
    (lambda: C.ContactSettings(points_per_segment=3), 'points_per_segment'),
    (lambda: C.ContactSettings(faces=('top',)), 'faces'),
    (lambda: C.ContactSettings(penalty=-1.0), 'penalty'),
])
def test_bad_obstacles_and_settings_are_refused(make, word):
    with pytest.raises((ValueError, TypeError), match=word):
        make()


def test_bad_solve_input_is_refused(solver):
    with pytest.raises(ValueError, match='pressure'):
        C.solve_contact(solver, -1.0, SPHERE)
    with pytest.raises(ValueError, match='pressure'):
        C.solve_contact(solver, float('nan'), SPHERE)
    with pytest.raises(TypeError, match='obstacles'):
        C.solve_contact(solver, 0.0, [])
    with pytest.raises(TypeError, match='face points'):
        C.solve_contact(object(), 0.0, SPHERE)
    with pytest.raises(ValueError, match='mu'):
        C.contact_path(solver, [0.0], SPHERE, mu=-0.1)


def test_an_obstacle_through_the_clamp_fails_honestly(solver):
    """Nothing can push the clamped root out: the growth stalls and says so."""
    result = C.solve_contact(solver, 100e3, C.Circle((0.0, 0.0), 0.01))
    assert not result.success
    assert result.status is SolverStatus.CONTINUATION_FAILED
    assert 'stalled' in result.message
