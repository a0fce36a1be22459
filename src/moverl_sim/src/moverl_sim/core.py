"""ROS-free PyBullet simulator of one robot arm among obstacles, with ground-truth contacts.

Obstacles with a motion (moverl_sim.world.ObjectMotion) are placed at their pose at the current motion time
before collision detection at every physics substep. Motion time = simulated time since the last
restart_motions() (or since the start).

The Simulator owns its own BulletClient (never the global pybullet connection), so several
simulators can live in one process. It is not thread safe: callers serialise access.
"""

import math
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Dict, NamedTuple, Tuple

import numpy as np
import pybullet
from pybullet_utils import bullet_client

from .depth_scene import DepthScene
from .follow import spline_at
from .trajectory import sample_linear, segment_velocities, substep_count
from .urdf import JointLimits, UrdfError, collision_as_visual, rewrite_mesh_paths, robot_description, simplified_visuals
from .world import World

__all__ = [
    "Simulator",
    "ContactStats",
    "ExecutionResult",
    "Motion",
    "InvalidTrajectory",
    "LimitViolation",
    "collision_shape",
    "CONTROLS",
]

POSITION_TOLERANCE = 1e-6  # rad (or m): tolerance on the joint position limits
VELOCITY_TOLERANCE = 1e-6  # relative tolerance on the velocity limits
START_TOLERANCE = 1e-4  # a first point at t=0 must be this close to the current state
#: The values control accepts (moverl_gym/test/test_launch_args.py compares them with moverl_gym.launch_args.CHOICES).
CONTROLS = ("kinematic", "dynamic")
# Bullet's broadphase collision filter groups (btBroadphaseProxy): a fixed base's collider is static, and static
# colliders do not collide with each other.
#: What may draw the depth cameras' images (Simulator's camera_renderer; config/sim.yaml says which and why).
CAMERA_RENDERERS = ("raster", "tinyrenderer")

_STATIC_FILTER = 2
_ALL_FILTER = -1


class InvalidTrajectory(ValueError):
    """Malformed request: empty, wrong sizes, NaN/inf, non-increasing times, wrong start point."""


class LimitViolation(ValueError):
    """A position leaves the joint limits or a segment exceeds the joint velocity limits."""


@dataclass
class ContactStats:
    """Contacts of the robot over one motion (every physics substep).

    world_pairs: (robot link name, world object id) -> deepest penetration (m, positive).
    self_pairs: (link name, link name), sorted -> deepest penetration (m, positive).
    """

    substeps: int = 0
    substeps_in_contact: int = 0
    world_pairs: Dict[Tuple[str, str], float] = field(default_factory=dict)
    self_pairs: Dict[Tuple[str, str], float] = field(default_factory=dict)
    total_contact_substeps: int = 0  # running total since the simulator started
    #: Who moved: the pairs (world and self) that touched at a substep where the robot moved (a commanded joint speed
    #: above the simulator's moving_speed), and those that touched while it rested (held still: whatever touched it
    #: came to it). A pair can be in both.
    moving_pairs: set = field(default_factory=set)
    resting_pairs: set = field(default_factory=set)

    @property
    def world_contacts(self):
        return len(self.world_pairs)

    @property
    def self_contacts(self):
        return len(self.self_pairs)

    @property
    def in_contact(self):
        return self.substeps_in_contact > 0

    @property
    def moving_contacts(self):
        return len(self.moving_pairs)

    @property
    def resting_contacts(self):
        return len(self.resting_pairs)


class ExecutionResult(NamedTuple):
    positions: Tuple[float, ...]  # controlled joints, in the configured order, at the end
    contacts: ContactStats


class Motion:
    """A validated trajectory, sampled at every physics substep, being executed."""

    __slots__ = (
        "targets",
        "velocities",
        "setpoints",
        "n",
        "k",
        "stats",
        "_counts",
        "final",
        "path_tolerance",
        "aborted",
    )

    def __init__(self, targets, velocities, final, path_tolerance=None, stats=None, setpoints=None):
        self.targets = targets  # list (per substep) of [[q1], [q2], ...]: where the robot is after substep k
        self.velocities = velocities  # same shape: segment velocities
        # Dynamic control: the motors' position setpoint of substep k, flat lists. PyBullet's position motor reaches
        # setpoint + velocity * dt within the substep, so the setpoint is the trajectory at the substep's START (the
        # end-of-substep position would put the robot one substep ahead: 4 mrad at 240 Hz, measured).
        # None: the targets' positions (kinematic control never reads them).
        self.setpoints = setpoints
        self.final = final  # tuple: last setpoint
        self.n = len(targets)
        self.k = 0
        self.stats = stats if stats is not None else ContactStats()
        self._counts = [0, 0]  # substeps, substeps in contact
        # Dynamic control: per-joint bound on |measured - setpoint| (0: none); exceeding it stops the motion.
        self.path_tolerance = path_tolerance
        self.aborted = ""  # why the motion was stopped early ("" when it was not)

    @property
    def done(self):
        return self.k >= self.n or bool(self.aborted)

    @property
    def remaining(self):
        return self.n - self.k


def _quat_from_pybullet(q):
    return (q[0], q[1], q[2], q[3])


def _frame(pos, orn) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = np.array(pybullet.getMatrixFromQuaternion(orn)).reshape(3, 3)
    m[:3, 3] = pos
    return m


def collision_shape(client, body, link):
    """PyBullet's collision shape of one link of a body, in the world frame, as its contacts see it: the hull vertices
    of its convex pieces (getMeshData: meshes and the hulls PyBullet makes of cylinders) and the corners of its boxes
    (N x 3), and its spheres as (centre, radius) pairs. The one reading of a link's shape from PyBullet
    (moverl_gym.geometry_parity compares it with the planning scene's, moverl_sim.workspace measures the reach).

    Args:
        client: a pybullet_utils BulletClient.
        body: the body's unique id.
        link: the link's index (-1: the base).

    Returns:
        (points, spheres).
    """
    if link == -1:
        com = _frame(*client.getBasePositionAndOrientation(body))
    else:
        s = client.getLinkState(body, link, computeForwardKinematics=True)
        com = _frame(s[0], s[1])
    shapes = client.getCollisionShapeData(body, link)
    pts, spheres = [], []
    if any(s[2] == pybullet.GEOM_MESH for s in shapes):  # convex hulls (meshes, cylinders)
        _, verts = client.getMeshData(body, link)
        if len(verts):
            v = np.asarray(verts, dtype=float).reshape(-1, 3)
            pts.append(v @ com[:3, :3].T + com[:3, 3])
    for shape in shapes:
        kind, dims, pos, orn = shape[2], shape[3], shape[5], shape[6]
        local = com @ _frame(pos, orn)
        if kind == pybullet.GEOM_BOX:
            half = np.array(dims) / 2
            corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
            pts.append(corners @ local[:3, :3].T + local[:3, 3])
        elif kind == pybullet.GEOM_SPHERE:
            spheres.append((local[:3, 3].copy(), float(dims[0])))
    return (np.vstack(pts) if pts else np.zeros((0, 3))), spheres


def _relative_pose(base_xyz, base_quat, xyz, quat):
    """Pose (xyz, quaternion x y z w) of a frame given in the world relative to a base frame given in the world.

    In double precision: PyBullet's invertTransform / multiplyTransforms return single precision (4e-8 m off)."""
    bx, by, bz, bw = base_quat
    x, y, z, w = quat
    # conj(base) * quat
    q = (
        bw * x - bx * w - by * z + bz * y,
        bw * y + bx * z - by * w - bz * x,
        bw * z - bx * y + by * x - bz * w,
        bw * w + bx * x + by * y + bz * z,
    )
    # conj(base) rotates d = xyz - base_xyz: d + 2 bw (u x d) + 2 u x (u x d), u = -(bx, by, bz)
    dx, dy, dz = xyz[0] - base_xyz[0], xyz[1] - base_xyz[1], xyz[2] - base_xyz[2]
    ux, uy, uz = -bx, -by, -bz
    cx, cy, cz = uy * dz - uz * dy, uz * dx - ux * dz, ux * dy - uy * dx
    ccx, ccy, ccz = uy * cz - uz * cy, uz * cx - ux * cz, ux * cy - uy * cx
    d = (dx + 2.0 * (bw * cx + ccx), dy + 2.0 * (bw * cy + ccy), dz + 2.0 * (bw * cz + ccz))
    return d, q


class Simulator:
    """One robot (fixed base at the world origin) and static obstacles in a PyBullet world.

    urdf_path: URDF file with resolvable (absolute) mesh paths (Simulator.from_robot writes one as the node does).
    joints: controlled joint names, in the order of every position vector.
    base_link: link mounted to the world; its contacts (and those of links rigidly fixed to it) with
        the world are ignored.
    fixed_joint_positions: {joint: value} for movable joints that are not controlled (held there).
    world: a moverl_sim.world.World.
    physics_hz, control: required, no default here: their one home is config/sim.yaml (moverl_sim.settings reads it
        for code that runs without the node's parameters).
    control: "kinematic" (joints set exactly at every substep, collision detection only) or
        "dynamic" (position-controlled motors track the setpoint, full physics).
    robot_visuals: "visual" (the robot is drawn as its visual meshes), "simplified" (its visual meshes decimated to
        at most simplified_faces triangles each: what the depth cameras see at a fraction of the cost) or "collision"
        (its collision shapes); required, config/sim.yaml's robot_visuals (and simplified_faces).
    camera_renderer: what draws the depth cameras' images (render_depth): "raster" (moverl_sim.depth_scene: a
        depth-only rasterizer of the visual shapes, read once here) or "tinyrenderer" (PyBullet's); required,
        config/sim.yaml's camera_renderer. A world raster cannot draw (a visual mesh of another format than OBJ, STL
        or COLLADA, or a file moverl_sim.meshes cannot read) falls back to TinyRenderer: self.camera_renderer says
        which draws, and self.camera_renderer_fallback why (the node warns).
    """

    def __init__(
        self,
        urdf_path,
        joints,
        base_link,
        fixed_joint_positions=None,
        world=None,
        *,
        physics_hz,
        control,
        gui=False,
        moving_speed,
        motion_time_scale=1.0,
        robot_visuals,
        simplified_faces=None,
        camera_renderer,
    ):
        if control not in CONTROLS:
            raise ValueError("control must be %s, got %r" % (" or ".join(repr(c) for c in CONTROLS), control))
        physics_hz = float(physics_hz)
        if not math.isfinite(physics_hz) or physics_hz <= 0:
            raise ValueError("physics_hz must be positive, got %r" % (physics_hz,))
        self.control = control
        self.physics_hz = physics_hz
        self.dt = 1.0 / physics_hz
        self.world = world if world is not None else World(name="empty")
        # Experiments only (sim.yaml motion_time_scale): the obstacles play their motions this many times faster than
        # the world file says; nobody else is told (a person faster than the world's declared speed bound).
        if not (math.isfinite(motion_time_scale) and motion_time_scale > 0):
            raise ValueError("motion_time_scale must be positive, got %r" % (motion_time_scale,))
        self._motion_scale = float(motion_time_scale)
        # rad/s (m/s): a substep whose commanded joint speeds are all at most this is one where the robot rests
        # (ContactStats.resting_pairs: it did not go to what touched it).
        if not (math.isfinite(moving_speed) and moving_speed >= 0):
            raise ValueError("moving_speed must be finite and >= 0, got %r" % (moving_speed,))
        self._moving_speed = float(moving_speed)
        self._substeps_total = 0
        self._motion_epoch = 0  # substeps_total at the last restart_motions()
        self._total_contact_substeps = 0
        self._q = None  # cached controlled positions (kinematic mode, at rest)

        self._p = bullet_client.BulletClient(connection_mode=pybullet.GUI if gui else pybullet.DIRECT)
        p = self._p
        try:
            p.setGravity(0, 0, -9.81)
            p.setTimeStep(self.dt)
            flags = pybullet.URDF_USE_SELF_COLLISION | pybullet.URDF_USE_SELF_COLLISION_EXCLUDE_PARENT
            if robot_visuals not in ("visual", "simplified", "collision"):
                raise ValueError(
                    "robot_visuals must be 'visual', 'simplified' or 'collision', got %r" % (robot_visuals,)
                )
            if robot_visuals == "simplified" and not (isinstance(simplified_faces, int) and simplified_faces >= 4):
                raise ValueError(
                    "robot_visuals 'simplified' needs simplified_faces, an int >= 4, got %r" % (simplified_faces,)
                )
            if camera_renderer not in CAMERA_RENDERERS:
                raise ValueError(
                    "camera_renderer must be one of %s, got %r"
                    % (", ".join(map(repr, CAMERA_RENDERERS)), camera_renderer)
                )
            loaded = str(urdf_path)
            # The rewritten URDF (and simplified meshes) live here until PyBullet and the depth scene have read them.
            scratch = None
            try:
                if robot_visuals != "visual":
                    scratch = tempfile.mkdtemp(prefix="moverl_robot_")
                    with open(urdf_path, encoding="utf-8") as fh:
                        text = fh.read()
                    base_dir = os.path.dirname(str(urdf_path))
                    if robot_visuals == "collision":  # the same URDF, drawn as its collision shapes
                        text = collision_as_visual(text, base_dir, str(urdf_path))
                    else:
                        text = simplified_visuals(text, scratch, simplified_faces, base_dir, str(urdf_path))
                    loaded = os.path.join(scratch, "robot.urdf")
                    with open(loaded, "w", encoding="utf-8") as fh:
                        fh.write(text)
                try:
                    self.robot = p.loadURDF(loaded, [0, 0, 0], [0, 0, 0, 1], useFixedBase=True, flags=flags)
                except pybullet.error as exc:
                    raise ValueError("PyBullet cannot load the URDF %s: %s" % (urdf_path, exc)) from None
                self._setup_robot(str(urdf_path), list(joints), base_link, dict(fixed_joint_positions or {}))
                self._setup_world()
                self._setup_collision_filters()
                self._depth_scene = None
                self.camera_renderer = camera_renderer  # what draws the cameras' images (after any fallback)
                self.camera_renderer_fallback = None  # why raster fell back to TinyRenderer (None: it did not)
                if camera_renderer == "raster":
                    try:
                        self._depth_scene = DepthScene.from_client(p._client)
                    except ValueError as exc:  # a shape it does not draw, a mesh it cannot read: PyBullet draws
                        self.camera_renderer = "tinyrenderer"
                        self.camera_renderer_fallback = "%s; PyBullet's TinyRenderer draws the cameras" % exc
            except UrdfError as exc:  # a mesh that cannot be read or simplified: the caller's ValueError
                raise ValueError(str(exc)) from None
            finally:
                if scratch is not None:
                    shutil.rmtree(scratch, ignore_errors=True)
        except Exception:
            self.close()
            raise
        # Bound PyBullet functions for the hot path (BulletClient.__getattr__ is slow).
        cid = self._p._client
        self._cid = cid
        self._reset_states = lambda body, idx, q, v: pybullet.resetJointStatesMultiDof(
            body, idx, q, v, physicsClientId=cid
        )
        self.reset_robot([min(max(0.0, lo), hi) for lo, hi in zip(self.lower, self.upper)])

    @classmethod
    def from_robot(cls, robot, world=None, *, description=None, description_name="robot description", **settings):
        """The simulator of a robot config's robot, its URDF resolved as the simulator node resolves it: the one way to
        build a Simulator of a robot (the node; moverl_sim.settings.simulator_for, hence the env's PyBullet backend,
        the tools and the pictures).

        The URDF text is `description` (the node's /robot_description) when given, else the file robot["urdf"] names
        (moverl_sim.urdf.robot_description: mesh paths resolved against the file's folder). Its mesh paths are then
        rewritten absolute (moverl_sim.urdf.rewrite_mesh_paths: package:// through the ROS packages) and the text is
        written to a scratch folder of this call's, which PyBullet loads and which is removed once the simulator is
        built, or has failed to build (nothing reads it later).

        Args:
            robot: a robot config's robot: mapping (moverl_sim.robot_config): urdf (not read when description is
                given), joints, base_link and, optional, fixed_joint_positions.
            world: a moverl_sim.world.World (None: an empty world).
            description: URDF text to build from instead of the file robot["urdf"].
            description_name: what error messages call `description` (the node: "/robot_description").
            **settings: the keyword arguments of Simulator (physics_hz, control, moving_speed, robot_visuals, ...):
                the node's parameters, or config/sim.yaml's (moverl_sim.settings.sim_settings).

        Returns:
            The Simulator (close() it).

        Raises:
            UrdfError: the URDF file cannot be read, the text is not a URDF, or a mesh it names does not exist.
            ValueError: the simulator cannot be built from it (as Simulator raises).
        """
        if description is None:
            source = robot["urdf"]
            text = robot_description(source)
        else:
            source, text = description_name, description
        text = rewrite_mesh_paths(text, source=source)
        scratch = tempfile.mkdtemp(prefix="moverl_sim_")
        try:
            urdf_path = os.path.join(scratch, "robot.urdf")
            with open(urdf_path, "w", encoding="utf-8") as fh:
                fh.write(text)
            return cls(
                urdf_path, robot["joints"], robot["base_link"], robot.get("fixed_joint_positions"), world, **settings
            )
        finally:
            shutil.rmtree(scratch, ignore_errors=True)

    # ------------------------------------------------------------------ setup
    def _setup_robot(self, urdf_path, joints, base_link, fixed):
        p, robot = self._p, self.robot
        n = p.getNumJoints(robot)
        root_name = p.getBodyInfo(robot)[0].decode()
        self.link_names = {-1: root_name}
        joint_info = {}
        parent_of = {}
        self._joint_type = {}
        for j in range(n):
            info = p.getJointInfo(robot, j)
            name = info[1].decode()
            joint_info[name] = info
            self.link_names[j] = info[12].decode()
            parent_of[j] = info[16]
            self._joint_type[j] = info[2]
        self._link_index = {v: k for k, v in self.link_names.items()}
        movable = [
            name for name, info in joint_info.items() if info[2] in (pybullet.JOINT_REVOLUTE, pybullet.JOINT_PRISMATIC)
        ]
        if not joints:
            raise ValueError("no controlled joints configured")
        if len(set(joints)) != len(joints):
            raise ValueError("controlled joints are listed twice: %s" % joints)
        for name in joints:
            if name not in joint_info:
                raise ValueError("joint %r is not in the URDF; its movable joints are: %s" % (name, ", ".join(movable)))
            if name not in movable:
                raise ValueError(
                    "joint %r is not a revolute or prismatic joint; movable joints are: %s" % (name, ", ".join(movable))
                )
        if base_link not in self._link_index:
            raise ValueError(
                "base link %r is not in the URDF; its links are: %s"
                % (base_link, ", ".join(self.link_names[i] for i in sorted(self.link_names)))
            )
        self.joint_names = tuple(joints)
        self.base_link = base_link
        self.joint_indices = [joint_info[name][0] for name in joints]
        # Position and velocity limits: the URDF's, read once for all Python code (moverl_sim.urdf.JointLimits).
        with open(urdf_path, encoding="utf-8") as fh:
            limits = JointLimits.from_urdf(fh.read(), joints)
        self.lower, self.upper = tuple(limits.lower.tolist()), tuple(limits.upper.tolist())
        self.velocity_limits = tuple(limits.velocity.tolist())
        self._effort = [float(joint_info[name][10]) if joint_info[name][10] > 0 else 1000.0 for name in joints]
        self._lower_np, self._upper_np = limits.lower.copy(), limits.upper.copy()
        self._vmax_np = limits.velocity.copy()
        # The same bounds as Python floats, for prepare's fast path (computed by numpy: the same doubles).
        self._lower_tol = tuple((self._lower_np - POSITION_TOLERANCE).tolist())
        self._upper_tol = tuple((self._upper_np + POSITION_TOLERANCE).tolist())
        self._vmax_tol = tuple((self._vmax_np * (1.0 + VELOCITY_TOLERANCE)).tolist())

        # Uncontrolled movable joints: held at fixed_joint_positions (default 0 clipped to the limits).
        for name in fixed:
            if name not in joint_info:
                raise ValueError(
                    "fixed_joint_positions names joint %r, which is not in the URDF; its "
                    "movable joints are: %s" % (name, ", ".join(movable))
                )
            if name in joints:
                raise ValueError("joint %r is both controlled and in fixed_joint_positions" % name)
        self.fixed_joint_names, self.fixed_joint_indices, fixed_values = [], [], []
        for name in movable:
            if name in joints:
                continue
            info = joint_info[name]
            lo, hi = float(info[8]), float(info[9])
            value = float(fixed.get(name, 0.0))
            if not math.isfinite(value):
                raise ValueError("fixed joint %r: non-finite position %r" % (name, value))
            if hi >= lo:
                if name in fixed and not lo - POSITION_TOLERANCE <= value <= hi + POSITION_TOLERANCE:
                    raise ValueError("fixed joint %r: position %g outside its limits [%g, %g]" % (name, value, lo, hi))
                value = min(max(value, lo), hi)
            self.fixed_joint_names.append(name)
            self.fixed_joint_indices.append(info[0])
            fixed_values.append(value)
        self.fixed_joint_positions = tuple(fixed_values)
        for j, value in zip(self.fixed_joint_indices, fixed_values):
            p.resetJointState(robot, j, value, 0.0)
        if self.control == "dynamic":
            # Motors hold the uncontrolled joints; PyBullet's default velocity motors are replaced.
            if self.fixed_joint_indices:
                p.setJointMotorControlArray(
                    robot,
                    self.fixed_joint_indices,
                    pybullet.POSITION_CONTROL,
                    targetPositions=fixed_values,
                    forces=[max(float(joint_info[nm][10]), 1.0) for nm in self.fixed_joint_names],
                )
        else:
            # Nothing is stepped in kinematic mode, but disable the default motors anyway.
            all_movable = [joint_info[nm][0] for nm in movable]
            p.setJointMotorControlArray(
                robot,
                all_movable,
                pybullet.VELOCITY_CONTROL,
                targetVelocities=[0.0] * len(all_movable),
                forces=[0.0] * len(all_movable),
            )

        # Rigid groups: links joined by fixed joints move together.
        group = {i: i for i in self.link_names}

        def find(i):
            while group[i] != i:
                group[i] = group[group[i]]
                i = group[i]
            return i

        for j in range(n):
            if self._joint_type[j] == pybullet.JOINT_FIXED:
                group[find(j)] = find(parent_of[j])
        self._group = {i: find(i) for i in self.link_names}
        root_group = self._group[-1]
        if self._group[self._link_index[base_link]] != root_group:
            raise ValueError("base link %r is not rigidly attached to the URDF root link %r" % (base_link, root_name))
        self._base_fixed_links = frozenset(i for i in self.link_names if self._group[i] == root_group)
        self._has_geometry = {i: len(p.getCollisionShapeData(robot, i)) > 0 for i in self.link_names}

        # Adjacency: parent/child through fixed joints and geometry-less links.
        group_has_geom = {}
        for i, g in self._group.items():
            group_has_geom[g] = group_has_geom.get(g, False) or self._has_geometry[i]
        group_parent = {}
        for j in range(n):
            if self._joint_type[j] != pybullet.JOINT_FIXED:
                group_parent[self._group[j]] = self._group[parent_of[j]]

        def effective_parent(g):
            q = group_parent.get(g)
            while q is not None and not group_has_geom[q]:
                q = group_parent.get(q)
            return q

        adjacent_groups = set()
        for g in set(self._group.values()):
            q = effective_parent(g)
            if q is not None:
                adjacent_groups.add((g, q))
                adjacent_groups.add((q, g))
        geom_links = [i for i in self.link_names if self._has_geometry[i]]
        self.adjacent_pairs = set()  # (link index, link index) pairs whose contacts are ignored
        for a in geom_links:
            for b in geom_links:
                if a < b:
                    ga, gb = self._group[a], self._group[b]
                    if ga == gb or (ga, gb) in adjacent_groups:
                        self.adjacent_pairs.add((a, b))
                        self.adjacent_pairs.add((b, a))

    def _shapes(self, obj):
        """PyBullet (collision shape, visual shape) of a world object, centred on its frame."""
        p = self._p
        if obj.shape == "box":
            half = [s / 2.0 for s in obj.size]
            col = p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
            vis = p.createVisualShape(pybullet.GEOM_BOX, halfExtents=half, rgbaColor=[0.6, 0.45, 0.3, 1])
        elif obj.shape == "sphere":
            col = p.createCollisionShape(pybullet.GEOM_SPHERE, radius=obj.size[0])
            vis = p.createVisualShape(pybullet.GEOM_SPHERE, radius=obj.size[0], rgbaColor=[0.8, 0.2, 0.2, 1])
        elif obj.shape == "cylinder":
            h, r = obj.size
            col = p.createCollisionShape(pybullet.GEOM_CYLINDER, radius=r, height=h)
            vis = p.createVisualShape(pybullet.GEOM_CYLINDER, radius=r, length=h, rgbaColor=[0.2, 0.4, 0.8, 1])
        else:  # World validation makes this unreachable
            raise ValueError("object %r: unknown shape %r" % (obj.id, obj.shape))
        return col, vis

    def _setup_world(self):
        """One PyBullet body per static object; moving objects that share a motion (the same ObjectMotion value, as
        the parts of a walking person) form ONE multibody: the first of them in the world file is the base, the others
        are links on fixed joints. Their motion is a translation shared by all, so the links' poses relative to the
        base never change, and one reset per substep moves the whole group (instead of one reset and one
        position_at() per object: the human world's person is 8 objects)."""
        p = self._p
        groups = {}  # motion -> its moving objects, in world file order
        for obj in self.world.objects:
            if obj.motion is not None:
                groups.setdefault(obj.motion, []).append(obj)
        self._object_links = {}  # object id -> (body, link index): -1 is a body's base, >= 0 a link of a group
        self._link_object = {}  # (body, link index) -> object id: names the objects of contact points
        self._movers = []  # (body, base object, its quaternion): one per motion, placed at every substep
        for obj in self.world.objects:
            group = groups.get(obj.motion, [obj])
            if obj is not group[0]:
                continue  # a link of its group's body, made with the group's base
            base, links = group[0], group[1:]
            col, vis = self._shapes(base)
            shapes = [self._shapes(o) for o in links]
            # Link frames relative to the base frame (PyBullet places a link at base pose * link pose). The link
            # inertial frames are the link frames and the base's is the base frame (all identity): PyBullet reports
            # and moves a body by its inertial frame, so the frames are exactly where the objects are.
            frames = [_relative_pose(base.xyz, base.quaternion, o.xyz, o.quaternion) for o in links]
            n = len(links)
            body = p.createMultiBody(
                baseMass=0,
                baseCollisionShapeIndex=col,
                baseVisualShapeIndex=vis,
                basePosition=list(base.xyz),
                baseOrientation=list(base.quaternion),
                baseInertialFramePosition=[0, 0, 0],
                linkMasses=[0] * n,
                linkCollisionShapeIndices=[c for c, _ in shapes],
                linkVisualShapeIndices=[v for _, v in shapes],
                linkPositions=[f[0] for f in frames],
                linkOrientations=[f[1] for f in frames],
                linkInertialFramePositions=[[0, 0, 0]] * n,
                linkInertialFrameOrientations=[[0, 0, 0, 1]] * n,
                linkParentIndices=[0] * n,  # 0: the base
                linkJointTypes=[pybullet.JOINT_FIXED] * n,
                linkJointAxis=[[0, 0, 1]] * n,
            )
            # Bullet filters pairs of static colliders (a fixed base) out, but counts links as dynamic: without
            # this, the links would collide with the other obstacles (the person's legs with the table), at a cost
            # in every collision detection and, under dynamic control, as constraints in the solver.
            for link in range(n):
                p.setCollisionFilterGroupMask(body, link, _STATIC_FILTER, _ALL_FILTER ^ _STATIC_FILTER)
            for link, o in enumerate(group, -1):
                self._object_links[o.id] = (body, link)
                self._link_object[(body, link)] = o.id
            if base.motion is not None:
                self._movers.append((body, base, list(base.quaternion)))
        self._place_movers(0.0)

    def place_obstacles(self, t):
        """Put every moving obstacle where it is at motion time t (for pictures: a motion places them as it runs)."""
        self._place_movers(t)

    def _place_movers(self, t):
        """Put every moving obstacle at its pose at motion time t: each group's base object (its links follow)."""
        cid = self._cid if hasattr(self, "_cid") else self._p._client
        t *= self._motion_scale
        for body, obj, quat in self._movers:
            pybullet.resetBasePositionAndOrientation(body, obj.position_at(t), quat, physicsClientId=cid)

    def _setup_collision_filters(self):
        p, robot = self._p, self.robot
        for a, b in self.adjacent_pairs:
            if a < b:
                p.setCollisionFilterPair(robot, robot, a, b, 0)
        for body, link in self._object_links.values():
            for robot_link in self._base_fixed_links:
                p.setCollisionFilterPair(robot, body, robot_link, link, 0)

    def close(self):
        p = getattr(self, "_p", None)
        if p is not None:
            try:
                p.disconnect()
            except pybullet.error:
                pass
            self._p = None

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass

    # ------------------------------------------------------------------ state
    @property
    def client_id(self):
        """PyBullet physicsClientId of this simulator's world (e.g. for moverl_sim.camera rendering)."""
        return self._cid

    @property
    def client(self):
        """The pybullet_utils BulletClient of this simulator's world (None once closed), for what the simulator does
        not do itself: reading link states, AABBs, closest points and camera images, colouring, adding markers or
        probe bodies (moverl_sim.scene_view, the audits). Moving the robot or the obstacles through it bypasses the
        simulator's own state (use reset_robot and place_obstacles): a caller that does so on purpose says why."""
        return self._p

    @property
    def link_index(self):
        """Robot link name -> PyBullet link index (-1: the URDF's root link): link_names inverted, read-only."""
        return MappingProxyType(self._link_index)

    @property
    def base_fixed_links(self):
        """frozenset of the robot's link indices rigidly attached to the base link (they never move; their contacts
        with the world are ignored)."""
        return self._base_fixed_links

    @property
    def object_bodies(self):
        """World object id -> (PyBullet body unique id, link index: -1 the body's base) of the world's objects (the
        objects that move together are one body's base and links)."""
        return dict(self._object_links)

    @property
    def depth_scene(self):
        """The moverl_sim.depth_scene.DepthScene the cameras are drawn from (None when PyBullet's TinyRenderer draws
        them: camera_renderer tinyrenderer, or its fallback)."""
        return self._depth_scene

    def render_depth(self, camera):
        """The z-depth image (height x width, metres; far = no return) a moverl_sim.camera.Camera sees of the world
        now, drawn by this simulator's camera_renderer."""
        if self._depth_scene is not None:
            return self._depth_scene.render(camera)
        return camera.render_depth(self._cid)

    def render_points(self, camera):
        """render_depth back-projected: (height * width) x 3 float32 points in the camera's optical frame."""
        return camera.points_from_depth(self.render_depth(camera))

    def render_segmented(self, camera):
        """(render_depth, what each pixel sees: (link + 1) << 24 | body unique id, -1 for no return), the
        segmentation mask of PyBullet's getCameraImage, from this simulator's camera_renderer."""
        if self._depth_scene is None:
            return camera.render_segmented(self._cid)
        depth, parts = self._depth_scene.render(camera, parts=True)
        codes = np.asarray([((link + 1) << 24) | body for body, link in self._depth_scene.parts] + [-1])
        return depth, codes[parts]  # part -1 indexes the trailing -1

    @property
    def sim_time(self):
        """Simulated seconds since start: substeps / physics_hz."""
        return self._substeps_total / self.physics_hz

    @property
    def motion_time(self):
        """Motion time (s) of the moving obstacles: simulated seconds since the last restart_motions()."""
        return (self._substeps_total - self._motion_epoch) / self.physics_hz

    @property
    def has_moving_obstacles(self):
        return bool(self._movers)

    @property
    def motion_epoch(self):
        """Simulated time (s) at which motion time was 0 (the last restart_motions(), or the start)."""
        return self._motion_epoch / self.physics_hz

    def restart_motions(self):
        """Restart the obstacles' motions: motion time 0 now (sim time is unchanged)."""
        self._motion_epoch = self._substeps_total
        self._place_movers(0.0)

    def obstacle_positions(self, sim_time=None):
        """{object id: (x, y, z)} of every obstacle now, or at simulated time `sim_time` (moving ones where their
        motion, as restarted last, puts them then)."""
        t = (self.motion_time if sim_time is None else sim_time - self.motion_epoch) * self._motion_scale
        return {o.id: o.position_at(t) for o in self.world.objects}

    @property
    def substeps_total(self):
        return self._substeps_total

    @property
    def total_contact_substeps(self):
        return self._total_contact_substeps

    def joint_positions(self):
        """Controlled joint positions, in the configured order."""
        if self._q is not None:  # kinematic mode: the joints are exactly where we put them
            return self._q
        return tuple(s[0] for s in self._p.getJointStates(self.robot, self.joint_indices))

    def joint_velocities(self):
        return tuple(s[1] for s in self._p.getJointStates(self.robot, self.joint_indices))

    def link_poses(self):
        """{link name: ((x, y, z), (qx, qy, qz, qw))} of every URDF link frame in the world frame."""
        p, robot = self._p, self.robot
        pos, orn = p.getBasePositionAndOrientation(robot)
        inertial = p.getDynamicsInfo(robot, -1)
        inv_pos, inv_orn = p.invertTransform(inertial[3], inertial[4])
        bpos, born = p.multiplyTransforms(pos, orn, inv_pos, inv_orn)
        poses = {self.link_names[-1]: (tuple(bpos), _quat_from_pybullet(born))}
        indices = [i for i in self.link_names if i >= 0]
        if indices:
            states = p.getLinkStates(robot, indices, computeForwardKinematics=True)
            for i, s in zip(indices, states):
                poses[self.link_names[i]] = (tuple(s[4]), _quat_from_pybullet(s[5]))
        return poses

    def contacts_now(self):
        """Contacts of the current configuration (runs collision detection; sim time does not advance)."""
        stats = ContactStats()
        self._p.performCollisionDetection()
        pts = pybullet.getContactPoints(self.robot, physicsClientId=self._cid)
        if pts and self._accumulate(pts, stats, moving=False):
            stats.substeps_in_contact = 1
        stats.total_contact_substeps = self._total_contact_substeps
        return stats

    def touched_within(self, seconds):
        """Pairs (robot link, moving object id) that will touch in the current configuration within the next `seconds`
        of simulated time, the obstacles moving as their motions say (at motion_time_scale), the robot held still:
        PyBullet's closest points at instants at most 1 cm of obstacle motion apart (links fixed to the base excluded,
        as for contacts). The obstacles are left where they are now."""
        if seconds <= 0.0 or not self._movers:
            return []
        names, link_object, base_fixed = self.link_names, self._link_object, self._base_fixed_links
        now = self.motion_time
        fastest = max(obj.motion.max_speed for _, obj, _ in self._movers) * self._motion_scale
        n = max(1, int(np.ceil(fastest * seconds / 0.01)))
        pairs = set()
        try:
            for k in range(1, n + 1):
                self._place_movers(now + seconds * k / n)
                for body, _, _ in self._movers:
                    for pt in pybullet.getClosestPoints(self.robot, body, 0.0, physicsClientId=self._cid):
                        name = link_object.get((body, pt[4]))
                        if name is not None and pt[3] not in base_fixed and pt[8] <= 0.0:
                            pairs.add((names[pt[3]], name))
        finally:
            self._place_movers(now)
        return sorted(pairs)

    # ------------------------------------------------------------------ validation
    def _check_positions(self, q, what):
        bad = ~((q >= self._lower_np - POSITION_TOLERANCE) & (q <= self._upper_np + POSITION_TOLERANCE))
        if bad.any():
            j = int(np.argmax(bad))
            raise LimitViolation(
                "%s: joint %s = %.6g outside its limits [%.6g, %.6g]"
                % (what, self.joint_names[j], q[j], self.lower[j], self.upper[j])
            )

    def reset_robot(self, q):
        """Teleport the controlled joints to q (velocity 0). No contacts counted, sim time unchanged."""
        try:
            arr = np.asarray(q, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise InvalidTrajectory("positions must be numbers, got %r" % (q,)) from None
        n = len(self.joint_indices)
        if arr.shape[0] != n:
            raise InvalidTrajectory(
                "expected %d positions (%s), got %d" % (n, ", ".join(self.joint_names), arr.shape[0])
            )
        if not np.all(np.isfinite(arr)):
            raise InvalidTrajectory("positions contain NaN or inf: %s" % arr.tolist())
        self._check_positions(arr, "reset")
        arr = np.minimum(np.maximum(arr, self._lower_np), self._upper_np)
        values = arr[:, None].tolist()
        self._q = None
        self._reset_states(self.robot, self.joint_indices, values, [[0.0]] * n)
        if self.control == "kinematic":
            self._q = tuple(arr.tolist())
        else:
            self._p.setJointMotorControlArray(
                self.robot,
                self.joint_indices,
                pybullet.POSITION_CONTROL,
                targetPositions=arr.tolist(),
                forces=self._effort,
            )
        return self.joint_positions()

    def prepare(self, times, positions, path_tolerance=None, velocities=None, accelerations=None):
        """Validate a trajectory and sample it at every physics substep. Nothing moves.

        times: time_from_start (s) of each point, strictly increasing, >= 0.
        positions: one row per point, one column per controlled joint.
        A first point at t=0 must equal the current state clamped into the joint limits (within 1e-4; a dynamic robot
        may stand a little beyond a limit); without one the motion starts from the current state.
        path_tolerance: per joint, the largest |measured - setpoint| allowed while the motion runs (0 or None: no
        bound); exceeding it stops the robot where it is (dynamic control only: kinematic control is exact).
        velocities, accelerations: per point (or None). When every point has them, dynamic control follows the cubic
        (velocities) or quintic (both) spline through the points, as joint_trajectory_controller does; kinematic
        control and position-only trajectories move linearly between points (on the same segments when the points
        are samples of straight moves).
        Raises InvalidTrajectory or LimitViolation.
        """
        if self.control == "kinematic":
            motion = self._prepare_linear(times, positions, path_tolerance)
            if motion is not None:
                return motion
        return self._prepare_checked(times, positions, path_tolerance, velocities, accelerations)

    def _prepare_linear(self, times, positions, path_tolerance=None):
        """prepare() of a valid trajectory for kinematic control, checked in plain Python: _prepare_checked's checks
        (the same comparisons on the same doubles) at a fraction of their numpy cost for the few points and joints of
        an env step (numpy's per-call overhead dominated the simulator's step); both sample with
        moverl_sim.trajectory. None when anything is off (a bad value, a limit, a start away from the current
        state): _prepare_checked then names it."""
        n = len(self.joint_indices)
        isfinite = math.isfinite
        try:
            t = [float(x) for x in times]
            P = [[float(x) for x in row] for row in positions]
        except (TypeError, ValueError):
            return None
        m = len(t)
        if m == 0 or len(P) != m or any(len(row) != n for row in P):
            return None
        if path_tolerance is not None and len(path_tolerance) > 0:  # valid, then unused: kinematic control is exact
            try:
                tolerance = [float(x) for x in path_tolerance]
            except (TypeError, ValueError):
                return None
            if len(tolerance) != n or not isfinite(sum(tolerance)) or min(tolerance) < 0:
                return None
        if not isfinite(sum(t)) or t[0] < 0 or any(t[i + 1] - t[i] <= 0 for i in range(m - 1)):
            return None  # (a finite sum: every value is finite)
        lo, hi = self._lower_tol, self._upper_tol
        for row in P:
            if not isfinite(sum(row)) or any(x < a or x > b for x, a, b in zip(row, lo, hi)):
                return None
        lower, upper = self.lower, self.upper
        current = [min(max(x, a), b) for x, a, b in zip(self.joint_positions(), lower, upper)]
        if t[0] == 0.0:
            if max(abs(x - c) for x, c in zip(P[0], current)) > START_TOLERANCE:
                return None
            P[0] = current
        else:
            t.insert(0, 0.0)
            P.insert(0, current)
        P = [[min(max(x, a), b) for x, a, b in zip(row, lower, upper)] for row in P]
        nsub = substep_count(t[-1], self.physics_hz)
        if nsub == 0:
            return Motion([], [], tuple(P[-1]), None)
        vel = segment_velocities(t, P)
        vmax = self._vmax_tol
        if any(abs(v) > limit for row in vel for v, limit in zip(row, vmax)):
            return None
        targets, velocities = sample_linear(t, P, vel, self.dt, nsub)
        return Motion(targets, velocities, tuple(P[-1]), None)

    def _prepare_checked(self, times, positions, path_tolerance=None, velocities=None, accelerations=None):
        """prepare() for every trajectory, with the check of each value and the message naming what is wrong."""
        n = len(self.joint_indices)
        try:
            t = np.asarray(times, dtype=float).reshape(-1)
            P = np.asarray(positions, dtype=float)
        except (TypeError, ValueError):
            raise InvalidTrajectory("times and positions must be numbers") from None
        if t.shape[0] == 0:
            raise InvalidTrajectory("empty trajectory")
        if P.ndim != 2 or P.shape[0] != t.shape[0] or P.shape[1] != n:
            raise InvalidTrajectory(
                "expected %d points x %d joints (%s), got positions of shape %s"
                % (t.shape[0], n, ", ".join(self.joint_names), P.shape)
            )
        # A finite sum means every value is finite (a NaN or inf makes it NaN or inf): one reduction on the hot path.
        if not math.isfinite(t.sum()) and not np.all(np.isfinite(t)):
            raise InvalidTrajectory("times contain NaN or inf")
        if not math.isfinite(P.sum()) and not np.all(np.isfinite(P)):
            i = int(np.argmax(~np.all(np.isfinite(P), axis=1)))
            raise InvalidTrajectory("point %d contains NaN or inf: %s" % (i, P[i].tolist()))
        if t[0] < 0:
            raise InvalidTrajectory("negative time_from_start %g at point 0" % t[0])
        if t.shape[0] > 1:
            dts = t[1:] - t[:-1]
            if dts.min() <= 0:
                i = int(np.argmax(dts <= 0))
                raise InvalidTrajectory(
                    "times must be strictly increasing: point %d at %g s, point %d at %g s" % (i, t[i], i + 1, t[i + 1])
                )
        if (P < self._lower_np - POSITION_TOLERANCE).any() or (P > self._upper_np + POSITION_TOLERANCE).any():
            bad = (P < self._lower_np - POSITION_TOLERANCE) | (P > self._upper_np + POSITION_TOLERANCE)
            i = int(np.argmax(bad.any(axis=1)))
            self._check_positions(P[i], "point %d" % i)
        current = np.minimum(np.maximum(np.array(self.joint_positions()), self._lower_np), self._upper_np)
        tolerance = None
        if path_tolerance is not None and len(path_tolerance) > 0:
            tolerance = np.asarray(path_tolerance, dtype=float).reshape(-1)
            if tolerance.shape != (n,) or not np.all(np.isfinite(tolerance)) or np.any(tolerance < 0):
                raise InvalidTrajectory(
                    "path_tolerance must have %d finite values >= 0, got %s" % (n, tolerance.tolist())
                )
            if not np.any(tolerance > 0) or self.control == "kinematic":
                tolerance = None
        if t[0] == 0.0:
            dev = np.abs(P[0] - current)
            if dev.max() > START_TOLERANCE:
                j = int(np.argmax(dev))
                raise InvalidTrajectory(
                    "the point at t=0 must be the current state: joint %s is %.6g, "
                    "currently %.6g" % (self.joint_names[j], P[0, j], current[j])
                )
            P = P.copy()
            P[0] = current
        else:
            t = np.concatenate(([0.0], t))
            P = np.vstack((current, P))
        P = np.minimum(np.maximum(P, self._lower_np), self._upper_np)
        T = float(t[-1])
        nsub = substep_count(T, self.physics_hz)
        if nsub == 0:
            return Motion([], [], tuple(P[-1].tolist()), tolerance)
        times, points = t.tolist(), P.tolist()
        rates = segment_velocities(times, points)
        vel = np.array(rates)
        over = np.abs(vel) > self._vmax_np * (1.0 + VELOCITY_TOLERANCE)
        if over.max():
            s, j = np.unravel_index(int(np.argmax(over)), over.shape)
            raise LimitViolation(
                "segment %.3g s -> %.3g s: joint %s moves at %.6g rad/s, above its velocity "
                "limit %.6g" % (t[s], t[s + 1], self.joint_names[j], abs(vel[s, j]), self.velocity_limits[j])
            )
        V = A = setpoints = None
        if self.control == "dynamic":
            V, A = self._spline_data(velocities, accelerations, len(positions), t.shape[0], n)
        if V is None:  # linear between the points
            targets, velocity = sample_linear(times, points, rates, self.dt, nsub)
        if self.control == "dynamic":
            ts = np.minimum(np.arange(1, nsub + 1, dtype=float) * self.dt, T)
            if V is not None:  # the controller's spline through the points
                q, _ = spline_at(t, P, V, A, ts)
                q[-1] = P[-1]
                targets = q[:, :, None].tolist()
            # Motor setpoints: the trajectory at each substep's start (see Motion.setpoints).
            sp, sv = spline_at(t, P, V, A, np.concatenate(([0.0], ts[:-1])))
            setpoints = sp.tolist()
            if V is not None:
                velocity = sv[:, :, None].tolist()
        return Motion(targets, velocity, tuple(P[-1].tolist()), tolerance, setpoints=setpoints)

    @staticmethod
    def _spline_data(velocities, accelerations, points, rows, n):
        """Velocities / accelerations as arrays with one row per trajectory row (a prepended current state is at
        rest), or None when not every point has them."""

        def table(values):
            if values is None or len(values) != points or any(len(r) != n for r in values):
                return None
            arr = np.asarray(values, dtype=float)
            if not np.all(np.isfinite(arr)):
                raise InvalidTrajectory("velocities / accelerations contain NaN or inf")
            return np.vstack((np.zeros((1, n)), arr)) if rows == points + 1 else arr

        V = table(velocities)
        return V, (table(accelerations) if V is not None else None)

    # ------------------------------------------------------------------ execution
    def execute(self, times, positions):
        """Validate and run a whole trajectory. Returns ExecutionResult(positions, contacts)."""
        motion = self.prepare(times, positions)
        self.advance(motion, motion.n)
        return self.finish(motion)

    def advance(self, motion, max_substeps):
        """Run up to max_substeps substeps of motion; returns how many ran."""
        robot, idx, cid = self.robot, self.joint_indices, self._cid
        self._q = None
        reset = pybullet.resetJointStatesMultiDof  # (called directly: a wrapper's frame per substep costs)
        get_contacts = pybullet.getContactPoints
        kinematic = self.control == "kinematic"
        if kinematic:
            detect = pybullet.performCollisionDetection
        else:
            step = pybullet.stepSimulation
            motor = pybullet.setJointMotorControlArray
            mode, effort = pybullet.POSITION_CONTROL, self._effort
            if motion.setpoints is None:
                motion.setpoints = [[v[0] for v in t] for t in motion.targets]
        accumulate = self._accumulate
        moving_speed = self._moving_speed
        stats = motion.stats
        targets, vels, setpoints = motion.targets, motion.velocities, motion.setpoints
        k0 = motion.k
        k1 = min(motion.n, k0 + max(0, int(max_substeps)))
        in_contact = 0
        movers = self._movers
        if movers:
            place = self._place_movers
            t_base = self._substeps_total - self._motion_epoch - k0 + 1  # substep k runs at motion time (t_base + k)/hz
            hz = self.physics_hz
        tolerance = motion.path_tolerance
        k = k0
        while k < k1:
            if movers:
                place((t_base + k) / hz)
            if kinematic:
                reset(robot, idx, targets[k], vels[k], physicsClientId=cid)
                detect(physicsClientId=cid)
            else:
                motor(
                    robot,
                    idx,
                    mode,
                    targetPositions=setpoints[k],
                    targetVelocities=[v[0] for v in vels[k]],
                    forces=effort,
                    physicsClientId=cid,
                )
                step(physicsClientId=cid)
            pts = get_contacts(robot, physicsClientId=cid)
            if pts and accumulate(pts, stats, max(abs(v[0]) for v in vels[k]) > moving_speed):
                in_contact += 1
            k += 1
            if tolerance is not None:
                err = np.abs(np.array(self.joint_positions()) - np.array([v[0] for v in targets[k - 1]]))
                if np.any(err > tolerance):
                    j = int(np.argmax(err - tolerance))
                    motion.aborted = (
                        "joint %s left its path tolerance: %.6g from its setpoint, tolerance %.6g "
                        "(stopped %.3f s into the motion)"
                        % (self.joint_names[j], err[j], tolerance[j], k / self.physics_hz)
                    )
                    break
        k1 = k
        ran = k1 - k0
        motion.k = k1
        stats.substeps += ran
        stats.substeps_in_contact += in_contact
        self._substeps_total += ran
        self._total_contact_substeps += in_contact
        stats.total_contact_substeps = self._total_contact_substeps
        return ran

    def finish(self, motion):
        """End a motion: in kinematic mode the robot stops exactly at the last setpoint."""
        if self.control == "kinematic":
            final = [[v] for v in motion.final]
            self._reset_states(self.robot, self.joint_indices, final, [[0.0]] * len(final))
            self._q = tuple(motion.final)
        else:
            # An aborted motion stops where the robot is; a finished one holds its last setpoint.
            hold = list(self.joint_positions()) if motion.aborted else list(motion.final)
            self._p.setJointMotorControlArray(
                self.robot, self.joint_indices, pybullet.POSITION_CONTROL, targetPositions=hold, forces=self._effort
            )
        motion.stats.total_contact_substeps = self._total_contact_substeps
        return ExecutionResult(self.joint_positions(), motion.stats)

    def stop(self):
        """Hold where the robot is now (dynamic control: the motors' setpoint becomes the measured position)."""
        if self.control == "dynamic":
            self._p.setJointMotorControlArray(
                self.robot,
                self.joint_indices,
                pybullet.POSITION_CONTROL,
                targetPositions=list(self.joint_positions()),
                forces=self._effort,
            )
        return self.joint_positions()

    def servo(self, q, v, stats, q_end=None):
        """One physics substep of a controller that computes its setpoint every substep (moverl_sim.follow): q, v
        are the trajectory at the substep's start, q_end at its end (kinematic control puts the robot there exactly;
        dynamic control's motors track (q, v)). Contacts are added to stats."""
        q_end = q if q_end is None else q_end
        motion = Motion([[[x] for x in q_end]], [[[x] for x in v]], tuple(q_end), stats=stats, setpoints=[list(q)])
        self.advance(motion, 1)
        if self.control == "kinematic":
            self._q = tuple(float(x) for x in q_end)
        return motion

    def hold(self, substeps=1, stats=None):
        """Let time pass with the robot holding still (realtime idling). With stats, contacts are detected at every
        substep and added to it (ground truth while idle: a moving obstacle may come to the robot); without, none."""
        substeps = int(substeps)
        if substeps <= 0:
            return
        if self.control == "dynamic" or stats is not None:
            cid, robot = self._cid, self.robot
            in_contact = 0
            for i in range(substeps):
                if self._movers:
                    self._place_movers((self._substeps_total - self._motion_epoch + i + 1) / self.physics_hz)
                if self.control == "dynamic":
                    pybullet.stepSimulation(physicsClientId=cid)
                else:
                    pybullet.performCollisionDetection(physicsClientId=cid)
                if stats is not None:
                    pts = pybullet.getContactPoints(robot, physicsClientId=cid)
                    if pts and self._accumulate(pts, stats, moving=False):
                        in_contact += 1
            if stats is not None:
                stats.substeps += substeps
                stats.substeps_in_contact += in_contact
                self._total_contact_substeps += in_contact
                stats.total_contact_substeps = self._total_contact_substeps
        self._substeps_total += substeps
        if self._movers:
            self._place_movers(self.motion_time)

    def _accumulate(self, pts, stats, moving):
        """Record penetrating contacts (as touched while the robot moved, or rested); True when at least one
        counted."""
        robot = self.robot
        names = self.link_names
        link_object = self._link_object
        adjacent = self.adjacent_pairs
        base_fixed = self._base_fixed_links
        found = False
        for pt in pts:
            dist = pt[8]
            if dist >= 0.0:
                continue
            a, b, la, lb = pt[1], pt[2], pt[3], pt[4]
            if a == robot and b == robot:
                if la == lb or (la, lb) in adjacent:
                    continue
                na, nb = names[la], names[lb]
                key = (na, nb) if na <= nb else (nb, na)
                pairs = stats.self_pairs
            else:
                if a != robot:
                    a, b, la, lb = b, a, lb, la
                obj = link_object.get((b, lb))
                if obj is None or la in base_fixed:
                    continue
                key = (names[la], obj)
                pairs = stats.world_pairs
            depth = -dist
            if depth > pairs.get(key, 0.0):
                pairs[key] = depth
            (stats.moving_pairs if moving else stats.resting_pairs).add(key)
            found = True
        return found
