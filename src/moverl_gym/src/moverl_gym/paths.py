"""Where the repository's launch files, worlds and configs are."""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType


def repo_root() -> Path:
    """The MoveRL checkout (override with the MOVERL_ROOT environment variable)."""
    env = os.environ.get("MOVERL_ROOT")
    if env:
        return Path(env).resolve()
    # src/moverl_gym/src/moverl_gym/paths.py -> the repository root is four levels up.
    return Path(__file__).resolve().parents[4]


def workspace_binary(package: str, name: str) -> str:
    """Path of a C++ executable of the catkin workspace (its devel or install space, then this checkout's devel/);
    FileNotFoundError naming where it looked when it is not built."""
    candidates = [
        Path(p) / "lib" / package / name for p in os.environ.get("CMAKE_PREFIX_PATH", "").split(os.pathsep) if p
    ]
    candidates.append(repo_root() / "devel" / "lib" / package / name)
    for c in candidates:
        if c.is_file() and os.access(c, os.X_OK):
            return str(c)
    raise FileNotFoundError(
        f"{name} not found (build the workspace: ./catkin_ws_setup.sh); looked in " + ", ".join(map(str, candidates))
    )


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


def load_script(path: Path, name: str | None = None, register: bool = False) -> ModuleType:
    """A Python file that is not in a package (an entry point, a tool, a test helper) as a module, run once.

    Args:
        path: the file.
        name: the module's name (default: the file's stem).
        register: also put it in sys.modules under that name (what dataclasses and pickling of its classes need).
    """
    name = name or Path(path).stem
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    if register:
        sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
