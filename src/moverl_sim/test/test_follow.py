"""The simulator's joint_trajectory_controller rules (moverl_sim.follow) and the dynamic control that follows them.

No roscore: goals are plain objects with the fields of trajectory_msgs/JointTrajectoryPoint and control_msgs/
JointTolerance. The tracking figures of the dynamic simulator that the shield's path tolerances rely on are measured
here (a min_jerk move, the robot tracks it at 1 kHz within a tenth of the smallest Panda tolerance).
"""

from types import SimpleNamespace as NS

import numpy as np
import pytest
from conftest import HOME, JOINTS, REPO_DIR, make_sim

from moverl_sim import follow
from moverl_sim.core import ContactStats
from moverl_sim.robot_config import load_robot_config

pytestmark = pytest.mark.core

LO, HI = [-3.0] * 7, [3.0] * 7
INTO_TABLE = [0.0, 1.2, 0.0, -1.0, 0.0, 1.571, 0.785]  # hand pushed down into the table top
ACCELERATION_LIMITS = np.array(load_robot_config(f"{REPO_DIR}/config/robots/panda.yaml")["acceleration_limits"])
SHUFFLED = JOINTS[::-1]


def pt(q, t, v=(), a=()):
    return NS(positions=list(q), velocities=list(v), accelerations=list(a), time_from_start=float(t))


def tol(name, position=0.0, velocity=0.0):
    return NS(name=name, position=position, velocity=velocity, acceleration=0.0)


DEFAULTS = follow.Tolerances.defaults(7)
HOLD = np.array(HOME)


def accept(points, names=JOINTS, start=0.0, now=10.0, **kw):
    return follow.accept(JOINTS, LO, HI, names, points, start, now, HOLD, DEFAULTS, **kw)


def rejected(code, *args, **kw):
    with pytest.raises(follow.GoalRejected) as err:
        accept(*args, **kw)
    assert err.value.code == code, err.value
    return str(err.value)


def test_joint_names_must_match_the_controller_in_any_order():
    msg = rejected(follow.INVALID_JOINTS, [pt(HOME, 1.0)], names=JOINTS[:6])
    assert "panda_joint7" in msg
    rejected(follow.INVALID_JOINTS, [pt(HOME, 1.0)], names=JOINTS[:6] + ["gripper"])
    rejected(follow.INVALID_JOINTS, [pt(HOME, 1.0)], names=JOINTS[:6] + [JOINTS[0]])
    # Shuffled names are fine: positions are reordered into the controller's order.
    traj = accept([pt(list(reversed(HOME)), 1.0)], names=SHUFFLED)
    np.testing.assert_allclose(traj.positions[-1], HOME)


@pytest.mark.parametrize(
    "points, what",
    [
        ([pt(HOME[:6], 1.0)], "positions"),
        ([pt(HOME, 1.0, v=[0.0] * 3)], "velocities"),
        ([pt(HOME, 1.0), pt(HOME, 1.0)], "strictly increasing"),
        ([pt(HOME, 2.0), pt(HOME, 1.0)], "strictly increasing"),
        ([pt([np.nan] + HOME[1:], 1.0)], "not finite"),
        ([pt([3.5] + HOME[1:], 1.0)], "limits"),
    ],
)
def test_malformed_goals_are_invalid(points, what):
    assert what in rejected(follow.INVALID_GOAL, points)


def test_a_trajectory_entirely_in_the_past_is_invalid():
    assert "past" in rejected(follow.INVALID_GOAL, [pt(HOME, 1.0)], start=5.0, now=10.0)


def test_empty_trajectory_stops_where_the_controller_holds():
    traj = accept([])
    assert len(traj.times) == 0
    q, v = traj.desired(11.0)
    np.testing.assert_allclose(q, HOLD)
    assert follow.check(traj, 11.0, HOLD, np.zeros(7)) == (follow.SUCCESSFUL, "")


def test_future_start_holds_then_follows():
    target = HOLD + 0.1
    traj = accept([pt(HOLD, 0.0), pt(target, 1.0)], start=12.0, now=10.0)
    np.testing.assert_allclose(traj.desired(11.0)[0], HOLD)  # before the start: hold
    np.testing.assert_allclose(traj.desired(12.5)[0], HOLD + 0.05)  # linear in between
    np.testing.assert_allclose(traj.desired(14.0)[0], target)  # after the end: the last point
    assert traj.end == 13.0


def test_zero_stamp_first_point_at_zero_is_replaced_by_a_bridge_from_the_setpoint():
    elsewhere = HOLD + 0.2
    traj = accept([pt(elsewhere, 0.0), pt(HOLD + 0.1, 1.0)], start=0.0, now=10.0)
    assert traj.times[0] == 10.0
    np.testing.assert_allclose(traj.positions[0], HOLD)  # from where the controller holds
    np.testing.assert_allclose(traj.desired(10.5)[0], HOLD + 0.05)


def test_points_already_passed_are_dropped_and_bridged():
    traj = accept([pt(HOLD + 0.1, 1.0), pt(HOLD + 0.2, 2.0), pt(HOLD + 0.3, 3.0)], start=8.5, now=10.0)
    # 9.5 has passed, 10.5 and 11.5 are ahead: a bridge from the setpoint now to the point at 10.5.
    np.testing.assert_allclose(traj.times, [10.0, 10.5, 11.5])
    np.testing.assert_allclose(traj.positions[0], HOLD)
    np.testing.assert_allclose(traj.positions[1], HOLD + 0.2)


def test_goal_tolerances_override_the_defaults():
    defaults = follow.Tolerances.defaults(7, path=0.1, goal=0.2, goal_time=0.5)
    t = defaults.merged(JOINTS, [tol(JOINTS[0], 0.01), tol(JOINTS[1], -1)], [tol(JOINTS[2], 0.03, 0.5)], 0.0)
    assert t.path[0] == 0.01 and t.path[1] == 0.0 and t.path[2] == 0.1  # set, removed, kept
    assert t.goal[2] == 0.03 and t.goal_velocity[2] == 0.5 and t.goal[0] == 0.2
    assert t.goal_time == 0.5
    assert defaults.merged(JOINTS, [], [], 1.5).goal_time == 1.5
    with pytest.raises(follow.GoalRejected):
        defaults.merged(JOINTS, [tol("nope", 0.1)], [], 0.0)


def test_path_tolerance_aborts_while_running():
    traj = accept(
        [pt(HOLD, 0.0), pt(HOLD + 0.1, 1.0)], start=10.0, now=10.0, path_tolerance=[tol(j, 0.01) for j in JOINTS]
    )
    desired, _ = traj.desired(10.5)
    assert follow.check(traj, 10.5, desired + 0.005, np.zeros(7)) is None
    lagging = desired.copy()
    lagging[3] -= 0.02
    code, msg = follow.check(traj, 10.5, lagging, np.zeros(7))
    assert code == follow.PATH_TOLERANCE_VIOLATED and "joint 3" in msg


def test_goal_tolerance_waits_goal_time_then_aborts():
    traj = accept(
        [pt(HOLD, 0.0), pt(HOLD + 0.1, 1.0)],
        start=10.0,
        now=10.0,
        goal_tolerance=[tol(j, 0.01, 0.05) for j in JOINTS],
        goal_time=0.5,
    )
    end = HOLD + 0.1
    assert follow.check(traj, 11.0, end, np.zeros(7)) == (follow.SUCCESSFUL, "")
    short = end - 0.05
    assert follow.check(traj, 11.2, short, np.zeros(7)) is None  # within goal_time: wait
    assert follow.check(traj, 11.6, short, np.zeros(7))[0] == follow.GOAL_TOLERANCE_VIOLATED
    moving = np.full(7, 0.1)
    assert follow.check(traj, 11.2, end, moving) is None  # not yet at rest
    assert follow.check(traj, 11.6, end, moving)[0] == follow.GOAL_TOLERANCE_VIOLATED


def minjerk_points(q0, q1, T, n):
    """The shield's min_jerk samples of one straight move (positions, velocities, accelerations)."""
    d = np.asarray(q1) - np.asarray(q0)
    out = []
    for k in range(n + 1):
        u = k / n
        s, ds, dds = u**3 * (10 - 15 * u + 6 * u**2), u**2 * (30 - 60 * u + 30 * u**2), u * (60 - 180 * u + 120 * u**2)
        out.append(pt(np.asarray(q0) + s * d, u * T, ds / T * d, dds / T**2 * d))
    return out


def test_splines_match_the_controllers_interpolation():
    q0, q1, T = HOLD, HOLD + 0.2, 0.4
    # Quintic through the shield's min_jerk samples reproduces the min-jerk law between samples.
    traj = accept(minjerk_points(q0, q1, T, 4), start=10.0, now=10.0)
    for u in np.linspace(0, 1, 17):
        s = u**3 * (10 - 15 * u + 6 * u**2)
        np.testing.assert_allclose(traj.desired(10.0 + u * T)[0], q0 + s * 0.2, atol=1e-12)
    # Cubic Hermite with velocities only: at rest at both ends, through the midpoint.
    cubic = accept([pt(q0, 0.0, np.zeros(7)), pt(q1, T, np.zeros(7))], start=10.0, now=10.0)
    np.testing.assert_allclose(cubic.desired(10.0 + T / 2)[0], q0 + 0.1, atol=1e-12)
    np.testing.assert_allclose(cubic.desired(10.0 + T / 2)[1], np.full(7, 1.5 * 0.2 / T), atol=1e-12)


@pytest.mark.parametrize("hz, bound", [(1000, 2e-4), (240, 2e-3)])
def test_dynamic_control_tracks_a_min_jerk_move(panda_urdf, table_world, hz, bound):
    """The robot's error against the controller's setpoint at every substep of a min_jerk move at its limits.
    At 1 kHz (the launch default for dynamic control) it stays far below the Panda's smallest path tolerance of the
    shield (0.62 mrad: 0.05 mrad measured); at 240 Hz it reaches about that tolerance (0.64 mrad measured)."""
    s = make_sim(panda_urdf, table_world, control="dynamic", physics_hz=hz)
    try:
        s.reset_robot(HOME)
        stats = ContactStats()
        worst = 0.0
        for sign in (1, -1, 1):
            q0 = np.array(s.joint_positions())
            d = sign * np.array(s.velocity_limits) * 0.05  # the largest env action
            q1 = q0 + d
            # The shield's min_jerk timing: peak velocity and acceleration within the Panda's limits.
            T = max(1.875 * 0.05, float(np.max(np.sqrt(5.7735 * np.abs(d) / ACCELERATION_LIMITS))))
            traj = follow.accept(
                JOINTS,
                s.lower,
                s.upper,
                JOINTS,
                minjerk_points(q0, q1, T, 10),
                s.sim_time,
                s.sim_time,
                q0,
                follow.Tolerances.defaults(7),
            )
            while s.sim_time < traj.end + 0.02:
                t = s.sim_time
                q, v = traj.desired(t)
                s.servo(q, v, stats, traj.desired(t + 1.0 / hz)[0])
                worst = max(worst, float(np.max(np.abs(np.array(s.joint_positions()) - traj.desired(s.sim_time)[0]))))
        print("\n%d Hz: worst tracking error %.3f mrad" % (hz, worst * 1e3))
        assert worst < bound
        assert stats.substeps_in_contact == 0
    finally:
        s.close()


def test_lockstep_dynamic_motion_stops_at_its_path_tolerance(panda_urdf, table_world):
    """ExecuteTrajectory's path_tolerance: a move into the table, the arm blocked by it, stops where the robot is."""
    s = make_sim(panda_urdf, table_world, control="dynamic", physics_hz=1000)
    try:
        s.reset_robot(HOME)
        motion = s.prepare([2.0], [INTO_TABLE], path_tolerance=[0.01] * 7)
        s.advance(motion, motion.n)
        assert motion.aborted and "path tolerance" in motion.aborted
        assert motion.k < motion.n  # stopped early
        stopped = s.finish(motion).positions
        s.hold(200)
        np.testing.assert_allclose(s.joint_positions(), stopped, atol=2e-3)  # holds where it stopped
    finally:
        s.close()


def test_start_point_may_be_the_clamped_state_of_a_robot_beyond_its_limit(panda_urdf, table_world):
    s = make_sim(panda_urdf, table_world, control="dynamic")
    try:
        s.reset_robot(HOME)
        beyond = list(HOME)
        beyond[3] = s.upper[3] + 0.004  # an encoder a little past the stop
        s.client.resetJointState(s.robot, s.joint_indices[3], beyond[3])
        clamped = list(np.clip(beyond, s.lower, s.upper))
        back = list(clamped)
        back[3] -= 0.1
        motion = s.prepare([0.0, 0.5], [clamped, back])  # the shield sends the clamped state first
        assert motion.n == 120
        with pytest.raises(ValueError, match="current state"):  # anything else is still refused
            s.prepare([0.0, 0.5], [beyond[:3] + [clamped[3] - 0.01] + beyond[4:], back])
    finally:
        s.close()


def test_idle_contacts_are_counted_when_asked(panda_urdf, table_world):
    s = make_sim(panda_urdf, table_world)
    try:
        s.reset_robot(INTO_TABLE)
        stats = ContactStats()
        s.hold(10, stats)
        assert stats.substeps == 10 and stats.substeps_in_contact == 10 and stats.world_contacts > 0
        s.hold(10)  # without stats: nothing detected
        assert stats.substeps == 10
    finally:
        s.close()
