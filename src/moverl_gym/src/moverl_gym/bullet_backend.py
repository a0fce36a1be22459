"""The env's PyBullet backend: the same robot and world stepped by moverl_sim's core in the env's own process.

No ROS and no shield: every step is executed straight (verdict UNCHECKED) and the physics engine counts its contacts,
as the simulator node does. Same URDF, robot config, world file, joint limits, action scaling, dt, reward and start
sampling as the ROS backend (the env's logic is shared); what it lacks is exactly what MoveRL adds: the ROS graph and
the safety shield. It is the speed reference of the benchmark, and it runs the env's check_env, seeding and reward
tests without a roscore. Collision-free starts and goals are sampled against the physics engine's contacts (there is
no planning scene).
"""

from __future__ import annotations

import numpy as np

from moverl_msgs.srv import ShieldStepResponse

from .backend import Backend, Obstacle, ResetResult, StepResult, WorldInfo
from .launch_args import check as check_launch_args
from .paths import robot_config_file, world_file


class BulletBackend(Backend):
    """Args:
    world: world name (worlds/<world>.yaml) or path. robot: config/robots/<robot>.yaml. robot_config: its path instead.
    shield: must be False (there is no shield here).
    """

    def __init__(
        self, world: str = "table", robot: str = "panda", robot_config: "str | None" = None, shield: bool = False
    ):
        if shield:
            raise ValueError("the PyBullet backend has no shield: use shield=False, or the ROS backend")
        from moverl_sim.robot_config import load_robot_config
        from moverl_sim.urdf import robot_description
        from moverl_sim.world import load_world

        # The world and robot exist, the robot config is valid (LaunchArgError naming those available otherwise).
        check_launch_args(dict(world=world, robot=robot, **({"robot_config": robot_config} if robot_config else {})))
        rc = load_robot_config(robot_config or robot_config_file(robot))
        self._args = (world, rc)
        self.urdf = robot_description(rc["urdf"])
        self.joints = list(rc["joints"])
        self.home = list(rc["home"])
        self.ee_link = rc["ee_link"]
        self.robot_config = rc
        self.shield_enabled = False
        self.restartable = True
        self._world = load_world(str(world_file(world)))
        self.world = WorldInfo(
            name=self._world.name,
            goal=self._world.goal,
            goal_region=self._world.goal_region,
            obstacles=tuple(
                Obstacle(
                    id=o.id, pose=np.array(list(o.start) + list(o.quaternion)), observed=o.observed, motion=o.motion
                )
                for o in self._world.objects
            ),
            motion_epoch=0.0,
        )
        self.sim = None
        self._start()

    def _start(self) -> None:
        from moverl_sim.core import Simulator
        from moverl_sim.settings import sim_settings

        _, rc = self._args
        # The URDF text read at construction (self.urdf, which the env reads too), resolved as the node resolves it.
        self.sim = Simulator.from_robot(
            rc, self._world, description=self.urdf, description_name=rc["urdf"], **sim_settings()
        )
        self.sim.reset_robot(np.clip(self.home, self.sim.lower, self.sim.upper))
        self._ee = {name: i for i, name in self.sim.link_names.items()}[self.ee_link]

    def _ee_now(self) -> np.ndarray:
        s = self.sim.client.getLinkState(self.sim.robot, self._ee, computeForwardKinematics=True)
        return np.array(list(s[4]) + list(s[5]))

    def step(self, target: np.ndarray, duration: float) -> StepResult:
        q0 = np.array(self.sim.joint_positions())
        result = self.sim.execute([0.0, duration], [q0, target])
        c = result.contacts
        return StepResult(
            verdict=ShieldStepResponse.UNCHECKED,
            message="",
            q=np.array(result.positions),
            stamp=self.sim.sim_time,
            ee=self._ee_now(),
            contacts=c.world_contacts + c.self_contacts,
            contact_substeps=c.substeps_in_contact,
            contacts_moving=c.moving_contacts,
            contacts_resting=c.resting_contacts,
        )

    def reset(self, q: "np.ndarray | None") -> ResetResult:
        if q is not None:
            try:
                self.sim.reset_robot(q)
            except ValueError as exc:
                return ResetResult(False, str(exc), None, self.sim.sim_time, self.sim.motion_epoch)
            self.sim.restart_motions()  # as the simulator node's reset does
        return ResetResult(True, "", np.array(self.sim.joint_positions()), self.sim.sim_time, self.sim.motion_epoch)

    def check_state(self, q: np.ndarray) -> bool:
        keep = self.sim.joint_positions()
        self.sim.reset_robot(q)
        free = not self.sim.contacts_now().in_contact
        self.sim.reset_robot(keep)
        return free

    def ee_pose(self, q: np.ndarray) -> np.ndarray:
        keep = self.sim.joint_positions()
        self.sim.reset_robot(q)
        pose = self._ee_now()
        self.sim.reset_robot(keep)
        return pose

    def restart(self) -> None:
        self.close()
        self._start()

    def close(self) -> None:
        if self.sim is not None:
            self.sim.close()
            self.sim = None
