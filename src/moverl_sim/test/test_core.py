import math
import time

import numpy as np
import pytest
from conftest import FIXED, HOME, JOINTS, make_sim

from moverl_sim.core import InvalidTrajectory, LimitViolation, Simulator
from moverl_sim.world import parse_world

pytestmark = pytest.mark.core

HOME_NP = np.array(HOME)
INTO_TABLE = [0.0, 1.2, 0.0, -1.0, 0.0, 1.571, 0.785]  # hand pushed down into the table top
FOLDED = [0.0, -0.785, 0.0, -3.136, 0.0, 0.0, 0.785]  # elbow fully folded: wrist hits the upper arm


def test_limits_come_from_the_urdf(sim):
    assert sim.joint_names == tuple(JOINTS)
    assert sim.lower[3] == pytest.approx(-3.1416) and sim.upper[3] == pytest.approx(0.0)
    assert sim.velocity_limits[0] == pytest.approx(2.175) and sim.velocity_limits[6] == pytest.approx(2.61)
    assert sim.fixed_joint_names == ["panda_finger_joint1", "panda_finger_joint2"]
    assert sim.fixed_joint_positions == (0.04, 0.04)


def test_adjacent_pairs_look_through_fixed_and_empty_links(sim):
    idx = {name: i for i, name in sim.link_names.items()}
    adjacent = sim.adjacent_pairs
    assert (idx["panda_link7"], idx["panda_hand"]) in adjacent  # via panda_link8 (fixed, no geometry)
    assert (idx["panda_link1"], idx["panda_link2"]) in adjacent
    assert (idx["panda_leftfinger"], idx["panda_hand"]) in adjacent
    assert (idx["panda_link2"], idx["panda_link7"]) not in adjacent
    assert (idx["panda_leftfinger"], idx["panda_rightfinger"]) not in adjacent


def test_home_has_no_contacts(home_sim):
    c = home_sim.contacts_now()
    assert c.world_pairs == {} and c.self_pairs == {} and not c.in_contact
    assert home_sim.joint_positions() == pytest.approx(HOME)


def test_free_move_has_no_contacts(home_sim):
    t0 = home_sim.sim_time
    target = HOME_NP + 0.1
    res = home_sim.execute([0.1], [target])
    c = res.contacts
    assert c.substeps == 24 and c.substeps_in_contact == 0
    assert c.world_contacts == 0 and c.self_contacts == 0
    assert res.positions == pytest.approx(target.tolist(), abs=1e-12)
    assert home_sim.joint_positions() == pytest.approx(target.tolist(), abs=1e-12)
    assert home_sim.sim_time - t0 == pytest.approx(0.1)


def test_move_into_table_reports_world_contacts(home_sim):
    c = home_sim.execute([2.0], [INTO_TABLE]).contacts
    assert c.substeps == 480
    assert c.substeps_in_contact > 0 and c.world_contacts > 0
    assert all(obj == "table" for _, obj in c.world_pairs)
    links = {link for link, _ in c.world_pairs}
    assert links and "panda_link0" not in links
    assert links <= {"panda_leftfinger", "panda_rightfinger", "panda_hand", "panda_link7", "panda_link6"}
    assert all(d > 0 for d in c.world_pairs.values())
    assert c.total_contact_substeps >= c.substeps_in_contact


def test_folded_configuration_reports_self_contacts(home_sim):
    c = home_sim.execute([1.0], [FOLDED]).contacts
    assert c.self_contacts > 0 and c.world_contacts == 0
    for a, b in c.self_pairs:
        assert a < b
    assert ("panda_link2", "panda_link7") in c.self_pairs
    assert all(d > 0 for d in c.self_pairs.values())


def test_multi_point_trajectory_interpolates_linearly(home_sim):
    mid = HOME_NP + np.array([0.05, -0.05, 0.05, 0.05, 0.05, 0.05, 0.05])
    end = HOME_NP + 0.1
    motion = home_sim.prepare([0.0, 0.1, 0.2], [HOME, mid, end])
    assert motion.n == 48
    q12 = np.array([v[0] for v in motion.targets[11]])  # substep 12: t = 0.05 s, halfway to mid
    assert q12 == pytest.approx(((HOME_NP + mid) / 2).tolist(), abs=1e-12)
    q36 = np.array([v[0] for v in motion.targets[35]])  # t = 0.15 s, halfway mid -> end
    assert q36 == pytest.approx(((mid + end) / 2).tolist(), abs=1e-12)
    assert home_sim.joint_positions() == pytest.approx(HOME)  # prepare moves nothing
    res = home_sim.execute([0.1, 0.2], [mid, end])  # no t=0 point: starts from the current state
    assert res.positions == pytest.approx(end.tolist())


BAD = {
    "empty": (InvalidTrajectory, [], np.zeros((0, 7))),
    "nan": (InvalidTrajectory, [0.1], [[math.nan] + HOME[1:]]),
    "inf_time": (InvalidTrajectory, [math.inf], [HOME]),
    "wrong_width": (InvalidTrajectory, [0.1], [HOME[:6]]),
    "non_increasing": (InvalidTrajectory, [0.1, 0.1], [HOME, HOME]),
    "decreasing": (InvalidTrajectory, [0.2, 0.1], [HOME, HOME]),
    "negative_time": (InvalidTrajectory, [-0.1, 0.1], [HOME, HOME]),
    "start_mismatch": (InvalidTrajectory, [0.0, 0.5], [(HOME_NP + 0.01).tolist(), HOME]),
    "position_limit": (LimitViolation, [5.0], [HOME[:3] + [0.1] + HOME[4:]]),  # joint4 upper limit 0
    "velocity_limit": (LimitViolation, [0.05], [(HOME_NP + 0.2).tolist()]),  # 4 rad/s > 2.175
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_trajectories_are_rejected_without_moving(home_sim, case):
    exc, times, positions = BAD[case]
    t0, total = home_sim.sim_time, home_sim.total_contact_substeps
    with pytest.raises(exc) as err:
        home_sim.execute(times, positions)
    assert str(err.value)
    assert home_sim.joint_positions() == pytest.approx(HOME, abs=1e-12)
    assert home_sim.sim_time == t0 and home_sim.total_contact_substeps == total


def test_kinematic_prepare_fast_path_gives_the_checked_paths_doubles(home_sim):
    """prepare()'s plain-Python path (kinematic control) and its numpy path sample a trajectory to the same doubles,
    bit for bit: segments shorter and longer than a substep, ends off the substep grid, a first point at t = 0 or
    not, points beyond a limit by less than its tolerance (clamped), a path tolerance (checked, then unused)."""
    sim = home_sim
    rng = np.random.default_rng(7)
    lower, upper, vmax = np.array(sim.lower), np.array(sim.upper), np.array(sim.velocity_limits)
    for i in range(300):
        m = int(rng.integers(1, 6))
        times = np.cumsum(rng.choice([rng.uniform(0.001, 0.004), rng.uniform(0.004, 0.2)], size=m))
        if i % 3 == 0:
            times = np.concatenate(([0.0], times))
        beyond = i % 5 == 0  # joint 4 at its upper limit, its points beyond it by less than the tolerance
        sim.reset_robot(HOME[:3] + [sim.upper[3] if beyond else HOME[3]] + HOME[4:])
        q, rows = np.array(sim.joint_positions()), []
        for k, t in enumerate(times):
            dt = t - (times[k - 1] if k else 0.0)
            q = np.clip(q + rng.uniform(-0.9, 0.9, 7) * vmax * dt, lower, upper) if t > 0 else q
            rows.append(q.tolist())
            if beyond:
                rows[-1][3] = sim.upper[3] + 5e-7
        tolerance = [] if i % 2 else [0.1] * 7
        fast = sim._prepare_linear(times.tolist(), rows, tolerance)
        checked = sim._prepare_checked(times.tolist(), rows, tolerance)
        assert fast is not None, (times, rows)
        assert (fast.n, fast.targets, fast.velocities, fast.final) == (
            checked.n,
            checked.targets,
            checked.velocities,
            checked.final,
        )
    for case in sorted(BAD):  # what is wrong is left to the numpy path, which names it
        _, times, positions = BAD[case]
        assert sim._prepare_linear(times, positions) is None, case
    assert sim._prepare_linear([0.1], [HOME], [0.1] * 6) is None  # a path tolerance of the wrong size


def test_error_messages_name_the_joint(home_sim):
    with pytest.raises(LimitViolation, match="panda_joint4"):
        home_sim.execute([5.0], [HOME[:3] + [0.1] + HOME[4:]])
    with pytest.raises(LimitViolation, match="panda_joint1.*velocity limit 2.175"):
        home_sim.execute([0.05], [[0.5] + HOME[1:]])


def test_velocity_at_the_limit_is_accepted(home_sim):
    q = list(HOME)
    q[0] += 2.175 * 0.1  # exactly at the URDF velocity limit
    res = home_sim.execute([0.1], [q])
    assert res.positions[0] == pytest.approx(q[0])


def test_reset_robot_validates(home_sim):
    for bad in ([0.0] * 6, [math.nan] * 7, HOME[:3] + [0.5] + HOME[4:], "abc"):
        with pytest.raises(ValueError):
            home_sim.reset_robot(bad)
        assert home_sim.joint_positions() == pytest.approx(HOME)
    t0 = home_sim.sim_time
    home_sim.reset_robot(FOLDED)  # teleport: no substeps, no contacts counted
    assert home_sim.sim_time == t0
    assert home_sim.joint_positions() == pytest.approx(FOLDED)


def test_determinism(panda_urdf, table_world):
    results = []
    for _ in range(2):
        s = make_sim(panda_urdf, table_world)
        s.reset_robot(HOME)
        a = s.execute([1.0, 2.0], [(HOME_NP + 0.2).tolist(), INTO_TABLE]).contacts
        s.reset_robot(HOME)
        b = s.execute([1.0, 2.0], [(HOME_NP + 0.2).tolist(), INTO_TABLE]).contacts
        results.append((a, b))
        s.close()
    (a1, b1), (a2, b2) = results
    assert a1.world_pairs and a1.world_pairs == b1.world_pairs == a2.world_pairs == b2.world_pairs
    assert a1.substeps_in_contact == b1.substeps_in_contact == a2.substeps_in_contact
    assert b1.total_contact_substeps == 2 * a1.substeps_in_contact


def test_two_simulators_are_independent(panda_urdf, table_world):
    s1 = make_sim(panda_urdf, table_world)
    s2 = make_sim(panda_urdf, parse_world({"name": "empty"}))
    try:
        s1.reset_robot(HOME)
        s2.reset_robot(HOME)
        assert s1.execute([2.0], [INTO_TABLE]).contacts.world_contacts > 0
        assert s2.execute([2.0], [INTO_TABLE]).contacts.world_contacts == 0  # no table in s2
        assert s1.joint_positions() == pytest.approx(s2.joint_positions())
    finally:
        s1.close()
        s2.close()


def test_world_shapes_collide(panda_urdf):
    w = parse_world(
        {
            "name": "shapes",
            "objects": [
                {"id": "ball", "shape": "sphere", "size": [0.05], "xyz": [0.307, 0.0, 0.59]},  # at the hand
                {"id": "post", "shape": "cylinder", "size": [0.3, 0.04], "xyz": [0.0, 0.0, 0.45]},  # around link2
                {"id": "far", "shape": "box", "size": [0.1, 0.1, 0.1], "xyz": [-1.0, -1.0, 0.5]},
            ],
        }
    )
    s = make_sim(panda_urdf, w)
    try:
        s.reset_robot(HOME)
        objs = {obj for _, obj in s.contacts_now().world_pairs}
        assert objs == {"ball", "post"}
    finally:
        s.close()


def test_bad_configuration_is_reported(panda_urdf, table_world):
    from moverl_sim.settings import sim_settings

    kw = sim_settings()
    with pytest.raises(ValueError, match="panda_jointX.*panda_joint1"):
        Simulator(panda_urdf, JOINTS[:6] + ["panda_jointX"], "panda_link0", FIXED, table_world, **kw)
    with pytest.raises(ValueError, match="base link 'nope'"):
        Simulator(panda_urdf, JOINTS, "nope", FIXED, table_world, **kw)
    with pytest.raises(ValueError, match="panda_joint8"):
        Simulator(panda_urdf, JOINTS[:6] + ["panda_joint8"], "panda_link0", FIXED, table_world, **kw)  # fixed joint
    with pytest.raises(ValueError, match="nope_joint"):
        Simulator(panda_urdf, JOINTS, "panda_link0", {"nope_joint": 0.0}, table_world, **kw)
    with pytest.raises(ValueError, match="control"):
        Simulator(panda_urdf, JOINTS, "panda_link0", FIXED, table_world, **{**kw, "control": "magic"})


def test_link_poses(home_sim):
    poses = home_sim.link_poses()
    assert set(poses) >= {"panda_link0", "panda_link8", "panda_hand", "panda_leftfinger"}
    pos, quat = poses["panda_link0"]
    assert pos == pytest.approx((0, 0, 0), abs=1e-9) and quat == pytest.approx((0, 0, 0, 1), abs=1e-9)
    assert poses["panda_link8"][0] == pytest.approx(poses["panda_hand"][0], abs=1e-6)
    assert poses["panda_link8"][0][2] > 0.4  # flange above the table at home
    assert np.linalg.norm(quat) == pytest.approx(1.0)


def test_dynamic_control_tracks_and_collides(panda_urdf, table_world):
    s = make_sim(panda_urdf, table_world, control="dynamic")
    try:
        s.reset_robot(HOME)
        target = (HOME_NP + 0.1).tolist()
        res = s.execute([0.5], [target])
        assert res.contacts.substeps_in_contact == 0
        assert res.positions == pytest.approx(target, abs=0.01)
        s.hold(60)
        assert s.joint_positions() == pytest.approx(target, abs=0.002)
        s.reset_robot(HOME)
        assert s.execute([2.0], [INTO_TABLE]).contacts.world_contacts > 0
    finally:
        s.close()


def test_execute_speed(home_sim):
    """One RL step: 0.05 s = 12 substeps. Python + PyBullet time, kinematic control."""
    a, b = (HOME_NP + 0.05).tolist(), list(HOME)
    for i in range(20):
        home_sim.execute([0.05], [a if i % 2 == 0 else b])
    n = 300
    t0 = time.perf_counter()
    for i in range(n):
        home_sim.execute([0.05], [a if i % 2 == 0 else b])
    per = (time.perf_counter() - t0) / n
    print("\nexecute (12 substeps, kinematic): %.0f us" % (per * 1e6))
    assert per < 5e-3


def test_world_message_conversion(table_world):
    pytest.importorskip("moverl_msgs", reason="moverl_msgs not built/sourced (source devel/setup.bash)")
    from shape_msgs.msg import SolidPrimitive

    from moverl_sim.core import ContactStats
    from moverl_sim.ros_conversions import contacts_to_msg, world_to_msg

    w = parse_world(
        {
            "name": "w",
            "goal": [0.4, 0.2, 0.2],
            "objects": [
                {"id": "b", "shape": "box", "size": [1, 2, 3], "xyz": [1, 2, 3]},
                {
                    "id": "c",
                    "shape": "cylinder",
                    "size": [0.4, 0.05],
                    "xyz": [0, 0, 0],
                    "rpy": [0, 0, math.pi / 2],
                    "observed": False,
                },
            ],
        }
    )
    msg = world_to_msg(w, 1.5)
    assert msg.header.frame_id == "world" and msg.header.stamp.to_sec() == pytest.approx(1.5)
    assert [o.id for o in msg.objects] == ["b", "c"]
    assert msg.objects[0].shape.type == SolidPrimitive.BOX and list(msg.objects[0].shape.dimensions) == [1, 2, 3]
    assert msg.objects[1].shape.type == SolidPrimitive.CYLINDER
    assert list(msg.objects[1].shape.dimensions) == [0.4, 0.05]
    assert msg.objects[1].pose.orientation.z == pytest.approx(math.sqrt(0.5)) and not msg.objects[1].observed
    stats = ContactStats(
        substeps=12,
        substeps_in_contact=3,
        world_pairs={("panda_hand", "table"): 0.01},
        self_pairs={("panda_link2", "panda_link7"): 0.02},
        total_contact_substeps=7,
    )
    c = contacts_to_msg(stats, 2.0)
    assert c.available and c.substeps == 12 and c.substeps_in_contact == 3
    assert c.world_contacts == 1 and c.self_contacts == 1 and c.total_contact_substeps == 7
    assert [(p.a, p.b) for p in c.pairs] == [("panda_hand", "table"), ("panda_link2", "panda_link7")]
