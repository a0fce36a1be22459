"""The depth cameras' own renderer (moverl_sim.depth_scene, the C++ rasterizer behind it) against the geometry it
draws: the world file's shapes ray-cast exactly, and PyBullet's TinyRenderer for the robot's meshes. No roscore."""

import dataclasses
import os

import numpy as np
import pybullet
import pytest
from conftest import JOINTS, make_sim
from pybullet_utils import bullet_client

from moverl_sim.camera import Camera, quaternion_to_rotation
from moverl_sim.depth_scene import DepthScene, box_mesh, capsule_mesh, cylinder_mesh, sphere_mesh, world_depth
from moverl_sim.world import load_world

pytestmark = pytest.mark.core

HUMAN_WORLD = os.path.join(os.path.dirname(__file__), "..", "..", "..", "worlds", "human.yaml")


# ---------------------------------------------------------------- the world's shapes, exactly
def _local(obj, t, points):
    """World points (n x 3) in an object's frame at motion time t."""
    return (points - np.asarray(obj.position_at(t))) @ quaternion_to_rotation(obj.quaternion)


def signed_distance(obj, t, points):
    p = _local(obj, t, points)
    if obj.shape == "box":
        q = np.abs(p) - np.asarray(obj.size) / 2.0
    elif obj.shape == "sphere":
        return np.linalg.norm(p, axis=1) - obj.size[0]
    else:
        h, r = obj.size
        q = np.column_stack((np.hypot(p[:, 0], p[:, 1]) - r, np.abs(p[:, 2]) - h / 2))
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


# ---------------------------------------------------------------- tests
def _cylinder_sdf(p, r, h):
    q = np.column_stack((np.hypot(p[:, 0], p[:, 1]) - r, np.abs(p[:, 2]) - h / 2))
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


@pytest.mark.parametrize(
    "mesh, radius, sdf",
    [
        (lambda: sphere_mesh(0.11), 0.11, lambda p: np.linalg.norm(p, axis=1) - 0.11),
        (lambda: cylinder_mesh(0.165, 0.58), 0.165, lambda p: _cylinder_sdf(p, 0.165, 0.58)),
        (
            lambda: capsule_mesh(0.05, 0.3),
            0.05,
            lambda p: np.linalg.norm(p - np.clip(p * [0, 0, 1], -0.15, 0.15), axis=1) - 0.05,
        ),
    ],
    ids=["sphere", "cylinder", "capsule"],
)
def test_curved_primitives_are_polyhedra_that_enclose_them_wound_outwards(mesh, radius, sdf):
    """Every face lies on or outside the shape (a ray that hits the shape hits the polyhedron first, never behind),
    its corners within 0.5 % of the radius, and every face is turned outwards (the rasterizer culls back faces)."""
    v, tri = mesh()
    a, b, c = (v[tri[:, i]] for i in range(3))
    assert np.all(np.einsum("ij,ij->i", np.cross(b - a, c - a), a + b + c) > 0)  # outward
    w = np.random.default_rng(0).dirichlet([1, 1, 1], size=64)  # points spread over every face
    samples = np.einsum("sk,tkj->tsj", w, np.stack((a, b, c), axis=1)).reshape(-1, 3)
    assert sdf(samples).min() >= -1e-9 * radius
    assert sdf(v).max() <= 0.005 * radius


def test_a_box_is_its_twelve_triangles_wound_outwards():
    v, tri = box_mesh([0.2, 0.4, 0.6])
    assert len(tri) == 12 and np.allclose(np.abs(v), [0.1, 0.2, 0.3])
    a, b, c = (v[tri[:, i]] for i in range(3))
    assert np.all(np.einsum("ij,ij->i", np.cross(b - a, c - a), a + b + c) > 0)


@pytest.fixture(scope="module")
def human_sim(panda_urdf):
    world = load_world(HUMAN_WORLD)
    s = make_sim(panda_urdf, world, camera_renderer="raster")
    s.reset_robot([0.0, -0.6, 0.0, -2.2, 0.0, 1.6, 0.8][: len(JOINTS)])
    yield s, world
    s.close()


@pytest.mark.parametrize("t", [0.0, 1.5, 4.2])
def test_the_world_files_shapes_are_drawn_where_they_are_never_behind_or_beside(human_sim, t):
    """The human world with the person at motion time t, each camera: where a pixel's ray hits a world object, the
    image is no farther than that hit (nothing is seen through or behind a surface); every pixel that sees a world
    object (not the robot) sees a point on an object's surface, at most 1.5 mm outside it (the enclosing polyhedra)."""
    sim, world = human_sim
    sim.place_obstacles(t)
    robot = sim.robot
    for spec in world.cameras:
        cam = Camera(spec)
        depth, seg = sim.render_segmented(cam)
        depth, seg = depth.reshape(-1), seg.reshape(-1)
        dirs = np.column_stack((cam._rays_x, cam._rays_y, np.ones_like(cam._rays_x))) @ cam.rotation.T
        origin = np.asarray(cam.position)
        exact = world_depth(world.objects, t, cam).reshape(-1)
        hits = np.isfinite(exact) & (exact < cam.far)
        assert hits.sum() > 1000
        assert np.all(depth[hits] <= exact[hits] + 1e-5), cam.id
        sees_world = (seg >= 0) & ((seg & ((1 << 24) - 1)) != robot)
        points = origin + dirs[sees_world] * depth[sees_world][:, None]
        sdf = np.min([signed_distance(o, t, points) for o in world.objects], axis=0)
        assert sdf.min() >= -1e-4 and sdf.max() <= 1.5e-3, (cam.id, sdf.min(), sdf.max())
        # And the person's pixels are the exact ones except at its rim: at most 2 % more (the polyhedra's rims).
        assert sees_world.sum() <= 1.02 * hits.sum() + 50


def test_a_scene_drawing_only_some_bodies_draws_them_as_the_whole_scene_does(human_sim):
    """DepthScene.drawing_only (render_cost.py --by-body): every body drawn is the scene's image; no body, the far plane
    everywhere; one body alone is seen where the whole scene sees it, at the same depth, and nowhere nearer than the
    whole scene; the world objects' bodies (Simulator.object_bodies) and the robot are every body there is."""
    sim, world = human_sim
    sim.place_obstacles(1.5)
    scene = sim.depth_scene
    uids = {uid for uid, _ in scene.parts}
    assert uids == {sim.robot} | {uid for uid, _ in sim.object_bodies.values()}
    assert set(sim.object_bodies) == {o.id for o in world.objects}
    for spec in world.cameras:
        cam = Camera(spec)
        full, seen = scene.render(cam, parts=True)
        assert np.array_equal(scene.drawing_only(uids).render(cam), full)
        assert np.all(scene.drawing_only([]).render(cam) == np.float32(cam.far))
        body_of_part = np.asarray([uid for uid, _ in scene.parts] + [-1])  # part -1: nothing seen
        for uid in uids:
            alone = scene.drawing_only([uid]).render(cam)
            mine = body_of_part[seen] == uid
            assert mine.sum() > 0, (cam.id, uid)
            assert np.array_equal(alone[mine], full[mine]), (cam.id, uid)
            assert np.all(alone >= full), (cam.id, uid)
            assert np.all(alone[~mine & (alone < cam.far)] > full[~mine & (alone < cam.far)]), (cam.id, uid)


def test_the_robots_meshes_are_drawn_as_tinyrenderer_draws_them(human_sim):
    """The same triangles (the simplified visual meshes) in both renderers: the pixels that see the robot, which link,
    and at what depth agree but for the rims (each renderer's coverage rule)."""
    sim, world = human_sim
    sim.place_obstacles(0.0)
    robot = sim.robot
    mine, theirs, same_link, same_depth = 0, 0, [], []
    for spec in world.cameras:
        cam = Camera(spec)
        depth, seg = sim.render_segmented(cam)
        ref, ref_seg = cam.render_segmented(sim.client_id)
        a, b = ((s >= 0) & ((s & 0xFFFFFF) == robot) for s in (seg, ref_seg))
        mine, theirs = mine + a.sum(), theirs + b.sum()
        both = a & b
        same_link.append(seg[both] == ref_seg[both])
        same_depth.append(np.abs(depth[both] - ref[both]) <= 1e-3)
    both = np.concatenate(same_link)
    assert theirs > 1000
    assert len(both) >= 0.97 * max(mine, theirs)
    assert np.mean(both) >= 0.98
    assert np.mean(np.concatenate(same_depth)) >= 0.99


def test_a_shape_it_does_not_draw_is_refused_naming_what_it_draws():
    client = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
    try:
        client.createMultiBody(baseMass=0, baseVisualShapeIndex=client.createVisualShape(pybullet.GEOM_PLANE))
        with pytest.raises(ValueError, match="does not draw geometry type 6; it draws box, sphere, cylinder, capsule"):
            DepthScene.from_client(client._client)
    finally:
        client.disconnect()


def test_the_simulator_refuses_an_unknown_renderer(panda_urdf, table_world):
    with pytest.raises(ValueError, match="camera_renderer must be one of 'raster', 'tinyrenderer', got 'opengl'"):
        make_sim(panda_urdf, table_world, camera_renderer="opengl")


def test_either_renderer_gives_the_cameras_conventions(panda_urdf, table_world):
    """The same camera conventions in both: z-depth images of the camera's size within its clip range, the points
    their back-projection, and a camera that sees nothing (looking up at the sky) reads exactly far everywhere."""
    sky = Camera(dataclasses.replace(table_world.cameras[0], xyz=(0.0, 0.0, 3.0), target=(0.3, 0.0, 4.0)))
    for renderer in ("raster", "tinyrenderer"):
        sim = make_sim(panda_urdf, table_world, camera_renderer=renderer)
        try:
            sim.reset_robot([0.0, -0.6, 0.0, -2.2, 0.0, 1.6, 0.8][: len(JOINTS)])
            for spec in table_world.cameras:
                cam = Camera(spec)
                depth = sim.render_depth(cam)
                assert depth.shape == (cam.height, cam.width)
                assert np.all((depth >= cam.near) & (depth <= cam.far))
                assert np.mean(depth < cam.far) > 0.1, "the camera sees the table and the robot"
                pts = sim.render_points(cam)
                assert pts.dtype == np.float32 and np.allclose(pts, cam.points_from_depth(depth))
            assert np.all(sim.render_depth(sky) == sky.far), renderer
        finally:
            sim.close()


def test_the_scene_refuses_to_draw_a_world_it_was_not_built_for(panda_urdf, table_world):
    sim = make_sim(panda_urdf, table_world, camera_renderer="raster")
    try:
        assert sim.camera_renderer == "raster" and sim.camera_renderer_fallback is None
        cam = Camera(table_world.cameras[0])
        sim.client.createMultiBody(baseMass=0, baseVisualShapeIndex=sim.client.createVisualShape(pybullet.GEOM_SPHERE))
        with pytest.raises(ValueError, match="bodies were added or removed since the depth scene was built"):
            sim.render_depth(cam)
    finally:
        sim.close()


DAE_FIXTURES = os.path.join(
    os.path.dirname(__file__), "..", "..", "moverl_planning_scene", "test", "fixtures", "geometry", "meshes"
)


def _mesh_robot(tmp_path, mesh_path, scale=1.0):
    """A URDF of two links: a box, and a link drawn as the mesh (scaled) on a revolute joint."""
    urdf = tmp_path / ("robot_%s.urdf" % os.path.basename(mesh_path))
    box = '<geometry><box size="0.1 0.1 0.1"/></geometry>'
    urdf.write_text(
        f'<robot name="v"><link name="a"><visual>{box}</visual><collision>{box}</collision></link>'
        '<joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
        f'<link name="b"><visual><geometry><mesh filename="{os.path.abspath(mesh_path)}" '
        f'scale="{scale} {scale} {scale}"/></geometry></visual><collision>{box}</collision></link></robot>'
    )
    return str(urdf)


@pytest.mark.parametrize("mesh", ["blob.dae", "blob_nested.dae"])
def test_a_robots_collada_mesh_is_drawn_as_tinyrenderer_draws_it(tmp_path, table_world, mesh):
    """A URDF whose visual mesh is COLLADA (common in ROS packages): the rasterizer draws it (moverl_sim.meshes reads
    it with its unit, millimetres here, and its nodes' transforms, nested in blob_nested.dae), where PyBullet's
    TinyRenderer draws it: the same pixels see the link at the same depth but for the rims."""
    from moverl_sim.core import Simulator
    from moverl_sim.settings import sim_settings

    urdf = _mesh_robot(tmp_path, os.path.join(DAE_FIXTURES, mesh), scale=5.0)
    sim = Simulator(urdf, ["j"], "a", None, table_world, **{**sim_settings(), "camera_renderer": "raster"})
    try:
        assert sim.camera_renderer == "raster" and sim.camera_renderer_fallback is None
        mine, theirs, same_depth = 0, 0, []
        for spec in table_world.cameras:
            cam = Camera(spec)
            depth, seg = sim.render_segmented(cam)
            ref, ref_seg = cam.render_segmented(sim.client_id)
            link_b = ((link_body >> 24) - 1 == 0 for link_body in (seg, ref_seg))
            a, b = ((s >= 0) & ((s & 0xFFFFFF) == sim.robot) & lb for s, lb in zip((seg, ref_seg), link_b))
            mine, theirs = mine + a.sum(), theirs + b.sum()
            same_depth.append(np.abs(depth[a & b] - ref[a & b]) <= 1e-3)
            assert (a & b).sum() >= 0.97 * max(a.sum(), b.sum()), spec.id
        assert mine > 300 and theirs > 300  # the blob, 0.27 m across, in view
        assert np.mean(np.concatenate(same_depth)) >= 0.99
    finally:
        sim.close()


def test_a_robot_with_a_mesh_it_cannot_read_falls_back_to_tinyrenderer(tmp_path, table_world):
    """A URDF whose visual mesh the rasterizer cannot read (here a COLLADA file without a visual scene; PyBullet
    loads it and draws nothing): the simulator is still built, its cameras drawn by TinyRenderer, and it says why (the
    node warns with it)."""
    from moverl_sim.core import Simulator
    from moverl_sim.settings import sim_settings

    with open(os.path.join(DAE_FIXTURES, "blob.dae"), encoding="utf-8") as fh:
        text = fh.read()
    no_scene = tmp_path / "no_scene.dae"
    no_scene.write_text(text[: text.index("<scene>")] + "</COLLADA>\n")
    sim = Simulator(
        _mesh_robot(tmp_path, str(no_scene)),
        ["j"],
        "a",
        None,
        table_world,
        **{**sim_settings(), "camera_renderer": "raster"},
    )
    try:
        assert sim.camera_renderer == "tinyrenderer"
        assert "no_scene.dae" in sim.camera_renderer_fallback and "TinyRenderer" in sim.camera_renderer_fallback
        assert "no visual scene" in sim.camera_renderer_fallback
        cam = Camera(table_world.cameras[0])
        assert np.array_equal(sim.render_depth(cam), cam.render_depth(sim.client_id))
    finally:
        sim.close()
