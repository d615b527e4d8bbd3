"""Eq. 22 at small levers: K_z at prestrain 0.40 is flagged where it breaks, dF/ddelta is exact."""

import numpy as np
import pytest

from fpc_gripper.model import ActuatorDesign, AdaptiveSolver
from fpc_gripper.model.batch import rigidity_grid
from fpc_gripper.model.stiffness import classify, RigidityStatus

DELTA = 0.010
#: The issue's sweep: K_z at prestrain 0.40 from 0 to 150 kPa.
PRESSURES = np.arange(0.0, 150e3 + 1.0, 5e3)


@pytest.fixture(scope='module')
def kz():
    solver = AdaptiveSolver(ActuatorDesign.paper(prestrain=0.40))
    return solver, [solver.rigidity(p, 'z', DELTA) for p in PRESSURES]


@pytest.mark.parametrize('args, status', [
    ((False, 0.05, DELTA, False), RigidityStatus.FAILED),
    ((True, 0.009, DELTA, False), RigidityStatus.SMALL_LEVER),
    ((True, -0.009, DELTA, True), RigidityStatus.SMALL_LEVER),
    ((True, 0.011, DELTA, True), RigidityStatus.BRANCH_CHANGE),
    ((True, 0.011, DELTA, False), RigidityStatus.OK),
])
def test_classify(args, status):
    assert classify(*args) is status


def test_no_tiny_rigidity_is_a_plain_success(kz):
    _, results = kz
    for p, k in zip(PRESSURES, results):
        assert k.rigidity_status is not RigidityStatus.FAILED, (p, k.message)
        if k.value < 1e-5:
            assert not k.success and k.rigidity_status is not RigidityStatus.OK, p
        assert k.success == (k.rigidity_status is RigidityStatus.OK)
        if k.success:
            assert k.lever >= DELTA and 'eq. 22' not in k.message
        else:
            assert 'eq. 22 does not apply' in k.message and np.isfinite(k.value)


def test_the_issue_pressures_are_flagged(kz):
    _, results = kz
    status = {p: k.rigidity_status for p, k in zip(PRESSURES, results)}
    for p in (0.0, 50e3, 85e3):
        assert status[p] is RigidityStatus.SMALL_LEVER, p
    assert status[90e3] is RigidityStatus.BRANCH_CHANGE


def test_the_direct_stiffness_is_the_slope_of_the_force(kz):
    solver, results = kz
    h = 1e-5
    for p, k in list(zip(PRESSURES, results))[::5]:
        up = solver.rigidity(p, 'z', DELTA + h).force
        down = solver.rigidity(p, 'z', DELTA - h).force
        slope = (up - down) / (2 * h)
        assert abs(k.direct_stiffness - slope) <= 1e-4 * abs(slope) + 1e-3, p


def test_a_jump_in_the_direct_stiffness_is_flagged(kz):
    _, results = kz
    stiffness = np.array([k.direct_stiffness for k in results])
    ok = np.array([k.success for k in results])
    jumps = np.flatnonzero(np.abs(np.diff(stiffness)) > 0.5 * np.abs(stiffness[:-1]))
    assert jumps.size >= 1     # 85 -> 90 kPa at least
    for j in jumps:
        assert not (ok[j] and ok[j + 1]), PRESSURES[j]


def test_the_grid_flags_as_the_single_call(kz):
    _, results = kz
    grid = rigidity_grid(ActuatorDesign.paper(prestrain=0.40), PRESSURES[::3], 'z', DELTA)
    for j, k in enumerate(results[::3]):
        assert grid.rigidity_status[0, j] == k.rigidity_status
        assert grid.success[0, j] == k.success
        assert abs(grid.direct_stiffness[0, j] - k.direct_stiffness) \
            <= 1e-9 * abs(k.direct_stiffness)
