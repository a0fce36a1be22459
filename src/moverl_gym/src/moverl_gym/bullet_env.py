"""The reach task stepped in PyBullet directly: no ROS, no shield. The speed reference for the benchmark.

Same robot, world, action scaling, dt, reward and contact counting (moverl_sim's core) as the ROS env;
what it lacks is exactly what MoveRL adds: the ROS graph and the safety shield.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import yaml

from .paths import config_file, world_file
from .robot import ActionScaler, JointLimits
from .task import ReachTask, TaskConfig


class BulletReachEnv(gym.Env):
    metadata = {"render_modes": []}

    def __init__(self, world: str = "table", robot: str = "panda"):
        from moverl_sim.core import Simulator
        from moverl_sim.urdf import resolve_uri
        from moverl_sim.world import load_world

        with open(config_file(f"robots/{robot}.yaml")) as f:
            rc = yaml.safe_load(f)["robot"]
        self.config = TaskConfig.from_yaml(config_file("env.yaml"))
        urdf = resolve_uri(rc["urdf"])
        w = load_world(str(world_file(world)))
        self.sim = Simulator(urdf, rc["joints"], rc["base_link"], rc.get("fixed_joint_positions"), w)
        with open(urdf) as f:
            self.limits = JointLimits.from_urdf(f.read(), rc["joints"])
        self.scaler = ActionScaler(self.limits, self.config.dt)
        self.task = ReachTask(self.config, w.goal)
        names = {name: i for i, name in self.sim.link_names.items()}
        self._ee = names[rc["ee_link"]]
        n = self.limits.size
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(n + 7 + 3,), dtype=np.float32)

    def _ee_pose(self):
        s = self.sim._p.getLinkState(self.sim.robot, self._ee, computeForwardKinematics=True)
        return np.array(list(s[4]) + list(s[5]))

    def _obs(self):
        return np.concatenate([self.q, self.ee, self.task.goal]).astype(np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        for _ in range(self.config.start_sampling_attempts):
            q = self.np_random.uniform(self.limits.lower, self.limits.upper)
            self.sim.reset_robot(q)
            if not self.sim.contacts_now().in_contact:
                break
        self.q = np.array(self.sim.joint_positions())
        self.ee = self._ee_pose()
        self.distance = self.task.distance(self.ee[:3])
        return self._obs(), {}

    def step(self, action):
        target = self.scaler.command(self.q, action)
        result = self.sim.execute([0.0, self.config.dt], [self.q, target])
        self.q = np.array(result.positions)
        self.ee = self._ee_pose()
        d = self.task.distance(self.ee[:3])
        reward = self.task.reward(self.distance, d, discarded=False)
        self.distance = d
        c = result.contacts
        info = {"contacts": c.world_contacts + c.self_contacts, "is_success": self.task.is_success(d)}
        return self._obs(), reward, self.task.is_success(d), False, info

    def close(self):
        self.sim.close()
