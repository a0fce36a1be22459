"""What the env needs from a robot, as plain data (no ROS types): the interface of its backends.

The env's logic (observation, reward, obstacle poses, starts, goals) works on these dataclasses and numpy arrays only.
Two backends implement the interface:
  - RosBackend (moverl_gym.ros_backend): the shield of a live ROS graph, which the env launches or attaches to; every
    action is checked by the planning scene and executed by the robot's driver (a simulator or a real robot).
  - BulletBackend (moverl_gym.bullet_backend): the same robot and world stepped by moverl_sim's PyBullet core in the
    env's own process; no ROS, no shield (every step is UNCHECKED, contacts are the physics engine's). It is the speed
    reference of the benchmark, and it lets check_env, seeding and reward tests run without a roscore.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from moverl_sim.world import ObjectMotion


@dataclass(frozen=True)
class Obstacle:
    """One world object as the env sees it."""

    id: str
    pose: np.ndarray  # x, y, z, qx, qy, qz, qw at motion time 0, robot base frame
    observed: bool  # part of the observation
    motion: "ObjectMotion | None" = None  # None: static


@dataclass(frozen=True)
class WorldInfo:
    name: str
    goal: "tuple | None"  # the world's default end-effector goal
    obstacles: tuple  # of Obstacle
    motion_epoch: float = 0.0  # driver clock (s) at which motion time was 0
    frame: str = "world"  # the frame of the poses (= the robot's base frame)
    goal_region: "tuple | None" = None  # ((low x, y, z), (high x, y, z)): each episode's goal sampled in it


@dataclass
class StepResult:
    """The answer to one step (codes: moverl_msgs/ShieldStep)."""

    verdict: int
    message: str
    q: np.ndarray  # controlled joints after the step
    stamp: float  # their stamp, driver clock (s)
    ee: np.ndarray  # end-effector pose after the step (x, y, z, qx, qy, qz, qw)
    contacts: int  # ground-truth contact pairs of the step's motion; -1 when unknown
    contact_substeps: int  # physics substeps in contact; -1 when unknown
    contacts_moving: int = -1  # of the contact pairs, those that touched while the robot moved; -1 when unknown
    contacts_resting: int = -1  # those that touched while it rested (something came to it); -1 when unknown
    unsafe_cause: int = 0  # ShieldStep.unsafe_cause
    strategy: str = ""
    planning_time: float = 0.0
    driver_error_code: int = 0  # control_msgs/FollowJointTrajectoryResult code, 0 when none
    map_age: float = -1.0  # ShieldStep.map_age: s, the sensed map's age at the check; -1 without one
    sensed_margin: float = 0.0  # ShieldStep.sensed_margin: m, the predictive margin it was checked with
    timing: dict = field(default_factory=dict)  # state_check, path_check, planning, execution (s)


@dataclass
class ResetResult:
    success: bool
    message: str
    q: "np.ndarray | None"
    stamp: float
    motion_epoch: float  # when motion time is 0 from now on (driver clock, s)
    unreachable: bool = False  # a planned reset found no path to a free target: try another
    moves: int = 0  # a planned reset: the driver moves it ran in (sensed obstacles: pieces of reset_horizon)
    path_duration: float = 0.0  # a planned reset: how long (s) its whole path lasts at the reset's timing


class Backend(ABC):
    """A robot the env drives. Attributes set by every implementation:

    joints (names, configured order), urdf (URDF text), home (configuration), ee_link, robot_config (the robot config's
    robot: mapping: urdf URI, joints, base_link, ...), shield_enabled, world (WorldInfo), obstacle_poses, restartable
    (True when restart() can relaunch a failed backend: a simulated graph the env launched).
    """

    joints: list
    urdf: str
    home: list
    ee_link: str
    robot_config: dict
    shield_enabled: bool
    world: WorldInfo
    restartable: bool = False
    #: reset() teleports the robot (a simulator's lockstep link): it may stand wherever the simulator accepts it (the
    #: simulator refuses a pose that touches, or will soon be walked into by, any obstacle), and the cameras see the
    #: scene from there at once.
    teleports: bool = False
    #: Where the observed obstacles' poses come from: "world_file" (their motion, computed by the env) or "tracker"
    #: (track() feeds a moverl_gym.tracking.TrackedPoses; launch argument obstacle_poses).
    obstacle_poses: str = "world_file"

    def track(self, tracked) -> None:
        """Feed `tracked` (moverl_gym.tracking.TrackedPoses) with every pose the tracker delivers, from now on and
        after a restart(). Only when obstacle_poses == "tracker"."""
        raise NotImplementedError(f"{type(self).__name__} has no tracker")

    @abstractmethod
    def step(self, target: np.ndarray, duration: float) -> StepResult:
        """Move towards target (through the shield, if any)."""

    @abstractmethod
    def reset(self, q: "np.ndarray | None") -> ResetResult:
        """Bring the robot to q for a new episode; None: stay where it is and report its state."""

    @abstractmethod
    def check_state(self, q: np.ndarray) -> bool:
        """True when q is collision-free (with the shield's margins when there is one)."""

    @abstractmethod
    def ee_pose(self, q: np.ndarray) -> np.ndarray:
        """End-effector pose (x, y, z, qx, qy, qz, qw) at q."""

    def sensed_census(self):
        """What the sensed map holds within the robot's reach (moverl_gym.sensed.SensedCensus), or None when there is
        no sensed map. Not for the hot path: a call to the planning scene."""
        return None

    @abstractmethod
    def restart(self) -> None:
        """Tear a failed backend down and start it again; only called when `restartable`."""

    @abstractmethod
    def close(self) -> None:
        """Release everything (a launched graph: every process of it is gone when close() returns)."""
