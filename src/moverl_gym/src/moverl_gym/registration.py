"""Env ids registered as data (panda-gym style): for every robot config the repo ships (config/robots/*.yaml, named in
the ids by its id_name), one id per scenario x observation kind, and the goal-conditioned ids.

    MoveRL/<Robot>Reach<Scenario>[EE]-v0         flat Box observation (joints + ee pose, or ee pose only), the paper's
                                                 reward (moverl_gym.env.MoveRLReachEnv)
    MoveRL/<Robot>Reach<Scenario>Goal[Dense]-v0  Dict observation for HER (observation, achieved_goal, desired_goal),
                                                 sparse (or dense) reward plus the shield's penalty
                                                 (moverl_gym.goal_env.MoveRLReachGoalEnv)
"""

from __future__ import annotations

import gymnasium as gym

from moverl_sim.robot_config import RobotConfigError, load_robot_config

from .paths import config_file

#: Scenario name -> world file name in worlds/.
SCENARIOS = {"Table": "table", "Human": "human", "Case": "case", "SharedBench": "shared_bench"}
#: Observation kind suffix -> obs_type.
OBSERVATIONS = {"": "joints", "EE": "ee"}
#: Goal-conditioned suffix -> reward_type.
GOAL_REWARDS = {"Goal": "sparse", "GoalDense": "dense"}
VERSION = "v0"


def _robots() -> dict[str, str]:
    """id_name -> robot config name (the file's stem), for every shipped robot config."""
    out = {}
    for path in sorted(config_file("robots").glob("*.yaml")):
        robot = load_robot_config(path)
        if "id_name" not in robot:
            raise RobotConfigError(f"{path}: 'robot.id_name': missing (a shipped robot config names its env ids)")
        out[robot["id_name"]] = path.stem
    return out


#: Robot name in the ids -> its config (config/robots/<config>.yaml).
ROBOTS: dict[str, str] = _robots()
#: The flat ids.
FLAT_ENV_IDS: list[str] = [f"MoveRL/{r}Reach{s}{o}-{VERSION}" for r in ROBOTS for s in SCENARIOS for o in OBSERVATIONS]
#: The goal-conditioned ids.
GOAL_ENV_IDS: list[str] = [f"MoveRL/{r}Reach{s}{g}-{VERSION}" for r in ROBOTS for s in SCENARIOS for g in GOAL_REWARDS]
ENV_IDS: list[str] = FLAT_ENV_IDS + GOAL_ENV_IDS


def _id_name(robot: str) -> str:
    """The id name of robot config `robot` (its file's stem: what a graph's rosparam /robot/name says)."""
    names = [r for r, config in ROBOTS.items() if config == robot]
    if not names:
        raise ValueError(f"no robot config named '{robot}' in {config_file('robots')}")
    return names[0]


def env_id(robot: str, scenario: str, suffix: str = "") -> str:
    """The id of robot config `robot` in a scenario ("Table", ...) with an id suffix ("", "EE", "Goal", ...)."""
    return f"MoveRL/{_id_name(robot)}Reach{scenario}{suffix}-{VERSION}"


def register_envs() -> None:
    """Register every id. Episodes are truncated by the env itself after config/env.yaml's max_episode_steps (so that
    task={"max_episode_steps": n} changes it): no TimeLimit wrapper is registered."""
    for robot_name, robot in ROBOTS.items():
        for scenario, world in SCENARIOS.items():
            ids = [(s, "moverl_gym.env:MoveRLReachEnv", {"obs_type": o}) for s, o in OBSERVATIONS.items()]
            ids += [(s, "moverl_gym.goal_env:MoveRLReachGoalEnv", {"reward_type": r}) for s, r in GOAL_REWARDS.items()]
            for suffix, entry_point, kwargs in ids:
                name = f"MoveRL/{robot_name}Reach{scenario}{suffix}-{VERSION}"
                if name not in gym.registry:
                    gym.register(name, entry_point=entry_point, kwargs={"world": world, "robot": robot, **kwargs})
