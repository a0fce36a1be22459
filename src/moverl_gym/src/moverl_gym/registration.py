"""Env ids registered as data: one per scenario x observation kind (panda-gym style)."""

from __future__ import annotations

import gymnasium as gym

#: Scenario name -> world file name in worlds/.
SCENARIOS = {"Table": "table", "Human": "human", "Case": "case"}
#: Observation kind suffix -> obs_type.
OBSERVATIONS = {"": "joints", "EE": "ee"}
ROBOT = "Panda"
VERSION = "v0"

ENV_IDS: list[str] = [f"MoveRL/{ROBOT}Reach{s}{o}-{VERSION}" for s in SCENARIOS for o in OBSERVATIONS]


def register_envs() -> None:
    """Register every id. Episodes are truncated by the env itself after config/env.yaml's max_episode_steps (so that
    task={"max_episode_steps": n} changes it): no TimeLimit wrapper is registered."""
    for scenario, world in SCENARIOS.items():
        for suffix, obs_type in OBSERVATIONS.items():
            env_id = f"MoveRL/{ROBOT}Reach{scenario}{suffix}-{VERSION}"
            if env_id in gym.registry:
                continue
            gym.register(
                env_id, entry_point="moverl_gym.env:MoveRLReachEnv", kwargs={"world": world, "obs_type": obs_type}
            )
