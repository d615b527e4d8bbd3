"""
Spike: the unloaded CCM-N solve in Cython pure-Python mode (AOT alternative to numba).

A port of exactly one path of `fpc_gripper.model`: ``CCMSolver(design, n).solve(p)`` with
no loads and the paper's reconstruction, i.e. `engine._solve_entry` on a `kernels.CCMBlocks`
namedtuple. Ported, with the same constants and the same floating-point operation order:

- `kernels.segment_derivatives_kernel` (energy, gradient, 4x4 Hessian block per segment,
  with `_horner5`, `_strain_unknowns`, `_pemc_strain`, `_chain_rule`) and
  `kernels.segment_energy_kernel` (the line search's energy), summed as
  `kernels._ccm_segment_terms` / `kernels.ccm_energy` do;
- `kernels.newton_step_blocks` (block Cholesky, else mirrored eigenvalues floored at
  EIGEN_FLOOR max|lambda| through LAPACK dsyevd, the routine numba's np.linalg.eigh calls);
- `engine._newton` (damped Newton, step cap, Armijo backtracking, flat-energy test) and
  `engine._solve` (warm, cold, then continuation in pressure).

Compiled by cythonize (bench/spike_aot/build.py) the module is C; imported from source it
runs as plain Python (slowly) with numpy's eigh in place of the LAPACK call. Every compiled
function is ``nogil``: `solve_entry` releases the GIL for the whole solve, as numba's nogil
entries do.

Not ported (the spike's scope): point loads (dense Hessian), the 'consistent' reconstruction,
rigidity, contact, the other discretisations and the batch entries.
"""

import math

import cython
from cython.cimports.libc.math import isfinite, sqrt  # plain Python: the math module's
import numpy as np

# C-level constants (the nogil code reads no Python object); plain Python sees the values.
#: As `kernels.EIGEN_FLOOR`.
EIGEN_FLOOR = cython.declare(cython.double, 1e-8)
# As `engine`'s SolverStatus codes.
SUCCESS = cython.declare(cython.int, 0)
MAX_ITERATIONS = cython.declare(cython.int, 1)
LINE_SEARCH_FAILED = cython.declare(cython.int, 2)
NOT_FINITE = cython.declare(cython.int, 3)
UNSTABLE = cython.declare(cython.int, 4)
CONTINUATION_FAILED = cython.declare(cython.int, 5)
_INF = cython.declare(cython.double, math.inf)
_NAN = cython.declare(cython.double, math.nan)


@cython.cclass
class Problem:
    """
    The CCM-N unloaded discretisation (a `kernels.CCMBlocks`) plus the solve's scratch.

    The scratch makes a solve allocation-free; it also means one Problem serves one
    thread at a time (a threaded batch would build one per thread).
    """

    # The arrays and figures of kernels.CCMBlocks the unloaded path reads.
    stiffness: cython.double[:, :, ::1]
    gas_volume: cython.double[::1]
    gas_moments: cython.double[:, ::1]
    pemc_basis: cython.double[:, :, ::1]
    pemc_weights: cython.double[:, ::1]
    pemc_products: cython.double[:, :, ::1]
    law: cython.double[:, ::1]
    prestrain: cython.double
    pressure_coefficient: cython.double
    n: cython.Py_ssize_t
    points: cython.Py_ssize_t
    # Newton state: current and trial iterate, gradient (N, 4), Hessian blocks (N, 4, 4).
    x: cython.double[:, ::1]
    grad: cython.double[:, ::1]
    hess: cython.double[:, :, ::1]
    trial: cython.double[:, ::1]
    g_trial: cython.double[:, ::1]
    h_trial: cython.double[:, :, ::1]
    step: cython.double[:, ::1]
    # The solve's best state so far (continuation) and the result.
    best: cython.double[:, ::1]
    out: cython.double[:, ::1]
    # Per-segment scratch of the kernels (as the numba kernels' local arrays).
    y: cython.double[::1]
    g_y: cython.double[::1]
    h_y: cython.double[:, ::1]
    pemc: cython.double[::1]
    jac: cython.double[:, ::1]
    m: cython.double[:, ::1]
    low: cython.double[:, ::1]
    rhs: cython.double[::1]
    sol: cython.double[::1]
    lam: cython.double[::1]
    vec: cython.double[:, ::1]
    # LAPACK dsyevd: Fortran-order copy of a block, work arrays.
    fortran: cython.double[::1]
    work: cython.double[::1]
    iwork: cython.int[::1]
    # Figures of the last `_newton`.
    iterations: cython.int
    grad_rel: cython.double
    step_norm: cython.double
    min_eig: cython.double

    def __init__(self, data):
        """Take the arrays of a `kernels.CCMBlocks` (``CCMSolver.kernel_data(False)``)."""
        if data.consistent:
            raise NotImplementedError('the spike ports the paper reconstruction only')
        self.stiffness = np.ascontiguousarray(data.stiffness, dtype=float)
        self.gas_volume = np.ascontiguousarray(data.gas_volume, dtype=float)
        self.gas_moments = np.ascontiguousarray(data.gas_moments, dtype=float)
        self.pemc_basis = np.ascontiguousarray(data.pemc_basis, dtype=float)
        self.pemc_weights = np.ascontiguousarray(data.pemc_weights, dtype=float)
        self.pemc_products = np.ascontiguousarray(data.pemc_products, dtype=float)
        self.law = np.ascontiguousarray(data.law, dtype=float)
        self.prestrain = float(data.prestrain)
        self.pressure_coefficient = float(data.pressure_coefficient)
        n = data.stiffness.shape[0]
        self.n = n
        self.points = data.pemc_basis.shape[1]
        self.x, self.trial, self.grad, self.g_trial, self.step, self.best, self.out = (
            np.zeros((n, 4)) for _ in range(7))
        self.hess, self.h_trial = np.zeros((n, 4, 4)), np.zeros((n, 4, 4))
        self.y, self.g_y, self.rhs, self.sol, self.lam = (np.zeros(4) for _ in range(5))
        self.pemc = np.zeros(10)
        self.h_y, self.m, self.low, self.vec = (np.zeros((4, 4)) for _ in range(4))
        # d(A, B', D', C)/dq: constant but for dB'/dq3 = 4 q3 (set per segment).
        jac = np.zeros((4, 4))
        jac[0, 0] = 1.0
        jac[1, 1] = 3.0
        jac[2, 3] = 1.0
        jac[3, 2] = 1.0
        self.jac = jac
        self.fortran = np.zeros(16)
        # dsyevd's optimal lwork for n = 4 is 2 n + n nb (nb = 32 in OpenBLAS): room to spare.
        self.work = np.zeros(1024)
        self.iwork = np.zeros(64, dtype=np.intc)
        self.iterations = 0
        self.grad_rel = self.step_norm = self.min_eig = _NAN


# -- segment kernels (kernels.py) ---------------------------------------------------------
@cython.cfunc
@cython.inline
@cython.nogil
@cython.exceptval(check=False)
def _horner5(law: cython.double[:, ::1], column: cython.int, s: cython.double) -> cython.double:
    """Column `column` of the PEMC law at strain s: sum_k law[k, column] s^k, k = 0..5."""
    acc: cython.double = law[5, column]
    k: cython.int
    for k in range(4, -1, -1):
        acc = acc * s + law[k, column]
    return acc


@cython.cfunc
@cython.inline
@cython.nogil
@cython.exceptval(check=False)
def _strain_unknowns(q: cython.double[:, ::1], i: cython.Py_ssize_t,
                     y: cython.double[::1]) -> cython.void:
    """Fill y = (A, B', D', C) of segment i."""
    y[0] = q[i, 0]
    y[1] = 3.0 * q[i, 1] + 2.0 * (q[i, 3] * q[i, 3])
    y[2] = q[i, 3]
    y[3] = q[i, 2]


@cython.cfunc
@cython.inline
@cython.nogil
@cython.exceptval(check=False)
def _pemc_strain(basis: cython.double[:, :, ::1], i: cython.Py_ssize_t, p: cython.Py_ssize_t,
                 y: cython.double[::1], prestrain: cython.double) -> cython.double:
    """PEMC strain eps0 + A + B' xi^2 + D' z' at quadrature point p of segment i."""
    return basis[i, p, 0] * y[0] + basis[i, p, 1] * y[1] + basis[i, p, 2] * y[2] + prestrain


@cython.cfunc
@cython.nogil
@cython.exceptval(check=False)
def _chain_rule(g: cython.double[::1], h: cython.double[:, ::1], jac: cython.double[:, ::1],
                work: cython.double[:, ::1], grad: cython.double[:, ::1],
                hess: cython.double[:, :, ::1], i: cython.Py_ssize_t) -> cython.void:
    """Write grad[i] = jac^T g and hess[i] = jac^T h jac (4 x 4), `work` as scratch."""
    a: cython.int
    b: cython.int
    c: cython.int
    acc: cython.double
    for b in range(4):
        acc = 0.0
        for a in range(4):
            acc += g[a] * jac[a, b]
        grad[i, b] = acc
    for a in range(4):
        for b in range(4):
            acc = 0.0
            for c in range(4):
                acc += h[a, c] * jac[c, b]
            work[a, b] = acc
    for a in range(4):
        for b in range(4):
            acc = 0.0
            for c in range(4):
                acc += jac[c, a] * work[c, b]
            hess[i, a, b] = acc


@cython.cfunc
@cython.nogil
@cython.exceptval(check=False)
def _derivatives(pb: Problem, q: cython.double[:, ::1], pressure: cython.double,
                 grad: cython.double[:, ::1], hess: cython.double[:, :, ::1]) -> cython.double:
    """
    Total energy [J]; gradient (N, 4) and Hessian blocks (N, 4, 4) into grad, hess.

    `kernels.ccm_blocks_derivatives`: segment_derivatives_kernel, then energy.sum().
    """
    pressure_work: cython.double = pb.pressure_coefficient * pressure
    y: cython.double[::1] = pb.y
    g_y: cython.double[::1] = pb.g_y
    h_y: cython.double[:, ::1] = pb.h_y
    pemc: cython.double[::1] = pb.pemc
    jac: cython.double[:, ::1] = pb.jac
    i: cython.Py_ssize_t
    p: cython.Py_ssize_t
    a: cython.int
    b: cython.int
    c: cython.int
    k: cython.int
    s: cython.double
    density: cython.double
    stress: cython.double
    tangent: cython.double
    quadratic: cython.double
    ky: cython.double
    lin_gas: cython.double
    work: cython.double
    total: cython.double = 0.0
    for i in range(pb.n):
        _strain_unknowns(q, i, y)
        for c in range(10):
            pemc[c] = 0.0
        for p in range(pb.points):
            s = _pemc_strain(pb.pemc_basis, i, p, y, pb.prestrain)
            density = _horner5(pb.law, 0, s)
            stress = _horner5(pb.law, 1, s)
            tangent = _horner5(pb.law, 2, s)
            pemc[0] += density * pb.pemc_products[i, p, 0]
            for c in range(1, 4):
                pemc[c] += stress * pb.pemc_products[i, p, c]
            for c in range(4, 10):
                pemc[c] += tangent * pb.pemc_products[i, p, c]
        quadratic = 0.0
        for a in range(4):
            ky = 0.0
            for b in range(4):
                ky += pb.stiffness[i, a, b] * y[b]
            g_y[a] = ky
            quadratic += y[a] * ky
        lin_gas = pb.gas_volume[i] + (pb.gas_moments[i, 0] * y[0] + pb.gas_moments[i, 1] * y[1]
                                      + pb.gas_moments[i, 2] * y[2])
        work = pressure_work * (1.0 + y[3])
        # energy.sum() of the numba kernel: a running sum from 0 in segment order.
        total += 0.5 * quadratic + pemc[0] - work * lin_gas
        for a in range(3):
            g_y[a] += pemc[1 + a] - work * pb.gas_moments[i, a]
        g_y[3] -= pressure_work * lin_gas
        for a in range(4):
            for b in range(4):
                h_y[a, b] = pb.stiffness[i, a, b]
        # phi_a phi_b, a <= b, at pemc[4 + k] in the order of kernels._PAIR_A/_PAIR_B.
        k = 0
        for a in range(3):
            for b in range(a, 3):
                h_y[a, b] += pemc[4 + k]
                if a != b:
                    h_y[b, a] += pemc[4 + k]
                k += 1
        for a in range(3):
            h_y[a, 3] -= pressure_work * pb.gas_moments[i, a]
            h_y[3, a] -= pressure_work * pb.gas_moments[i, a]
        # Chain rule y(q): A = q0, B' = 3 q1 + 2 q3^2, D' = q3, C = q2.
        jac[1, 3] = 4.0 * q[i, 3]
        _chain_rule(g_y, h_y, jac, pb.m, grad, hess, i)
        hess[i, 3, 3] += 4.0 * g_y[1]
    return total


@cython.cfunc
@cython.nogil
@cython.exceptval(check=False)
def _energy(pb: Problem, q: cython.double[:, ::1], pressure: cython.double) -> cython.double:
    """Total potential [J]: `kernels.ccm_energy` unloaded (segment_energy_kernel, summed)."""
    pressure_work: cython.double = pb.pressure_coefficient * pressure
    y: cython.double[::1] = pb.y
    i: cython.Py_ssize_t
    p: cython.Py_ssize_t
    a: cython.int
    b: cython.int
    s: cython.double
    quadratic: cython.double
    ky: cython.double
    pemc: cython.double
    lin_gas: cython.double
    work: cython.double
    total: cython.double = 0.0
    for i in range(pb.n):
        _strain_unknowns(q, i, y)
        quadratic = 0.0
        for a in range(4):
            ky = 0.0
            for b in range(4):
                ky += pb.stiffness[i, a, b] * y[b]
            quadratic += y[a] * ky
        pemc = 0.0
        for p in range(pb.points):
            s = _pemc_strain(pb.pemc_basis, i, p, y, pb.prestrain)
            pemc += pb.pemc_weights[i, p] * _horner5(pb.law, 0, s)
        lin_gas = pb.gas_volume[i] + (pb.gas_moments[i, 0] * y[0] + pb.gas_moments[i, 1] * y[1]
                                      + pb.gas_moments[i, 2] * y[2])
        work = pressure_work * (1.0 + y[3])
        total += 0.5 * quadratic + pemc - work * lin_gas
    # + load_energy_kernel, which is 0.0 without loads.
    return total + 0.0


# -- Newton step (kernels.newton_step_blocks) ------------------------------------------------
@cython.cfunc
@cython.nogil
@cython.exceptval(check=False)
def _cholesky_factor(a: cython.double[:, :, ::1], blk: cython.Py_ssize_t,
                     low: cython.double[:, ::1]) -> cython.bint:
    """Cholesky factor of the lower triangle of block a[blk] into low; False if not PD."""
    i: cython.int
    j: cython.int
    k: cython.int
    acc: cython.double
    for i in range(4):
        for j in range(i + 1):
            acc = a[blk, i, j]
            for k in range(j):
                acc -= low[i, k] * low[j, k]
            if i == j:
                if acc <= 0.0:
                    return False
                low[i, i] = sqrt(acc)
            else:
                low[i, j] = acc / low[j, j]
    return True


@cython.cfunc
@cython.nogil
@cython.exceptval(check=False)
def _cholesky_substitute(low: cython.double[:, ::1], rhs: cython.double[::1],
                         out: cython.double[::1]) -> cython.void:
    """Solve L L^T x = rhs into out by forward and back substitution."""
    i: cython.int
    k: cython.int
    acc: cython.double
    for i in range(4):
        acc = rhs[i]
        for k in range(i):
            acc -= low[i, k] * out[k]
        out[i] = acc / low[i, i]
    for i in range(3, -1, -1):
        acc = out[i]
        for k in range(i + 1, 4):
            acc -= low[k, i] * out[k]
        out[i] = acc / low[i, i]


@cython.cfunc
@cython.nogil
@cython.exceptval(check=False)
def _eigh(pb: Problem, hess: cython.double[:, :, ::1], blk: cython.Py_ssize_t) -> cython.int:
    """
    Eigen-decomposition of block hess[blk] into pb.lam (ascending) and pb.vec (columns).

    As numba's np.linalg.eigh: LAPACK dsyevd ('V', 'L') on a Fortran-order copy, with a
    workspace query first. Returns LAPACK's info (0 on success).
    """
    i: cython.int
    j: cython.int
    if cython.compiled:
        jobz: cython.char = ord('V')
        uplo: cython.char = ord('L')
        n: cython.int = 4
        lwork: cython.int = -1
        liwork: cython.int = -1
        info: cython.int = 0
        for i in range(4):
            for j in range(4):
                pb.fortran[j * 4 + i] = hess[blk, i, j]
        dsyevd(cython.address(jobz), cython.address(uplo), cython.address(n),  # noqa: F821
               cython.address(pb.fortran[0]), cython.address(n), cython.address(pb.lam[0]),
               cython.address(pb.work[0]), cython.address(lwork), cython.address(pb.iwork[0]),
               cython.address(liwork), cython.address(info))
        lwork = cython.cast(cython.int, pb.work[0])
        liwork = pb.iwork[0]
        if info != 0 or lwork > pb.work.shape[0] or liwork > pb.iwork.shape[0]:
            return -1000 if info == 0 else info
        dsyevd(cython.address(jobz), cython.address(uplo), cython.address(n),  # noqa: F821
               cython.address(pb.fortran[0]), cython.address(n), cython.address(pb.lam[0]),
               cython.address(pb.work[0]), cython.address(lwork), cython.address(pb.iwork[0]),
               cython.address(liwork), cython.address(info))
        for i in range(4):
            for j in range(4):
                pb.vec[i, j] = pb.fortran[j * 4 + i]
        return info
    else:
        # Plain Python: numpy's eigh (also LAPACK dsyevd, lower triangle).
        lam, vec = np.linalg.eigh(np.asarray(hess[blk]))
        pb.lam[:] = lam
        pb.vec[:, :] = vec
        return 0


@cython.cfunc
@cython.nogil
@cython.exceptval(check=False)
def _mirrored_solve(lam: cython.double[::1], vec: cython.double[:, ::1],
                    rhs: cython.double[::1], floor: cython.double,
                    out: cython.double[::1]) -> cython.void:
    """Solve V |Lambda| V^T x = rhs into out, |lambda| floored at floor."""
    i: cython.int
    k: cython.int
    coef: cython.double
    for i in range(4):
        out[i] = 0.0
    for k in range(4):
        coef = 0.0
        for i in range(4):
            coef += rhs[i] * vec[i, k]
        coef /= max(abs(lam[k]), floor)
        for i in range(4):
            out[i] += vec[i, k] * coef


@cython.cfunc
@cython.nogil
@cython.exceptval(check=False)
def _block_step(pb: Problem, grad: cython.double[:, ::1], hess: cython.double[:, :, ::1],
                floor: cython.double, step: cython.double[:, ::1]) -> cython.double:
    """
    Newton step into `step`; return the smallest eigenvalue (1.0 if every block is PD).

    Cholesky per block; where a block is not PD, every block's eigenvalues are mirrored
    (|lambda| floored at `floor` times the block's largest). A failed dsyevd gives a NaN
    step, which the Newton loop reports as NOT_FINITE (numba raises LinAlgError).
    """
    i: cython.Py_ssize_t
    a: cython.int
    definite: cython.bint = True
    min_eig: cython.double
    lam_min: cython.double
    lam_max: cython.double
    for i in range(pb.n):
        for a in range(4):
            pb.rhs[a] = -grad[i, a]
        if not _cholesky_factor(hess, i, pb.low):
            definite = False
            break
        _cholesky_substitute(pb.low, pb.rhs, pb.sol)
        for a in range(4):
            step[i, a] = pb.sol[a]
    if definite:
        return 1.0
    min_eig = _INF
    for i in range(pb.n):
        if _eigh(pb, hess, i) != 0:
            for a in range(4):
                step[i, a] = _NAN
            return _NAN
        # lam.min(), np.abs(lam).max() of the numba kernel.
        lam_min = pb.lam[0]
        lam_max = abs(pb.lam[0])
        for a in range(1, 4):
            lam_min = min(lam_min, pb.lam[a])
            lam_max = max(lam_max, abs(pb.lam[a]))
        min_eig = min(min_eig, lam_min)
        for a in range(4):
            pb.rhs[a] = -grad[i, a]
        _mirrored_solve(pb.lam, pb.vec, pb.rhs, floor * lam_max, pb.sol)
        for a in range(4):
            step[i, a] = pb.sol[a]
    return min_eig


# -- the engine's loops (engine._newton, engine._solve) -----------------------------------
@cython.cfunc
@cython.inline
@cython.nogil
@cython.exceptval(check=False)
def _max_abs(a: cython.double[:, ::1]) -> cython.double:
    """Return max |a|, NaN if a holds one (as engine._max_abs compiled)."""
    out: cython.double = 0.0
    value: cython.double
    i: cython.Py_ssize_t
    j: cython.Py_ssize_t
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            value = a[i, j]
            if value != value:
                return _NAN
            out = max(out, abs(value))
    return out


@cython.cfunc
@cython.inline
@cython.nogil
@cython.exceptval(check=False)
def _max_ratio(a: cython.double[:, ::1], cap: cython.double[:, ::1]) -> cython.double:
    """Return max |a| / cap, elementwise."""
    out: cython.double = 0.0
    i: cython.Py_ssize_t
    j: cython.Py_ssize_t
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            out = max(out, abs(a[i, j]) / cap[i, j])
    return out


@cython.cfunc
@cython.inline
@cython.nogil
@cython.exceptval(check=False)
def _dot(a: cython.double[:, ::1], b: cython.double[:, ::1]) -> cython.double:
    """Return the sum of a * b, in memory order."""
    out: cython.double = 0.0
    i: cython.Py_ssize_t
    j: cython.Py_ssize_t
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            out += a[i, j] * b[i, j]
    return out


@cython.cfunc
@cython.inline
@cython.nogil
@cython.exceptval(check=False)
def _copy2(src: cython.double[:, ::1], dst: cython.double[:, ::1]) -> cython.void:
    i: cython.Py_ssize_t
    j: cython.Py_ssize_t
    for i in range(src.shape[0]):
        for j in range(src.shape[1]):
            dst[i, j] = src[i, j]


@cython.cfunc
@cython.inline
@cython.nogil
@cython.exceptval(check=False)
def _copy3(src: cython.double[:, :, ::1], dst: cython.double[:, :, ::1]) -> cython.void:
    i: cython.Py_ssize_t
    j: cython.Py_ssize_t
    k: cython.Py_ssize_t
    for i in range(src.shape[0]):
        for j in range(src.shape[1]):
            for k in range(src.shape[2]):
                dst[i, j, k] = src[i, j, k]


@cython.cfunc
@cython.inline
@cython.nogil
@cython.exceptval(check=False)
def _axpy(x: cython.double[:, ::1], alpha: cython.double, step: cython.double[:, ::1],
          out: cython.double[:, ::1]) -> cython.void:
    """Set out = x + alpha * step."""
    i: cython.Py_ssize_t
    j: cython.Py_ssize_t
    for i in range(x.shape[0]):
        for j in range(x.shape[1]):
            out[i, j] = x[i, j] + alpha * step[i, j]


@cython.cfunc
@cython.nogil
@cython.exceptval(check=False)
def _newton(pb: Problem, x0: cython.double[:, ::1], pressure: cython.double,
            max_iterations: cython.int, gtol: cython.double, xtol: cython.double,
            flat_slope: cython.double, energy_scale: cython.double, armijo: cython.double,
            scale: cython.double, cap: cython.double[:, ::1],
            out: cython.double[:, ::1]) -> cython.int:
    """
    engine._newton from x0: the final state into `out`, return the status code.

    Iterations, relative gradient, last step and smallest eigenvalue go to pb.iterations,
    pb.grad_rel, pb.step_norm, pb.min_eig (the rest of engine._newton's tuple).
    """
    x: cython.double[:, ::1] = pb.x
    grad: cython.double[:, ::1] = pb.grad
    hess: cython.double[:, :, ::1] = pb.hess
    trial: cython.double[:, ::1] = pb.trial
    g_trial: cython.double[:, ::1] = pb.g_trial
    h_trial: cython.double[:, :, ::1] = pb.h_trial
    step: cython.double[:, ::1] = pb.step
    iteration: cython.int
    i: cython.Py_ssize_t
    j: cython.Py_ssize_t
    energy: cython.double
    e_trial: cython.double
    min_eig: cython.double
    ratio: cython.double
    slope: cython.double
    alpha: cython.double
    flat: cython.bint
    step_norm: cython.double = _INF
    grad_rel: cython.double = _INF
    _copy2(x0, x)
    energy = _derivatives(pb, x, pressure, grad, hess)
    for iteration in range(1, max_iterations + 1):
        pb.iterations = iteration
        grad_rel = _max_abs(grad) / scale
        pb.grad_rel = grad_rel
        pb.step_norm = step_norm
        pb.min_eig = _NAN
        if not (isfinite(energy) and isfinite(grad_rel)):
            _copy2(x, out)
            return NOT_FINITE
        min_eig = _block_step(pb, grad, hess, EIGEN_FLOOR, step)
        step_norm = _max_abs(step)
        pb.step_norm = step_norm
        if not isfinite(step_norm):
            _copy2(x, out)
            return NOT_FINITE
        if grad_rel <= gtol and step_norm <= xtol:
            _axpy(x, 1.0, step, out)
            pb.min_eig = min_eig
            return SUCCESS if min_eig > 0.0 else UNSTABLE
        ratio = _max_ratio(step, cap)
        if ratio > 1.0:
            for i in range(pb.n):
                for j in range(4):
                    step[i, j] = step[i, j] / ratio
        slope = _dot(grad, step)
        if not slope < 0.0:
            for i in range(pb.n):
                for j in range(4):
                    step[i, j] = -grad[i, j] / scale
            slope = -_dot(grad, grad) / scale
        _axpy(x, 1.0, step, trial)
        e_trial = _derivatives(pb, trial, pressure, g_trial, h_trial)
        flat = -slope <= flat_slope * (abs(energy) + energy_scale)
        if e_trial <= energy + armijo * slope or flat:
            _copy2(trial, x)
            _copy2(g_trial, grad)
            _copy3(h_trial, hess)
            energy = e_trial
            step_norm = _max_abs(step)
            continue
        alpha = 0.5
        while True:
            _axpy(x, alpha, step, trial)
            if _energy(pb, trial, pressure) <= energy + armijo * alpha * slope:
                break
            alpha *= 0.5
            if alpha < 1e-10:
                _copy2(x, out)
                pb.min_eig = min_eig
                return LINE_SEARCH_FAILED
        _copy2(trial, x)
        step_norm = alpha * _max_abs(step)
        energy = _derivatives(pb, x, pressure, grad, hess)
    _copy2(x, out)
    pb.iterations = max_iterations
    pb.grad_rel = grad_rel
    pb.step_norm = step_norm
    pb.min_eig = _NAN
    return MAX_ITERATIONS


@cython.cfunc
@cython.nogil
@cython.exceptval(check=False)
def _solve(pb: Problem, initial: cython.double[:, ::1], warm: cython.bint,
           flat: cython.double[:, ::1], pressure: cython.double,
           max_iterations: cython.int, gtol: cython.double, xtol: cython.double,
           flat_slope: cython.double, energy_scale: cython.double, armijo: cython.double,
           scale: cython.double, cap: cython.double[:, ::1],
           result: cython.double[::1]) -> cython.int:
    """
    engine._solve unloaded: warm, cold, then continuation in pressure.

    The state goes to pb.out, the status is returned and (iterations, gradient, step,
    min_eig, fraction) go to result[0:5].
    """
    out: cython.double[:, ::1] = pb.out
    best: cython.double[:, ::1] = pb.best
    spent: cython.int = 0
    status: cython.int
    lam: cython.double
    dlam: cython.double
    target: cython.double
    if warm:
        status = _newton(pb, initial, pressure, max_iterations, gtol, xtol, flat_slope,
                         energy_scale, armijo, scale, cap, out)
        if status == SUCCESS:
            return _figures(pb, result, pb.iterations, pb.grad_rel, pb.step_norm, pb.min_eig,
                            1.0, status)
        spent = pb.iterations
    status = _newton(pb, flat, pressure, max_iterations, gtol, xtol, flat_slope, energy_scale,
                     armijo, scale, cap, out)
    spent += pb.iterations
    if status == SUCCESS or status == UNSTABLE:
        return _figures(pb, result, spent, pb.grad_rel, pb.step_norm, pb.min_eig, 1.0, status)
    status = _newton(pb, flat, 0.0, max_iterations, gtol, xtol, flat_slope, energy_scale,
                     armijo, scale, cap, out)
    spent += pb.iterations
    if status != SUCCESS:
        return _figures(pb, result, spent, _INF, _INF, _NAN, 0.0, CONTINUATION_FAILED)
    _copy2(out, best)
    lam = 0.0
    dlam = 0.25
    while True:
        target = min(1.0, lam + dlam)
        status = _newton(pb, best, target * pressure, max_iterations, gtol, xtol, flat_slope,
                         energy_scale, armijo, scale, cap, out)
        spent += pb.iterations
        if status == SUCCESS:
            _copy2(out, best)
            lam = target
            dlam = min(2.0 * dlam, 1.0)
            if lam >= 1.0:
                return _figures(pb, result, spent, pb.grad_rel, pb.step_norm, pb.min_eig,
                                1.0, status)
        else:
            dlam *= 0.5
            if dlam < 1.0 / 256:
                _copy2(best, out)
                return _figures(pb, result, spent, pb.grad_rel, pb.step_norm, _NAN, lam,
                                CONTINUATION_FAILED)


@cython.cfunc
@cython.nogil
@cython.exceptval(check=False)
def _figures(pb: Problem, result: cython.double[::1], iterations: cython.int,
             grad: cython.double, step: cython.double, eig: cython.double,
             fraction: cython.double, status: cython.int) -> cython.int:
    """Write the solve's figures into result; return status."""
    result[0] = iterations
    result[1] = grad
    result[2] = step
    result[3] = eig
    result[4] = fraction
    return status


# -- Python entry ---------------------------------------------------------------------------
def solve_entry(pb: Problem, initial, warm: cython.bint, flat, pressure: cython.double,
                nodes, forces, options, cap):
    """
    Run `engine._solve_entry` for the unloaded CCM, with the engine's packed options.

    Returns (x, status, iterations, grad, step, eig, fraction); the options are
    `engine._packed`'s and `flat` the engine's flat state.

    `nodes` and `forces` must be empty (the spike has no loaded path).
    """
    if len(nodes) or len(forces):
        raise NotImplementedError('the spike ports the unloaded solve only')
    max_iterations, gtol, xtol, flat_slope, energy_scale, armijo, scale = options
    initial_v: cython.double[:, ::1] = initial
    flat_v: cython.double[:, ::1] = flat
    cap_v: cython.double[:, ::1] = cap
    figures = np.empty(5)
    result: cython.double[::1] = figures
    n_it: cython.int = max_iterations
    c_gtol: cython.double = gtol
    c_xtol: cython.double = xtol
    c_flat: cython.double = flat_slope
    c_escale: cython.double = energy_scale
    c_armijo: cython.double = armijo
    c_scale: cython.double = scale
    status: cython.int
    with cython.nogil:
        status = _solve(pb, initial_v, warm, flat_v, pressure, n_it, c_gtol, c_xtol, c_flat,
                        c_escale, c_armijo, c_scale, cap_v, result)
    return (np.array(pb.out), int(status), int(figures[0]), float(figures[1]),
            float(figures[2]), float(figures[3]), float(figures[4]))


# -- kernel-level entries, for measure.py's agreement checks --------------------------------
def derivatives(pb: Problem, q, pressure: cython.double):
    """`kernels.ccm_blocks_derivatives` unloaded: (energy, gradient (N, 4), blocks)."""
    q_v: cython.double[:, ::1] = np.ascontiguousarray(q, dtype=float)
    grad = np.empty((pb.n, 4))
    hess = np.empty((pb.n, 4, 4))
    return float(_derivatives(pb, q_v, pressure, grad, hess)), grad, hess


def energy(pb: Problem, q, pressure: cython.double):
    """`kernels.ccm_energy` unloaded [J]."""
    q_v: cython.double[:, ::1] = np.ascontiguousarray(q, dtype=float)
    return float(_energy(pb, q_v, pressure))


def block_step(pb: Problem, grad, hess):
    """`kernels.newton_step_blocks(grad, hess, EIGEN_FLOOR)`: (step (N, 4), min_eig)."""
    step = np.empty((pb.n, 4))
    min_eig = _block_step(pb, np.ascontiguousarray(grad, dtype=float),
                          np.ascontiguousarray(hess, dtype=float), EIGEN_FLOOR, step)
    return step, float(min_eig)
