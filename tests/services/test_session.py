"""The scripted session without ROS: when phases start, how each is judged, the summary."""

import math

import pytest

from fpc_gripper.services.session import default_phases
from fpc_gripper.services.session import format_summary
from fpc_gripper.services.session import Phase
from fpc_gripper.services.session import Session

GRASP = 1.5


def state(status, aperture_target=0.12, force_target=math.nan, forces=(0.5, 0.5, 0.5),
          message='ok'):
    """controller_state values as the session script hears them."""
    values = {'goal_status': status, 'aperture_target_m': f'{aperture_target:.6f}',
              'force_target_n': f'{force_target:.4f}', 'aperture_m': '0.100000',
              'level': 0, 'message': message}
    values.update({f'finger_{i}/contact_force_n': f'{f:.4f}' for i, f in enumerate(forces)})
    return values


def started_session(phases=None, arcs=None):
    """A session whose first phase started at t = 2 s."""
    session = Session(phases or default_phases(grasp_force=GRASP), GRASP, started=0.0,
                      arcs=arcs)
    session.state = state('none')
    assert session.step(0.5, ready=True) is None            # warming up
    first = session.step(2.0, ready=True)
    assert first is session.phases[0] and first.start == pytest.approx(2.0)
    return session


def test_the_first_goal_waits_for_the_controller_to_be_heard():
    session = Session(default_phases(), GRASP, started=0.0)
    assert session.step(5.0, ready=True) is None            # no state heard yet
    session.state = state('none')
    assert session.step(5.1, ready=False) is None           # nobody hears the goals
    assert session.step(5.2, ready=True).name == 'open'


def test_a_controller_that_never_comes_up_fails_the_session():
    session = Session(default_phases(), GRASP, started=0.0)
    assert session.step(20.5, ready=False) is None
    assert session.finished and not session.passed
    assert session.phases[0].detail == 'the controller did not come up'
    assert [p.detail for p in session.phases[1:]] == ['not run'] * 3
    assert session.step(21.0, ready=True) is None           # over: nothing starts


def test_an_aperture_goal_is_reached_only_once_seen_active_then_after_the_dwell():
    session = started_session()
    # A 'reached' left from before the goal arrived does not count.
    session.state = state('reached', aperture_target=0.05)
    assert session.step(2.1, True) is None
    session.state = state('active')
    session.step(2.2, True)
    session.state = state('reached')
    session.step(2.6, True)
    assert session.phases[0].time_to_goal == pytest.approx(0.6)
    assert session.step(3.0, True) is None                  # dwelling 0.5 s
    grasp = session.step(3.2, True)
    assert grasp is session.phases[1] and session.phases[0].reached
    assert session.phases[0].end == pytest.approx(3.2)
    assert session.phases[0].final['goal_status'] == 'reached'


def test_a_goal_not_reached_in_time_fails_and_ends_the_session():
    session = started_session()
    session.state = state('active')
    session.step(9.0, True)
    assert not session.finished
    session.step(10.1, True)
    assert session.finished and not session.passed
    assert session.phases[0].detail == 'not reached in 8.0 s (status active)'
    assert [p.detail for p in session.phases[1:]] == ['not run'] * 3


def hold_session(arcs=None):
    """A session whose hold phase (3 s) started at t = 2 s."""
    phases = [Phase('hold', 'hold', 3.0, timeout=4.0), Phase('release', 'aperture', 0.12)]
    session = started_session(phases, arcs)
    session.state = state('reached', force_target=GRASP)
    return session


def test_a_hold_passes_when_the_goal_and_every_share_of_the_force_hold():
    session = hold_session(arcs=lambda: [(0.08, 0.09), None, (0.09, 0.09)])
    assert session.step(4.9, True) is None
    release = session.step(5.0, True)
    hold = session.phases[0]
    assert release is session.phases[1] and hold.reached
    assert hold.time_to_goal == 0.0
    assert hold.arcs == [(0.08, 0.09), None, (0.09, 0.09)]


@pytest.mark.parametrize('changed, word', [
    (state('reached', forces=(0.5, 0.5, 0.4)), 'worst force error 0.100 N'),
    (state('stalled', forces=(0.5, 0.5, 0.5)), 'status stalled')])
def test_a_hold_fails_as_soon_as_a_force_or_the_goal_leaves(changed, word):
    session = hold_session()
    session.step(3.0, True)
    session.state = changed
    session.step(3.1, True)
    assert session.finished and not session.phases[0].reached
    assert word in session.phases[0].detail


def test_the_summary_has_a_line_per_phase_and_the_recording():
    phases = default_phases()
    phases[0].reached, phases[0].time_to_goal = True, 0.75
    phases[0].final = state('reached')
    phases[0].arcs = [(0.0800, 0.0900), (0.09, 0.09001), None]
    phases[2].holding = 0.42
    info = {'mcap': 'out/session.mcap', 'messages': 1234, 'max_command': 2.5e5,
            'max_pressure': 4.0e5, 'contact_residual': 1.2e-4, 'wall_s': 30.0}
    lines = format_summary(phases, info).splitlines()
    assert len(lines) == 1 + len(phases) + 1
    open_line = lines[1].split()
    assert open_line[:5] == ['open', '120.0', 'mm', 'REACHED', '0.75']
    assert open_line[5:9] == ['100.00', '0.500', '0.500', '0.500']
    assert open_line[9:12] == ['80.0-90.0', '90.0', '-']
    assert lines[3].split()[-1] == '0.420'
    assert 'FAILED' in lines[2] and lines[2].split()[-1] == '-'
    assert lines[-1].startswith('recording: out/session.mcap (1234 messages); largest command '
                                '250.0 kPa (limit 400)')
