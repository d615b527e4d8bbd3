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
from .validation import real_number, real_pair

__all__ = ['Circle', 'HalfPlane', 'ConvexPolygon', 'Ellipse', 'ContactSettings',
           'ContactResult', 'ContactArc', 'FingerPoints', 'finger_points', 'solve_contact',
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


class ContactResult:
    """
    Equilibrium of a finger touching rigid obstacles.

    Attributes
    ----------
    success : bool
        True only for a converged, stable state.
    status : SolverStatus
    message : str
    iterations : int
    pressure : float
        [Pa].
    obstacles : tuple
        At the pose of this state.
    finger : LadderResult
        The finger's state (its `points`, `tip`, `tangent`...).
    tip : ndarray (2,)
        [m].
    s, face, obstacle : ndarray, shape (C,)
        Per (point, obstacle) pair: reference arc length [m], face index into FACES,
        obstacle index.
    position : ndarray, shape (C, 2)
        The pair's finger point [m].
    gap : ndarray, shape (C,)
        Signed distance of the point from the obstacle [m].
    normal, tangent : ndarray, shape (C, 2)
        Outward normal nu of the obstacle at the nearest boundary point, and
        tau = (-nu_z, nu_x).
    force : ndarray, shape (C, 2)
        Contact force on the finger [N].
    normal_force, tangential_force : ndarray, shape (C,)
        force . nu (>= 0) and force . tau [N].
    line_load, tangential_line_load : ndarray, shape (C,)
        Normal and tangential force over the point's tributary length [N/m].
    pair_status : ndarray of int, shape (C,)
        `kernels.contact` status (FREE, NORMAL, STICK, SLIP_POS, SLIP_NEG).
    in_contact : ndarray of bool, shape (C,)
        Carrying a normal force.
    touching : ndarray of bool, shape (C,)
        In contact, or at a gap of at most TOUCH_GAP.
    arcs : list of ContactArc
        Runs of touching points.
    total_force : ndarray, shape (B, 2)
        Force of the finger on each obstacle [N].
    total_moment : ndarray, shape (B,)
        Its moment about the obstacle's `reference`, about +Y [N m].
    normal_force_total : float
        Sum of every normal force [N].
    faces : tuple of str
        Faces in contact.

    """

    def __init__(self, solver, outcome, points, obstacles, params, pressure, tip_force,
                 mu=0.0, loads=()):
        self.solver = solver
        self.status = SolverStatus(outcome.status)
        self.success = self.status is SolverStatus.SUCCESS
        self.iterations = outcome.iterations
        self.pressure = float(pressure)
        self.mu = float(mu)
        self.points = points
        self.obstacles = tuple(obstacles)
        self.state = (outcome.x, outcome.multipliers, outcome.pair_status)
        self.anchors = outcome.anchors
        self.fraction = outcome.fraction
        self.stability = outcome.stability
        self._finger = (outcome, list(loads), tip_force)
        count = len(self.obstacles)
        self._pair_point = np.repeat(np.arange(points.s.size), count)
        self.obstacle = np.tile(np.arange(count), points.s.size)
        self.pair_status = np.asarray(outcome.pair_status)
        positions = solver.point_positions(outcome.x, points.segment, points.offset,
                                           points.height)
        self.position = positions[self._pair_point]
        (self.gap, self.normal, self.force, self.normal_force,
         self.tangential_force) = ck.pair_forces(
            np.array([o.kind for o in self.obstacles], dtype=np.int64),
            np.ascontiguousarray(params, dtype=float), positions, self._pair_point,
            self.obstacle, self.pair_status, np.ascontiguousarray(outcome.multipliers),
            self.mu)
        scale = solver.gradient_scale / solver.length
        self.in_contact = (self.pair_status != ck.FREE) & (self.normal_force > _FORCE_TOL
                                                           * scale)
        self.touching = self.in_contact | (np.abs(self.gap) <= TOUCH_GAP)
        on_finger = np.zeros((count, 2))
        np.add.at(on_finger, self.obstacle, self.force)
        self.total_force = -on_finger
        self.normal_force_total = float(self.normal_force[self.in_contact].sum())

    # Built on first use: a path of many steps reads forces, rarely these.
    s = property(lambda self: self.points.s[self._pair_point],
                 doc="Reference arc length of every pair's point [m].")
    face = property(lambda self: self.points.face[self._pair_point],
                    doc="Face (index into FACES) of every pair's point.")
    tangent = property(lambda self: np.stack([-self.normal[:, 1], self.normal[:, 0]], axis=1),
                       doc='tau = (-nu_z, nu_x) of every pair.')
    line_load = property(lambda self: self.normal_force / self.points.weight[self._pair_point],
                         doc='Normal force over the tributary length [N/m].')
    tangential_line_load = property(
        lambda self: self.tangential_force / self.points.weight[self._pair_point],
        doc='Tangential force over the tributary length [N/m].')

    @functools.cached_property
    def faces(self):
        """Faces in contact."""
        return tuple(FACES[f] for f in sorted(set(self.face[self.in_contact])))

    @functools.cached_property
    def total_moment(self):
        """Moment of the finger's forces on each obstacle about its reference, +Y [N m]."""
        out = np.zeros(len(self.obstacles))
        for b, obstacle in enumerate(self.obstacles):
            mine = self.obstacle == b
            arm = self.position[mine] - obstacle.reference
            reaction = -self.force[mine]
            out[b] = float(np.sum(arm[:, 1] * reaction[:, 0] - arm[:, 0] * reaction[:, 1]))
        return out

    # Built on first use: a path of many steps reads forces, rarely these.
    @functools.cached_property
    def finger(self):
        """The finger's result (`points`, `tangent`, `strains`...) at this state."""
        outcome, loads, tip_force = self._finger
        return self.solver._result(outcome.x, outcome.status, outcome.iterations, 0.0, 0.0,
                                   outcome.stability, outcome.fraction, self.pressure, loads,
                                   tip_force)

    @functools.cached_property
    def tip(self):
        """Position of the midplane tip, (X, Z) [m]."""
        return np.asarray(self.solver.node_jacobian(self.state[0], self.solver.tip_node)[0])

    @functools.cached_property
    def arcs(self):
        """Runs of touching points (ContactArc), by obstacle and face."""
        return self._arcs()

    def _arcs(self):
        arcs = []
        for b in range(len(self.obstacles)):
            for f, face in enumerate(FACES):
                mine = np.nonzero((self.obstacle == b) & (self.face == f))[0]
                run = []
                for j in list(mine) + [None]:
                    if j is not None and self.touching[j]:
                        run.append(j)
                        continue
                    if run:
                        arcs.append(ContactArc(face, b, float(self.s[run[0]]),
                                               float(self.s[run[-1]]), len(run),
                                               float(self.normal_force[run].clip(0).sum())))
                    run = []
        return arcs

    @property
    def message(self):
        """What happened, with the contact in figures."""
        why = ('could not be certified (the finger is not stable under its contact '
               'forces as fixed loads)' if self.stability == 0.0 else 'fails')
        return _MESSAGES[self.status].format(summary=self.summary(), fraction=self.fraction,
                                             finger=self.finger.message, why=why)

    def summary(self):
        """One line: arcs in contact and the total normal force."""
        if not self.arcs:
            return 'no contact'
        parts = [f'{a.face} face on obstacle {a.obstacle} '
                 + (f'at s = {a.start * 1e3:.1f} mm' if a.points == 1 else
                    f'along s = {a.start * 1e3:.1f}..{a.end * 1e3:.1f} mm')
                 for a in self.arcs]
        return f'{"; ".join(parts)}; total normal force {self.normal_force_total:.4g} N'

    def contact_arc(self, face=None):
        """(start, end) [m] of the touching points (on `face`, if given); None if none."""
        mask = self.touching if face is None else self.touching & (
            self.face == FACES.index(face))
        if not mask.any():
            return None
        return float(self.s[mask].min()), float(self.s[mask].max())

    def __repr__(self):
        return (f'ContactResult(success={self.success}, status={self.status.name}, '
                f'normal_force_total={self.normal_force_total:.4g}, arcs={len(self.arcs)})')


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
    initial : ContactResult, optional
        Warm start from a result of the same solver, points and obstacle count.

    Returns
    -------
    ContactResult

    References
    ----------
    docs/physics.md, section 15.

    """
    pressure, force = _check_solve(solver, pressure, tip_force)
    obstacles = check_obstacles(obstacles)
    points = finger_points(solver, settings)
    state = None
    if initial is not None:
        if not (isinstance(initial, ContactResult) and initial.solver is solver
                and initial.pair_status.size == points.s.size * len(obstacles)):
            raise ValueError('`initial` must be None or a ContactResult of the same solver, '
                             'contact points and number of obstacles')
        state = initial.state
    con = _contact_set(solver, points, obstacles, 0.0, settings.penalty)
    loads = solver.tip_loads(force)
    outcome = engine.contact_solve(solver.engine_problem, pressure, loads, con, solver._options,
                                   state, top=solver.design.max_pressure)
    return ContactResult(solver, outcome, points, obstacles, con.params, pressure, force,
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
    start : ContactResult, optional
        State before step 0, with the obstacles at their base pose (shift zero): e.g. a
        `solve_contact` result.

    Returns
    -------
    list of ContactResult
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
        if not (isinstance(start, ContactResult) and start.solver is solver
                and start.pair_status.size == points.s.size * count):
            raise ValueError('`start` must be a ContactResult of the same solver, contact '
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
        results.append(ContactResult(solver, outcome, points, placed, params,
                                     pressures[begin + k], force, mu, loads))
    return results
