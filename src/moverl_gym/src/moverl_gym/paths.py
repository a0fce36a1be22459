"""Where the repository's launch files, worlds and configs are."""

from __future__ import annotations

import os
from pathlib import Path


def repo_root() -> Path:
    """The MoveRL checkout (override with the MOVERL_ROOT environment variable)."""
    env = os.environ.get("MOVERL_ROOT")
    if env:
        return Path(env).resolve()
    # src/moverl_gym/src/moverl_gym/paths.py -> the repository root is four levels up.
    return Path(__file__).resolve().parents[4]


def config_file(name: str) -> Path:
    return repo_root() / "config" / name


def world_file(world: str) -> Path:
    """A world by name (worlds/<name>.yaml) or by path."""
    path = Path(world)
    if path.suffix in (".yaml", ".yml") or path.is_absolute():
        return path.resolve()
    return repo_root() / "worlds" / f"{world}.yaml"


def robot_config_file(robot: str) -> Path:
    """A shipped robot config by name: config/robots/<robot>.yaml."""
    return repo_root() / "config" / "robots" / f"{robot}.yaml"


def launch_file(name: str = "moverl.launch") -> Path:
    return repo_root() / "launch" / name
