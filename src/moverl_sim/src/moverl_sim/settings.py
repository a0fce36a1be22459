"""The simulator's tunables for code that builds a Simulator without the node's parameters (the env's PyBullet
backend, the audits, render_world, tests): read from config/sim.yaml, their one home, so that all of them simulate
what the node simulates."""

from __future__ import annotations

import os

import yaml

# src/moverl_sim/src/moverl_sim/settings.py -> the repository root is four levels up (MOVERL_ROOT overrides, as in
# moverl_gym.paths).
_ROOT = os.environ.get("MOVERL_ROOT") or os.path.dirname(
    os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.realpath(__file__)))))
)


def sim_settings(path: str | None = None) -> dict:
    """physics_hz, control, moving_speed, robot_visuals, simplified_faces and camera_renderer from config/sim.yaml
    (or `path`), as keyword arguments of Simulator."""
    with open(path or os.path.join(_ROOT, "config", "sim.yaml"), encoding="utf-8") as f:
        cfg = yaml.safe_load(f)
    return {
        "physics_hz": float(cfg["physics_hz"]),
        "control": str(cfg["control"]),
        "moving_speed": float(cfg["moving_speed"]),
        "robot_visuals": str(cfg["robot_visuals"]),
        "simplified_faces": int(cfg["simplified_faces"]),
        "camera_renderer": str(cfg["camera_renderer"]),
    }


def simulator_for(robot_config: dict, world, **overrides):
    """A Simulator of a robot config's robot (moverl_sim.robot_config: its URDF resolved as the node resolves it, its
    joints, base and fixed joints) in `world`, with config/sim.yaml's settings, `overrides` replacing some (e.g.
    robot_visuals="visual"): the one way the tools, tests and pictures build the simulator the node runs
    (Simulator.from_robot, which the node calls with its parameters).

    Raises:
        moverl_sim.urdf.UrdfError: the URDF or one of its meshes cannot be found or read.
        ValueError: the simulator cannot be built from it.
    """
    from .core import Simulator

    return Simulator.from_robot(robot_config, world, **{**sim_settings(), **overrides})
