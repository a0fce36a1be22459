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
    """physics_hz, control, moving_speed and robot_visuals from config/sim.yaml (or `path`), as keyword arguments of
    Simulator."""
    with open(path or os.path.join(_ROOT, "config", "sim.yaml"), encoding="utf-8") as f:
        cfg = yaml.safe_load(f)
    return {
        "physics_hz": float(cfg["physics_hz"]),
        "control": str(cfg["control"]),
        "moving_speed": float(cfg["moving_speed"]),
        "robot_visuals": str(cfg["robot_visuals"]),
    }
