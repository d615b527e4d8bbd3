"""Compiled (numba) Newton steps: block, dense and banded Cholesky, and indefinite Hessians."""

import math

import numpy as np

from ..compiled import jit

__all__ = ['EIGEN_FLOOR', 'newton_step', 'newton_step_blocks', 'newton_step_dense',
           'banded_cholesky', 'cholesky_solve', 'banded_step', 'shifted_step']

# Built at install (`compiled`), once per argument types; nogil lets a caller thread them.
_jit = jit
#: Eigenvalues of an indefinite Hessian are mirrored and floored at this times max |lambda|.
EIGEN_FLOOR = 1e-8


# -- the CCM: blocks or one dense matrix -----------------------------------------------------
@_jit
def _block_cholesky_steps(grad, hess, step):
    """
    Solve every block's H_i x_i = -g_i into step[i] by Cholesky; False if one is not PD.

    Each block's arithmetic is `_cholesky_substitute`'s and potrf's, in the same order,
    so the step is bit-identical to solving the blocks one at a time. The blocks run in
    lockstep (the innermost loops over the blocks): their square roots and divisions
    overlap, where one block at a time waits on each. As LAPACK potrf (OpenBLAS) it fails
    on a pivot <= 0 only: NaN propagates.
    """
    n, m = grad.shape
    low = np.empty((m, m, n))
    acc = np.empty(n)
    for i in range(m):
        for j in range(i + 1):
            for b in range(n):
                acc[b] = hess[b, i, j]
            for k in range(j):
                for b in range(n):
                    acc[b] -= low[i, k, b] * low[j, k, b]
            if i == j:
                for b in range(n):
                    if acc[b] <= 0.0:
                        return False
                for b in range(n):
                    low[i, i, b] = math.sqrt(acc[b])
            else:
                for b in range(n):
                    low[i, j, b] = acc[b] / low[j, j, b]
    out = np.empty((m, n))
    for i in range(m):
        for b in range(n):
            acc[b] = -grad[b, i]
        for k in range(i):
            for b in range(n):
                acc[b] -= low[i, k, b] * out[k, b]
        for b in range(n):
            out[i, b] = acc[b] / low[i, i, b]
    for i in range(m - 1, -1, -1):
        for b in range(n):
            acc[b] = out[i, b]
        for k in range(i + 1, m):
            for b in range(n):
                acc[b] -= low[k, i, b] * out[k, b]
        for b in range(n):
            out[i, b] = acc[b] / low[i, i, b]
    for b in range(n):
        for i in range(m):
            step[b, i] = out[i, b]
    return True


@_jit
def _cholesky_substitute(low, rhs, out):
    """Solve L L^T x = rhs into out by forward and back substitution."""
    n = rhs.size
    for i in range(n):
        acc = rhs[i]
        for k in range(i):
            acc -= low[i, k] * out[k]
        out[i] = acc / low[i, i]
    for i in range(n - 1, -1, -1):
        acc = out[i]
        for k in range(i + 1, n):
            acc -= low[k, i] * out[k]
        out[i] = acc / low[i, i]


@_jit
def _dense_cholesky(a):
    """LAPACK Cholesky factor of a (lower), and whether a is positive definite."""
    # In nopython mode only `except Exception` is supported; LinAlgError is the only raise.
    try:
        return np.linalg.cholesky(a), True
    except Exception:
        return np.empty((0, 0)), False


@_jit
def _mirrored_solve(lam, vec, rhs, floor, out):
    """Solve V |Lambda| V^T x = rhs into out, |lambda| floored at floor."""
    n = lam.size
    out[:] = 0.0
    for k in range(n):
        coef = 0.0
        for i in range(n):
            coef += rhs[i] * vec[i, k]
        coef /= max(abs(lam[k]), floor)
        for i in range(n):
            out[i] += vec[i, k] * coef


@_jit
def newton_step_blocks(grad, hess, floor):
    """
    Newton step for a block-diagonal Hessian, compiled.

    Where every block is positive definite, the step solves each block by
    Cholesky. Otherwise the eigenvalues of every block are mirrored (|lambda|,
    floored at `floor` times the block's largest) so that the step still descends.

    Parameters
    ----------
    grad : ndarray, shape (N, m)
    hess : ndarray, shape (N, m, m)
    floor : float

    Returns
    -------
    step : ndarray, shape (N, m)
    min_eig : float
        1.0 when every block is positive definite, else the smallest eigenvalue.

    """
    n, m = grad.shape
    step = np.empty((n, m))
    if _block_cholesky_steps(grad, hess, step):
        return step, 1.0
    rhs = np.empty(m)
    out = np.empty(m)
    min_eig = np.inf
    for i in range(n):
        lam, vec = np.linalg.eigh(hess[i])
        min_eig = min(min_eig, lam.min())
        for a in range(m):
            rhs[a] = -grad[i, a]
        _mirrored_solve(lam, vec, rhs, floor * np.abs(lam).max(), out)
        step[i] = out
    return step, min_eig


@_jit
def newton_step_dense(grad, hess, floor):
    """
    Newton step for a dense Hessian, compiled: Cholesky, else mirrored eigenvalues.

    Parameters
    ----------
    grad : ndarray, shape (n,)
    hess : ndarray, shape (n, n)
    floor : float
        Mirrored eigenvalues are floored at this times the largest |lambda|.

    Returns
    -------
    step : ndarray, shape (n,)
    min_eig : float
        1.0 when the Hessian is positive definite, else its smallest eigenvalue.

    """
    # A 4 N system is large enough that LAPACK's blocked factorisation beats loops.
    low, definite = _dense_cholesky(hess)
    return _factored_step(grad, hess, low, definite, floor)


@_jit
def _factored_step(grad, hess, low, definite, floor):
    """`newton_step_dense` given the Cholesky factor of hess (when `definite`)."""
    n = hess.shape[0]
    rhs = -grad
    out = np.empty(n)
    if definite:
        _cholesky_substitute(low, rhs, out)
        return out, 1.0
    lam, vec = np.linalg.eigh(hess)
    _mirrored_solve(lam, vec, rhs, floor * np.abs(lam).max(), out)
    return out, lam.min()


def newton_step(grad, hess, floor=EIGEN_FLOOR):
    """
    Newton step -H^-1 g, and the smallest eigenvalue (1.0 when H is positive definite).

    Where H is not positive definite its eigenvalues are mirrored (|lambda|, floored at
    `floor` times the largest) so that the step still descends.

    Parameters
    ----------
    grad : ndarray
        (N, m) for a block Hessian; any shape for a dense one.
    hess : ndarray, shape (N, m, m) or (n, n)
        Block-diagonal or dense Hessian.
    floor : float

    Returns
    -------
    step : ndarray, shape of `grad`
    min_eig : float

    """
    grad = np.ascontiguousarray(grad, dtype=float)
    hess = np.ascontiguousarray(hess, dtype=float)
    if hess.ndim == 3:
        return newton_step_blocks(grad, hess, float(floor))
    step, min_eig = newton_step_dense(grad.ravel(), hess, float(floor))
    return step.reshape(grad.shape), min_eig


# -- banded Cholesky (LAPACK dpbtf2 / dpbtrs, lower; the rows give the half-bandwidth) --------
@_jit
def banded_cholesky(lower):
    """
    Cholesky factor of a symmetric band matrix in lower form, and whether it is PD.

    Parameters
    ----------
    lower : ndarray, shape (b + 1, n)
        lower[d, k] = H[k + d, k], half-bandwidth b (3 for the PCC, the degree for the
        rod's condensed system).

    Returns
    -------
    factor : ndarray, shape (b + 1, n)
        L in the same form (H = L L^T); meaningful only when `definite`.
    definite : bool
        False on the first pivot <= 0; as LAPACK, NaN pivots propagate instead.

    """
    n = lower.shape[1]
    band = lower.shape[0] - 1
    factor = lower.copy()
    for j in range(n):
        pivot = factor[0, j]
        if pivot <= 0.0:
            return factor, False
        pivot = math.sqrt(pivot)
        factor[0, j] = pivot
        reach = min(band, n - 1 - j)
        scale = 1.0 / pivot
        for d in range(1, reach + 1):
            factor[d, j] *= scale
        # Rank-one update of the trailing (reach x reach) block, column by column.
        for col in range(reach):
            xc = factor[col + 1, j]
            for row in range(col, reach):
                factor[row - col, j + 1 + col] -= factor[row + 1, j] * xc
    return factor, True


@_jit
def _substitute(factor, x):
    """Solve L L^T y = x in place (forward then back substitution in the band)."""
    n = x.size
    band = factor.shape[0] - 1
    for j in range(n):
        if x[j] != 0.0:
            x[j] /= factor[0, j]
            temp = x[j]
            for d in range(1, min(band, n - 1 - j) + 1):
                x[j + d] -= temp * factor[d, j]
    for j in range(n - 1, -1, -1):
        temp = x[j]
        for d in range(min(band, n - 1 - j), 0, -1):
            temp -= factor[d, j] * x[j + d]
        x[j] = temp / factor[0, j]


@_jit
def cholesky_solve(factor, rhs):
    """Solve L L^T x = rhs for x, shape (n,), given the `banded_cholesky` factor L."""
    out = rhs.copy()
    _substitute(factor, out)
    return out


@_jit
def banded_step(lower, grad):
    """
    Newton step -H^-1 g by banded Cholesky.

    Returns
    -------
    factor : ndarray, shape (4, n)
        The Cholesky factor (reused by linear solves with the same H).
    step : ndarray, shape (n,)
        -H^-1 g; meaningless unless `definite`.
    definite : bool
        H is positive definite.

    """
    factor, definite = banded_cholesky(lower)
    step = -grad
    if definite:
        _substitute(factor, step)
    return factor, step, definite


@_jit
def _dense_from_band(lower):
    """Return the full (n, n) matrix of a symmetric band in lower form."""
    n = lower.shape[1]
    out = np.zeros((n, n))
    for d in range(lower.shape[0]):
        for k in range(n - d):
            out[k + d, k] = lower[d, k]
            out[k, k + d] = lower[d, k]
    return out


@_jit
def shifted_step(lower, grad, gradient_scale):
    """
    Descent step of an indefinite banded Hessian H, and its scaled lambda_min (< 0).

    Solves (H + tau D) dx = -g with D = |diag H| and tau = 2 |lambda_min| (+1e-10) of the
    Jacobi-scaled Hessian D^(-1/2) H D^(-1/2), doubling tau until the banded Cholesky
    succeeds; a gradient step -g / gradient_scale if it never does.

    Returns
    -------
    step : ndarray, shape (n,)
        NaN where the scaled Hessian is not finite.
    min_eig : float
        lambda_min of the scaled Hessian, at most -1e-300.

    """
    n = lower.shape[1]
    root = np.empty(n)
    for k in range(n):
        root[k] = math.sqrt(max(abs(lower[0, k]), 1e-300))
    scaled = lower.copy()
    for d in range(lower.shape[0]):
        for k in range(n - d):
            scaled[d, k] /= root[k + d] * root[k]
    if not np.all(np.isfinite(scaled)):
        return np.full(n, np.nan), -1.0
    min_eig = min(np.linalg.eigvalsh(_dense_from_band(scaled))[0], -1e-300)
    shift = 2.0 * abs(min_eig) + 1e-10
    for _ in range(60):
        trial = scaled.copy()
        for k in range(n):
            trial[0, k] += shift
        factor, definite = banded_cholesky(trial)
        if definite:
            step = -grad / root
            _substitute(factor, step)
            return step / root, min_eig
        shift *= 2.0
    return -grad / gradient_scale, min_eig
