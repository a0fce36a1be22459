"""Env ids registered as data (panda-gym style): one per scenario x observation kind, and the goal-conditioned ids.

MoveRL/PandaReach<Scenario>[EE]-v0        flat Box observation (joints + ee pose, or ee pose only), the paper's
                                          reward (moverl_gym.env.MoveRLReachEnv)
MoveRL/PandaReach<Scenario>Goal[Dense]-v0 Dict observation for HER (observation, achieved_goal, desired_goal),
                                          sparse (or dense) reward plus the shield's penalty
                                          (moverl_gym.goal_env.MoveRLReachGoalEnv)
"""

from __future__ import annotations

import gymnasium as gym

#: Scenario name -> world file name in worlds/.
SCENARIOS = {"Table": "table", "Human": "human", "Case": "case"}
#: Observation kind suffix -> obs_type.
OBSERVATIONS = {"": "joints", "EE": "ee"}
#: Goal-conditioned suffix -> reward_type.
GOAL_REWARDS = {"Goal": "sparse", "GoalDense": "dense"}
ROBOT = "Panda"
VERSION = "v0"

#: The flat ids.
FLAT_ENV_IDS: list[str] = [f"MoveRL/{ROBOT}Reach{s}{o}-{VERSION}" for s in SCENARIOS for o in OBSERVATIONS]
#: The goal-conditioned ids.
GOAL_ENV_IDS: list[str] = [f"MoveRL/{ROBOT}Reach{s}{g}-{VERSION}" for s in SCENARIOS for g in GOAL_REWARDS]
ENV_IDS: list[str] = FLAT_ENV_IDS + GOAL_ENV_IDS


def register_envs() -> None:
    """Register every id. Episodes are truncated by the env itself after config/env.yaml's max_episode_steps (so that
    task={"max_episode_steps": n} changes it): no TimeLimit wrapper is registered."""
    for scenario, world in SCENARIOS.items():
        ids = [(f"{scenario}{s}", "moverl_gym.env:MoveRLReachEnv", {"obs_type": o}) for s, o in OBSERVATIONS.items()]
        ids += [
            (f"{scenario}{s}", "moverl_gym.goal_env:MoveRLReachGoalEnv", {"reward_type": r})
            for s, r in GOAL_REWARDS.items()
        ]
        for name, entry_point, kwargs in ids:
            env_id = f"MoveRL/{ROBOT}Reach{name}-{VERSION}"
            if env_id not in gym.registry:
                gym.register(env_id, entry_point=entry_point, kwargs={"world": world, **kwargs})
