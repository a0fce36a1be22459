"""Moving obstacles that share a motion are one PyBullet multibody (a base and links on fixed joints), placed by one
reset per substep: the geometry must be exactly that of one body per object, and contacts must name the objects."""

import os

import pybullet
import pytest
from conftest import FIXED, HOME, JOINTS, PANDA_URI, REPO_DIR, make_sim
from pybullet_utils import bullet_client

from moverl_sim.world import load_world, parse_world

pytestmark = pytest.mark.core

HUMAN_WORLD = os.path.join(REPO_DIR, "worlds", "human.yaml")
# The hand in the person's left arm at the centre of the walk (PyBullet IK for the hand at (0.70, 0.35, 0.40),
# pointing along +x). At motion time 1.5 s (the person 0.15 m to +y) it is in the torso, at 4.5 s (-y) in nothing.
INTO_LEFT_ARM = [0.49, 0.698, -0.061, -1.243, -2.196, 2.583, -0.037]

SWAY = {"type": "oscillate", "axis": [1, 1, 0], "amplitude": 0.1, "period": 2.0, "phase": 0.4}
BOB = {"type": "oscillate", "axis": [0, 0, 1], "amplitude": 0.05, "period": 3.0}


def _obj(oid, shape, size, xyz, rpy=(0, 0, 0), motion=None):
    return {"id": oid, "shape": shape, "size": size, "xyz": xyz, "rpy": list(rpy), "motion": motion}


# Rotated bases and links of every shape, two groups whose objects are interleaved, a single mover, a static object.
MIXED_WORLD = {
    "name": "groups",
    "objects": [
        _obj("post", "cylinder", [0.3, 0.04], [-0.5, 0.5, 0.15]),
        _obj("slab", "box", [0.2, 0.1, 0.05], [0.5, -0.4, 0.3], [0.3, -0.5, 1.1], SWAY),
        _obj("pair_a", "box", [0.1, 0.1, 0.1], [-0.4, -0.4, 0.6], motion=BOB),
        _obj("rod", "cylinder", [0.3, 0.03], [0.6, -0.3, 0.5], [1.0, 0.2, -0.7], SWAY),
        _obj("lone", "sphere", [0.05], [0.0, 0.6, 0.8], motion={**SWAY, "phase": 1.0}),
        _obj("knob", "sphere", [0.04], [0.45, -0.5, 0.2], motion=SWAY),
        _obj("pair_b", "cylinder", [0.2, 0.05], [-0.4, -0.2, 0.6], [0.0, 0.9, 0.0], BOB),
    ],
}


def _worlds():
    return {"human": load_world(HUMAN_WORLD), "mixed": parse_world(MIXED_WORLD)}


def _separate_bodies(world, t):
    """The objects as they were before grouping, one plain body each at its pose at motion time t:
    {object id: collision AABB}."""
    p = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
    try:
        aabbs = {}
        for obj in world.objects:
            if obj.shape == "box":
                col = p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[s / 2.0 for s in obj.size])
            elif obj.shape == "sphere":
                col = p.createCollisionShape(pybullet.GEOM_SPHERE, radius=obj.size[0])
            else:
                col = p.createCollisionShape(pybullet.GEOM_CYLINDER, radius=obj.size[1], height=obj.size[0])
            body = p.createMultiBody(
                baseMass=0,
                baseCollisionShapeIndex=col,
                basePosition=list(obj.position_at(t)),
                baseOrientation=list(obj.quaternion),
            )
            aabbs[obj.id] = p.getAABB(body, -1)
        return aabbs
    finally:
        p.disconnect()


def _frame(sim, body, link):
    """World pose of a body's base (link -1) or link frame (the inertial frames are the frames)."""
    if link == -1:
        return pybullet.getBasePositionAndOrientation(body, physicsClientId=sim.client_id)
    state = pybullet.getLinkState(body, link, computeForwardKinematics=True, physicsClientId=sim.client_id)
    return state[0], state[1]


def _assert_exact_layout(sim, world, t):
    """Every object's collision AABB and frame are those of its own body at motion time t (within 1e-9 m)."""
    expected = _separate_bodies(world, t)
    for obj in world.objects:
        body, link = sim.object_bodies[obj.id]
        aabb = pybullet.getAABB(body, link, physicsClientId=sim.client_id)
        for got, want in zip(aabb, expected[obj.id]):
            assert got == pytest.approx(want, abs=1e-9), (obj.id, t, aabb, expected[obj.id])
        pos, quat = _frame(sim, body, link)
        assert pos == pytest.approx(obj.position_at(t), abs=1e-9), (obj.id, t)
        q = obj.quaternion
        assert quat == pytest.approx(q, abs=1e-9) or quat == pytest.approx([-v for v in q], abs=1e-9), (obj.id, t)


def test_objects_sharing_a_motion_are_one_body(panda_urdf):
    worlds = _worlds()
    s = make_sim(panda_urdf, worlds["human"])
    try:
        links = s.object_bodies
        person = {links[o.id][0] for o in worlds["human"].moving_objects}
        assert len(person) == 1 and len(s._movers) == 1 and links["human_torso"][1] == -1
        assert sorted(link for body, link in links.values() if body in person) == list(range(-1, 7))
        assert links["table"][0] not in person and links["table"][1] == -1
        # The links are static colliders, as the separate bodies were: the legs pass through the table, no contact.
        pybullet.performCollisionDetection(physicsClientId=s.client_id)
        assert not pybullet.getContactPoints(bodyA=person.pop(), physicsClientId=s.client_id)
    finally:
        s.close()
    s = make_sim(panda_urdf, worlds["mixed"])
    try:
        links = s.object_bodies
        assert len(s._movers) == 3  # sway group, bob group, the single mover
        assert links["slab"][0] == links["rod"][0] == links["knob"][0]
        assert [links[i][1] for i in ("slab", "rod", "knob")] == [-1, 0, 1]  # world file order; the first is the base
        assert links["pair_a"][0] == links["pair_b"][0] and [links["pair_a"][1], links["pair_b"][1]] == [-1, 0]
        assert links["lone"][1] == -1 and links["post"][1] == -1
        assert len({body for body, _ in links.values()}) == 4
        assert {s._link_object[v] for v in links.values()} == set(links)
    finally:
        s.close()


@pytest.mark.parametrize("name", ["human", "mixed"])
@pytest.mark.parametrize("control", ["kinematic", "dynamic"])
def test_grouped_objects_are_where_separate_bodies_would_be(panda_urdf, name, control):
    world = _worlds()[name]
    s = make_sim(panda_urdf, world, control=control)
    try:
        s.reset_robot(HOME)
        for t in (0.0, 0.37, 1.1, 2.9, 4.5):
            s.place_obstacles(t)
            _assert_exact_layout(s, world, t)
        # The motions of the hot path (advance(), hold()) and a restart.
        s.restart_motions()
        _assert_exact_layout(s, world, 0.0)
        for _ in range(3):
            s.execute([0.05], [HOME])
            _assert_exact_layout(s, world, s.motion_time)
        s.hold(7)
        _assert_exact_layout(s, world, s.motion_time)
        s.hold(5, stats=s.contacts_now())
        _assert_exact_layout(s, world, s.motion_time)
    finally:
        s.close()


@pytest.mark.parametrize("control", ["kinematic", "dynamic"])
def test_contacts_with_grouped_objects_name_the_object(panda_urdf, control):
    s = make_sim(panda_urdf, load_world(HUMAN_WORLD), control=control)
    try:
        s.reset_robot(INTO_LEFT_ARM)
        # A link of the person's body (human_left_arm), its base (human_torso), nothing.
        assert {obj for _, obj in s.contacts_now().world_pairs} == {"human_left_arm"}
        s.place_obstacles(1.5)
        assert {obj for _, obj in s.contacts_now().world_pairs} == {"human_torso"}
        s.place_obstacles(4.5)
        assert not s.contacts_now().world_pairs
        # Holding still through the walk: the arm, then the torso (dynamic control: the arm pushes the robot, which
        # may then miss the torso); the person is not pushed away.
        s.restart_motions()
        r = s.execute([1.5], [INTO_LEFT_ARM])
        objects = {obj for _, obj in r.contacts.world_pairs}
        if control == "kinematic":
            assert objects == {"human_left_arm", "human_torso"}
        else:
            assert "human_left_arm" in objects and objects <= {"human_left_arm", "human_torso"}
        _assert_exact_layout(s, s.world, s.motion_time)
    finally:
        s.close()


def test_scene_view_colours_every_object(panda_urdf):
    """SceneView colours each object's own link (pictures of the grouped person keep their skin and shirt)."""
    from moverl_sim.scene_view import SceneView, ViewSettings, object_colour

    world = load_world(HUMAN_WORLD)
    robot = {"urdf": PANDA_URI, "joints": JOINTS, "base_link": "panda_link0", "fixed_joint_positions": FIXED}
    view = SceneView(robot, world, ViewSettings(width=32, height=24, yaw=0.0, pitch=-30.0, fov=60.0))
    try:
        p = view.sim.client
        for obj in world.objects:
            body, link = view.sim.object_bodies[obj.id]
            colours = {d[1]: d[7] for d in p.getVisualShapeData(body)}
            assert colours[link] == pytest.approx(object_colour(obj))
    finally:
        view.close()
