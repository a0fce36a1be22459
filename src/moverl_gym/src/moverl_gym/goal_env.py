"""Goal-conditioned MoveRL ids for HER (panda-gym's convention): the reach env with a Dict observation.

    observation    joint angles (obs_type="joints"), end-effector pose and observed obstacles: the flat env's
                   observation without the goal
    achieved_goal  end-effector position
    desired_goal   the goal

Reward (moverl_gym.task.goal_reward): sparse -1 until success, 0 at the goal, or dense -distance; plus the shield's
safety_penalty (config/env.yaml) when it discarded the action. compute_reward(achieved_goal, desired_goal, info) is
pure numpy and vectorised: SB3's HerReplayBuffer calls it on batches of relabelled goals through env_method, so it
never touches ROS. Safety enters through info["discarded"]: give HerReplayBuffer copy_info_dict=True so that relabelled
samples keep their penalty (without it SB3 passes empty infos, and the penalty of a discarded step is lost on relabelled
samples only; the rewards the env returns always carry it). Every other rule (shield, starts, truncation, info) is the
flat env's.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from .env import MoveRLReachEnv
from .task import goal_reward

REWARD_TYPES = ("sparse", "dense")


def _discarded(info) -> "float | np.ndarray":
    """info["discarded"] of one info dict, or of a batch (list or array of dicts, as SB3 passes them); 0 if absent."""
    if isinstance(info, dict):
        return float(bool(info.get("discarded", False)))
    return np.array([float(bool(i.get("discarded", False))) for i in info], dtype=np.float64)


class MoveRLReachGoalEnv(MoveRLReachEnv):
    """The reach env as a goal-conditioned env (Dict observation, compute_reward), for HER.

    Args:
        reward_type: "sparse" (-1 until success, 0 there) or "dense" (-distance); both add safety_penalty when the
            shield discards the action.
        **kwargs: as MoveRLReachEnv.
    """

    def __init__(self, reward_type: str = "sparse", **kwargs):
        if reward_type not in REWARD_TYPES:
            raise ValueError(f"reward_type must be one of {REWARD_TYPES}, got {reward_type!r}")
        self.reward_type = reward_type
        super().__init__(**kwargs)

    def _setup(self, world, shield, goal) -> None:
        if self.config.contact_penalty:  # goal_reward (what HER recomputes) has no contact term
            raise ValueError("contact_penalty is for the flat ids' reward; the goal-conditioned ids take only 0")
        super()._setup(world, shield, goal)
        flat = self.observation_space
        keep = np.ones(flat.shape[0], dtype=bool)
        start = self._goal_slice_start()
        keep[start : start + 3] = False
        self._keep = keep
        goal_space = gym.spaces.Box(self._goal_low.astype(np.float32), self._goal_high.astype(np.float32))
        self.observation_space = gym.spaces.Dict(
            {
                "observation": gym.spaces.Box(flat.low[keep], flat.high[keep], dtype=np.float32),
                "achieved_goal": goal_space,
                "desired_goal": goal_space,
            }
        )

    def _goal_slice_start(self) -> int:
        """Where the goal sits in the flat observation: after the joints (if observed) and the 7-number ee pose."""
        return (self.limits.size if self.obs_type == "joints" else 0) + 7

    def _goal_obs(self, flat: np.ndarray) -> dict:
        start = self._goal_slice_start()
        return {
            "observation": flat[self._keep],
            "achieved_goal": flat[start - 7 : start - 4].copy(),
            "desired_goal": flat[start : start + 3].copy(),
        }

    def compute_reward(self, achieved_goal, desired_goal, info) -> np.ndarray:
        """The reward for (achieved, desired, info): one sample or a batch; pure numpy (see the module)."""
        return goal_reward(achieved_goal, desired_goal, _discarded(info), self.config, self.reward_type == "sparse")

    def reset(self, *, seed=None, options=None):
        flat, info = super().reset(seed=seed, options=options)
        return self._goal_obs(flat), info

    def step(self, action):
        flat, _, terminated, truncated, info = super().step(action)
        obs = self._goal_obs(flat)
        # From the observation itself, so that compute_reward(obs["achieved_goal"], obs["desired_goal"], info) gives
        # exactly this reward (SB3's checker and HER rely on it).
        reward = float(self.compute_reward(obs["achieved_goal"], obs["desired_goal"], info))
        return obs, reward, terminated, truncated, info
