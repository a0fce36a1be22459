"""The real-time driver's core (moverl_sim.realtime): wall-clock pacing, goals followed, preempted, cancelled and
aborted by a stall, ExecuteTrajectory motions, idle contacts. No roscore; a real Simulator, the wall clock injected.

Goals are plain objects with the fields of trajectory_msgs/JointTrajectoryPoint that moverl_sim.follow reads; goal
handles are whatever the caller passes (the node's actionlib handles; strings here).
"""

from types import SimpleNamespace as NS

import numpy as np
import pytest
from conftest import HOME, JOINTS, make_sim

from moverl_sim import follow
from moverl_sim.realtime import CATCH_UP, IDLE_REPORT_PERIOD, STALE_WINDOW, STALL_GAP, Pacer, RealtimeController

pytestmark = pytest.mark.core

HZ = 240.0
INTO_TABLE = [0.0, 1.2, 0.0, -1.0, 0.0, 1.571, 0.785]  # hand pushed down into the table top


class Clock:
    """A wall clock the test moves."""

    def __init__(self, t=1000.0):
        self.t = t

    def __call__(self):
        return self.t


def pt(q, t):
    return NS(positions=list(q), velocities=[], accelerations=[], time_from_start=float(t))


@pytest.fixture
def rt(panda_urdf, table_world):
    s = make_sim(panda_urdf, table_world, physics_hz=HZ)
    s.reset_robot(HOME)
    clock = Clock()
    yield RealtimeController(s, follow.Tolerances.defaults(7), clock), clock
    s.close()


def run(rt, clock, substeps, per_beat=4):
    """The loop's beats for this many substeps (per_beat at a time, wall time advancing with them): what ended and
    what was reported."""
    ended, reports = [], []
    for _ in range(substeps // per_beat):
        clock.t += per_beat / HZ
        assert not rt.beat(clock.t)
        e, r = rt.step(per_beat, clock.t)
        ended += e
        reports += r
    return ended, reports


# ---------------------------------------------------------------------------------------------- pacing
def test_substeps_are_due_at_wall_clock_pace():
    pacer = Pacer(HZ, start=50.0)
    assert pacer.max_batch == int(HZ * CATCH_UP) == 12
    assert pacer.due(50.0) == 0 and pacer.next_wake() == 50.0 + 1 / HZ
    assert pacer.due(50.0 + 5.5 / HZ) == 5  # substeps 1..5; the 6th at 50 + 6/HZ
    assert pacer.next_wake() == 50.0 + 6 / HZ
    assert pacer.due(50.0 + 5.9 / HZ) == 0
    assert pacer.due(50.0 + 7.0 / HZ + 1e-9) == 2 and pacer.done == 7


def test_a_loop_that_falls_behind_lets_sim_time_slip():
    """One second late: at most CATCH_UP (12 substeps at 240 Hz) run at once, the rest is dropped (sim time slips),
    and from there the pace is the wall clock's again."""
    pacer = Pacer(HZ, start=0.0)
    assert pacer.due(1.0 + 0.1 / HZ) == 12 and pacer.done == 12
    assert pacer.start == pytest.approx(1.0 - 12 / HZ)  # substep 12 is now due at wall time 1.0
    assert pacer.next_wake() == pytest.approx(1.0 + 1 / HZ)
    assert pacer.due(1.0 + 3.1 / HZ) == 3


# ---------------------------------------------------------------------------------------------- goals
def test_a_goal_is_followed_to_its_end_and_succeeds(rt):
    rt, clock = rt
    target = (np.array(HOME) + 0.2).tolist()
    # A first point at time 0 with a zero stamp: replaced by the bridge from where the controller holds. Goal time:
    # the robot comes to rest (stopped_velocity_tolerance) one substep after the end.
    previous, accepted = rt.accept("A", JOINTS, [pt(HOME, 0.0), pt(target, 0.5)], start=0.0, goal_time=0.1)
    assert previous is None and rt.goal.handle == "A" and rt.busy
    assert accepted.times.tolist() == [0.0, 0.5] and accepted.positions[0].tolist() == HOME
    ended, reports = run(rt, clock, 240)
    assert ended == [("A", follow.SUCCESSFUL, "")]
    # Its contacts: the 121 substeps until it succeeded, stamped then.
    assert len(reports) == 1 and reports[0][0].substeps == 121 and reports[0][0].substeps_in_contact == 0
    assert reports[0][1] == 121 / HZ
    assert rt.goal is None and not rt.busy
    assert rt.sim.joint_positions() == pytest.approx(target, abs=1e-9) and rt.setpoint == pytest.approx(target)
    # Then the robot holds there.
    run(rt, clock, 24)
    assert rt.sim.joint_positions() == pytest.approx(target, abs=1e-9)


def test_a_new_goal_preempts_the_active_one_from_where_its_setpoint_is(rt):
    rt, clock = rt
    far = (np.array(HOME) + 0.5).tolist()
    rt.accept("A", JOINTS, [pt(HOME, 0.0), pt(far, 1.0)], start=0.0)
    run(rt, clock, 60)  # a quarter of the way
    now = rt.sim.sim_time
    where = rt.goal.trajectory.desired(now)[0]
    assert 0.1 < float(np.max(where - np.array(HOME))) < 0.2
    back = (np.array(HOME) - 0.1).tolist()
    previous, accepted = rt.accept("B", JOINTS, [pt(HOME, 0.0), pt(back, 1.0)], start=0.0, goal_time=0.1)
    assert previous == "A" and rt.goal.handle == "B"
    assert rt.setpoint == where.tolist() and accepted.positions[0].tolist() == rt.setpoint
    ended, _ = run(rt, clock, 300)
    assert ended == [("B", follow.SUCCESSFUL, "")]  # A ended by preemption: the caller cancels its handle
    assert rt.sim.joint_positions() == pytest.approx(back, abs=1e-9)


def test_a_rejected_goal_leaves_the_active_one_running(rt):
    rt, clock = rt
    far = (np.array(HOME) + 0.3).tolist()
    rt.accept("A", JOINTS, [pt(HOME, 0.0), pt(far, 1.0)], start=0.0, goal_time=0.1)
    run(rt, clock, 24)
    with pytest.raises(follow.GoalRejected) as err:
        rt.accept("B", JOINTS[:6], [pt(far[:6], 1.0)], start=0.0)
    assert err.value.code == follow.INVALID_JOINTS and rt.goal.handle == "A"
    ended, _ = run(rt, clock, 240)
    assert ended == [("A", follow.SUCCESSFUL, "")]


def test_cancel_ends_the_active_goal_and_the_robot_holds_where_it_is(rt):
    rt, clock = rt
    rt.accept("A", JOINTS, [pt(HOME, 0.0), pt((np.array(HOME) + 0.3).tolist(), 1.0)], start=0.0)
    run(rt, clock, 48)
    assert not rt.cancel("B") and rt.goal.handle == "A"  # not the active goal: nothing happens
    assert rt.cancel("A") and rt.goal is None
    here = list(rt.sim.joint_positions())
    assert rt.setpoint == here and here != pytest.approx(HOME, abs=1e-3)
    ended, _ = run(rt, clock, 24)
    assert ended == [] and rt.sim.joint_positions() == pytest.approx(here, abs=1e-12)


def test_an_empty_goal_stops_the_robot_at_once(rt):
    rt, clock = rt
    rt.accept("A", JOINTS, [pt(HOME, 0.0), pt((np.array(HOME) + 0.3).tolist(), 1.0)], start=0.0)
    run(rt, clock, 48)
    previous, accepted = rt.accept("B", JOINTS, [], start=0.0)
    assert previous == "A" and len(accepted.times) == 0 and rt.goal is None
    assert rt.setpoint == list(rt.sim.joint_positions())


# ---------------------------------------------------------------------------------------------- stalls
def test_a_stall_aborts_the_active_goal_and_makes_goals_queued_meanwhile_stale(rt):
    rt, clock = rt
    assert not rt.goal_is_stale()
    rt.accept("A", JOINTS, [pt(HOME, 0.0), pt((np.array(HOME) + 0.3).tolist(), 1.0)], start=0.0)
    run(rt, clock, 48)
    beat = clock.t
    clock.t = beat + STALL_GAP - 0.01  # a slow beat is no stall
    assert not rt.goal_is_stale()
    clock.t = beat + STALL_GAP + 0.05  # the process stopped: a goal arriving now is stale
    assert rt.goal_is_stale()
    assert rt.beat(clock.t)  # the loop wakes up and notices
    assert rt.abort_goal() == "A" and rt.goal is None and rt.abort_goal() is None
    assert rt.setpoint == list(rt.sim.joint_positions())
    woke = clock.t
    clock.t = woke + STALE_WINDOW - 0.01  # goals that were queued while stopped still arrive: stale
    assert not rt.beat(clock.t) and rt.goal_is_stale()
    clock.t = woke + STALE_WINDOW + 0.01
    assert not rt.beat(clock.t) and not rt.goal_is_stale()
    rt.accept("B", JOINTS, [pt(HOME, 1.0)], start=0.0)  # a fresh goal is followed
    assert rt.goal.handle == "B"


# ---------------------------------------------------------------------------------------------- ExecuteTrajectory
def test_an_execute_motion_runs_in_the_loop_and_blocks_goals(rt):
    rt, clock = rt
    target = (np.array(HOME) + 0.1).tolist()
    motion = rt.sim.prepare([0.1], [target])
    rt.submit(motion)
    assert rt.busy and not rt.motion_done.is_set()
    with pytest.raises(follow.GoalRejected, match="ExecuteTrajectory motion"):
        rt.accept("A", JOINTS, [pt(HOME, 1.0)], start=0.0)
    run(rt, clock, 20)  # 24 substeps: not yet
    assert not rt.motion_done.is_set()
    run(rt, clock, 8)
    assert rt.motion_done.is_set() and rt.motion is None and not rt.busy
    assert rt.motion_result.contacts.substeps == 24
    assert rt.motion_result.positions == pytest.approx(target, abs=1e-12)


# ---------------------------------------------------------------------------------------------- idle
def test_contacts_while_idle_are_reported_at_most_every_period(rt):
    rt, clock = rt
    rt.sim.reset_robot(INTO_TABLE)  # resting in the table: contacts at every substep
    rt.reset_done()
    reports = []
    assert IDLE_REPORT_PERIOD == 0.1
    for _ in range(30):  # 30 beats of 5 substeps, 1/48 s of wall time each: a report every 5th beat (0.104 s)
        clock.t += 5 / HZ
        reports += rt.step(5, clock.t)[1]
    assert [stats.substeps for stats, _ in reports] == [5] + [25] * 5
    assert all(stats.substeps_in_contact == stats.substeps and stats.world_contacts > 0 for stats, _ in reports)
    assert all(stats.resting_contacts > 0 and not stats.moving_pairs for stats, _ in reports)
    assert [stamp for _, stamp in reports] == [(5 + 25 * i) / HZ for i in range(6)]
