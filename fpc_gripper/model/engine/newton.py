"""The discretisation hooks and the damped Newton over them: each loop once, compiled or not."""

from numba import types
from numba.extending import overload, register_jitable
import numpy as np

from .outcomes import (_CONTINUATION_FAILED, _LINE_SEARCH_FAILED, _MAX_ITERATIONS, _NOT_FINITE,
                       _SUCCESS, _UNSTABLE)
from ..kernels import linear


def linear_step(grad, hess, floor=linear.EIGEN_FLOOR):
    """
    Newton step -H^-1 g, and the smallest eigenvalue's sign (1.0 when positive definite).

    Where H is not positive definite its eigenvalues are mirrored (|lambda|, floored at
    `floor` times the largest) so that the step still descends; the smallest eigenvalue
    is returned. H is dense (n, n), or (N, m, m) blocks for g of shape (N, m). Compiled
    (`kernels.linear.newton_step`).
    """
    return linear.newton_step(grad, hess, floor)


def linear_solve(hess, rhs):
    """Solve H x = rhs for a dense (n, n) or block (N, m, m) H; LinAlgError if singular."""
    if hess.ndim == 3:
        return np.linalg.solve(hess, rhs[:, :, None])[:, :, 0]
    return np.linalg.solve(hess, rhs.ravel()).reshape(rhs.shape)


# -- the discretisation interface ----------------------------------------------------------
# A discretisation hands the engine either a Python object with methods (the loops then run
# interpreted) or a `CompiledProblem` over namedtuples of arrays whose type is registered
# here (`register`) with compiled functions of the same names taking the namedtuple first
# (the loops then run compiled, for that type). These functions are that interface; the
# loops call nothing else. The first six (`HOOKS`) serve every solve (`outputs`: the fields of
# a state, `OUTPUT_FIELDS`); the three `_point_*` (`POINT_HOOKS`: face points, the PCC and
# the rod) serve contact only.
HOOKS = ('derivatives', 'energy', 'step', 'solve_linear', 'node_jacobian', 'outputs')
POINT_HOOKS = ('point_derivatives', 'point_jacobian', 'point_positions')
#: What every `outputs` hook returns, in order. nodes (N + 1, 2) [m], the tip last; beta (N,)
#: and theta (N,), every segment's rotation and its angle at its start [rad]; coefficients
#: (N, 4) (b1 [-], b3 [1/m^2], c1 [-], d [1/m]), or (0, 4) where the discretisation has
#: none; valid (the CCM's small-rotation rule, else True); and with `samples`: the energy
#: [J] (else NaN), points (M, 2) [m], tangent (M,) [rad] and strains (M, 3) (eps [-],
#: kappa [1/m], c1 [-]), or (0, 3) where the discretisation has none; without, (0, ...).
OUTPUT_FIELDS = ('nodes', 'beta', 'theta', 'coefficients', 'valid', 'energy', 'points',
                 'tangent', 'strains')

_REGISTERED = {}


def register(data_type, hooks):
    """
    Register the compiled hooks of a discretisation's data type, a namedtuple class.

    Parameters
    ----------
    data_type : type
        The namedtuple class of the data its `CompiledProblem` carries.
    hooks : dict
        numba dispatchers by name: every name of `HOOKS`, and those of `POINT_HOOKS` for a
        discretisation with face points (contact).

    Raises
    ------
    ValueError
        Where a name of `HOOKS` is missing or a name is not a hook.

    """
    missing = [name for name in HOOKS if name not in hooks]
    unknown = [name for name in hooks if name not in HOOKS + POINT_HOOKS]
    if missing or unknown:
        raise ValueError(f'`hooks` of {data_type.__name__} must name every one of {HOOKS} and '
                         f'only those or {POINT_HOOKS}; missing {missing}, unknown {unknown}')
    _REGISTERED[data_type] = dict(hooks)


def hooks_of(data_type):
    """Return the compiled hooks registered for a data type, by name (a copy)."""
    return dict(_REGISTERED[data_type])


def _loads(nodes, forces):
    return [(int(node), forces[k]) for k, node in enumerate(nodes)]


def _derivatives(problem, x, pressure, nodes, forces):
    """Energy [J], gradient (shape of x) and Hessian (opaque to the engine) at x."""
    return problem.derivatives(x, pressure, _loads(nodes, forces))


def _energy(problem, x, pressure, nodes, forces):
    """Total potential [J] at x."""
    return problem.energy(x, pressure, _loads(nodes, forces))


def _step(problem, grad, hess):
    """Newton step (shape of grad) and the smallest eigenvalue (1.0 when H is PD)."""
    return problem.step(grad, hess)


def _solve_linear(problem, hess, rhs):
    """Solve H x = rhs: (x, True), or (anything, False) where H is singular."""
    try:
        return problem.solve_linear(hess, rhs), True
    except np.linalg.LinAlgError:
        return rhs, False


def _node_jacobian(problem, x, node):
    """Position (2,) of a node [m] and its derivatives, shape (2,) + x.shape."""
    return problem.node_jacobian(x, node)


def _outputs(problem, x, pressure, nodes, forces, samples):
    """Return the fields of a state, `OUTPUT_FIELDS` (samples where asked)."""
    return problem.outputs(x, pressure, _loads(nodes, forces), samples)


def _point_derivatives(problem, x, pressure, nodes, forces, pseg, poff, pz, pforce):
    """Return `_derivatives` with dead forces pforce (K, 2) at face points too."""
    return problem.point_derivatives(x, pressure, _loads(nodes, forces), pseg, poff, pz,
                                     pforce)


def _point_positions(problem, x, pseg, poff, pz):
    """Positions (K, 2) [m] of face points: segment, arc length into it [m], height [m]."""
    return problem.point_positions(x, pseg, poff, pz)


def _point_jacobian(problem, x, seg, offset, z):
    """Position (2,) of a face point [m] and its derivatives, shape (2,) + x.shape."""
    return problem.point_jacobian(x, seg, offset, z)


def _kernel(problem, name):
    """Return the compiled `name` of a registered namedtuple type, None for others."""
    if isinstance(problem, types.BaseNamedTuple):
        return _REGISTERED.get(problem.instance_class, {}).get(name)
    return None


@overload(_derivatives, jit_options={'nogil': True})
def _derivatives_compiled(problem, x, pressure, nodes, forces):
    kernel = _kernel(problem, 'derivatives')
    if kernel is not None:
        return lambda problem, x, pressure, nodes, forces: kernel(problem, x, pressure, nodes,
                                                                  forces)
    return None


@overload(_energy, jit_options={'nogil': True})
def _energy_compiled(problem, x, pressure, nodes, forces):
    kernel = _kernel(problem, 'energy')
    if kernel is not None:
        return lambda problem, x, pressure, nodes, forces: kernel(problem, x, pressure, nodes,
                                                                  forces)
    return None


@overload(_step, jit_options={'nogil': True})
def _step_compiled(problem, grad, hess):
    kernel = _kernel(problem, 'step')
    if kernel is not None:
        return lambda problem, grad, hess: kernel(problem, grad, hess)
    return None


@overload(_solve_linear, jit_options={'nogil': True})
def _solve_linear_compiled(problem, hess, rhs):
    kernel = _kernel(problem, 'solve_linear')
    if kernel is not None:
        return lambda problem, hess, rhs: kernel(problem, hess, rhs)
    return None


@overload(_node_jacobian, jit_options={'nogil': True})
def _node_jacobian_compiled(problem, x, node):
    kernel = _kernel(problem, 'node_jacobian')
    if kernel is not None:
        return lambda problem, x, node: kernel(problem, x, node)
    return None


@overload(_outputs, jit_options={'nogil': True})
def _outputs_compiled(problem, x, pressure, nodes, forces, samples):
    kernel = _kernel(problem, 'outputs')
    if kernel is not None:
        return lambda problem, x, pressure, nodes, forces, samples: kernel(
            problem, x, pressure, nodes, forces, samples)
    return None


@overload(_point_derivatives, jit_options={'nogil': True})
def _point_derivatives_compiled(problem, x, pressure, nodes, forces, pseg, poff, pz, pforce):
    kernel = _kernel(problem, 'point_derivatives')
    if kernel is not None:
        return lambda problem, x, pressure, nodes, forces, pseg, poff, pz, pforce: kernel(
            problem, x, pressure, nodes, forces, pseg, poff, pz, pforce)
    return None


@overload(_point_positions, jit_options={'nogil': True})
def _point_positions_compiled(problem, x, pseg, poff, pz):
    kernel = _kernel(problem, 'point_positions')
    if kernel is not None:
        return lambda problem, x, pseg, poff, pz: kernel(problem, x, pseg, poff, pz)
    return None


@overload(_point_jacobian, jit_options={'nogil': True})
def _point_jacobian_compiled(problem, x, seg, offset, z):
    kernel = _kernel(problem, 'point_jacobian')
    if kernel is not None:
        return lambda problem, x, seg, offset, z: kernel(problem, x, seg, offset, z)
    return None


# Reductions of the loops: numpy when interpreted, allocation-free loops when compiled.
def _max_abs(a):
    """Return max |a|, 0 for an empty array."""
    return float(np.abs(a).max()) if a.size else 0.0


def _max_ratio(a, cap):
    """Return max |a| / cap, cap elementwise of a's shape; 0 for an empty array."""
    return float((np.abs(a) / cap).max()) if a.size else 0.0


def _dot(a, b):
    """Return the sum of a * b over all elements."""
    return float(np.vdot(a, b))


@overload(_max_abs, jit_options={'nogil': True})
def _max_abs_compiled(a):
    def impl(a):
        out = 0.0
        for value in a.flat:
            if value != value:
                # max() would drop a NaN: the loops test this figure for finiteness.
                return np.nan
            out = max(out, abs(value))
        return out
    return impl


@overload(_max_ratio, jit_options={'nogil': True})
def _max_ratio_compiled(a, cap):
    def impl(a, cap):
        out = 0.0
        flat_cap = cap.ravel()
        k = 0
        for value in a.flat:
            out = max(out, abs(value) / flat_cap[k])
            k += 1
        return out
    return impl


@overload(_dot, jit_options={'nogil': True})
def _dot_compiled(a, b):
    def impl(a, b):
        out = 0.0
        flat_b = b.ravel()
        k = 0
        for value in a.flat:
            out += value * flat_b[k]
            k += 1
        return out
    return impl


# -- the loops: each written once, run compiled or interpreted -----------------------------
@register_jitable
def _newton(problem, x, pressure, nodes, forces, options, cap):
    """Damped Newton: (x, status, iterations, gradient, step, min_eig); see `newton`."""
    max_iterations, gtol, xtol, flat_slope, energy_scale, armijo, scale = options
    step_norm = np.inf
    grad_rel = np.inf
    energy, grad, hess = _derivatives(problem, x, pressure, nodes, forces)
    for iteration in range(1, max_iterations + 1):
        grad_rel = _max_abs(grad) / scale
        if not (np.isfinite(energy) and np.isfinite(grad_rel)):
            return x, _NOT_FINITE, iteration, grad_rel, step_norm, np.nan
        step, min_eig = _step(problem, grad, hess)
        step_norm = _max_abs(step)
        if not np.isfinite(step_norm):
            return x, _NOT_FINITE, iteration, grad_rel, step_norm, np.nan
        if grad_rel <= gtol and step_norm <= xtol:
            status = _SUCCESS if min_eig > 0.0 else _UNSTABLE
            return x + step, status, iteration, grad_rel, step_norm, min_eig
        ratio = _max_ratio(step, cap)
        if ratio > 1.0:
            step = step / ratio
        slope = _dot(grad, step)
        if not slope < 0.0:
            step = -grad / scale
            slope = -_dot(grad, grad) / scale
        trial = x + step
        e_trial, g_trial, h_trial = _derivatives(problem, trial, pressure, nodes, forces)
        flat = -slope <= flat_slope * (abs(energy) + energy_scale)
        if e_trial <= energy + armijo * slope or flat:
            x, energy, grad, hess = trial, e_trial, g_trial, h_trial
            step_norm = _max_abs(step)
            continue
        alpha = 0.5
        while True:
            trial = x + alpha * step
            if _energy(problem, trial, pressure, nodes, forces) <= energy + armijo * alpha * slope:
                break
            alpha *= 0.5
            if alpha < 1e-10:
                return x, _LINE_SEARCH_FAILED, iteration, grad_rel, step_norm, min_eig
        x = trial
        step_norm = alpha * _max_abs(step)
        energy, grad, hess = _derivatives(problem, x, pressure, nodes, forces)
    return x, _MAX_ITERATIONS, max_iterations, grad_rel, step_norm, np.nan


@register_jitable
def _solve(problem, initial, warm, flat, pressure, nodes, forces, options, cap):
    """Warm, cold, then continuation: `_newton`'s tuple and the fraction; see `solve`."""
    spent = 0
    if warm:
        x, status, its, grad, step, eig = _newton(problem, initial, pressure, nodes, forces,
                                                  options, cap)
        if status == _SUCCESS:
            return x, status, its, grad, step, eig, 1.0
        spent = its
    x, status, its, grad, step, eig = _newton(problem, flat, pressure, nodes, forces, options,
                                              cap)
    spent += its
    if status == _SUCCESS or status == _UNSTABLE:
        return x, status, spent, grad, step, eig, 1.0
    x, status, its, grad, step, eig = _newton(problem, flat, 0.0, nodes[:0], forces[:0],
                                              options, cap)
    spent += its
    if status != _SUCCESS:
        return x, _CONTINUATION_FAILED, spent, np.inf, np.inf, np.nan, 0.0
    lam = 0.0
    dlam = 0.25
    while True:
        target = min(1.0, lam + dlam)
        sub, status, its, grad, step, eig = _newton(problem, x, target * pressure, nodes,
                                                    target * forces, options, cap)
        spent += its
        if status == _SUCCESS:
            x, lam = sub, target
            dlam = min(2.0 * dlam, 1.0)
            if lam >= 1.0:
                return x, status, spent, grad, step, eig, 1.0
        else:
            dlam *= 0.5
            if dlam < 1.0 / 256:
                return x, _CONTINUATION_FAILED, spent, grad, step, np.nan, lam
