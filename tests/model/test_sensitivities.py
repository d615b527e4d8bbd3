"""Exact parameter sensitivities: the section law's, the equilibria's and the material points'."""

from helpers import deviation, fd_derivative
import numpy as np
import pytest

from fpc_gripper.model import ActuatorDesign, engine, Material, PCCSolver
from fpc_gripper.model.section.law import SECTION_PARAMETERS

DESIGN = ActuatorDesign.paper(prestrain=0.25)
L = DESIGN.free_length
#: Tolerance of the finite differences of exact derivatives [-].
FD_RTOL = 1e-6


#: Relative central-difference steps of the SECTION_PARAMETERS.
_STEPS = (1e-4, 1e-4, 1e-4, 1e-4, 1e-4, 1e-4, 1e-4, 1e-4)


def _moved(k, h):
    """DESIGN with SECTION_PARAMETERS[k] moved by h (relative for all but the prestrain)."""
    name = SECTION_PARAMETERS[k]
    if name == 'prestrain':
        return DESIGN.replace(prestrain=DESIGN.prestrain + h)
    if name.startswith('emc_a'):
        law = list(DESIGN.emc_coefficients)
        law[k - 1] *= 1.0 + h
        return DESIGN.replace(emc_coefficients=tuple(law))
    if name == 'pressure_work_factor':
        return DESIGN.replace(pressure_work_factor=2.5 * (1.0 + h))
    field = 'constraining_layer' if name == 'cl_modulus' else 'fluidic_layer'
    old = getattr(DESIGN, field)
    return DESIGN.replace(**{field: Material(old.E1 * (1 + h), old.E2 * (1 + h), old.nu)})


def _unit(k):
    """Size of one unit of SECTION_PARAMETERS[k] per unit of `_moved`'s h."""
    name = SECTION_PARAMETERS[k]
    if name == 'prestrain':
        return 1.0
    if name.startswith('emc_a'):
        return DESIGN.emc_coefficients[k - 1]
    if name == 'pressure_work_factor':
        return 2.5
    return getattr(DESIGN, 'constraining_layer' if name == 'cl_modulus'
                   else 'fluidic_layer').E1


def _fd(fun, k):
    return fd_derivative(lambda h: fun(_moved(k, h[0])), np.zeros(1), _STEPS[k])[..., 0] \
        / _unit(k)


@pytest.fixture(scope='module')
def loaded():
    solver = PCCSolver(DESIGN, n_segments=22)
    force = (0.1, 0.25)
    result = solver.solve(120e3, force)
    assert result.success
    return solver, solver.unknowns(result), solver.tip_loads(force), force


def test_parameter_gradient_is_exact(loaded):
    solver, x, loads, _ = loaded
    rates = solver.parameter_gradient(x, 120e3, loads)
    assert rates.shape == (len(SECTION_PARAMETERS), x.size)
    for k in range(len(SECTION_PARAMETERS)):
        fd = _fd(lambda d: PCCSolver(d, 22).derivatives(x, 120e3, loads)[1], k)
        assert deviation(rates[k], fd) <= FD_RTOL, SECTION_PARAMETERS[k]


def test_equilibrium_sensitivities_are_exact(loaded):
    solver, x, loads, force = loaded
    dx, dforce = engine.sensitivity(solver.engine_problem, x, 120e3, loads,
                                    solver.parameter_gradient(x, 120e3, loads))
    assert dforce is None
    for k in range(len(SECTION_PARAMETERS)):
        fd = _fd(lambda d: (lambda s: s.unknowns(s.solve(120e3, force)))(PCCSolver(d, 22)), k)
        assert deviation(dx[k], fd) <= FD_RTOL, SECTION_PARAMETERS[k]


@pytest.mark.parametrize('axis', ['x', 'z'])
def test_displacement_controlled_force_sensitivities_are_exact(axis):
    # The bordered system's sensitivity, with the unloaded tip's motion in the target.
    solver = PCCSolver(DESIGN, n_segments=22)
    rigidity = solver.rigidity(40e3, axis)
    free = solver.unknowns(rigidity.unloaded)
    dfree = engine.sensitivity(solver.engine_problem, free, 40e3, [],
                               solver.parameter_gradient(free, 40e3, []))[0]
    direction = {'x': np.array([1.0, 0.0]), 'z': np.array([0.0, 1.0])}[axis]
    rate = dfree @ (direction @ solver.node_jacobian(free, solver.tip_node)[1])
    loaded = solver.unknowns(rigidity.loaded)
    loads = [(solver.tip_node, rigidity.force * direction)]
    dx, dforce = engine.sensitivity(solver.engine_problem, loaded, 40e3, loads,
                                    solver.parameter_gradient(loaded, 40e3, loads),
                                    control=(solver.tip_node, direction, rate))
    for k in range(len(SECTION_PARAMETERS)):
        fd = _fd(lambda d: np.array(PCCSolver(d, 22).rigidity(40e3, axis).force), k)
        assert abs(dforce[k] - fd) <= FD_RTOL * abs(fd) + 1e-12 * abs(rigidity.force), \
            SECTION_PARAMETERS[k]
        fd_x = _fd(lambda d: (lambda s: s.unknowns(s.rigidity(40e3, axis).loaded))(
            PCCSolver(d, 22)), k)
        assert deviation(dx[k], fd_x) <= FD_RTOL, SECTION_PARAMETERS[k]


def test_material_jacobian_is_exact(loaded):
    solver, x, _, _ = loaded
    s = np.array([0.0037, 0.0213, 0.0449, solver.edges[7], 0.0871, L])
    _, jac = solver.material_jacobian(x, s)
    fd = fd_derivative(lambda v: solver.material_jacobian(v, s)[0], x, 1e-6)
    assert deviation(jac, fd) <= FD_RTOL
