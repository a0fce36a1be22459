"""The lockstep driver's core (moverl_sim.lockstep): ~execute's request check, a motion run in pieces between camera
renders, ~reset_robot. No roscore; a real Simulator and real camera renders.

Requests are plain objects with the fields of trajectory_msgs/JointTrajectoryPoint the node passes on.
"""

from types import SimpleNamespace as NS

import numpy as np
import pytest
from conftest import HOME, JOINTS, REPO_DIR, make_sim

from moverl_sim import lockstep
from moverl_sim.camera import Camera
from moverl_sim.camera_schedule import CameraSchedule
from moverl_sim.core import InvalidTrajectory, LimitViolation
from moverl_sim.world import load_world

pytestmark = pytest.mark.core

INTO_TABLE = [0.0, 1.2, 0.0, -1.0, 0.0, 1.571, 0.785]  # hand pushed down into the table top
HZ = 240.0


def pt(q, v=(), a=()):
    return NS(positions=list(q), velocities=list(v), accelerations=list(a))


@pytest.fixture(scope="module")
def human_world():
    return load_world(f"{REPO_DIR}/worlds/human.yaml")  # a walking person: obstacles placed at every substep


def contacts_of(result):
    c = result.contacts
    return (
        c.substeps,
        c.substeps_in_contact,
        dict(c.world_pairs),
        dict(c.self_pairs),
        set(c.moving_pairs),
        set(c.resting_pairs),
        c.total_contact_substeps,
    )


# ---------------------------------------------------------------------------------------------- the request
def test_a_request_is_put_in_the_simulators_joint_order():
    names = JOINTS[::-1]
    q = [float(i) for i in range(7)]
    v = [0.1 * i for i in range(7)]
    times, positions, velocities, accelerations = lockstep.trajectory_arrays(
        JOINTS, [2.0] * 7, names, [pt(q), pt(q, v=v, a=q)], [0.1, 0.2]
    )
    assert times == [0.1, 0.2]
    assert positions == [q[::-1], q[::-1]]
    assert velocities == [[], v[::-1]] and accelerations == [[], q[::-1]]


@pytest.mark.parametrize(
    "names, points, error, message",
    [
        (JOINTS[:6], [pt(HOME[:6])], InvalidTrajectory, "missing ['panda_joint7'], unknown [], duplicated []"),
        (JOINTS[:6] + ["x"], [pt(HOME)], InvalidTrajectory, "missing ['panda_joint7'], unknown ['x'], duplicated []"),
        (
            JOINTS[:6] + [JOINTS[0]],
            [pt(HOME)],
            InvalidTrajectory,
            "missing ['panda_joint7'], unknown [], duplicated ['panda_joint1']",
        ),
        (JOINTS, [], InvalidTrajectory, "empty trajectory"),
        (JOINTS, [pt(HOME), pt(HOME[:6])], InvalidTrajectory, "point 1 has 6 positions, expected 7"),
        (JOINTS, [pt(HOME, v=[0.0] * 6)], InvalidTrajectory, "point 0: velocities must be empty or 7 finite values"),
        (
            JOINTS,
            [pt(HOME, a=[0.0] * 6 + [float("nan")])],
            InvalidTrajectory,
            "point 0: accelerations must be empty or 7 finite values",
        ),
        (JOINTS, [pt(HOME), pt(HOME, v=[0.0] * 6 + [2.0 * 1.000002])], LimitViolation, "point 1: a velocity is above"),
    ],
)
def test_bad_requests_are_refused_with_what_is_wrong(names, points, error, message):
    with pytest.raises(error) as err:
        lockstep.trajectory_arrays(JOINTS, [2.0] * 7, names, points, [0.1 * (i + 1) for i in range(len(points))])
    assert message in str(err.value)


def test_a_velocity_at_the_limit_is_accepted():
    _, _, velocities, _ = lockstep.trajectory_arrays(JOINTS, [2.0] * 7, JOINTS, [pt(HOME, v=[-2.0] * 7)], [0.1])
    assert velocities == [[-2.0] * 7]


# ---------------------------------------------------------------------------------------------- the motion
def run_rendering(sim, motion, cameras, fail_at=None):
    """run_motion with real renders of these cameras (as the sim node: rendered() after each, stop() on a failure);
    returns (result, [(substep, cameras, during, cloud shapes)])."""
    schedule = CameraSchedule([cam.period for cam in cameras])
    calls = []

    def on_due(due, during):
        if fail_at is not None and len(calls) == fail_at:
            schedule.stop()  # the node's answer to a failed render
            calls.append((sim.substeps_total, due, during, None))
            return []
        shapes = []
        for i in due:
            shapes.append(sim.render_points(cameras[i]).shape)
            schedule.rendered(i, sim.sim_time)
        calls.append((sim.substeps_total, due, during, shapes))
        return [sim.substeps_total]

    result, out = lockstep.run_motion(sim, motion, schedule, on_due)
    assert out == [k for k, _, _, shapes in calls if shapes is not None]
    return result, calls


def test_pieces_between_renders_change_nothing(panda_urdf, human_world):
    """A move into the table while the person walks, with two cameras rendering in the middle of it: the same
    substeps, contacts (pairs, depths, who moved) and final state as the move in one call, to the bit."""
    cameras = [Camera(spec) for spec in human_world.cameras[:2]]
    assert [cam.period for cam in cameras] == [0.5, 0.5]
    sims = [make_sim(panda_urdf, human_world, physics_hz=HZ) for _ in range(2)]
    try:
        for s in sims:
            s.reset_robot(HOME)
            s.restart_motions()
            s.hold(30)  # the motions at 30 substeps: the pieces do not start at a motion-time origin
        plain = sims[0].prepare([2.0], [INTO_TABLE])
        one_call, none = lockstep.run_motion(sims[0], plain, None, None)
        assert none == []
        pieced = sims[1].prepare([2.0], [INTO_TABLE])
        result, calls = run_rendering(sims[1], pieced, cameras)
        # Both render at the start (never rendered), then every 0.5 s: 120 substeps apart, during the move; the end
        # (substep 510, 0.125 s after the last render) is not due.
        assert [(k, due, during) for k, due, during, _ in calls] == [
            (30, [0, 1], False),
            (150, [0, 1], True),
            (270, [0, 1], True),
            (390, [0, 1], True),
        ]
        assert all(shape == (160 * 120, 3) for *_, shapes in calls for shape in shapes)
        assert contacts_of(one_call)[1] > 0 and contacts_of(one_call)[2]  # touched the table
        assert contacts_of(result) == contacts_of(one_call)
        assert result.positions == one_call.positions
        assert sims[1].joint_positions() == sims[0].joint_positions()
        assert sims[1].substeps_total == sims[0].substeps_total == 30 + 480
    finally:
        for s in sims:
            s.close()


def test_a_failed_render_runs_the_rest_in_one_piece(panda_urdf, table_world):
    cameras = [Camera(spec) for spec in table_world.cameras[:1]]
    s = make_sim(panda_urdf, table_world, physics_hz=HZ)
    try:
        s.reset_robot(HOME)
        target = (np.array(HOME) + 0.3).tolist()
        result, calls = run_rendering(s, s.prepare([1.5], [target]), cameras, fail_at=2)
        # Renders at 0 and 120 (0.5 s), fails at 240: nothing more, the motion runs to its end (360 substeps).
        assert [(k, shapes is not None) for k, _, _, shapes in calls] == [(0, True), (120, True), (240, False)]
        assert result.contacts.substeps == 360 and s.substeps_total == 360
        assert result.positions == pytest.approx(target, abs=1e-12)
    finally:
        s.close()


def test_a_motion_stopped_at_its_path_tolerance_ends_the_pieces(panda_urdf, table_world):
    """Dynamic control: a move into the table stops where the arm is blocked; the pieces stop there too, and the
    renders were made until then."""
    cameras = [Camera(spec) for spec in table_world.cameras[:1]]
    sims = [make_sim(panda_urdf, table_world, control="dynamic", physics_hz=1000) for _ in range(2)]
    try:
        for s in sims:
            s.reset_robot(HOME)
        plain = sims[0].prepare([2.0], [INTO_TABLE], path_tolerance=[0.01] * 7)
        one_call, _ = lockstep.run_motion(sims[0], plain, None, None)
        assert plain.aborted and plain.k < plain.n
        pieced = sims[1].prepare([2.0], [INTO_TABLE], path_tolerance=[0.01] * 7)
        result, calls = run_rendering(sims[1], pieced, cameras)
        assert pieced.aborted == plain.aborted and pieced.k == plain.k
        assert [k for k, *_ in calls] == list(range(0, plain.k, 500))  # 2 Hz at 1 kHz, until the stop
        assert contacts_of(result) == contacts_of(one_call) and result.positions == one_call.positions
    finally:
        for s in sims:
            s.close()


# ---------------------------------------------------------------------------------------------- the reset
def test_reset_teleports_and_restarts_the_motions(panda_urdf, human_world):
    s = make_sim(panda_urdf, human_world, physics_hz=HZ)
    try:
        s.hold(100)
        target = (np.array(HOME) + 0.1).tolist()
        lockstep.reset_robot(s, target)
        assert s.joint_positions() == pytest.approx(target, abs=1e-12)
        assert s.motion_epoch == s.sim_time == 100 / HZ and s.motion_time == 0.0
        start = s.obstacle_positions()
        s.hold(50)
        assert s.obstacle_positions() != start  # the person walked
        lockstep.reset_robot(s, HOME)  # motion time 0 again: the person where it stood at the first reset
        assert s.motion_epoch == 150 / HZ and s.obstacle_positions() == start
    finally:
        s.close()


def test_a_settled_reset_is_stamped_after_the_old_state(panda_urdf, human_world):
    """settle_substeps (the node's lockstep reset while cameras render): the robot teleported, then that many
    substeps pass with it held, so that its new state cannot share a stamp with its old one (a planning scene would
    filter the reset's clouds with the old configuration only); a refused reset lets no time pass."""
    s = make_sim(panda_urdf, human_world, physics_hz=HZ)
    try:
        s.hold(100)
        target = (np.array(HOME) + 0.1).tolist()
        lockstep.reset_robot(s, target, restart=False, settle_substeps=1)
        assert s.joint_positions() == pytest.approx(target, abs=1e-12)
        assert s.sim_time == 101 / HZ and s.motion_epoch == 0.0  # one substep later, the walk going on
        lockstep.reset_robot(s, HOME, restart=False)
        assert s.sim_time == 101 / HZ  # none without it
    finally:
        s.close()


def test_a_reset_into_an_obstacle_is_unreachable_and_puts_the_robot_back(panda_urdf, table_world):
    s = make_sim(panda_urdf, table_world, physics_hz=HZ)
    try:
        s.reset_robot(HOME)
        s.hold(10)
        with pytest.raises(lockstep.Unreachable) as err:
            lockstep.reset_robot(s, INTO_TABLE)
        assert str(err.value).startswith("the target touches the world where the obstacles' motions restart (")
        assert "/ table" in str(err.value)
        assert s.joint_positions() == pytest.approx(HOME, abs=1e-12)
        assert s.motion_epoch == s.sim_time  # the motions stay restarted
        assert not s.contacts_now().in_contact
    finally:
        s.close()


def test_a_reset_a_moving_obstacle_will_walk_into_is_unreachable(panda_urdf, tmp_path):
    """A teleport that a moving obstacle will touch within reset_clearance_time of its motion is refused like one into
    an obstacle: a real robot never appears in a person's way. One it walks away from is fine, and so is a static
    object's neighbourhood."""
    from moverl_sim.world import load_world

    world = tmp_path / "visitor.yaml"
    world.write_text(
        "name: visitor\nobjects:\n"
        "  - {id: table, shape: box, size: [1.5, 0.8, 0.03], xyz: [0.35, 0.0, -0.015]}\n"
        "  - {id: visitor, shape: box, size: [0.1, 0.3, 0.3], xyz: [0.6, 0.0, 0.45],\n"
        "     motion: {type: oscillate, axis: [-1, 0, 0], amplitude: 0.3, period: 6.0}}\n"  # towards the hand first
    )
    s = make_sim(panda_urdf, load_world(world), physics_hz=HZ)
    try:
        away = list(HOME)
        away[0] = 1.5  # the arm turned aside: the visitor's walk never reaches it
        s.reset_robot(away)
        s.restart_motions()
        assert s.touched_within(6.0) == []
        s.reset_robot(HOME)
        assert s.touched_within(0.2) == [] and s.touched_within(1.5)  # it reaches the hand within 1.5 s, not 0.2
        assert s.obstacle_positions()["visitor"] == pytest.approx((0.6, 0.0, 0.45))  # left where it was
        s.reset_robot(away)
        s.hold(50)
        with pytest.raises(lockstep.Unreachable) as err:
            lockstep.reset_robot(s, HOME, clearance_time=1.5)
        assert "reset_clearance_time" in str(err.value) and "/ visitor" in str(err.value)
        assert s.joint_positions() == pytest.approx(away, abs=1e-12)  # put back
        assert s.motion_epoch == s.sim_time  # the motions stay restarted
        lockstep.reset_robot(s, HOME, clearance_time=0.2)
        assert s.joint_positions() == pytest.approx(HOME, abs=1e-12)
        lockstep.reset_robot(s, HOME, clearance_time=0.0)  # 0: only touching targets are refused
        # The sensed modes: the motions go on across a reset. At the far end of its walk, turning back, the visitor
        # does not reach the hand within 1.5 s: the same reset is accepted there.
        s.reset_robot(away)
        s.hold(int(4.5 * HZ))
        epoch = s.motion_epoch
        lockstep.reset_robot(s, HOME, clearance_time=1.5, restart=False)
        assert s.motion_epoch == epoch and s.joint_positions() == pytest.approx(HOME, abs=1e-12)
    finally:
        s.close()


def test_an_invalid_reset_target_changes_nothing(panda_urdf, table_world):
    s = make_sim(panda_urdf, table_world, physics_hz=HZ)
    try:
        s.reset_robot(HOME)
        s.hold(10)
        beyond = list(HOME)
        beyond[3] = 1.0  # panda_joint4's upper limit is 0
        with pytest.raises(ValueError, match="panda_joint4") as err:
            lockstep.reset_robot(s, beyond)
        assert not isinstance(err.value, lockstep.Unreachable)
        assert s.joint_positions() == pytest.approx(HOME, abs=1e-12) and s.motion_epoch == 0.0
    finally:
        s.close()


def test_a_robot_that_cannot_be_put_back_is_an_error_not_a_refusal(panda_urdf, table_world):
    """A dynamic robot pushed beyond a joint limit (an encoder past the stop) is not a valid configuration to put back
    after an unreachable target: an error (the service fails), never answered as a refusal the caller acts on."""
    s = make_sim(panda_urdf, table_world, control="dynamic", physics_hz=HZ)
    try:
        s.reset_robot(HOME)
        s.client.resetJointState(s.robot, s.joint_indices[3], s.upper[3] + 0.004)
        with pytest.raises(RuntimeError, match="cannot put the robot back where it was: reset: joint panda_joint4"):
            lockstep.reset_robot(s, INTO_TABLE)
    finally:
        s.close()
