"""Virtual object: each finger's contact against independent solves of the contact model."""

import numpy as np
import pytest

from fpc_gripper.control.virtual_object import VirtualObject
from fpc_gripper.grasp import make_object
from fpc_gripper.io.config import load_gripper_config
from fpc_gripper.model.contact import ContactSettings, solve_contact
from fpc_gripper.model.discretisations.pcc import PCCSolver
from fpc_gripper.model.pipeline import contact_segments, ModelSettings

CONFIG = load_gripper_config()


@pytest.fixture(scope='module')
def sphere():
    return VirtualObject(make_object('sphere', 0.050), CONFIG)


@pytest.fixture(scope='module')
def solver():
    """A solver of the contact model that shares nothing with the code under test."""
    return PCCSolver(CONFIG.fingers[0].design, contact_segments(ModelSettings().tolerance))


@pytest.mark.parametrize('pressure', [0.0, 30.0e3])
def test_contact_is_the_contact_model_at_that_pressure(sphere, solver, pressure):
    finger = CONFIG.fingers[1]
    contact = sphere.contact(1, pressure)
    section = make_object('sphere', 0.050).section(finger.mount_angle, CONFIG.palm_radius)
    reference = solve_contact(solver, pressure, section)
    assert contact.in_contact
    assert contact.normal_force == pytest.approx(reference.normal_force_total, rel=1e-9)
    on_finger = reference.force.sum(axis=0)
    assert contact.force == pytest.approx(tuple(on_finger), rel=1e-9, abs=1e-12)
    # Force at the tip plus the torque is the same wrench as the contact forces.
    arm = reference.position - reference.tip
    moment = np.sum(arm[:, 1] * reference.force[:, 0] - arm[:, 0] * reference.force[:, 1])
    assert contact.torque == pytest.approx(moment, rel=1e-9, abs=1e-12)
    assert contact.arc == reference.contact_arc()


def test_force_falls_with_pressure_and_vanishes_past_the_touch_pressure(sphere):
    touch = sphere.touch_pressure
    pressures = np.linspace(0.0, touch, 7)[:-1]
    forces = [sphere.contact(0, p).normal_force for p in pressures]
    assert np.all(np.diff(forces) < 0.0)
    assert sphere.contact(0, touch + 1.0e3).normal_force == 0.0
    assert not sphere.contact(0, 300e3).in_contact
    assert sphere.total_normal_force([0.0] * 3) == pytest.approx(3 * forces[0], rel=1e-9)


def test_compliant_object_is_a_penalty_surface(solver):
    """lambda = k max(-g, 0) at every point, and it pushes less than a rigid one."""
    obj = make_object('cylinder', 0.040)
    stiffness = 500.0
    soft = VirtualObject(obj, CONFIG, penalty=stiffness)
    rigid = VirtualObject(obj, CONFIG)
    section = obj.section(0.0, CONFIG.palm_radius)
    state = solve_contact(solver, 60e3, section, settings=ContactSettings(penalty=stiffness))
    np.testing.assert_allclose(state.normal_force, stiffness * np.maximum(-state.gap, 0.0),
                               atol=1e-9)
    assert soft.contact(0, 60e3).normal_force == pytest.approx(state.normal_force_total,
                                                               rel=1e-9)
    assert 0.0 < soft.contact(0, 60e3).normal_force < rigid.contact(0, 60e3).normal_force


def test_holding_force_comes_from_the_grasp_api(sphere):
    point = sphere.holding_force(0.0, 0.5)
    assert point.success and point.holding_force > 0.0


def test_bad_penalty_is_refused():
    with pytest.raises(ValueError, match='penalty'):
        VirtualObject(make_object('sphere', 0.05), CONFIG, penalty=-1.0)
