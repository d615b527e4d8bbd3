"""The engine's Python front for contact: one solve, a step, a path in pressure."""

import math
import typing

import numpy as np

from .active_set import _contact, _GAP_TOL
from .outcomes import _STATUS, SolverStatus
from .problems import CompiledProblem
from .solves import _compiled, _contact_entry, _flat, _own, _packed, solve, TIP
from ..kernels import contact as ck
from ..kernels.chain import load_arrays


# -- contact ---------------------------------------------------------------------------------
class ContactOutcome(typing.NamedTuple):
    """
    State of a contact solve or path step (internal: `contact` builds its results from it).

    Attributes
    ----------
    x : ndarray
        Finger state [scaled units].
    status : SolverStatus
    iterations : int
        Bordered Newton iterations (free solve and continuation included).
    multipliers : ndarray, shape (C, 2)
        Per pair: (lambda_N [N], 0) in contact without sticking; the force (F_X, F_Z) on the
        finger [N] when sticking; zeros when free.
    pair_status : ndarray of int, shape (C,)
        `kernels.contact` status of every pair.
    anchors : ndarray, shape (C, 2)
        The anchors the step used [m].
    fraction : float
        Of the obstacle growth (cold solve) or of the step reached.
    stability : float
        > 0 stable; < 0 not; 0 not certified (the Hessian under the contact forces as dead
        loads is not positive definite); NaN not computed.

    """

    x: np.ndarray
    status: SolverStatus
    iterations: int
    multipliers: np.ndarray
    pair_status: np.ndarray
    anchors: np.ndarray
    fraction: float
    stability: float


def _contact_inputs(problem, loads, contact, options):
    """Compiled data (or None), flat state, loads, options and a private copy of `contact`."""
    if isinstance(problem, CompiledProblem):
        has_points, kind = problem.has_points(), type(problem.data[True]).__name__
    else:
        has_points = all(hasattr(problem, name) for name in (
            'point_positions', 'point_jacobian', 'point_derivatives'))
        kind = type(problem).__name__
    if not has_points:
        raise TypeError(f'contact needs a discretisation with face points (the PCC or the '
                        f'rod), got {kind}')
    flat = _flat(problem)
    nodes, forces = load_arrays(loads)
    opts, cap = _packed(problem, options, flat.shape)
    con = contact._replace(status=np.array(contact.status, dtype=np.int64),
                           anchor=np.array(contact.anchor, dtype=float))
    return _compiled(problem, True), flat, nodes, forces, opts, cap, con


def _contact_outcome(out, problem, con):
    x, code, iterations, lam, fraction, stability = out
    return ContactOutcome(_own(x, problem), _STATUS[code], int(iterations), lam,
                          con.status.copy(), con.anchor.copy(), float(fraction),
                          float(stability))


def _free_depth(problem, x, con):
    """Deepest penetration of a finger state into the obstacles [m] (<= 0: clear)."""
    positions = problem.point_positions(x, con.pseg, con.poff, con.pz)
    return -ck.pair_geometry(con.kind, con.params, positions, con.pair_point,
                             con.pair_object)[:, 0].min()


def contact_solve(problem, pressure, loads, contact, options, initial=None, top=None):
    """
    Frictionless contact equilibrium: the constrained minimum of the total potential.

    min Pi(x) subject to g_j(x) >= 0 for every candidate (finger point, obstacle) pair,
    g the signed distance of the point from the obstacle. An active-set method: the
    equality-constrained problem of the active pairs is solved by the bordered Newton
    (`_constrained_newton`, exact derivatives, H^-1 through the discretisation's own
    solves), then pairs that penetrate are added and pairs that pull released, until
    nothing changes. A warm start (`initial`) is tried first and kept only if it converges
    to a stable state. Otherwise the finger is solved free (`solve`), and if it
    penetrates, the gripper's own path is taken: from the pressure at which the free
    finger touches the obstacles (bisection between `pressure` and `top`) the pressure is
    released to `pressure` in steps of at most 10 kPa (halved on failure, down to 1/64),
    each a solve from the last. Where the finger touches at every pressure up to `top`
    (or the release fails), the obstacles are grown instead from their shapes offset by
    the deepest penetration (touching) to their true shapes in doubling or halving steps
    (1/4 first, 1/256 smallest). So the answer is a function of the inputs alone, and the
    one the finger reaches by closing on the obstacles.

    Parameters
    ----------
    problem : CompiledProblem or discretisation
        With face points (`point_positions`, `point_jacobian`, `point_derivatives`).
    pressure : float
        [Pa].
    loads : sequence of (int, ndarray (2,))
        Node loads besides the contact [N].
    contact : ContactSet
        Its `mu` is ignored (frictionless); its status and anchor arrays are not written.
    options : NewtonOptions
    initial : (x, multipliers, pair_status), optional
        A previous outcome's, of the same discretisation and pairs.
    top : float, optional
        Highest pressure of the release path [Pa] (the design's limit); None: growth only.

    Returns
    -------
    ContactOutcome
        SUCCESS for a stable constrained equilibrium, UNSTABLE when its stability fails or
        cannot be certified, CONTINUATION_FAILED with the fraction of the release (or
        growth) reached.

    References
    ----------
    docs/physics.md, section 15.

    """
    data, flat, nodes, forces, opts, cap, con = _contact_inputs(problem, loads, contact,
                                                                options)
    con = con._replace(mu=0.0)
    count = con.status.size
    spent = 0
    if initial is not None:
        status0 = np.where(np.asarray(initial[2]) == ck.FREE, ck.FREE, ck.NORMAL).astype(
            np.int64)
        warm = _run_contact(problem, data, np.ascontiguousarray(initial[0], dtype=float),
                            np.ascontiguousarray(initial[1], dtype=float), status0, 0.0,
                            pressure, nodes, forces, con, opts, cap, False)
        if warm.status is SolverStatus.SUCCESS:
            return warm
        spent = warm.iterations
        con = con._replace(status=np.zeros(count, dtype=np.int64))
    # The free finger (the engine's own solve, compiled once for every use), then growth.
    free = solve(problem, pressure, loads, options, level=TIP)
    spent += free.iterations
    lam = np.zeros((count, 2))
    if free.status not in (SolverStatus.SUCCESS, SolverStatus.UNSTABLE):
        return ContactOutcome(free.x, free.status, spent, lam, con.status.copy(),
                              con.anchor.copy(), 0.0, math.nan)
    depth = _free_depth(problem, free.x, con)
    if depth <= _GAP_TOL * con.scale:
        return ContactOutcome(free.x, free.status, spent, lam, con.status.copy(),
                              con.anchor.copy(), 1.0, free.min_eig)
    if top is not None and float(top) > float(pressure):
        out = _release(problem, data, float(pressure), float(top), loads, nodes, forces, con,
                       opts, cap, options)
        if out is not None:
            return out._replace(iterations=out.iterations + spent)
    out = _run_contact(problem, data, free.x, lam, con.status, depth, pressure, nodes, forces,
                       con, opts, cap, True)
    return out._replace(iterations=out.iterations + spent)


#: Largest pressure step of a cold contact solve's release path [Pa], and its smallest
#: fraction after halvings.
_RELEASE_STEP = 10.0e3
_RELEASE_SMALLEST = 1.0 / 64


def _release(problem, data, pressure, top, loads, nodes, forces, con, opts, cap, options):
    """
    Close the finger on the obstacles: from the pressure where it touches down to `pressure`.

    Returns the outcome at `pressure`, or None when the free finger touches at `top` too
    or a step fails even at its smallest (then the caller grows the obstacles).
    """
    def depth(p):
        out = solve(problem, p, loads, options, level=TIP)
        if out.status not in (SolverStatus.SUCCESS, SolverStatus.UNSTABLE):
            return math.inf, out
        return _free_depth(problem, out.x, con), out

    high, state = depth(top)
    if high > _GAP_TOL * con.scale:
        return None
    low = pressure
    spent = state.iterations
    # Bisection on the free finger's penetration to 1e-6 of the span: where it touches.
    while top - low > 1e-6 * max(top, 1.0):
        middle = 0.5 * (low + top)
        d, out = depth(middle)
        spent += out.iterations
        if d > _GAP_TOL * con.scale:
            low = middle
        else:
            top, state = middle, out
    x, lam = state.x, np.zeros((con.status.size, 2))
    status = np.zeros(con.status.size, dtype=np.int64)
    current, size = top, _RELEASE_STEP
    while current > pressure:
        goal = max(pressure, current - size)
        out = _run_contact(problem, data, x, lam, status, 0.0, goal, nodes, forces, con, opts,
                           cap, False)
        spent += out.iterations
        if out.status in (SolverStatus.SUCCESS, SolverStatus.UNSTABLE):
            x, lam, status, current = out.x, out.multipliers, out.pair_status, goal
            size = min(2.0 * size, _RELEASE_STEP)
            continue
        size *= 0.5
        if size < _RELEASE_SMALLEST * _RELEASE_STEP:
            return None
    return out._replace(iterations=spent)


def _run_contact(problem, data, x, lam, status, depth, pressure, nodes, forces, con, opts, cap,
                 grow):
    """Run `_contact` compiled (on `data`) or interpreted, and wrap its outcome."""
    args = (x, lam, status, float(depth), float(pressure), nodes, forces, con, opts, cap,
            bool(grow))
    if data is None:
        out = _contact(problem, *args)
    else:
        out = _contact_entry(data, *args)
    return _contact_outcome(out, problem, con)


def contact_step(problem, pressure, loads, contact, state, options):
    """
    One step of a contact path with Coulomb friction, from a converged state.

    Every pair in contact starts the step sticking to its anchor (a return map); a
    sticking pair whose tangential force passes mu times its normal force slips, with
    the friction force mu lambda_N against its motion, a slipping pair that would move
    against its friction force sticks again, a penetrating pair touches (sticking to its
    anchor), a pulling one is released: the active-set loop of `contact_solve`.

    Parameters
    ----------
    problem, pressure, loads, options
        As `contact_solve`.
    contact : ContactSet
        Obstacles at the step's pose and the anchors of every pair (see `contact_path`).
    state : (x, multipliers, pair_status)
        The converged state the step starts from.

    Returns
    -------
    ContactOutcome
        MAX_ITERATIONS when the step does not converge (the caller takes a smaller one).

    """
    data, flat, nodes, forces, opts, cap, con = _contact_inputs(problem, loads, contact,
                                                                options)
    x = np.ascontiguousarray(state[0], dtype=float)
    lam0 = np.array(state[1], dtype=float)
    status0 = np.array(state[2], dtype=np.int64)
    if con.mu > 0.0:
        _start_sticking(problem, x, con, lam0, status0)
    return _run_contact(problem, data, x, lam0, status0, 0.0, pressure, nodes, forces, con,
                        opts, cap, False)


def _start_sticking(problem, x, con, lam, status):
    """Turn touching pairs that do not stick into sticking ones (the return map's trial)."""
    slipping = np.nonzero((status == ck.SLIP_POS) | (status == ck.SLIP_NEG)
                          | (status == ck.NORMAL))[0]
    if not slipping.size:
        return
    positions = problem.point_positions(x, con.pseg, con.poff, con.pz)
    for j in slipping:
        b = con.pair_object[j]
        p = positions[con.pair_point[j]]
        _, gx, gz, _, _, _ = ck.signed_distance(int(con.kind[b]), con.params[b], p[0], p[1])
        sense = {ck.SLIP_POS: con.mu, ck.SLIP_NEG: -con.mu}.get(int(status[j]), 0.0)
        multiplier = lam[j, 0]
        lam[j] = multiplier * (gx - sense * gz), multiplier * (gz + sense * gx)
        status[j] = ck.STICK


def next_anchors(problem, x, contact, pair_status):
    """
    Return the anchors of the next path step [m], shape (C, 2).

    Sticking pairs keep theirs; every other pair takes the obstacle point nearest to its
    finger point now.
    """
    positions = problem.point_positions(np.ascontiguousarray(x, dtype=float), contact.pseg,
                                        contact.poff, contact.pz)
    nearest = ck.pair_geometry(contact.kind, contact.params, positions, contact.pair_point,
                               contact.pair_object)[:, 4:]
    return np.where((np.asarray(pair_status) == ck.STICK)[:, None], contact.anchor, nearest)


def contact_path(problem, pressures, shifts, loads, contact, options, state, halvings=6):
    """
    March a contact path with friction: the answer depends on the path, which is the input.

    Step k takes the finger to pressure `pressures[k]` and every obstacle to its base pose
    (`contact.params`) moved by `shifts[k]`, from the converged state of step k - 1 (or
    `state`). Anchors ride with their obstacle; after each step sticking pairs keep theirs
    and the others take the obstacle point nearest their finger point (`next_anchors`). A
    step that fails is split in two (linearly in pressure and pose), down to
    2^-`halvings` of it, else the path stops there.

    Parameters
    ----------
    problem, loads, options
        As `contact_solve`.
    pressures : sequence of float, length S
        [Pa].
    shifts : array_like, shape (S, B, 2)
        Translation of every obstacle from its base pose [m].
    contact : ContactSet
        Base obstacles, pairs and the anchors at the start (at the pose of `shifts` of
        the start state: `state[3]`).
    state : (x, multipliers, pair_status, shift (B, 2), pressure)
        Converged start.
    halvings : int

    Returns
    -------
    list of (ContactOutcome, params (B, P))
        One per step reached (the obstacles' parameter rows of that step); shorter than S
        when a step cannot be completed, its last entry then the failed outcome.

    """
    x, lam, status, shift, pressure = state
    shift = np.array(shift, dtype=float).reshape(contact.kind.size, 2)
    anchors = np.array(contact.anchor, dtype=float)
    out = []
    for k in range(len(pressures)):
        goal_p = float(pressures[k])
        goal_s = np.asarray(shifts[k], dtype=float).reshape(shift.shape)
        done, size = 0.0, 1.0
        start_p, start_s = pressure, shift.copy()
        while done < 1.0:
            frac = min(1.0, done + size)
            p_k = start_p + frac * (goal_p - start_p)
            s_k = start_s + frac * (goal_s - start_s)
            params = ck.shifted_params(contact.kind, contact.params, s_k)
            moved = anchors + (s_k - shift)[contact.pair_object]
            step = contact._replace(params=params, anchor=moved)
            outcome = contact_step(problem, p_k, loads, step, (x, lam, status), options)
            if outcome.status in (SolverStatus.SUCCESS, SolverStatus.UNSTABLE):
                x, lam, status = outcome.x, outcome.multipliers, outcome.pair_status
                anchors = next_anchors(problem, x, step._replace(anchor=moved), status)
                shift, pressure, done = s_k, p_k, frac
                size = min(1.0, 2.0 * size)
                if done >= 1.0:
                    out.append((outcome, params))
            else:
                size *= 0.5
                if size < 2.0 ** -halvings:
                    out.append((outcome._replace(fraction=done), params))
                    return out
    return out
