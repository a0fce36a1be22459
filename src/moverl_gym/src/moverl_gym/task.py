"""The reach task, ROS-free: goal, reward and success (paper sec. 4.5-4.6, constants from config/env.yaml)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import yaml


@dataclass(frozen=True)
class TaskConfig:
    """Constants of the reach task. Every field is required: config/env.yaml is the one place where each is set and
    documented (from_yaml reads it; gym.make(id, task={...}) overrides single keys)."""

    dt: float
    kappa: float
    goal_reward: float
    step_penalty: float
    safety_penalty: float
    contact_penalty: float
    goal_tolerance: float
    max_episode_steps: int
    start_noise: float
    goal_noise: float
    start_sampling_attempts: int
    goal_wait: float
    step_timeout: float
    reset_timeout: float
    max_graph_restarts: int
    restart_min_steps: int
    observation_margin: float
    track_timeout: float

    @classmethod
    def from_yaml(cls, path: Path, **overrides) -> "TaskConfig":
        with open(path) as f:
            data = yaml.safe_load(f) or {}
        data.update(overrides)
        known = {f.name for f in fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"unknown task settings {sorted(unknown)} (known: {sorted(known)})")
        missing = known - set(data)
        if missing:
            raise ValueError(f"{path}: missing task settings {sorted(missing)}")
        types = {f.name: f.type for f in fields(cls)}
        return cls(**{k: (int(v) if types[k] in (int, "int") else float(v)) for k, v in data.items()})


class ReachTask:
    """Reward r = kappa * (d_prev - d) + goal_reward at the goal (else step_penalty) + safety_penalty if discarded
    + contact_penalty if the step's motion made contact (ground truth; 0 in config/env.yaml, the paper's reward)."""

    def __init__(self, config: TaskConfig, goal):
        self.config = config
        self.goal = np.asarray(goal, dtype=np.float64)
        if self.goal.shape != (3,) or not np.isfinite(self.goal).all():
            raise ValueError(f"goal must be 3 finite numbers, got {goal}")

    def distance(self, ee_position) -> float:
        d = np.subtract(ee_position, self.goal)
        return math.sqrt(d.dot(d))  # what np.linalg.norm computes for a vector (sqrt(x.x)), without its checks

    def is_success(self, distance: float) -> bool:
        return distance < self.config.goal_tolerance

    def reward(self, d_prev: float, d: float, discarded: bool, contacts: int = 0) -> float:
        """The step's reward.

        Args:
            d_prev: distance to the goal before the step (m).
            d: distance after it (m).
            discarded: the shield discarded (or truncated) the action.
            contacts: ground-truth contact pairs of the step's motion; -1 (unknown: a driver without contact sensing)
                adds no contact penalty.
        """
        c = self.config
        r = c.kappa * (d_prev - d)
        r += c.goal_reward if self.is_success(d) else c.step_penalty
        if discarded:
            r += c.safety_penalty
        if contacts > 0:
            r += c.contact_penalty
        return float(r)


def goal_reward(achieved_goal, desired_goal, discarded, config: TaskConfig, sparse: bool) -> np.ndarray:
    """Reward of the goal-conditioned ids (panda-gym's convention, plus the shield's penalty), vectorised over a batch.

    A function of (achieved, desired, discarded) alone, so HER can recompute it for relabelled goals:
        sparse: -1 until the end effector is within goal_tolerance of the goal, 0 there (success);
        dense:  -d, the distance to the goal;
    plus safety_penalty where the shield discarded the action (`discarded`, 0/1 per sample, read from info).

    Args:
        achieved_goal, desired_goal: (..., 3) positions.
        discarded: scalar or (...) flags.
    Returns:
        float32 array of shape (...).
    """
    d = np.linalg.norm(
        np.asarray(achieved_goal, dtype=np.float64) - np.asarray(desired_goal, dtype=np.float64), axis=-1
    )
    r = -(d >= config.goal_tolerance).astype(np.float64) if sparse else -d
    return (r + config.safety_penalty * np.asarray(discarded, dtype=np.float64)).astype(np.float32)
