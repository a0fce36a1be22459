"""Pictures of a robot in a MoveRL world, offscreen (PyBullet DIRECT + TinyRenderer: no display, no GPU).

The robot and the world are built exactly as the simulator builds them (moverl_sim.core.Simulator, from the robot
config and the world file), so a picture shows what the shield and the simulator know; the goal is a red sphere (visual
only). Used by the env's render_mode="rgb_array" (in the env's process, from the state it observes: it works against a
real robot too) and by the render_world tool (docs/worlds). The camera framing lives in config/render.yaml.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np
import pybullet
import yaml

from .settings import _ROOT, simulator_for

GOAL_RADIUS = 0.025  # m, the goal marker
REACH = 0.9  # metres around the robot base that the camera always shows


@dataclass(frozen=True)
class ViewSettings:
    """The picture's size and the camera's direction (config/render.yaml documents each)."""

    width: int
    height: int
    yaw: float  # degrees, 0: looking along +x
    pitch: float  # degrees, negative: from above
    fov: float  # vertical field of view, degrees

    @classmethod
    def from_yaml(cls, path: str | None = None, **overrides) -> "ViewSettings":
        with open(path or os.path.join(_ROOT, "config", "render.yaml"), encoding="utf-8") as f:
            data = yaml.safe_load(f) or {}
        data.update({k: v for k, v in overrides.items() if v is not None})
        s = cls(int(data["width"]), int(data["height"]), float(data["yaw"]), float(data["pitch"]), float(data["fov"]))
        if s.width <= 0 or s.height <= 0 or not 0 < s.fov < 180:
            raise ValueError(f"render settings: width and height must be positive, 0 < fov < 180; got {s}")
        return s


def object_colour(obj) -> list:
    """Colours by object id (the simulator itself colours by shape)."""
    oid = obj.id.lower()
    if oid == "table":
        return [0.72, 0.56, 0.38, 1.0]
    if oid.startswith("human"):
        if "head" in oid or "arm" in oid or "neck" in oid:
            return [0.93, 0.76, 0.62, 1.0]  # skin
        if "leg" in oid or "pelvis" in oid:
            return [0.25, 0.30, 0.45, 1.0]  # trousers
        return [0.30, 0.55, 0.75, 1.0]  # shirt
    if oid.startswith("case"):
        return [0.55, 0.60, 0.65, 1.0]
    return [0.45, 0.65, 0.45, 1.0]


def scene_bounds(world) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounds of the robot's reach and every object (bounding spheres of the objects)."""
    lo = np.array([-0.3, -REACH * 0.7, 0.0])
    hi = np.array([REACH * 0.8, REACH * 0.7, 1.0])
    for obj in world.objects:
        if obj.shape == "box":
            r = 0.5 * math.sqrt(sum(s * s for s in obj.size))
        elif obj.shape == "sphere":
            r = obj.size[0]
        else:
            r = math.hypot(obj.size[0] / 2.0, obj.size[1])
        c = np.array(obj.xyz)
        lo, hi = np.minimum(lo, c - r), np.maximum(hi, c + r)
    return lo, hi


class SceneView:
    """A robot (robot config dict, as config/robots/*.yaml's robot: section) in a world (moverl_sim.world.World),
    rendered on demand. Owns a PyBullet DIRECT client: close() it.

    Args:
        robot: the robot config's robot: mapping (urdf, joints, base_link, fixed_joint_positions).
        world: the world.
        settings: picture size and camera (default: config/render.yaml).
    """

    def __init__(self, robot: dict, world, settings: ViewSettings | None = None):
        self.world = world
        self.settings = settings or ViewSettings.from_yaml()
        # a picture for people: the robot as it looks; no depth camera here, so no depth scene to read
        self.sim = simulator_for(robot, world, robot_visuals="visual", camera_renderer="tinyrenderer")
        p = self.sim.client
        for oid, (body, link) in self.sim.object_bodies.items():
            p.changeVisualShape(body, link, rgbaColor=object_colour(world.object(oid)))
        self._goal_body = None
        s = self.settings
        lo, hi = scene_bounds(world)
        centre = 0.5 * (lo + hi)
        radius = 0.5 * float(np.linalg.norm(hi - lo))
        distance = radius / math.tan(math.radians(s.fov / 2.0)) * 0.75
        self._view = p.computeViewMatrixFromYawPitchRoll(
            cameraTargetPosition=centre.tolist(),
            distance=distance,
            yaw=s.yaw - 90.0,
            pitch=s.pitch,
            roll=0.0,
            upAxisIndex=2,
        )
        self._proj = p.computeProjectionMatrixFOV(
            fov=s.fov, aspect=s.width / float(s.height), nearVal=0.05, farVal=distance * 4
        )

    def pose(self, q, motion_time: float = 0.0, goal=None) -> None:
        """Put the robot at q, the moving obstacles where they are at motion_time, and the goal marker at goal."""
        self.sim.reset_robot(list(q))
        self.sim.place_obstacles(motion_time)
        if goal is None:
            return
        p = self.sim.client
        if self._goal_body is None:
            vis = p.createVisualShape(pybullet.GEOM_SPHERE, radius=GOAL_RADIUS, rgbaColor=[0.9, 0.05, 0.05, 1])
            self._goal_body = p.createMultiBody(baseMass=0, baseVisualShapeIndex=vis, basePosition=list(goal))
        else:
            p.resetBasePositionAndOrientation(self._goal_body, list(goal), [0, 0, 0, 1])

    def image(self) -> np.ndarray:
        """The picture as posed: (height, width, 3) uint8."""
        s = self.settings
        _, _, rgba, _, _ = self.sim.client.getCameraImage(
            s.width,
            s.height,
            viewMatrix=self._view,
            projectionMatrix=self._proj,
            renderer=pybullet.ER_TINY_RENDERER,
            lightDirection=[-0.4, -0.6, 1.0],
            shadow=0,
        )
        return np.reshape(np.asarray(rgba, dtype=np.uint8), (s.height, s.width, 4))[:, :, :3].copy()

    def close(self) -> None:
        if self.sim is not None:
            self.sim.close()
            self.sim = None
