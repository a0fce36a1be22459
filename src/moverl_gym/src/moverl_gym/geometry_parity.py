"""Geometry parity: does the planning scene's collision shape of every link contain PyBullet's? (issue #15; no ROS)

PyBullet's shape of a link (what the simulator's contacts come from) is read from PyBullet itself: the hull vertices
of its convex pieces (getMeshData: meshes and the 32-sided hulls it makes of cylinders), the corners of its boxes and
points of its spheres (getCollisionShapeData), plus points inside its pieces (random convex combinations of nearby
vertices that PyBullet's own closest-point query puts inside the link). The scene's shape is asked through
`scene_geometry`, the ROS-free command-line view of the planning scene's core (the same FCL objects the checker uses):

* contained: every PyBullet point lies within the scene's shape of the same link (a point outside is a collision the
  scene can miss; how far outside is measured too), up to PyBullet's own rounding of hull vertices (QUANTUM);
* tight: every point of the scene's shape (its hull points, primitive surface points and points inside its pieces)
  lies within PyBullet's shape, its 1 mm collision margin included, plus 1 mm (PyBullet rounds box corners): the
  scene is no looser than it must be (e.g. no hull of a whole multi-piece OBJ, no COLLADA turned by its up axis);
* frames: the scene's link frames equal PyBullet's (URDF link frames, through the inertial frames PyBullet uses).

PyBullet keeps a 1 mm margin around its convex hulls (contacts count from there): the world padding (1 cm) and the
self padding (4 mm per link) cover it. `compare` returns a report per link; `format_report` prints it.
"""

from __future__ import annotations

import json
import math
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

MARGIN = 0.001  # PyBullet's collision margin around convex hulls (gUrdfDefaultCollisionMargin)
PROBE = 1e-4  # radius of the probe sphere used to ask PyBullet whether a point is inside a link
# PyBullet's hull computer (btConvexHullComputer) snaps a piece's points to a grid of 1/10216 of its bounding box per
# axis, so its hull vertices may lie up to sqrt(3) * extent / 10216 outside the exact hull (0.05 mm for a 30 cm piece,
# far inside the paddings). A PyBullet point may lie this far (plus 1e-6 m) outside the scene's shape of its link.
QUANTUM = 1.0 / 10216
# A scene point may lie this far outside PyBullet's shape (its margin included): PyBullet rounds the edges and corners
# of boxes by its margin, which takes (sqrt(3) - 1) * 1 mm = 0.73 mm off the corners.
TIGHT_TOL = 1e-3
OUTSIDE_STEPS = (1e-5, 1e-4, 1e-3, 1e-2, 1e-1)  # tolerances tried to tell how far outside a PyBullet point is


class GeometryParityError(RuntimeError):
    """The scene_geometry tool is missing or failed."""


def scene_geometry_binary() -> str:
    """Path of the scene_geometry executable of the catkin workspace (devel or install space)."""
    from .paths import workspace_binary

    try:
        return workspace_binary("moverl_planning_scene", "scene_geometry")
    except FileNotFoundError as exc:
        raise GeometryParityError(str(exc)) from None


def urdf_movable_joints(urdf_path) -> list[str]:
    """Revolute and prismatic joints of a URDF, in file order (the fixtures control all of them)."""
    root = ET.parse(urdf_path).getroot()
    return [j.get("name") for j in root.findall("joint") if j.get("type") in ("revolute", "prismatic")]


def _run_scene(urdf_path, joints, base_link, fixed, commands: list[str]) -> list[str]:
    cmd = [scene_geometry_binary(), "--urdf", str(urdf_path), "--joints", ",".join(joints)]
    if base_link:
        cmd += ["--base-link", base_link]
    if fixed:
        cmd += ["--fixed", ",".join(f"{k}={v!r}" for k, v in fixed.items())]
    proc = subprocess.run(cmd, input="\n".join(commands) + "\n", capture_output=True, text=True, timeout=600)
    if proc.returncode != 0:
        raise GeometryParityError(f"scene_geometry failed ({proc.returncode}): {proc.stderr.strip()[-2000:]}")
    lines = proc.stdout.splitlines()
    if len(lines) != len(commands):
        raise GeometryParityError(f"scene_geometry answered {len(lines)} lines to {len(commands)} commands")
    bad = [(c, a) for c, a in zip(commands, lines) if a.startswith("error")]
    if bad:
        raise GeometryParityError(f"scene_geometry: {bad[0][1]} (to '{bad[0][0]}')")
    return lines


def _matrix(pos, orn) -> np.ndarray:
    import pybullet

    m = np.eye(4)
    m[:3, :3] = np.array(pybullet.getMatrixFromQuaternion(orn)).reshape(3, 3)
    m[:3, 3] = pos
    return m


def _apply(m: np.ndarray, pts) -> np.ndarray:
    pts = np.asarray(pts, dtype=float).reshape(-1, 3)
    return pts @ m[:3, :3].T + m[:3, 3]


def _interior(points: np.ndarray, rng, count: int, k: int = 8) -> np.ndarray:
    """Random convex combinations of a random point and its k nearest neighbours (candidates inside a piece)."""
    if len(points) < 2 or count <= 0:
        return np.zeros((0, 3))
    out = []
    for _ in range(count):
        i = rng.integers(len(points))
        d = np.linalg.norm(points - points[i], axis=1)
        near = points[np.argsort(d)[: k + 1]]
        w = rng.dirichlet(np.ones(len(near)))
        out.append(w @ near)
    return np.array(out)


def _sphere_points(center, radius) -> np.ndarray:
    dirs = [v for v in np.array(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1])).T.reshape(-1, 3) if v.any()]
    return np.array([center + radius * v / np.linalg.norm(v) for v in dirs])


class _Bullet:
    """PyBullet's view: the robot loaded as moverl_sim loads it, and a probe sphere for inside/outside queries."""

    def __init__(self, urdf_path, joints, base_link, fixed):
        import pybullet
        from pybullet_utils import bullet_client

        self.p = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
        p = self.p
        flags = pybullet.URDF_USE_SELF_COLLISION | pybullet.URDF_USE_SELF_COLLISION_EXCLUDE_PARENT
        self.robot = p.loadURDF(str(urdf_path), [0, 0, 0], [0, 0, 0, 1], useFixedBase=True, flags=flags)
        self.names = {-1: p.getBodyInfo(self.robot)[0].decode()}
        joint_index = {}
        for j in range(p.getNumJoints(self.robot)):
            info = p.getJointInfo(self.robot, j)
            self.names[j] = info[12].decode()
            joint_index[info[1].decode()] = j
        self.index = {v: k for k, v in self.names.items()}
        self.joints = [joint_index[j] for j in joints]
        for name, value in (fixed or {}).items():
            p.resetJointState(self.robot, joint_index[name], value)
        self.base = self.index[base_link] if base_link else -1
        shape = p.createCollisionShape(pybullet.GEOM_SPHERE, radius=PROBE)
        self.probe = p.createMultiBody(baseMass=0, baseCollisionShapeIndex=shape, basePosition=[0, 0, 10])

    def close(self):
        self.p.disconnect()

    def set(self, q):
        for j, v in zip(self.joints, q):
            self.p.resetJointState(self.robot, j, float(v))

    def com_frame(self, link) -> np.ndarray:
        if link == -1:
            return _matrix(*self.p.getBasePositionAndOrientation(self.robot))
        s = self.p.getLinkState(self.robot, link, computeForwardKinematics=True)
        return _matrix(s[0], s[1])

    def link_frame(self, link) -> np.ndarray:
        """The URDF frame of a link in the world."""
        if link == -1:
            info = self.p.getDynamicsInfo(self.robot, -1)
            return self.com_frame(-1) @ np.linalg.inv(_matrix(info[3], info[4]))
        s = self.p.getLinkState(self.robot, link, computeForwardKinematics=True)
        return _matrix(s[4], s[5])

    def shape_points(self, link) -> np.ndarray:
        """PyBullet's hull vertices, box corners and sphere points of a link (world frame)."""
        from moverl_sim.core import collision_shape

        pts, spheres = collision_shape(self.p, self.robot, link)
        return np.vstack([pts] + [_sphere_points(c, r) for c, r in spheres])

    def distance(self, link, x) -> float:
        """Signed distance from the probe at x to the link's shape as PyBullet sees it (margin included; inf: none)."""
        self.p.resetBasePositionAndOrientation(self.probe, [float(v) for v in x], [0, 0, 0, 1])
        pts = self.p.getClosestPoints(self.robot, self.probe, 0.05, linkIndexA=link, linkIndexB=-1)
        return min((pt[8] for pt in pts), default=math.inf)


def _scene_points(geoms, rng, interior: int) -> np.ndarray:
    """Points of the scene's shape of a link (link frame): hull points, primitive surface points, interiors."""
    pts = []
    for g in geoms:
        origin = np.vstack([np.array(g["origin"]).reshape(3, 4), [0, 0, 0, 1]])
        d = g["dims"]
        if g["type"] == "mesh":
            local = np.array(g["vertices"]).reshape(-1, 3)
        elif g["type"] == "box":
            local = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * np.array(d) / 2
        elif g["type"] == "sphere":
            local = _sphere_points(np.zeros(3), d[0])
        elif g["type"] == "cylinder":
            a = np.linspace(0, 2 * math.pi, 64, endpoint=False)
            ring = np.stack([d[0] * np.cos(a), d[0] * np.sin(a), np.zeros_like(a)], axis=1)
            local = np.vstack([ring + [0, 0, d[1] / 2], ring - [0, 0, d[1] / 2]])
        else:
            continue
        pts.append(_apply(origin, np.vstack([local, _interior(local, rng, interior)])))
    return np.vstack(pts) if pts else np.zeros((0, 3))


def compare(
    urdf_path, joints=None, base_link=None, fixed=None, configs: int = 3, interior: int = 100, seed: int = 0
) -> dict:
    """Compares PyBullet's and the scene's shape of every link at `configs` random configurations (the first one
    all zeros, clipped to the limits). joints: controlled joints (default: every revolute/prismatic joint);
    fixed: positions of the other movable joints. Returns {"links": {name: {...}}, "contained": bool, ...}."""
    urdf_path = Path(urdf_path).resolve()
    joints = list(joints or urdf_movable_joints(urdf_path))
    rng = np.random.default_rng(seed)
    bullet = _Bullet(urdf_path, joints, base_link, fixed)
    try:
        p, robot = bullet.p, bullet.robot
        lower = np.array([p.getJointInfo(robot, j)[8] for j in bullet.joints])
        upper = np.array([p.getJointInfo(robot, j)[9] for j in bullet.joints])
        continuous = upper < lower  # PyBullet reports continuous joints as [0, -1]
        lower[continuous], upper[continuous] = -math.pi, math.pi
        Q = [np.clip(np.zeros(len(joints)), lower, upper)]
        Q += [rng.uniform(lower, upper) for _ in range(configs - 1)]
        links = [k for k in sorted(bullet.names)]
        # The scene's geometry (link frames) and its link poses (base frame) at every configuration.
        cmds = ["geometry"]
        for q in Q:
            cmds.append("q " + " ".join(repr(float(v)) for v in q))
            cmds += [f"pose {bullet.names[k]}" for k in links]
        answers = _run_scene(urdf_path, joints, base_link, fixed, cmds)
        geometry = json.loads(answers[0])
        scene_pose, a = [], 1
        for _ in Q:
            a += 1
            poses = {}
            for k in links:
                v = [float(x) for x in answers[a].split()]
                m = np.eye(4)
                m[:3, :3] = np.array(v[:9]).reshape(3, 3)
                m[:3, 3] = v[9:]
                poses[k] = m
                a += 1
            scene_pose.append(poses)
        report = {
            k: {
                "pybullet_points": 0,
                "outside": 0,
                "outside_by_m": 0.0,
                "tolerance_m": 0.0,
                "scene_points": 0,
                "scene_excess_m": 0.0,
                "fk_error_m": 0.0,
                "pybullet_shape": False,
                "scene_shape": bullet.names[k] in geometry,
            }
            for k in links
        }
        queries = []  # (config, link, point in the base frame)
        for c, q in enumerate(Q):
            bullet.set(q)
            world_to_base = np.linalg.inv(bullet.link_frame(bullet.base))
            for k in links:
                r = report[k]
                frame = world_to_base @ bullet.link_frame(k)
                r["fk_error_m"] = max(r["fk_error_m"], float(np.abs(frame - scene_pose[c][k])[:3].max()))
                pts = bullet.shape_points(k)
                if len(pts) == 0 and not p.getCollisionShapeData(robot, k):
                    continue
                r["pybullet_shape"] = True
                extent = float(np.max(pts.max(axis=0) - pts.min(axis=0))) if len(pts) else 0.0
                r["tolerance_m"] = max(r["tolerance_m"], math.sqrt(3) * QUANTUM * extent + 1e-6)
                inside = [x for x in _interior(pts, rng, interior) if bullet.distance(k, x) < -(MARGIN + PROBE) - 1e-5]
                pts = np.vstack([pts, np.array(inside).reshape(-1, 3)])
                r["pybullet_points"] += len(pts)
                queries += [(c, k, x) for x in _apply(world_to_base, pts)]
                # Tight: the scene's points against PyBullet's shape.
                geoms = geometry.get(bullet.names[k])
                if geoms:
                    spts = _apply(bullet.link_frame(k), _scene_points(geoms, rng, interior // 4 + 1))
                    r["scene_points"] += len(spts)
                    for x in spts:
                        # distance beyond PyBullet's shape (margin included; negative inside)
                        r["scene_excess_m"] = max(r["scene_excess_m"], bullet.distance(k, x) + PROBE)

        # Contained: every PyBullet point inside the scene's shape of its link.
        def ask(tol, items):  # tol None: each link's tolerance
            cmds, last = [], None
            for c, k, x in items:
                if c != last:
                    cmds.append("q " + " ".join(repr(float(v)) for v in Q[c]))
                    last = c
                t = report[k]["tolerance_m"] if tol is None else max(tol, report[k]["tolerance_m"])
                cmds.append(f"in {bullet.names[k]} {t!r} {float(x[0])!r} {float(x[1])!r} {float(x[2])!r}")
            ans = [line for line in _run_scene(urdf_path, joints, base_link, fixed, cmds) if line != "ok"]
            return [line == "1" for line in ans]

        outside = [item for item, ok in zip(queries, ask(None, queries)) if not ok]
        for item in outside:
            report[item[1]]["outside"] += 1
        for tol in OUTSIDE_STEPS:  # how far outside: the smallest tolerance that takes each point in
            if not outside:
                break
            still = []
            for item, ok in zip(outside, ask(tol, outside)):
                r = report[item[1]]
                if ok:
                    r["outside_by_m"] = max(r["outside_by_m"], tol)
                else:
                    still.append(item)
            outside = still
        for item in outside:
            report[item[1]]["outside_by_m"] = math.inf
    finally:
        bullet.close()
    named = {bullet.names[k]: v for k, v in report.items() if v["pybullet_shape"] or v["scene_shape"]}
    return {
        "urdf": str(urdf_path),
        "configs": len(Q),
        "links": named,
        "contained": all(v["outside"] == 0 for v in named.values()),
        "tight": all(v["scene_excess_m"] <= TIGHT_TOL for v in named.values() if v["pybullet_shape"]),
        "fk_error_m": max((v["fk_error_m"] for v in named.values()), default=0.0),
    }


def format_report(rep: dict) -> str:
    """A table: one line per link with collision geometry."""
    head = (
        f"{'link':28s} {'PyBullet pts':>12s} {'outside scene':>13s} {'by up to':>9s} {'allowed':>9s} "
        f"{'scene pts':>9s} "
        f"{'scene beyond PyBullet':>21s} {'FK error':>9s}"
    )
    lines = [head, "-" * len(head)]
    for name, r in rep["links"].items():
        by = "-" if r["outside"] == 0 else f"{1e3 * r['outside_by_m']:.3g} mm"
        if not r["pybullet_shape"]:
            beyond = "(PyBullet: none)"
        else:
            beyond = f"{1e3 * max(0.0, r['scene_excess_m']):.2f} mm"
        allowed = f"{1e3 * r['tolerance_m']:.3f} mm"
        lines.append(
            f"{name:28s} {r['pybullet_points']:12d} {r['outside']:13d} {by:>9s} {allowed:>9s} "
            f"{r['scene_points']:9d} "
            f"{beyond:>21s} {1e3 * r['fk_error_m']:7.4f} mm"
        )
    lines.append(
        f"contained (every PyBullet point inside the scene's shape, up to PyBullet's hull rounding): "
        f"{rep['contained']}; "
        f"tight (scene within PyBullet's shape, margin included, + {1e3 * TIGHT_TOL:g} mm): "
        f"{rep['tight']}; {rep['configs']} configurations"
    )
    return "\n".join(lines)
