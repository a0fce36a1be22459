"""Where a robot can get, from its model (the robot config's URDF as PyBullet loads it): ROS-free.

The *shoulder* is the last point of the chain from the base link to the end-effector link that no controlled joint
moves: of the link frame origins on that chain (each joint's origin), the last one that lies on the axis of every
controlled joint before it (the Panda: panda_link2's origin, joint 2's axis 0.333 m above the base, where joint 1's
axis crosses it). The *reach* is the farthest any point of the robot's collision geometry gets from the shoulder over
the controlled joints' ranges (the URDF's limits; uncontrolled joints held at fixed_joint_positions); the *flange
reach* the farthest the end-effector link's origin gets (what a datasheet calls the maximum reach: 855 mm for the
Panda's flange). The *base radius* is how far the collision geometry of the links that never move (the base link and
what is fixed to it) reaches from the base's vertical axis: nothing gets under it.

Both reaches are maximised by coordinate ascent from several starts: with all other joints held, the squared distance
of a point from the shoulder is ``a + b cos(q) + c sin(q)`` in a revolute joint's angle q (three forward kinematics
fix a, b and c; its maximum over the joint's range is at an end or where the derivative vanishes), and convex in a
prismatic joint's travel (its maximum is at an end). Each step is therefore the exact maximum over one joint, and a
sweep never decreases the distance. moverl_sim.coverage uses both facts (what surfaces the robot can touch).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pybullet

from .core import Simulator, _frame, collision_shape
from .settings import simulator_for

__all__ = ["Workspace", "ON_AXIS", "STARTS"]

#: m: a point this close to a joint's axis is on it (URDF offsets are given to 0.1 mm at best).
ON_AXIS = 1e-6
#: Starts of the coordinate ascent: the robot's home, the middle of every range, and this many random
#: configurations (a fixed seed, so the figures are the same on every machine).
STARTS = 4
_SWEEPS = 200  # at most, per start; a sweep that gains less than 1e-9 m ends it
_THIRDS = np.array([0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0])


@dataclass(frozen=True)
class Workspace:
    """A robot's shoulder and reaches in the world frame (the simulator puts the robot's base at the origin).

    Attributes:
        shoulder: (x, y, z), m: the last point of the base-to-end-effector chain that no controlled joint moves.
        shoulder_link: the link whose frame origin it is.
        reach: m: the farthest any point of the robot's collision geometry gets from the shoulder.
        reach_q: a configuration (controlled joints) where it does.
        flange_reach: m: the farthest the end-effector link's origin gets from the shoulder.
        base_radius: m: how far the geometry of the links that never move reaches from the vertical axis of the base.
    """

    shoulder: tuple
    shoulder_link: str
    reach: float
    reach_q: tuple
    flange_reach: float
    base_radius: float

    @classmethod
    def of_robot(cls, robot: dict) -> "Workspace":
        """Compute the workspace of a robot.

        Args:
            robot: a robot config's robot: mapping (moverl_sim.robot_config.load_robot_config).

        Returns:
            Its Workspace.

        Raises:
            ValueError: the end-effector link is not in the URDF, or not below the base link.
            moverl_sim.urdf.UrdfError: the URDF or one of its meshes cannot be found.
        """
        sim = simulator_for(robot, None, camera_renderer="tinyrenderer")  # no depth camera: no depth scene to read
        try:
            return _Kinematics(sim, robot["ee_link"], robot["home"]).workspace()
        finally:
            sim.close()


class _Kinematics:
    """The robot of a Simulator as points that move with its controlled joints."""

    def __init__(self, sim: Simulator, ee_link: str, home):
        self.sim, self.p, self.robot = sim, sim.client, sim.robot
        names = sim.link_names
        index = {v: k for k, v in names.items()}
        if ee_link not in index:
            raise ValueError("end-effector link %r is not in the URDF; its links are: %s" % (ee_link, sorted(index)))
        self.names = names
        self.joints = list(sim.joint_indices)
        self.lower, self.upper = np.array(sim.lower), np.array(sim.upper)
        self.prismatic = [self.p.getJointInfo(self.robot, j)[2] == pybullet.JOINT_PRISMATIC for j in self.joints]
        self.home = np.clip(np.asarray(home, dtype=float), self.lower, self.upper)
        # The chain base link -> end-effector link (PyBullet's link index of a joint's child is the joint's index).
        base = index[sim.base_link]
        chain, link = [], index[ee_link]
        while link != base:
            chain.append(link)
            if link == -1:
                raise ValueError("end-effector link %r is not below the base link %r" % (ee_link, sim.base_link))
            link = self.p.getJointInfo(self.robot, link)[16]
        self.chain = [base] + chain[::-1]
        self.ee = index[ee_link]
        self.base_fixed = sim.base_fixed_links
        # Every link's collision geometry in its inertial frame (PyBullet's link frame): hull vertices and box corners,
        # spheres as centre + radius (the distance to a sphere's farthest point is the centre's plus the radius).
        self.set(self.home)
        self.geometry = []  # (link, local points N x 3, pad N)
        for link in sorted(names):
            pts, spheres = collision_shape(self.p, self.robot, link)
            if not len(pts) and not spheres:
                continue
            frame = self._inertial_frames([link])[0]
            world = np.vstack([pts.reshape(-1, 3)] + [c.reshape(1, 3) for c, _ in spheres])
            pad = np.concatenate([np.zeros(len(pts)), [r for _, r in spheres]])
            local = (world - frame[:3, 3]) @ frame[:3, :3]
            self.geometry.append((link, local, pad))

    def set(self, q):
        for j, v in zip(self.joints, q):
            self.p.resetJointState(self.robot, j, float(v), 0.0)

    def _inertial_frames(self, links):
        out = []
        for link in links:
            if link == -1:
                pos, orn = self.p.getBasePositionAndOrientation(self.robot)
            else:
                s = self.p.getLinkState(self.robot, link, computeForwardKinematics=True)
                pos, orn = s[0], s[1]
            out.append(_frame(pos, orn))
        return out

    def _origins(self, links) -> np.ndarray:
        """URDF link frame origins (world) of `links` in the current configuration."""
        poses = self.sim.link_poses()
        return np.array([poses[self.names[link]][0] for link in links], dtype=float)

    def shoulder(self):
        """The last chain link whose origin no controlled joint moves (turned by 1 rad or moved by 1 cm each)."""
        self.set(self.home)
        at_home = self._origins(self.chain)
        fixed = np.ones(len(self.chain), dtype=bool)
        for i in range(len(self.joints)):
            q = self.home.copy()
            q[i] += 0.01 if self.prismatic[i] else 1.0
            self.set(q)
            fixed &= np.linalg.norm(self._origins(self.chain) - at_home, axis=1) <= ON_AXIS
        self.set(self.home)
        last = int(np.flatnonzero(fixed)[-1])  # the base link's origin never moves
        return at_home[last], self.chain[last]

    def _points(self, only_ee: bool):
        """World points and pads of the geometry (or of the end-effector link's origin) now."""
        if only_ee:
            return np.array([self.p.getLinkState(self.robot, self.ee, computeForwardKinematics=True)[4]]), np.zeros(1)
        frames = self._inertial_frames([g[0] for g in self.geometry])
        pts = [local @ f[:3, :3].T + f[:3, 3] for (_, local, _), f in zip(self.geometry, frames)]
        return np.vstack(pts), np.concatenate([g[2] for g in self.geometry])

    def _value(self, centre, only_ee: bool) -> float:
        pts, pad = self._points(only_ee)
        return float(np.max(np.linalg.norm(pts - centre, axis=1) + pad))

    def _best_angle(self, q, i, centre, only_ee: bool):
        """The exact maximum over revolute joint i's range, the other joints held: (angle, distance)."""
        lo, hi, q0 = self.lower[i], self.upper[i], q[i]
        d2 = []
        for shift in _THIRDS:
            q[i] = q0 + shift
            self.set(q)
            pts, pad = self._points(only_ee)
            d2.append(np.sum((pts - centre) ** 2, axis=1))
        q[i] = q0
        d2 = np.array(d2)  # 3 x N: d2(q0 + s) = a + b cos(s) + c sin(s) for each point
        a = d2.mean(axis=0)
        b = (2.0 / 3.0) * (np.cos(_THIRDS) @ d2)
        c = (2.0 / 3.0) * (np.sin(_THIRDS) @ d2)
        phase = np.arctan2(c, b)  # each point's d2 peaks at q0 + phase (mod 2 pi)
        peak = q0 + phase + 2.0 * math.pi * np.ceil((lo - q0 - phase) / (2.0 * math.pi))
        angles = np.stack([np.full_like(a, lo), np.full_like(a, hi), np.where(peak <= hi, peak, lo)])
        dist = np.sqrt(np.maximum(a + b * np.cos(angles - q0) + c * np.sin(angles - q0), 0.0)) + pad
        k, n = np.unravel_index(np.argmax(dist), dist.shape)
        return float(angles[k, n]), float(dist[k, n])

    def farthest(self, centre, only_ee: bool, starts):
        """Coordinate ascent (module docstring) of the largest distance from `centre`: (distance, q)."""
        best, best_q = -1.0, None
        for q0 in starts:
            q = np.array(q0, dtype=float)
            self.set(q)
            value = self._value(centre, only_ee)
            for _ in range(_SWEEPS):
                start_value = value
                for i in range(len(self.joints)):
                    held = q[i]
                    if self.prismatic[i]:
                        options = []
                        for v in (self.lower[i], self.upper[i]):  # convex in the travel: an end
                            q[i] = v
                            self.set(q)
                            options.append((self._value(centre, only_ee), v))
                        val, angle = max(options)
                    else:
                        angle, val = self._best_angle(q, i, centre, only_ee)
                    q[i] = held
                    if val > value:
                        q[i], value = angle, val
                    self.set(q)
                if value - start_value < 1e-9:
                    break
            value = self._value(centre, only_ee)  # measured, not fitted
            if value > best:
                best, best_q = value, tuple(float(v) for v in q)
        self.set(self.home)
        return best, best_q

    def workspace(self) -> Workspace:
        shoulder, link = self.shoulder()
        rng = np.random.default_rng(0)
        starts = [self.home, 0.5 * (self.lower + self.upper)]
        starts += [rng.uniform(self.lower, self.upper) for _ in range(STARTS)]
        reach, reach_q = self.farthest(shoulder, False, starts)
        flange, _ = self.farthest(shoulder, True, starts)
        return Workspace(
            tuple(float(v) for v in shoulder), self.names[link], reach, reach_q, flange, self.base_radius()
        )

    def base_radius(self) -> float:
        radius = 0.0
        for link in self.base_fixed:
            pts, spheres = collision_shape(self.p, self.robot, link)
            extents = np.hypot(pts[:, 0], pts[:, 1]).tolist() + [math.hypot(c[0], c[1]) + r for c, r in spheres]
            radius = max([radius] + extents)
        return radius
