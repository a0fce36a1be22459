"""Simulated depth cameras: world-file parsing, pose, rendering geometry (moverl_sim.camera). No roscore."""

import os

import numpy as np
import pybullet
import pytest
from pybullet_utils import bullet_client

from moverl_sim.camera import (
    Camera,
    depth_from_zbuffer,
    look_at_rotation,
    quaternion_to_rotation,  # noqa: E402
    rotation_to_quaternion,
)
from moverl_sim.world import WorldCamera, WorldFileError, load_world, parse_world, rpy_to_quaternion

pytestmark = pytest.mark.core

CAM = {
    "id": "front",
    "xyz": [1.2, 0.5, 1.0],
    "target": [0.3, 0.0, 0.1],
    "width": 160,
    "height": 120,
    "fov": 60,
    "near": 0.1,
    "far": 3.5,
    "rate": 2,
}


def camera(**kw):
    d = dict(CAM)
    d.update(kw)
    return Camera(
        WorldCamera(
            id=d["id"],
            xyz=tuple(d["xyz"]),
            target=tuple(d["target"]),
            up=tuple(d.get("up", (0, 0, 1))),
            width=d["width"],
            height=d["height"],
            fov=d["fov"],
            near=d["near"],
            far=d["far"],
            rate=d["rate"],
        )
    )


# Box of the geometry tests: 0.3 (x) x 1.0 (y) x 0.6 (z), centre C, yawed and slightly rolled.
BOX_HALF = np.array([0.15, 0.5, 0.3])
BOX_C = np.array([1.6, 0.3, 0.5])
BOX_RPY = (0.1, 0.0, 0.5)


def box_frame():
    """Rotation (box -> world) and centre of the test box."""
    return quaternion_to_rotation(rpy_to_quaternion(BOX_RPY)), BOX_C


def box_local(p):
    R, c = box_frame()
    return (np.asarray(p, dtype=float) - c) @ R


def box_world(p_local):
    R, c = box_frame()
    return R @ np.asarray(p_local, dtype=float) + c


@pytest.fixture(scope="module")
def box_client():
    """A bare physics client with the test box only (no robot, no floor)."""
    c = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
    col = c.createCollisionShape(pybullet.GEOM_BOX, halfExtents=BOX_HALF.tolist())
    vis = c.createVisualShape(pybullet.GEOM_BOX, halfExtents=BOX_HALF.tolist())
    c.createMultiBody(0, col, vis, basePosition=BOX_C.tolist(), baseOrientation=list(rpy_to_quaternion(BOX_RPY)))
    yield c._client
    c.disconnect()


def face_camera(width=160, height=120):
    """Camera in front of the box's -x face (inside the face's y/z extent, so only that face is visible), looking
    obliquely (~35 deg) at a point of the face, with a rolled up vector."""
    xyz = box_world([-1.15, 0.35, 0.2])
    target = box_world([-0.15, -0.25, -0.1])  # on the face x_local = -0.15
    return camera(xyz=xyz.tolist(), target=target.tolist(), up=[0.2, 0.1, 1.0], width=width, height=height)


# ---------------------------------------------------------------------- world files
def test_camera_world_file_is_parsed(tmp_path):
    p = tmp_path / "w.yaml"
    p.write_text(
        "name: w\ncameras:\n"
        "  - {id: front, xyz: [1.2, 0.5, 1.0], target: [0.3, 0, 0.1], width: 160, height: 120,\n"
        "     fov: 60, near: 0.1, far: 3.5, rate: 2}\n"
        "  - {id: side_2, xyz: [0, -1, 1], target: [0, 0, 0], up: [1, 0, 0], width: 8, height: 6,\n"
        "     fov: 45.5, near: 0.05, far: 2, rate: 0.5}\n"
    )
    w = load_world(p)
    assert [c.id for c in w.cameras] == ["front", "side_2"]
    c = w.camera("front")
    assert c.xyz == (1.2, 0.5, 1.0) and c.target == (0.3, 0.0, 0.1) and c.up == (0.0, 0.0, 1.0)
    assert (c.width, c.height, c.fov, c.near, c.far, c.rate) == (160, 120, 60.0, 0.1, 3.5, 2.0)
    assert c.optical_frame == "front_optical_frame"
    assert w.camera("side_2").up == (1.0, 0.0, 0.0)
    assert parse_world({"name": "w"}).cameras == ()  # optional


def test_repo_worlds_have_cameras():
    import os

    from conftest import REPO_DIR

    for name in ("table", "human", "case"):
        w = load_world(os.path.join(REPO_DIR, "worlds", name + ".yaml"))
        assert 2 <= len(w.cameras) <= 3, name
        for c in w.cameras:
            assert c.far > 3.0, "%s/%s: far must exceed the planning scene's max_range (3.0 m)" % (name, c.id)


def _cam_yaml(**kw):
    d = dict(CAM)
    d.update(kw)
    return {k: v for k, v in d.items() if v is not None}


BAD_CAMERAS = {
    # case: (cameras list, substring the error must contain)
    "not_a_list": ({"id": "a"}, "'cameras': expected a list"),
    "missing_id": ([_cam_yaml(id=None)], "'cameras[0].id': missing required key"),
    "missing_far": ([_cam_yaml(far=None)], "'cameras[0] (id front).far': missing required key"),
    "bad_id": ([_cam_yaml(id="front cam")], "only letters, digits and '_'"),
    "duplicate_id": ([_cam_yaml(), _cam_yaml(xyz=[0, 1, 1])], "'cameras[1] (id front).id': duplicate camera id"),
    "unknown_key": ([_cam_yaml(fps=30)], "'cameras[0] (id front).fps': unknown key"),
    "fov_zero": ([_cam_yaml(fov=0)], "(id front).fov': vertical field of view must be in (0, 180)"),
    "fov_180": ([_cam_yaml(fov=180)], "(id front).fov'"),
    "near_ge_far": ([_cam_yaml(near=2.0, far=2.0)], "(id front).far': must be > near"),
    "near_zero": ([_cam_yaml(near=0)], "(id front).near': must be > 0"),
    "up_parallel": ([_cam_yaml(xyz=[0, 0, 2], target=[0, 0, 0])], "(id front).up': must not be parallel"),
    "up_antiparallel": ([_cam_yaml(up=[-0.9, -0.5, -0.9])], "(id front).up': must not be parallel"),
    "up_zero": ([_cam_yaml(up=[0, 0, 0])], "(id front).up': must be a non-zero vector"),
    "target_is_xyz": ([_cam_yaml(target=[1.2, 0.5, 1.0])], "(id front).target': must differ from xyz"),
    "width_zero": ([_cam_yaml(width=0)], "(id front).width': expected a positive integer"),
    "height_float": ([_cam_yaml(height=120.5)], "(id front).height': expected a positive integer"),
    "width_bool": ([_cam_yaml(width=True)], "(id front).width'"),
    "rate_zero": ([_cam_yaml(rate=0)], "(id front).rate': must be > 0"),
    "rate_negative": ([_cam_yaml(rate=-1)], "(id front).rate': must be > 0"),
    "xyz_short": ([_cam_yaml(xyz=[1, 2])], "(id front).xyz': expected 3 numbers"),
    "fov_string": ([_cam_yaml(fov="wide")], "(id front).fov': expected a finite number"),
}


@pytest.mark.parametrize("case", sorted(BAD_CAMERAS))
def test_camera_world_file_errors(case):
    cameras, expected = BAD_CAMERAS[case]
    with pytest.raises(WorldFileError) as err:
        parse_world({"name": "w", "cameras": cameras}, source="bad.yaml")
    msg = str(err.value)
    assert msg.startswith("bad.yaml: "), msg
    assert expected in msg, msg


# ---------------------------------------------------------------------- pose
@pytest.mark.parametrize(
    "xyz,target,up",
    [
        ([1.2, 0.5, 1.0], [0.3, 0.0, 0.1], [0, 0, 1]),
        ([0.0, -1.0, 1.5], [0.2, 0.1, 0.0], [0, 0, 1]),
        ([0.4, 0.0, 1.6], [0.4, 0.0, 0.0], [1, 0, 0]),  # straight down, image up = +x
        ([-0.5, 0.3, 0.2], [1.0, 0.3, 0.2], [0.1, 0.3, 1]),  # horizontal, tilted up vector
    ],
)
def test_pose_quaternion_maps_optical_axes(xyz, target, up):
    cam = camera(xyz=xyz, target=target, up=up)
    pos, q = cam.pose
    assert pos == pytest.approx(tuple(xyz))
    assert np.linalg.norm(q) == pytest.approx(1.0)
    R = quaternion_to_rotation(q)
    view = np.subtract(target, xyz) / np.linalg.norm(np.subtract(target, xyz))
    up_n = np.asarray(up, dtype=float) / np.linalg.norm(up)
    assert R @ [0, 0, 1] == pytest.approx(view, abs=1e-9)  # optical z: forward
    y = R @ [0, 1, 0]
    down = -(up_n - np.dot(up_n, view) * view)
    assert y == pytest.approx(down / np.linalg.norm(down), abs=1e-9)  # optical y: -up (made orthogonal)
    assert np.dot(y, -up_n) > 0.0
    assert R @ [1, 0, 0] == pytest.approx(np.cross(view, up_n) / np.linalg.norm(np.cross(view, up_n)), abs=1e-9)
    assert np.linalg.det(R) == pytest.approx(1.0)
    # The render uses the same pose: the view matrix equals PyBullet's own look-at for these vectors.
    assert cam.view_matrix == pytest.approx(list(pybullet.computeViewMatrix(xyz, target, up)), abs=1e-6)
    # Round trips.
    assert rotation_to_quaternion(R) == pytest.approx(q, abs=1e-12)
    pts = np.array([[0.1, -0.2, 1.0], [0.0, 0.0, 2.0]])
    assert cam.world_to_optical(cam.optical_to_world(pts)) == pytest.approx(pts)
    assert cam.optical_to_world([[0, 0, 1.0]])[0] == pytest.approx(np.asarray(xyz) + view)


def test_look_at_rejects_parallel_up():
    with pytest.raises(ValueError, match="parallel"):
        look_at_rotation([0, 0, 1], [0, 0, 0], [0, 0, 1])


# ---------------------------------------------------------------------- rendering
def test_points_hit_the_box_face_in_world_coordinates(box_client):
    cam = face_camera()
    pts = cam.render(box_client)
    assert pts.dtype == np.float32 and pts.shape == (cam.width * cam.height, 3)
    hit = pts[:, 2] < cam.far
    assert hit.sum() > 2000, "the box face should fill a good part of the image"
    local = box_local(cam.optical_to_world(pts[hit]))
    # On the -x face's plane within 2 mm, inside the face's extent (the face edges within 1 mm).
    assert np.abs(local[:, 0] + BOX_HALF[0]).max() < 2e-3
    assert np.all(np.abs(local[:, 1]) < BOX_HALF[1] + 1e-3) and np.all(np.abs(local[:, 2]) < BOX_HALF[2] + 1e-3)
    # The face's pixels: every pixel whose sampling ray meets the face (2 mm inside its edges) is a hit.
    u = np.tile(np.arange(cam.width), cam.height)
    v = np.repeat(np.arange(cam.height), cam.width)
    rays = np.stack(
        [(u - cam.principal_point[0]) / cam.focal, (v - cam.principal_point[1]) / cam.focal, np.ones(u.shape)], -1
    )
    o = box_local(cam.optical_to_world([[0, 0, 0]]))[0]
    d = box_local(cam.optical_to_world(rays)) - o
    s = (-BOX_HALF[0] - o[0]) / d[:, 0]
    p = o + s[:, None] * d
    margin = 2e-3  # TinyRenderer covers exactly the pixels whose sampling ray meets the face
    inside = (s > 0) & (np.abs(p[:, 1]) < BOX_HALF[1] - margin) & (np.abs(p[:, 2]) < BOX_HALF[2] - margin)
    assert inside.sum() > 2000 and np.all(hit[inside])


def test_centre_pixel_is_on_the_optical_axis(box_client):
    cam = face_camera()
    u, v = cam.width // 2, cam.height // 2 - 1
    assert cam.principal_point == (u, v)
    pts = cam.render(box_client).reshape(cam.height, cam.width, 3)
    x, y, z = (float(a) for a in pts[v, u])
    assert x == 0.0 and y == 0.0
    # The optical axis meets the (obliquely seen) face at the target: a pixel off would be ~7 mm off here.
    expected = float(np.linalg.norm(np.subtract(cam.spec.target, cam.spec.xyz)))
    assert z == pytest.approx(expected, abs=1e-3)
    assert abs(float(pts[v, u + 1, 2]) - expected) > 3e-3 and abs(float(pts[v + 1, u, 2]) - expected) > 3e-3


def test_image_orientation(box_client):
    """Top image rows look along +up, right columns along view x up (no flips between render and pose)."""
    # Camera level with the box centre, looking at it; the box fills the middle of the image only.
    xyz = box_world([-2.5, 0.0, 0.0])
    cam = camera(xyz=xyz.tolist(), target=box_world([0, 0.2, 0.15]).tolist(), width=64, height=48)
    hit = (cam.render(box_client)[:, 2] < cam.far).reshape(cam.height, cam.width)
    rows, cols = np.where(hit)
    # The target is up and to the box's +y (= image left, since x_opt = view x up): the box lies low and right.
    assert rows.mean() > cam.principal_point[1] and cols.mean() > cam.principal_point[0]


def test_no_return_pixels_are_at_far(box_client):
    # Looking away from the box: nothing at all is hit.
    cam = camera(xyz=[0, 0, 0], target=[-1, 0, 0.2])
    pts = cam.render(box_client)
    assert np.all(pts[:, 2] == np.float32(cam.far))
    u = np.tile(np.arange(cam.width), cam.height)
    v = np.repeat(np.arange(cam.height), cam.width)
    assert pts[:, 0] == pytest.approx((u - cam.principal_point[0]) / cam.focal * cam.far, abs=1e-5)
    assert pts[:, 1] == pytest.approx((v - cam.principal_point[1]) / cam.focal * cam.far, abs=1e-5)
    # The box beyond the far plane is clipped: no return either; within range it is hit.
    at_box = face_camera()
    assert np.any(at_box.render(box_client)[:, 2] < at_box.far)
    # The face's nearest point is at z = 0.74 m.
    short = camera(xyz=at_box.spec.xyz, target=at_box.spec.target, up=at_box.spec.up, far=0.6)
    assert np.all(short.render(box_client)[:, 2] == np.float32(0.6))


def test_segmented_render_is_the_depth_render_with_the_body_of_each_pixel(box_client):
    cam = face_camera()
    depth, seg = cam.render_segmented(box_client)
    assert np.array_equal(depth, cam.render_depth(box_client))
    hit = depth < cam.far
    assert hit.sum() > 2000
    assert np.all(seg[~hit] == -1), "no return: no body"
    bodies = set(np.unique(seg[hit] & ((1 << 24) - 1)).tolist())
    assert len(bodies) == 1, f"only the box is in view: {bodies}"


def test_depth_from_zbuffer():
    near, far = 0.1, 3.5
    z = np.array([0.5, 1.0, 3.0])
    zbuf = (1.0 / near - 1.0 / z) / (1.0 / near - 1.0 / far)  # OpenGL depth of z
    assert depth_from_zbuffer(zbuf, near, far) == pytest.approx(z)
    assert depth_from_zbuffer(np.array([0.0, 1.0]), near, far).tolist() == [near, far]


def test_render_in_a_simulator(panda_urdf, table_world):
    """Camera.render works on the Simulator's client: the table top (z = 0) and the robot are seen."""
    from conftest import HOME, make_sim

    sim = make_sim(panda_urdf, table_world)
    try:
        sim.reset_robot(HOME)
        cam = camera(xyz=[1.2, 0.6, 1.0], target=[0.3, 0.0, 0.2])
        world = cam.optical_to_world(cam.render(sim.client_id)[:, :].astype(np.float64))
        hit = np.linalg.norm(world - cam.position, axis=1) < 3.0
        on_table = hit & (np.abs(world[:, 2]) < 2e-3)
        above = hit & (world[:, 2] > 0.05)
        assert on_table.sum() > 1000 and above.sum() > 100  # table top and robot
    finally:
        sim.close()


def test_point_cloud_message():
    pytest.importorskip("sensor_msgs", reason="ROS messages not sourced (source env.sh)")
    from sensor_msgs import point_cloud2
    from sensor_msgs.msg import PointField

    from moverl_sim.ros_conversions import points_to_msg

    pts = np.arange(2 * 3 * 3, dtype=np.float32).reshape(-1, 3)
    msg = points_to_msg(pts, 3, 2, "front_optical_frame", 1.25)
    assert (msg.height, msg.width, msg.point_step, msg.row_step) == (2, 3, 12, 36)
    assert msg.header.frame_id == "front_optical_frame" and msg.header.stamp.to_sec() == pytest.approx(1.25)
    assert [(f.name, f.offset, f.datatype, f.count) for f in msg.fields] == [
        ("x", 0, PointField.FLOAT32, 1),
        ("y", 4, PointField.FLOAT32, 1),
        ("z", 8, PointField.FLOAT32, 1),
    ]
    assert not msg.is_bigendian and msg.is_dense
    assert np.array(list(point_cloud2.read_points(msg)), dtype=np.float32) == pytest.approx(pts)
    with pytest.raises(ValueError):
        points_to_msg(pts, 4, 2, "f", 0.0)


# ---------------------------------------------------------------------- coverage of the repo worlds
@pytest.fixture(scope="module")
def panda_workspace():
    from conftest import REPO_DIR

    from moverl_sim.robot_config import load_robot_config
    from moverl_sim.workspace import Workspace

    return Workspace.of_robot(load_robot_config(os.path.join(REPO_DIR, "config", "robots", "panda.yaml")))


def test_coverage_reachable_surfaces(panda_workspace):
    from moverl_sim import coverage

    w = parse_world(
        {
            "name": "w",
            "objects": [
                {"id": "table", "shape": "box", "size": [1.5, 0.8, 0.03], "xyz": [0.35, 0, -0.015]},
                {"id": "near", "shape": "box", "size": [0.1, 0.1, 0.1], "xyz": [0.5, 0, 0.05]},
                {"id": "far_away", "shape": "sphere", "size": [0.1], "xyz": [2.0, 0, 0.5]},
            ],
        }
    )
    s = coverage.surface_samples(w, 0.02)
    reach = coverage.reachable_mask(s, w, panda_workspace)
    near = s.objects == 1
    top = near & (s.normals[:, 2] > 0.5)
    bottom = near & (s.normals[:, 2] < -0.5)
    assert reach[top].all() and not reach[bottom].any()  # the bottom face sits on the table
    assert not reach[s.objects == 2].any()  # out of reach
    table_top = (s.objects == 0) & (s.normals[:, 2] > 0.5)
    under_box = table_top & (np.abs(s.points[:, 0] - 0.5) < 0.05) & (np.abs(s.points[:, 1]) < 0.05)
    assert under_box.any() and not reach[under_box].any()  # covered by the box
    assert not reach[(s.objects == 0) & (s.normals[:, 2] < -0.5)].any()  # the table's underside


def test_coverage_reach_is_the_robots(panda_workspace):
    """The same box is within the Panda's reach and beyond the xArm6's: what counts as reachable is the robot's."""
    from conftest import REPO_DIR

    from moverl_sim import coverage
    from moverl_sim.robot_config import load_robot_config
    from moverl_sim.workspace import Workspace

    xarm6 = Workspace.of_robot(load_robot_config(os.path.join(REPO_DIR, "config", "robots", "xarm6.yaml")))
    w = parse_world(
        {"name": "w", "objects": [{"id": "far", "shape": "box", "size": [0.1, 0.1, 0.1], "xyz": [0.95, 0, 0.3]}]}
    )
    s = coverage.surface_samples(w, 0.02)
    near_face = s.normals[:, 0] < -0.5  # faces the robot, 0.9 m from the base axis: the probe's centre at 0.85 m
    assert coverage.reachable_mask(s, w, panda_workspace)[near_face].all()
    assert not coverage.reachable_mask(s, w, xarm6)[near_face].any()
    assert xarm6.reach < 0.85 < panda_workspace.reach


@pytest.mark.parametrize("name,minimum", [("table", 0.99), ("human", 0.98), ("case", 0.99)])
def test_repo_world_cameras_see_the_reachable_obstacle_surface(panda_urdf, panda_workspace, name, minimum):
    """The worlds' cameras see (almost) all the obstacle surface the robot can reach, the robot at home (the
    human at the centre and both ends of the walk). render_world --cameras prints the same figures."""
    from conftest import HOME, REPO_DIR, make_sim

    from moverl_sim import coverage

    w = load_world(os.path.join(REPO_DIR, "worlds", name + ".yaml"))
    cams = [Camera(c) for c in w.cameras]
    sim = make_sim(panda_urdf, w)
    try:
        sim.reset_robot(HOME)
        times = [0.0]
        if w.moving_objects:
            period = w.moving_objects[0].motion.period
            times = [0.0, 0.25 * period, 0.75 * period]
        for t in times:
            sim._place_movers(t)
            samples = coverage.surface_samples(w, 0.02, t)
            depths = [c.render_depth(sim.client_id) for c in cams]
            table, _, _, _ = coverage.coverage_report(w, cams, depths, samples, panda_workspace, t)
            total = sum(a for a, _ in table.values())
            seen = sum(b for _, b in table.values())
            assert total > 1000
            assert seen / total >= minimum, "%s at t = %g: %s" % (name, t, table)
    finally:
        sim.close()
