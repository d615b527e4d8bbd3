"""Contact by an active set: the pairs' statuses, stability, cold solves by growth."""

import math

from numba.extending import register_jitable
import numpy as np

from .bordered import (_columns, _constrained_newton, _constraint_derivatives, _dense_solve,
                       _positive_definite, _row_count, _rows, _times)
from .newton import _point_positions, _step
from .outcomes import _CONTINUATION_FAILED, _MAX_ITERATIONS, _SUCCESS, _UNSTABLE
from ..kernels import contact as ck


# -- contact: active set, stability, cold solves by obstacle growth ---------------------------
#: Outer (active-set) iterations of one contact solve.
_MAX_ACTIVE_SET = 50
#: Gap below which a free pair is penetrating, relative to the set's length scale [-].
_GAP_TOL = 1e-10
#: Multiplier below which a pair pulls (and is released), relative to the force scale [-].
_FORCE_TOL = 1e-10
#: Penetration, relative to the length scale, that a pair released during a solve may keep
#: before it is regained (anti-cycling; 9 nm on the paper's finger) [-].
_REGAIN_TOL = 1e-7


@register_jitable
def _gather(lam_pairs, status):
    """Row multipliers of a status layout from the (C, 2) pair multipliers."""
    lam = np.empty(_row_count(status))
    r = 0
    for j in range(status.size):
        s = status[j]
        if s == ck.STICK:
            lam[r] = lam_pairs[j, 0]
            lam[r + 1] = lam_pairs[j, 1]
            r += 2
        elif s != ck.FREE:
            lam[r] = lam_pairs[j, 0]
            r += 1
    return lam


@register_jitable
def _scatter(lam, status):
    """(C, 2) pair multipliers of row multipliers: (lambda_N, 0), or (F_x, F_z) when sticking."""
    out = np.zeros((status.size, 2))
    r = 0
    for j in range(status.size):
        s = status[j]
        if s == ck.STICK:
            out[j, 0] = lam[r]
            out[j, 1] = lam[r + 1]
            r += 2
        elif s != ck.FREE:
            out[j, 0] = lam[r]
            r += 1
    return out


@register_jitable
def _pair_gaps(problem, x, con, offset):
    """Point positions (K, 2) and the shifted gap g + offset (C,) of every pair [m]."""
    positions = _point_positions(problem, x, con.pseg, con.poff, con.pz)
    gaps = np.empty(con.status.size)
    for j in range(con.status.size):
        k = con.pair_point[j]
        b = con.pair_object[j]
        gaps[j] = ck.signed_distance(con.kind[b], con.params[b], positions[k, 0],
                                     positions[k, 1])[0] + offset
    return positions, gaps


@register_jitable
def _update_status(problem, x, lam_pairs, con, offset, force_scale, released):
    """
    One active-set update after an inner solve: 1 if a status changed, else 0 (or -1).

    Penetrating free pairs are added (sliding against their motion, or frictionless); if
    none was added, pairs that pull are released; a sticking pair whose tangential force
    passes mu times its normal force slips in that force's sense; a slipping pair whose
    point moved against its friction force sticks again. With friction the incremental
    problem is not monotone: a pair may pull when it touches and penetrate when it is
    free. A pair released earlier in the same solve (`released` counts the releases)
    comes back only below -_REGAIN_TOL scale, and after its second release touching
    frictionless, after its third sticking; a fourth ends the solve (returns -1: the
    caller takes a smaller step).
    """
    positions, gaps = _pair_gaps(problem, x, con, offset)
    gap_tol = _GAP_TOL * con.scale
    force_tol = _FORCE_TOL * force_scale
    added = False
    for j in range(con.status.size):
        limit = _REGAIN_TOL * con.scale if released[j] else gap_tol
        if con.status[j] == ck.FREE and gaps[j] < -limit:
            if released[j] >= 4:
                return -1
            # A pair that closes during a step has no point to stick to yet (where its
            # path crossed the surface is unknown): it slides, against its motion along
            # the surface since the step's start (from the obstacle point nearest to where
            # it started, its anchor), and sticks from the next step on; without friction
            # or motion it touches frictionless.
            con.status[j] = ck.NORMAL
            if con.mu > 0.0:
                k = con.pair_point[j]
                b = con.pair_object[j]
                _, gx, gz, _, _, _ = ck.signed_distance(con.kind[b], con.params[b],
                                                        positions[k, 0], positions[k, 1])
                moved = (-gz * (positions[k, 0] - con.anchor[j, 0])
                         + gx * (positions[k, 1] - con.anchor[j, 1]))
                if moved > gap_tol:
                    con.status[j] = ck.SLIP_NEG
                elif moved < -gap_tol:
                    con.status[j] = ck.SLIP_POS
                if released[j] == 2:
                    con.status[j] = ck.NORMAL
                elif released[j] == 3:
                    con.status[j] = ck.STICK
            lam_pairs[j, 0] = 0.0
            lam_pairs[j, 1] = 0.0
            added = True
    if added:
        return 1
    changed = False
    for j in range(con.status.size):
        s = con.status[j]
        if s == ck.FREE:
            continue
        k = con.pair_point[j]
        b = con.pair_object[j]
        _, gx, gz, _, _, _ = ck.signed_distance(con.kind[b], con.params[b], positions[k, 0],
                                                positions[k, 1])
        size = math.hypot(gx, gz)
        nx, nz = gx / size, gz / size
        tx, tz = -nz, nx
        if s == ck.NORMAL:
            if lam_pairs[j, 0] < -force_tol:
                con.status[j] = ck.FREE
                lam_pairs[j, 0] = 0.0
                released[j] += 1
                changed = True
        elif s == ck.STICK:
            normal = lam_pairs[j, 0] * nx + lam_pairs[j, 1] * nz
            tangent = lam_pairs[j, 0] * tx + lam_pairs[j, 1] * tz
            if abs(tangent) > con.mu * normal + force_tol:
                # Outside the cone (a tie that pulls is outside too): slip first, the
                # slipping solve tells whether the pair then lifts off.
                con.status[j] = ck.SLIP_POS if tangent > 0.0 else ck.SLIP_NEG
                lam_pairs[j, 0] = max(normal, 0.0) / size
                lam_pairs[j, 1] = 0.0
                changed = True
            elif normal < -force_tol:
                con.status[j] = ck.FREE
                lam_pairs[j, 0] = 0.0
                lam_pairs[j, 1] = 0.0
                released[j] += 1
                changed = True
        else:
            sense = 1.0 if s == ck.SLIP_POS else -1.0
            normal = lam_pairs[j, 0] * size
            moved = tx * (positions[k, 0] - con.anchor[j, 0]) \
                + tz * (positions[k, 1] - con.anchor[j, 1])
            if normal < -force_tol:
                con.status[j] = ck.FREE
                lam_pairs[j, 0] = 0.0
                released[j] += 1
                changed = True
            elif sense * moved > gap_tol:
                # Friction on the finger along +sense tau means slip along -sense tau.
                con.status[j] = ck.STICK
                lam_pairs[j, 0] = normal * (nx + sense * con.mu * tx)
                lam_pairs[j, 1] = normal * (nz + sense * con.mu * tz)
                changed = True
    return 1 if changed else 0


@register_jitable
def _contact_settle(problem, x, lam_pairs, pressure, nodes, forces, con, offset, options, cap):
    """Inner bordered Newton and active-set updates until no status changes."""
    force_scale = options[6] / con.scale
    released = np.zeros(con.status.size, dtype=np.int64)
    spent = 0
    for _ in range(_MAX_ACTIVE_SET):
        lam = _gather(lam_pairs, con.status)
        x_new, lam_new, ok, its = _constrained_newton(problem, x, lam, pressure, nodes,
                                                      forces, con, offset, options, cap)
        spent += its
        if not ok:
            return x, lam_pairs, False, spent
        x = x_new
        lam_pairs = _scatter(lam_new, con.status)
        changed = _update_status(problem, x, lam_pairs, con, offset, force_scale, released)
        if changed < 0:
            return x, lam_pairs, False, spent
        if changed == 0:
            return x, lam_pairs, True, spent
    return x, lam_pairs, False, spent


@register_jitable
def _contact_stable(problem, x, lam_pairs, pressure, nodes, forces, con, offset):
    """
    Stability of a converged contact state: 1.0 stable, -1.0 not, 0.0 not certified.

    Stable when the Hessian of the Lagrangian is positive definite on the tangent space
    of the active rows (taken frictionless: d = w). With H, the Hessian under the contact
    forces as dead loads, positive definite that holds exactly when
    S = [[I - A^1/2 V H^-1 V^T A^1/2, -A^1/2 V H^-1 G^T], [., -E - G H^-1 G^T]] has as many
    negative eigenvalues as rows and no zero one (Haynsworth inertia additivity): when its
    last block is negative definite (independent rows) and the Schur complement of that
    block positive definite (two Cholesky factorisations). 0.0 where H is not positive
    definite.
    """
    lam = _gather(lam_pairs, con.status)
    c, comp, brow, grow, urow, vrow, coef, point, direction = _rows(con, problem, x, lam,
                                                                    offset)
    _, residual, hess = _constraint_derivatives(con, problem, x, pressure, nodes, forces, lam,
                                                point, direction)
    if _step(problem, residual, hess)[1] <= 0.0:
        return 0.0
    m = c.size
    q = coef.size
    yg, ok_g = _columns(problem, hess, grow, residual.shape)
    yv, ok_v = _columns(problem, hess, vrow, residual.shape)
    if not (ok_g and ok_v):
        return 0.0
    root = np.empty(q)
    for i in range(q):
        root[i] = np.sqrt(max(coef[i], 0.0))
    # -S22 = E + G H^-1 G^T, positive definite for independent rows.
    neg = _times(grow, yg)
    for i in range(m):
        neg[i, i] += comp[i]
    if not _positive_definite(neg):
        return -1.0
    # S11 - S12 S22^-1 S21 = S11 + S12 (-S22)^-1 S21, S12 = -A^1/2 V H^-1 G^T.
    vv = _times(vrow, yv)
    vg = _times(vrow, yg)
    schur = np.zeros((q, q))
    for i in range(q):
        for k in range(q):
            schur[i, k] = (1.0 if i == k else 0.0) - root[i] * vv[i, k] * root[k]
    for k in range(q):
        column, ok = _dense_solve(neg, root[k] * vg[k])
        if not ok:
            return -1.0
        for i in range(q):
            total = 0.0
            for r in range(m):
                total += root[i] * vg[i, r] * column[r]
            schur[i, k] += total
    return 1.0 if _positive_definite(schur) else -1.0


@register_jitable
def _contact_grow(problem, x, depth, pressure, nodes, forces, con, options, cap):
    """
    Grow the obstacles from their shapes offset by `depth` to their true shapes.

    `depth` is the free finger's deepest penetration, so that it touches them at first;
    the growth step doubles or halves (1/4 first, 1/256 smallest). Returns the tuple of
    `_contact`.
    """
    con.status[:] = ck.FREE
    lam = np.zeros((con.status.size, 2))
    spent = 0
    done = 0.0
    step = 0.25
    while True:
        goal = min(1.0, done + step)
        saved = con.status.copy()
        x_new, lam_new, ok, its = _contact_settle(problem, x, lam, pressure, nodes, forces,
                                                  con, (1.0 - goal) * depth, options, cap)
        spent += its
        if ok:
            x, lam, done = x_new, lam_new, goal
            step = min(2.0 * step, 1.0)
            if done >= 1.0:
                break
        else:
            con.status[:] = saved
            step *= 0.5
            if step < 1.0 / 256:
                return x, _CONTINUATION_FAILED, spent, lam, done, np.nan
    stable = _contact_stable(problem, x, lam, pressure, nodes, forces, con, 0.0)
    return x, _SUCCESS if stable > 0.0 else _UNSTABLE, spent, lam, 1.0, stable


@register_jitable
def _contact_step(problem, x, lam_pairs, status0, pressure, nodes, forces, con, options, cap):
    """Settle from a state and its statuses (a warm start or a path step); see `_contact`."""
    con.status[:] = status0
    x, lam, ok, its = _contact_settle(problem, x, lam_pairs.copy(), pressure, nodes, forces,
                                      con, 0.0, options, cap)
    if not ok:
        return x, _MAX_ITERATIONS, its, lam, 0.0, np.nan
    stable = _contact_stable(problem, x, lam, pressure, nodes, forces, con, 0.0)
    return x, _SUCCESS if stable > 0.0 else _UNSTABLE, its, lam, 1.0, stable


@register_jitable
def _contact(problem, x, lam, status, depth, pressure, nodes, forces, con, options, cap,
             grow):
    """
    Run `_contact_grow` (from the free finger x) or `_contact_step` (from x, lam, status).

    Returns (x, status code, iterations, lam_pairs (C, 2), fraction, stability);
    `con.status` holds the final statuses.
    """
    if grow:
        return _contact_grow(problem, x, depth, pressure, nodes, forces, con, options, cap)
    return _contact_step(problem, x, lam, status, pressure, nodes, forces, con, options, cap)
