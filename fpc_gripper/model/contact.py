"""Finger-object contact: rigid planar obstacles, frictionless or with Coulomb friction."""

from dataclasses import dataclass
import functools
import weakref

import numpy as np

from . import engine
from .engine import SolverStatus
from .kernels import contact as ck
from .obstacles import (check_obstacles, Circle, ConvexPolygon, Ellipse, HalfPlane,
                        obstacle_params, translated)
from .result import Result
from .validation import real_number, real_pair

__all__ = ['Circle', 'HalfPlane', 'ConvexPolygon', 'Ellipse', 'ContactSettings',
           'contact_result', 'CONTACT_FIELDS', 'ContactArc', 'FingerPoints', 'finger_points',
           'solve_contact',
           'contact_path', 'translated', 'point_gaps', 'FACES']

#: Faces of the finger: the PEMC face at z = -H/2 (inner: the gripper closes towards it)
#: and the constraining layer at z = +H/2 (outer).
FACES = ('inner', 'outer')
#: A pair whose gap is at most this is touching, even without force [m].
TOUCH_GAP = 1e-9
#: Relative force below which a pair carries no force [-] (of the finger's force scale).
_FORCE_TOL = 1e-9
_MESSAGES = {
    SolverStatus.SUCCESS: 'converged: {summary}',
    SolverStatus.MAX_ITERATIONS: 'the contact step did not converge (active set or Newton; '
                                 '{fraction:.1%} of the step reached)',
    SolverStatus.LINE_SEARCH_FAILED: 'the free finger found no descent: {finger}',
    SolverStatus.NOT_FINITE: 'energy or gradient became non-finite',
    SolverStatus.UNSTABLE: 'converged to a state whose stability {why}: {summary}',
    SolverStatus.CONTINUATION_FAILED: 'growing the obstacles into place stalled at '
                                      '{fraction:.1%}',
}


@dataclass(frozen=True)
class ContactSettings:
    """
    How the finger's contact is discretised.

    Parameters
    ----------
    faces : tuple of str
        Faces that may touch, from FACES ('inner': the PEMC face at z = -H/2, 'outer': the
        constraining layer at z = +H/2).
    points_per_segment : {1, 2}
        Contact points per PCC segment and face: its end (1), or its middle and end (2).
        More would over-constrain a segment lying on a circle (an arc of three unknowns
        through more than two points besides its start). The rod has points at its
        element ends only (1).
    penalty : float
        0 (the default): contact is a constraint. > 0: a penalty surface of that
        stiffness [N/m] instead, lambda = k max(-g, 0) (for validation: it converges to
        the constraint as 1/k).

    """

    faces: tuple = FACES
    points_per_segment: int = 2
    penalty: float = 0.0

    def __post_init__(self):
        """Check every field."""
        faces = tuple(self.faces) if not isinstance(self.faces, str) else (self.faces,)
        if not faces or any(f not in FACES for f in faces) or len(set(faces)) != len(faces):
            raise ValueError(f'`faces` must be distinct names from {FACES}, got '
                             f'{self.faces!r}')
        object.__setattr__(self, 'faces', tuple(f for f in FACES if f in faces))
        m = self.points_per_segment
        if isinstance(m, bool) or m not in (1, 2):
            raise ValueError(f'`points_per_segment` must be 1 or 2, got {m!r}')
        penalty = real_number('penalty', self.penalty, '[N/m]')
        if penalty < 0.0:
            raise ValueError(f'`penalty` must be >= 0 [N/m], got {penalty}')
        object.__setattr__(self, 'penalty', penalty)


@dataclass(frozen=True)
class FingerPoints:
    """
    Candidate contact points of a finger discretisation.

    Attributes
    ----------
    segment : ndarray of int, shape (K,)
    offset : ndarray, shape (K,)
        Reference arc length into the segment [m].
    height : ndarray, shape (K,)
        z from the midplane along its normal [m].
    s : ndarray, shape (K,)
        Reference arc length from the clamp [m].
    face : ndarray of int, shape (K,)
        Index into FACES.
    weight : ndarray, shape (K,)
        Tributary length of the point along its face [m]: a point's force over it is
        the line load.

    """

    segment: np.ndarray
    offset: np.ndarray
    height: np.ndarray
    s: np.ndarray
    face: np.ndarray
    weight: np.ndarray


#: The face points of each solver and contact settings (weak keys: they go with the solver).
_FINGER_POINTS = weakref.WeakKeyDictionary()


def finger_points(solver, settings=ContactSettings()):
    """
    Contact points of a finger: fixed material points on its faces.

    Each point is a gap function of the state, exact on the PCC's arcs (closed form) and
    at the rod's element ends; between points a convex obstacle may penetrate by the
    sagitta difference h^2 (1/R - 1/R_face) / 8 of their spacing h, so the contact
    converges at second order in h (docs/physics.md, section 15.2).

    Parameters
    ----------
    solver : PCCSolver or RodSolver
    settings : ContactSettings

    Returns
    -------
    FingerPoints

    """
    if not isinstance(settings, ContactSettings):
        raise TypeError(f'`settings` must be a ContactSettings, got '
                        f'{type(settings).__name__}')
    _check_solver(solver)
    # A function of the solver's edges and the settings: built once per solver, and kept
    # here rather than on the solver, which contact never writes into.
    memo = _FINGER_POINTS.setdefault(solver, {})
    if settings not in memo:
        memo[settings] = _finger_points(solver, settings)
    return memo[settings]


def _check_solver(solver):
    if not hasattr(solver, 'point_jacobian'):
        raise TypeError(f'contact needs a finger model with face points (PCCSolver or '
                        f'RodSolver, e.g. `pipeline.contact_model`), got '
                        f'{type(solver).__name__}')


def _finger_points(solver, settings):
    edges = np.asarray(solver.edges, dtype=float)
    lengths = np.diff(edges)
    m = settings.points_per_segment
    if getattr(solver, 'rung', '') == 'rod' and m != 1:
        raise ValueError('`points_per_segment` must be 1 for RodSolver (its points are its '
                         'element ends)')
    fractions = (1.0,) if m == 1 else (0.5, 1.0)
    seg = np.repeat(np.arange(lengths.size), len(fractions))
    off = (lengths[:, None] * np.array(fractions)[None, :]).ravel()
    s = edges[seg] + off
    # Tributary lengths: from half-way to the previous point to half-way to the next.
    bounds = np.concatenate([[0.0], 0.5 * (s[1:] + s[:-1]), [edges[-1]]])
    weight = np.diff(bounds)
    half = 0.5 * solver.design.H
    parts = []
    for face in settings.faces:
        index = FACES.index(face)
        parts.append((seg, off, np.full(s.size, -half if face == 'inner' else half), s,
                      np.full(s.size, index), weight))
    return FingerPoints(*(np.concatenate(column) for column in zip(*parts)))


def _contact_set(solver, points, obstacles, mu, penalty):
    kind, params = obstacle_params(obstacles)
    count = points.s.size * len(obstacles)
    compliance = 0.0 if penalty == 0.0 else 1.0 / penalty
    return engine.ContactSet(
        np.ascontiguousarray(points.segment, dtype=np.int64),
        np.ascontiguousarray(points.offset, dtype=float),
        np.ascontiguousarray(points.height, dtype=float), kind, params,
        np.repeat(np.arange(points.s.size), len(obstacles)).astype(np.int64),
        np.tile(np.arange(len(obstacles)), points.s.size).astype(np.int64),
        np.zeros(count, dtype=np.int64), np.zeros((count, 2)), float(mu), compliance,
        float(solver.length))


@dataclass(frozen=True)
class ContactArc:
    """
    A run of neighbouring contact points on one face against one obstacle.

    Attributes
    ----------
    face : str
    obstacle : int
        Index into the result's obstacles.
    start, end : float
        Reference arc length of its first and last point [m] (equal for a point contact).
    points : int
    normal_force : float
        Sum of its points' normal forces [N].

    """

    face: str
    obstacle: int
    start: float
    end: float
    points: int
    normal_force: float

    @property
    def length(self):
        """Return end - start [m]."""
        return self.end - self.start


#: The fields of a contact solve's `Result`, besides success, status, message and iterations.
CONTACT_FIELDS = {
    'pressure': '[Pa]', 'mu': 'Coulomb coefficient [-]',
    'points': 'the finger points that may touch (`FingerPoints`)',
    'obstacles': 'at the pose of this state',
    'state': '(engine unknowns, multipliers, pair statuses): a warm start',
    'anchors': "sticking pairs' anchors", 'fraction': 'of the step reached',
    'stability': 'the smallest eigenvalue certifying stability (0: not certified)',
    'finger': "the finger's Result at this state (outputs 'all'; its loads the tip force)",
    'tip': 'position of the midplane tip, (X, Z) [m]',
    's': "per (point, obstacle) pair: the point's reference arc length [m]",
    'face': 'face index into FACES', 'obstacle': 'obstacle index',
    'position': "the pair's finger point [m]",
    'gap': 'signed distance of the point from the obstacle [m]',
    'normal': 'outward normal nu of the obstacle at the nearest boundary point',
    'tangent': 'tau = (-nu_z, nu_x)', 'force': 'contact force on the finger [N]',
    'normal_force': 'force . nu (>= 0) [N]', 'tangential_force': 'force . tau [N]',
    'line_load': 'normal force over the tributary length [N/m]',
    'tangential_line_load': 'tangential force over the tributary length [N/m]',
    'pair_status': '`kernels.contact` status (FREE, NORMAL, STICK, SLIP_POS, SLIP_NEG)',
    'in_contact': 'carrying a normal force', 'touching': 'in contact, or within TOUCH_GAP',
    'arcs': 'runs of touching points (ContactArc)',
    'total_force': 'force of the finger on each obstacle, (B, 2) [N]',
    'total_moment': "its moment about the obstacle's `reference`, about +Y, (B,) [N m]",
    'normal_force_total': 'sum of every normal force [N]', 'faces': 'faces in contact',
    'summary': 'one line: arcs in contact and the total normal force',
    'contact_arc': 'function (face=None) -> (start, end) [m] of the touching points, or None',
}


def contact_result(solver, outcome, points, obstacles, params, pressure, tip_force, mu=0.0,
                   loads=()):
    """
    Build the Result of a contact solve (`CONTACT_FIELDS`): every field computed here.

    Parameters
    ----------
    solver : PCCSolver or RodSolver
    outcome : engine.ContactOutcome
    points : FingerPoints
    obstacles : sequence
        At the pose of this state.
    params : ndarray
        The obstacles' kernel parameters at that pose.
    pressure : float
        [Pa].
    tip_force : ndarray (2,)
        [N].
    mu : float
        [-].
    loads : sequence
        The engine loads of the tip force.

    """
    status = SolverStatus(outcome.status)
    obstacles = tuple(obstacles)
    count = len(obstacles)
    pair_point = np.repeat(np.arange(points.s.size), count)
    obstacle = np.tile(np.arange(count), points.s.size)
    pair_status = np.asarray(outcome.pair_status)
    positions = solver.point_positions(outcome.x, points.segment, points.offset, points.height)
    position = positions[pair_point]
    gap, normal, force, normal_force, tangential_force = ck.pair_forces(
        np.array([o.kind for o in obstacles], dtype=np.int64),
        np.ascontiguousarray(params, dtype=float), positions, pair_point, obstacle,
        pair_status, np.ascontiguousarray(outcome.multipliers), float(mu))
    scale = solver.gradient_scale / solver.length
    in_contact = (pair_status != ck.FREE) & (normal_force > _FORCE_TOL * scale)
    touching = in_contact | (np.abs(gap) <= TOUCH_GAP)
    on_finger = np.zeros((count, 2))
    np.add.at(on_finger, obstacle, force)
    s = points.s[pair_point]
    face = points.face[pair_point]
    moment = np.zeros(count)
    for b, item in enumerate(obstacles):
        mine = obstacle == b
        arm = position[mine] - item.reference
        reaction = -force[mine]
        moment[b] = float(np.sum(arm[:, 1] * reaction[:, 0] - arm[:, 0] * reaction[:, 1]))
    arcs = _arcs(count, obstacle, face, touching, s, normal_force)
    normal_force_total = float(normal_force[in_contact].sum())
    summary = _summary(arcs, normal_force_total)
    finger = _finger(solver, outcome, pressure, tip_force, loads)
    why = ('could not be certified (the finger is not stable under its contact forces as '
           'fixed loads)' if outcome.stability == 0.0 else 'fails')
    message = _MESSAGES[status].format(summary=summary, fraction=outcome.fraction,
                                       finger=finger.message, why=why)
    weight = points.weight[pair_point]
    return Result.of({
        'success': status is SolverStatus.SUCCESS, 'status': status, 'message': message,
        'iterations': outcome.iterations, 'pressure': float(pressure), 'mu': float(mu),
        'points': points, 'obstacles': obstacles,
        'state': (outcome.x, outcome.multipliers, outcome.pair_status),
        'anchors': outcome.anchors, 'fraction': outcome.fraction,
        'stability': outcome.stability, 'finger': finger, 'tip': finger.tip, 's': s,
        'face': face, 'obstacle': obstacle, 'position': position, 'gap': gap,
        'normal': normal, 'tangent': np.stack([-normal[:, 1], normal[:, 0]], axis=1),
        'force': force, 'normal_force': normal_force, 'tangential_force': tangential_force,
        'line_load': normal_force / weight, 'tangential_line_load': tangential_force / weight,
        'pair_status': pair_status, 'in_contact': in_contact, 'touching': touching,
        'arcs': arcs, 'total_force': -on_finger, 'total_moment': moment,
        'normal_force_total': normal_force_total,
        'faces': tuple(FACES[f] for f in sorted(set(face[in_contact]))), 'summary': summary,
        'contact_arc': functools.partial(_contact_arc, touching, face, s),
    })


def _finger(solver, outcome, pressure, tip_force, loads):
    """Return the finger's Result at a contact state, its loads the tip force alone."""
    force = np.asarray(tip_force, dtype=float)
    fields = None
    if isinstance(solver.engine_problem, engine.CompiledProblem):
        fields = engine.outputs(solver.engine_problem, outcome.x[None], [pressure],
                                [(node, np.asarray(f, dtype=float)[None]) for node, f in loads],
                                engine.ALL)[0]
    return solver._result(engine.NewtonOutcome(outcome.x, outcome.status, outcome.iterations,
                                               0.0, 0.0, outcome.stability, outcome.fraction,
                                               fields), pressure, force)


def _arcs(count, obstacle, face, touching, s, normal_force):
    """Return the runs of touching points (ContactArc), by obstacle and face."""
    arcs = []
    for b in range(count):
        for f, name in enumerate(FACES):
            mine = np.nonzero((obstacle == b) & (face == f))[0]
            run = []
            for j in list(mine) + [None]:
                if j is not None and touching[j]:
                    run.append(j)
                    continue
                if run:
                    arcs.append(ContactArc(name, b, float(s[run[0]]), float(s[run[-1]]),
                                           len(run), float(normal_force[run].clip(0).sum())))
                run = []
    return arcs


def _summary(arcs, total):
    """One line: arcs in contact and the total normal force."""
    if not arcs:
        return 'no contact'
    parts = [f'{a.face} face on obstacle {a.obstacle} '
             + (f'at s = {a.start * 1e3:.1f} mm' if a.points == 1 else
                f'along s = {a.start * 1e3:.1f}..{a.end * 1e3:.1f} mm')
             for a in arcs]
    return f'{"; ".join(parts)}; total normal force {total:.4g} N'


def _contact_arc(touching, face, s, face_name=None):
    """(start, end) [m] of the touching points (on `face_name`, if given); None if none."""
    mask = touching if face_name is None else touching & (face == FACES.index(face_name))
    if not mask.any():
        return None
    return float(s[mask].min()), float(s[mask].max())


def _same_finger(result, solver, points, count):
    """Whether a contact result can start a solve of `solver` with these points, obstacles."""
    return (isinstance(result, Result) and 'pair_status' in result
            and result.finger.segment_edges is solver.edges
            and result.pair_status.size == points.s.size * count)


def point_gaps(solver, x, obstacles, settings=ContactSettings()):
    """
    Gaps of every (finger point, obstacle) pair at a finger state [m], shape (C,).

    Parameters
    ----------
    solver : PCCSolver or RodSolver
    x : ndarray
        Engine unknowns of the finger (e.g. ``solver._pack(result.state)``).
    obstacles : obstacle or sequence of obstacles
    settings : ContactSettings

    """
    obstacles = check_obstacles(obstacles)
    points = finger_points(solver, settings)
    kind, params = obstacle_params(obstacles)
    positions = solver.point_positions(np.ascontiguousarray(x, dtype=float), points.segment,
                                       points.offset, points.height)
    count = len(obstacles)
    return ck.pair_geometry(kind, params, positions,
                            np.repeat(np.arange(points.s.size), count),
                            np.tile(np.arange(count), points.s.size))[:, 0]


def _check_solve(solver, pressure, tip_force):
    pressure = real_number('pressure', pressure, '[Pa]')
    if pressure < 0.0:
        raise ValueError(f'`pressure` must be >= 0 (gauge) [Pa], got {pressure}')
    _check_solver(solver)
    return pressure, np.array(real_pair('tip_force', tip_force, '[N]'))


def solve_contact(solver, pressure, obstacles, tip_force=(0.0, 0.0),
                  settings=ContactSettings(), initial=None):
    """
    Frictionless equilibrium of a finger against rigid obstacles in its plane.

    Contact is a constraint of the energy minimisation, solved inside the engine
    (`engine.contact_solve`: active set, bordered Newton with exact derivatives). The
    answer is a function of the arguments alone: `initial` only saves iterations.

    Parameters
    ----------
    solver : PCCSolver or RodSolver
        The finger (`pipeline.contact_model` gives the default one).
    pressure : float
        Gauge pressure [Pa].
    obstacles : obstacle or sequence of obstacles
        Circle, HalfPlane, ConvexPolygon, Ellipse, in the finger frame [m].
    tip_force : (float, float)
        Tip load besides the contact [N].
    settings : ContactSettings
    initial : Result, optional
        Warm start from a result of the same solver, points and obstacle count.

    Returns
    -------
    Result
        `CONTACT_FIELDS`, with success, status, message and iterations.

    References
    ----------
    docs/physics.md, section 15.

    """
    pressure, force = _check_solve(solver, pressure, tip_force)
    obstacles = check_obstacles(obstacles)
    points = finger_points(solver, settings)
    state = None
    if initial is not None:
        if not _same_finger(initial, solver, points, len(obstacles)):
            raise ValueError('`initial` must be None or a contact result of the same solver, '
                             'contact points and number of obstacles')
        state = initial.state
    con = _contact_set(solver, points, obstacles, 0.0, settings.penalty)
    loads = solver.tip_loads(force)
    outcome = engine.contact_solve(solver.engine_problem, pressure, loads, con, solver._options,
                                   state, top=solver.design.max_pressure)
    return contact_result(solver, outcome, points, obstacles, con.params, pressure, force,
                          loads=loads)


def contact_path(solver, pressures, obstacles, shifts=None, mu=0.0, tip_force=(0.0, 0.0),
                 settings=ContactSettings(), start=None):
    """
    Follow a loading path with Coulomb friction: pressures and obstacle motions, in steps.

    Friction makes the answer depend on the path, so the path is the input: step k
    brings the pressure to `pressures[k]` and every obstacle to its pose in `obstacles`
    moved by `shifts[k]`, from the state of step k - 1 (an incremental stick/slip problem
    solved by the engine: `engine.contact_path`). Without `start`, step 0 is the
    frictionless equilibrium at the first pressure and pose (`solve_contact`): place the
    object where the finger does not touch it, and the path starts free.

    Parameters
    ----------
    solver : PCCSolver or RodSolver
    pressures : sequence of float
        [Pa], >= 0.
    obstacles : obstacle or sequence of obstacles
        At shift zero, in the finger frame.
    shifts : array_like, shape (S, B, 2) or (S, 2), optional
        Translation of every obstacle at every step [m] (default: none).
    mu : float
        Coulomb coefficient [-], >= 0.
    tip_force : (float, float)
        Tip load besides the contact [N], the same at every step.
    settings : ContactSettings
    start : Result, optional
        State before step 0, with the obstacles at their base pose (shift zero): e.g. a
        `solve_contact` result.

    Returns
    -------
    list of Result
        One per step; shorter if a step could not be completed (the last entry then says
        why).

    """
    mu = real_number('mu', mu, '[-]')
    if mu < 0.0:
        raise ValueError(f'`mu` must be >= 0 [-], got {mu}')
    obstacles = check_obstacles(obstacles)
    pressures = [real_number(f'pressures[{k}]', p, '[Pa]') for k, p in enumerate(pressures)]
    if not pressures:
        raise ValueError('`pressures` must hold at least one pressure [Pa]')
    if any(p < 0.0 for p in pressures):
        raise ValueError(f'`pressures` must be >= 0 (gauge) [Pa], got {pressures}')
    count = len(obstacles)
    if shifts is None:
        shifts = np.zeros((len(pressures), count, 2))
    shifts = np.asarray(shifts, dtype=float)
    if shifts.shape == (len(pressures), 2):
        shifts = np.repeat(shifts[:, None, :], count, axis=1)
    if shifts.shape != (len(pressures), count, 2) or not np.all(np.isfinite(shifts)):
        raise ValueError(f'`shifts` must be finite with shape ({len(pressures)}, {count}, 2) '
                         f'or ({len(pressures)}, 2) [m], got {shifts.shape}')
    pressure, force = _check_solve(solver, pressures[0], tip_force)
    points = finger_points(solver, settings)
    results = []
    if start is None:
        placed = [translated(o, s) for o, s in zip(obstacles, shifts[0])]
        first = solve_contact(solver, pressure, placed, tip_force, settings)
        results.append(first)
        if not first.success:
            return results
        start, begin, base_shift = first, 1, shifts[0]
    else:
        if not _same_finger(start, solver, points, count):
            raise ValueError('`start` must be a contact result of the same solver, contact '
                             'points and number of obstacles')
        begin, base_shift = 0, np.zeros((count, 2))
    con = _contact_set(solver, points, obstacles, mu, settings.penalty)
    x, lam, status = start.state
    # Sticking pairs stay tied where the start's step tied them.
    shifted = con._replace(params=ck.shifted_params(con.kind, con.params, base_shift),
                           anchor=start.anchors)
    anchors = engine.next_anchors(solver.engine_problem, x, shifted, status)
    con = con._replace(anchor=anchors)
    loads = solver.tip_loads(force)
    steps = engine.contact_path(solver.engine_problem, pressures[begin:], shifts[begin:], loads,
                                con, solver._options,
                                (x, lam, status, base_shift, start.pressure))
    for k, (outcome, params) in enumerate(steps):
        placed = tuple(translated(o, s) for o, s in zip(obstacles, shifts[begin + k]))
        results.append(contact_result(solver, outcome, points, placed, params,
                                      pressures[begin + k], force, mu, loads))
    return results
