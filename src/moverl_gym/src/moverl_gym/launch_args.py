"""launch/moverl.launch's arguments and the values each accepts, checked before any process starts.

The one list of them. Every argument the env (``launch_args=``, ``world=``, ``robot=``, ``shield=``) or a roslaunch
user (``name:=value``) gives moverl.launch goes through check(): an unknown name is refused with the closest valid one
(difflib), a value outside its closed set with the valid choices, a world, robot or robot config that does not exist
with those available, and a robot config with an unknown, missing or malformed key with the file, the key and the
valid keys (moverl_sim.robot_config). It takes milliseconds; without it a wrong value surfaced as a node's death after
the graph started (``roslaunch exited with code 0:``), a 60 s wait for services that never came, or not at all (an
unknown value or name silently meant the default).

Who checks with it, each value once where it enters:

* In process, the entry point: the env (MoveRLReachEnv, before it makes a backend) checks its launch_args and shield
  once (checked(), a CheckedLaunch); the ROS backend adds the world and robot when it launches a graph (their checks,
  and those that combine them with the checked values, run then: CheckedLaunch.adding), and LaunchedGraph takes the
  result as it is. A tool or test that builds a LaunchedGraph from a plain mapping has it checked there, once (before
  its reaper starts anything).
* roslaunch: moverl.launch's first tag after its arguments is ``<param name="moverl/launch_args" command=...>``,
  which runs scripts/check_launch_args.py with every argument while roslaunch reads the file; roslaunch starts nothing
  (no master, no node) when the command fails. roslaunch ignores a command-line argument that the file does not
  declare (``obstacle:=sensed``); the script checks those names too (from roslaunch's command line) when roslaunch
  was asked to launch moverl.launch itself. This check is the launch file's own, in roslaunch's process: it guards
  every way in (roslaunch, rostest, a file that includes moverl.launch) and writes /moverl/launch_args, so a graph the
  env launches passes it too.

Why a Python module, and not a commented YAML list in config/ read through roslaunch's ``$(eval)``: roslaunch cannot
refuse a value by itself (``<arg>`` has no choices; ``$(eval)`` has no imports and fails with nothing better than the
exception of its expression), but it does run a command param while it reads a launch file, before it starts anything;
and the check is code anyway (suggestions, paths, robot configs). A YAML list would need this code plus a loader, for
this one reader. The nodes that parse a value themselves keep their own check (defence in depth: other launch files
start them too); test_launch_args.py compares each such list with CHOICES (the shield's C++, the simulator node), and
moverl.launch's arguments and their comments with ARGS, so they cannot diverge silently.

Nothing here imports ROS or runs moverl_gym's __init__ (which registers the gym ids, 0.3 s of gymnasium):
scripts/check_launch_args.py loads this module on every roslaunch.
"""

from __future__ import annotations

import difflib
import functools
import json
import math
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from xml.etree import ElementTree

import yaml

from moverl_sim.robot_config import RobotConfigError, load_robot_config

from .paths import launch_file, repo_root, robot_config_file, world_file

#: The values roslaunch treats as booleans everywhere (``if=``, ``$(eval)``, a ``<param>``), any case. "1" and "0"
#: are not: a <param> then holds an int, which the C++ nodes' bool parameters refuse.
BOOL = ("true", "false")

#: Arguments with a closed set of values -> the values. Where a node parses the value too, its own list is named in
#: the comment; test_launch_args.py checks that the two agree (add a value in both places, e.g. a new strategy).
CHOICES: dict[str, tuple[str, ...]] = {
    "shield": BOOL,
    "simulator": BOOL,
    "gui": BOOL,
    "markers": BOOL,
    "rviz": BOOL,
    "strategy": (
        "plan",
        "discard",
        "last_safe",
        "retreat",
    ),  # moverl_shield/src/shield_core.cpp: strategyName, parseStrategy
    "driver": ("sim_service", "follow_joint_trajectory"),  # moverl_shield/src/shield_node.cpp
    "profile": ("linear", "min_jerk"),  # moverl_shield/src/trajectory.cpp: profileName, parseProfile
    "obstacles": ("objects", "octomap", "both", "sensed"),  # moverl_planning_scene/src/scene_server.cpp
    "scene_process": ("shield", "own"),  # launch files only: moverl.launch maps it onto shield.launch's scene
    "mode": ("lockstep", "realtime"),  # moverl_sim.node_config.MODES (moverl.launch derives the sim's mode from it)
    "control": ("", "kinematic", "dynamic"),  # moverl_sim.core.CONTROLS (node_config's); "": config/sim.yaml's
    "safety": ("", "separation", "ssm"),  # moverl_planning_scene/src/sensed_margin.cpp: safetyName, parseSafety
    # ("": config/planning_scene.yaml's octomap/safety)
    "people": ("", "unmonitored", "tracked"),  # launch/planning_scene.launch: octomap/ssm/tracking/use
    "tracker_fault": ("", "none", "frozen", "offset"),  # moverl_sim.tracker.FAULTS ("": config/sim.yaml's)
    "obstacle_poses": ("world_file", "tracker"),  # the env (RosBackend); moverl.launch maps tracker onto sim.launch's
}
#: Arguments whose values are not a closed set -> what they take (each is checked: see check()).
OPEN: dict[str, str] = {
    "world": "a world name (worlds/<world>.yaml) or a world file's path",
    "world_file": "a world file's path",
    "robot": "a robot config name (config/robots/<robot>.yaml)",
    "robot_config": "a robot config file's path",
    "action": "a ROS name (the FollowJointTrajectory action)",
    "joint_states": "a ROS name (the robot's joint-state topic)",
    "physics_hz": "a positive number, or empty",
    "initial_positions": "a list of one number per controlled joint, or empty",
    "mute_cameras": "a list of camera ids of the world file, or empty (fault injection)",
    "motion_time_scale": "a positive number, or empty (experiments: obstacles faster than declared)",
    "camera_rate": "a positive number of renders per simulated second for every camera, or empty (the world file's)",
}
#: The obstacle modes that sense (a depth-camera map): their worlds' sensing assumptions are checked
#: (moverl_sim.world.sensing_problems).
SENSED_OBSTACLES = ("octomap", "both", "sensed")
#: Every argument moverl.launch takes (its derived, value= arguments cannot be set).
ARGS: tuple[str, ...] = tuple(sorted([*CHOICES, *OPEN]))

# A ROS graph resource name (wiki.ros.org/Names): a letter, ~ or / first; then letters, digits, _ and /.
_ROS_NAME = re.compile(r"^[~/]?[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*$")


class LaunchArgError(ValueError):
    """An argument moverl.launch does not take, or a value it does not accept; the message names the valid ones."""


def launch_value(value) -> str:
    """A Python value as roslaunch's ``name:=value`` text: booleans as true/false, sequences as a YAML list."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if hasattr(value, "tolist"):  # numpy
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return json.dumps([float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else x for x in value])
    return os.fspath(value) if isinstance(value, os.PathLike) else str(value)


def robots_available() -> list[str]:
    """The names of the shipped robot configs."""
    return sorted(p.stem for p in (repo_root() / "config" / "robots").glob("*.yaml"))


def worlds_available() -> list[str]:
    """The names of the shipped worlds."""
    return sorted(p.stem for p in (repo_root() / "worlds").glob("*.yaml"))


def check(args: Mapping[str, object], whole: bool = False) -> dict[str, str]:
    """Check arguments for launch/moverl.launch; return them as roslaunch's text.

    Args:
        args: name -> value (a string, a bool, a number, a list for initial_positions, a path).
        whole: these are all the arguments of a launch (the rest take their defaults): checks that need the world
            file (sensing, mute_cameras) or the robot (initial_positions' length) read the default world or robot when
            none is given. False: some arguments only (the env's launch_args, whose world and robot come separately):
            those checks wait for a world or a robot.

    Returns:
        name -> the value as ``name:=value`` text (launch_value), for the same names.

    Raises:
        LaunchArgError: naming every wrong argument with its valid names or choices.
    """
    return dict(_check(args, whole, None).values)


@dataclass(frozen=True)
class CheckedLaunch:
    """Arguments of moverl.launch that check() accepted, as roslaunch's text: what the code below an entry point takes
    as it is (RosBackend, LaunchedGraph), so that each value is checked once, where it enters. Made by checked() and
    adding() only.

    Attributes:
        values: name -> the value as ``name:=value`` text, every one checked.
        whole: they are all the arguments of a launch: the checks that need the world or the robot ran, with the
            default world or robot where none is given (check's ``whole``).
    """

    values: Mapping[str, str]
    whole: bool = False
    #: The robot configs read while checking (path -> robot: section, None when wrong), for initial_positions' length.
    _robots: Mapping = field(default_factory=dict, repr=False, compare=False)

    def adding(self, args: Mapping[str, object], whole: bool = False) -> CheckedLaunch:
        """These arguments with more: the new ones are checked, and so are the checks that combine them with these
        (a new world's sensing with obstacles, a new robot's joints with initial_positions, ...), or that waited for
        ``whole``; nothing checked already is checked again.

        Raises:
            LaunchArgError: naming every wrong new argument (or combination) with its valid names or choices.
        """
        return _check(args, whole or self.whole, self)

    def with_world_file(self) -> CheckedLaunch:
        """The same launch with its world given as a file (world_file, the world's file: checked with world), for
        moverl.launch, whose world is a name."""
        if "world" not in self.values:
            return self
        values = {k: v for k, v in self.values.items() if k != "world"}
        values["world_file"] = str(world_file(self.values["world"]))
        return CheckedLaunch(MappingProxyType(values), self.whole, self._robots)


def checked(args: "Mapping[str, object] | CheckedLaunch", whole: bool = False) -> CheckedLaunch:
    """Arguments for moverl.launch, checked once: a mapping is checked (check()); a CheckedLaunch is taken as it is
    (with ``whole``, its checks that waited for the world or the robot run now, if they have not).

    Raises:
        LaunchArgError: naming every wrong argument with its valid names or choices.
    """
    if isinstance(args, CheckedLaunch):
        return args if args.whole or not whole else args.adding({}, whole=True)
    return _check(args, whole, None)


def _check(args: Mapping[str, object], whole: bool, base: CheckedLaunch | None) -> CheckedLaunch:
    """args checked, on top of base's checked values (None: none), as a CheckedLaunch; LaunchArgError otherwise."""
    problems = []
    new = {}
    for name, value in args.items():
        if name in ARGS:
            new[name] = launch_value(value)
        else:
            problems.append(_unknown_name(str(name)))
    for name, text in new.items():
        if name in CHOICES:
            problems.append(_choice(name, text))
            if CHOICES[name] is BOOL:
                new[name] = text.lower()
    before = base.values if base is not None else {}
    values = {**before, **new}
    robots = dict(base._robots) if base is not None else {}
    problems += _open_values(values, new, whole, before, base is not None and base.whole, robots)
    problems.append(_safety_without_map(values, new, whole))
    problems.append(_tracked_people_need_ssm(values, new, whole))
    problems = [p for p in problems if p]
    if len(problems) == 1:
        raise LaunchArgError(f"launch/moverl.launch: {problems[0]}")
    if problems:
        raise LaunchArgError(
            f"launch/moverl.launch: {len(problems)} wrong arguments:\n" + "\n".join(f"  {p}" for p in problems)
        )
    return CheckedLaunch(MappingProxyType(values), whole, MappingProxyType(robots))


def _closest(word: str, valid) -> str:
    close = difflib.get_close_matches(word, list(valid), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _unknown_name(name: str) -> str:
    return f"no argument {name!r}{_closest(name, ARGS)}; the arguments are: {', '.join(ARGS)}"


def _choice(name: str, text: str) -> str:
    choices = CHOICES[name]
    if (text.lower() if choices is BOOL else text) in choices:
        return ""
    shown = ", ".join(c if c else '"" (empty: the config default)' for c in choices)
    return f"{name}={text!r} is not one of: {shown}{_closest(text, [c for c in choices if c])}"


def _safety_without_map(values: Mapping[str, str], new: Mapping[str, str], whole: bool) -> str:
    """A safety definition is a promise of the checks against the cameras' map: refused without one."""
    if not values.get("safety") or not ({"safety", "obstacles"} & set(new)):
        return ""
    obstacles = values.get("obstacles", "objects" if whole else None)  # moverl.launch's default
    if obstacles is None or obstacles in SENSED_OBSTACLES:
        return ""
    return (
        f"safety={values['safety']!r} applies to the cameras' map only: it needs obstacles:= one of "
        f"{', '.join(SENSED_OBSTACLES)} (obstacles={obstacles!r}: the world file's shapes, known exactly)"
    )


def _tracked_people_need_ssm(values: Mapping[str, str], new: Mapping[str, str], whole: bool) -> str:
    """people:=tracked is ssm's (the tracked parts' reach replaces ISO 13855's), and with the simulator only its
    tracker (obstacle_poses:=tracker) reports them."""
    if values.get("people") != "tracked" or not ({"people", "safety", "obstacle_poses", "simulator"} & set(new)):
        return ""
    if values.get("safety") != "ssm" and (whole or "safety" in values):
        safety = values.get("safety", "")
        return f"people='tracked' monitors the people's speed for ssm: it needs safety:=ssm (safety={safety!r})"
    simulated = values.get("simulator", "true" if whole else None)
    poses = values.get("obstacle_poses", "world_file" if whole else None)
    if simulated == "true" and poses is not None and poses != "tracker":
        return (
            "people='tracked' with the simulator needs obstacle_poses:=tracker (the simulator's tracker reports the "
            f"world file's people; obstacle_poses={poses!r})"
        )
    return ""


#: The arguments each check of a combination reads (besides the world or the robot they need).
_WORLD_INPUTS = ("world", "world_file", "obstacles", "mute_cameras")
_ROBOT_INPUTS = ("robot", "robot_config", "initial_positions")


def _knows_world(values: Mapping[str, str], whole: bool) -> bool:
    return whole or "world" in values or "world_file" in values


def _knows_robot(values: Mapping[str, str], whole: bool) -> bool:
    return whole or "robot" in values or "robot_config" in values


def _open_values(
    values: dict[str, str], new: dict[str, str], whole: bool, before: Mapping[str, str], was_whole: bool, configs: dict
) -> list[str]:
    """The problems of the arguments whose values are not a closed set (worlds, robots, names, numbers): of the new
    ones, and of the combinations a new one enters or that waited for a world or a robot (the rest, `before`, was
    checked). configs: robot config file -> its robot: section (None when wrong), those read so far; more are added."""
    problems = []
    world = None
    if "world" in values:
        world = world_file(values["world"])
    if "world" in new and not world.is_file():
        known = worlds_available()
        problems.append(
            f"world={values['world']!r}: no world file {world} (worlds available: {known})"
            f"{_closest(values['world'], known)}"
        )
    if "world_file" in new:
        path = Path(values["world_file"]).expanduser().resolve()
        # moverl.launch's default world_file is worlds/<world>.yaml: a wrong world is reported once, above.
        if not path.is_file() and path != world:
            known = worlds_available()
            problems.append(
                f"world_file={values['world_file']!r}: no world file {path} (worlds available: {known})"
                f"{_closest(path.stem, known)}"
            )
    robot = None
    if "robot" in values:
        robot = robot_config_file(values["robot"])
    if "robot" in new:
        if not robot.is_file():
            known = robots_available()
            problems.append(
                f"robot={values['robot']!r}: no robot config {values['robot']} (available: {', '.join(known)})"
                f"{_closest(values['robot'], known)}"
            )
        elif robot not in configs:
            problems.append(_robot_config(robot, configs))
    if "robot_config" in new:
        path = Path(values["robot_config"]).expanduser().resolve()
        # moverl.launch's default robot_config is config/robots/<robot>.yaml: a wrong robot is reported once, above.
        if not path.is_file() and path != robot:
            problems.append(f"robot_config={values['robot_config']!r}: no robot config file {path}")
        elif path.is_file() and path not in configs:
            problems.append(_robot_config(path, configs))
    for name in ("action", "joint_states"):
        if name in new and not _ROS_NAME.match(values[name]):
            problems.append(f"{name}={values[name]!r} is not {OPEN[name]}")
    for name in ("physics_hz", "motion_time_scale", "camera_rate"):
        if name in new and values[name]:
            try:
                x = float(values[name])
            except ValueError:
                x = math.nan
            if not (math.isfinite(x) and x > 0):
                problems.append(f"{name}={values[name]!r} is not {OPEN[name]}")
    if _knows_world(values, whole) and (not _knows_world(before, was_whole) or any(n in new for n in _WORLD_INPUTS)):
        problems += _world_problems(values)
    positions = values.get("initial_positions")
    if positions and "initial_positions" in new:
        problems.append(_initial_positions(positions))
    robot_due = not _knows_robot(before, was_whole) or any(n in new for n in _ROBOT_INPUTS)
    if positions and _knows_robot(values, whole) and robot_due:
        # The robot the graph loads: robot_config, whose default is config/robots/<robot>.yaml.
        if "robot_config" in values:
            path = Path(values["robot_config"]).expanduser().resolve()
        else:
            path = robot_config_file(values.get("robot", launch_defaults()["robot"]))
        if path not in configs and path.is_file():
            problems.append(_robot_config(path, configs))
        problems.append(_joint_count(positions, configs.get(path)))
    return problems


def _world_problems(values: dict[str, str]) -> list[str]:
    """The world file the graph would load, where the other arguments need it: its sensing in the sensed modes (a
    speed bound below its fastest motion, no cameras: moverl_sim.world.sensing_problems), and mute_cameras' ids."""
    from moverl_sim.world import WorldFileError, load_world, sensing_problems

    sensed = values.get("obstacles", launch_defaults()["obstacles"]) in SENSED_OBSTACLES
    mute = values.get("mute_cameras", "")
    if not sensed and not mute:
        return []
    world_name = values.get("world", launch_defaults()["world"])
    path = Path(values["world_file"]) if "world_file" in values else world_file(world_name)
    if not path.expanduser().is_file():
        return []  # reported by _open_values
    try:
        world = load_world(path.expanduser())
    except WorldFileError as exc:
        return [f"world: {exc}"]
    problems = []
    if sensed:
        problems += sensing_problems(world, default_speed_bound())
    if mute:
        try:
            ids = yaml.safe_load(mute)
        except yaml.YAMLError:
            ids = None
        known = [c.id for c in world.cameras]
        if not isinstance(ids, list) or not all(isinstance(i, str) for i in ids):
            problems.append(f"mute_cameras={mute!r} is not {OPEN['mute_cameras']}")
        elif set(ids) - set(known):
            problems.append(
                f"mute_cameras={mute!r}: no camera {', '.join(sorted(set(ids) - set(known)))} in {world.source} "
                f"(its cameras: {', '.join(known) or 'none'})"
            )
    return problems


@functools.cache
def default_speed_bound() -> float:
    """config/planning_scene.yaml's octomap/speed_bound: the sensed mode's bound when a world file gives none."""
    with open(repo_root() / "config" / "planning_scene.yaml", encoding="utf-8") as fh:
        return float(yaml.safe_load(fh)["octomap"]["speed_bound"])


@functools.cache
def launch_defaults() -> dict[str, str]:
    """moverl.launch's literal argument defaults (those without a substitution), by argument."""
    arguments = ElementTree.parse(launch_file()).getroot().iter("arg")
    return {a.get("name"): a.get("default") for a in arguments if "$(" not in a.get("default", "$(")}


def _robot_config(path: Path, configs: dict) -> str:
    try:
        configs[path] = load_robot_config(path)
    except RobotConfigError as exc:
        configs[path] = None
        return f"robot config: {exc}"
    return ""


def _positions(text: str) -> list | None:
    """initial_positions' text as a list of finite numbers, or None."""
    try:
        q = yaml.safe_load(text)
    except yaml.YAMLError:
        return None
    ok = isinstance(q, list) and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in q
    )
    return q if ok else None


def _initial_positions(text: str) -> str:
    return "" if _positions(text) is not None else f"initial_positions={text!r} is not {OPEN['initial_positions']}"


def _joint_count(text: str, robot: dict | None) -> str:
    q = _positions(text)
    if q is not None and robot is not None and len(q) != len(robot["joints"]):
        return (
            f"initial_positions={text!r} has {len(q)} numbers; robot {robot['name']} has {len(robot['joints'])} "
            f"controlled joints ({', '.join(robot['joints'])})"
        )
    return ""
