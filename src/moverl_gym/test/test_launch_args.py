"""launch/moverl.launch's arguments are checked before any process starts, from one list (moverl_gym.launch_args),
by the env, LaunchedGraph and roslaunch alike; no roscore (roslaunch runs with --dump-params: it reads the launch files,
running their command params, and never starts a master or a node).

* Every argument with one wrong value and one misspelt name, through gym.make and LaunchedGraph: refused within 2 s,
  naming the valid choices (or the closest valid name), and no process started (the test process's tree is watched;
  a graph's reaper may not even be created). The refusal times are printed.
* The same through roslaunch: a wrong value, a name moverl.launch does not declare, a valid set of arguments.
* The list agrees with moverl.launch (its arguments, defaults, comments and the check command's arguments) and with the
  nodes that parse a value themselves (the shield's C++, the simulator node): a value added in one place only fails.
"""

import os
import re
import shlex
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

import moverl_gym  # noqa: F401  (registers the env ids)
import moverl_gym.env  # noqa: F401  (imported here, so that the refusals below are not timed with the import)
from moverl_gym import launch_args, reaper
from moverl_gym.graph import LaunchedGraph
from moverl_gym.launch_args import ARGS, BOOL, CHOICES, OPEN, SENSED_OBSTACLES, LaunchArgError, check, launch_value
from moverl_gym.paths import launch_file, repo_root
from moverl_gym.proctree import TreeWatch
from moverl_sim import node_config, tracker

pytestmark = pytest.mark.core

REPO = repo_root()
ENV_ID = "MoveRL/PandaReachTable-v0"
LIMIT = 2.0  # s: a wrong argument is refused within this

#: One wrong value per argument, and what the message must say besides the argument's name (for a closed set: every
#: valid choice, checked below). A new argument of moverl.launch needs an entry (test_every_argument_has_a_wrong_value).
WRONG = {
    "shield": ("yes", ()),
    "simulator": ("1", ()),
    "gui": ("on", ()),
    "markers": ("0", ()),
    "rviz": ("maybe", ()),
    "strategy": ("replan", ()),
    "driver": ("ros_control", ()),
    "profile": ("cubic", ()),
    "obstacles": ("lidar", ()),
    "scene_process": ("separate", ()),
    "mode": ("fast", ()),
    "control": ("torque", ()),
    "world": ("tabel", ("worlds available", "'table'", "did you mean 'table'")),
    "world_file": ("/nonexistent/tabel.yaml", ("no world file", "worlds available")),
    "robot": ("ur5", ("no robot config ur5", "available: panda, xarm6")),
    "robot_config": ("/nonexistent/ur5.yaml", ("no robot config file",)),
    "action": ("not a name", ("ROS name",)),
    "joint_states": ("/joint states", ("ROS name",)),
    "physics_hz": ("-240", ("positive number",)),
    "initial_positions": ("[0, 0]", ("7 controlled joints",)),
    "mute_cameras": ("[nope]", ("no camera nope", "its cameras: left, right")),
    "motion_time_scale": ("0", ("positive number",)),
    "camera_rate": ("-30", ("positive number",)),
    "obstacle_poses": ("vicon", ()),
    "safety": ("iso", ()),
    "people": ("monitored", ()),
    "tracker_fault": ("lying", ()),
}
#: The env's own arguments (not in launch_args).
ENV_KWARGS = ("world", "robot", "shield")


def misspelt(name: str) -> str:
    return name[:-1]


def expected(name: str) -> list[str]:
    """What a refusal of a wrong value of `name` must say."""
    return [f"{name}="] + [c for c in CHOICES.get(name, ()) if c] + list(WRONG[name][1])


class NoGraph:
    """Fails a test that creates a graph's reaper (the only way a graph's processes start) and watches the test
    process's tree: no process may appear below it."""

    def __init__(self, monkeypatch):
        def refuse(*args, **kwargs):
            raise AssertionError("a graph's reaper was started for a wrong argument")

        monkeypatch.setattr(reaper.Handle, "__init__", refuse)
        self.watch = TreeWatch(os.getpid(), period=0.02)

    def __enter__(self):
        self.watch.start()
        self.before = set(self.watch.seen)
        return self

    def __exit__(self, *exc):
        self.watch.sample()
        self.watch.stop()
        started = [self.watch.seen[k] for k in set(self.watch.seen) - self.before]
        assert not started, f"processes started: {started}"


def refused(call) -> tuple[float, str]:
    """(seconds, message) of a call that must raise LaunchArgError."""
    t0 = time.perf_counter()
    with pytest.raises(LaunchArgError) as err:
        call()
    return time.perf_counter() - t0, str(err.value)


def test_every_argument_has_a_wrong_value():
    assert set(WRONG) == set(ARGS)


def test_every_argument_refused_within_2_s_naming_the_valid_ones(monkeypatch, capsys):
    """The walk: each argument with a wrong value and with a misspelt name, through gym.make (the env's arguments as
    its own keyword arguments) and LaunchedGraph."""
    rows, failures = [], []
    monkeypatch.delenv("ROS_MASTER_URI", raising=False)  # graph="launch" asks no master whether to attach
    with NoGraph(monkeypatch):
        for name in ARGS:
            value = WRONG[name][0]
            walk = []
            if name != "world_file":  # the env takes a world file's path as world=
                # graph="launch": attached to a graph, world only names the graph's world and robot is not used.
                kwargs = {name: value, "graph": "launch"} if name in ENV_KWARGS else {"launch_args": {name: value}}
                walk.append(("gym.make value", lambda: gym.make(ENV_ID, **kwargs), expected(name)))
            walk.append(("LaunchedGraph value", lambda: LaunchedGraph({name: value}), expected(name)))
            typo = {misspelt(name): value}
            hint = [f"no argument {misspelt(name)!r}", f"did you mean {name!r}", ", ".join(ARGS)]
            walk.append(("gym.make name", lambda: gym.make(ENV_ID, launch_args=typo), hint))
            walk.append(("LaunchedGraph name", lambda: LaunchedGraph(typo), hint))
            times = []
            for how, call, words in walk:
                seconds, msg = refused(call)
                times.append(seconds)
                missing = [w for w in words if w not in msg]
                if missing or seconds > LIMIT:
                    failures.append(f"{how} {name}: {seconds:.3f} s, {missing} not in: {msg}")
            rows.append(f"  {name:<18} {value!r:<26} {misspelt(name)!r:<18} {1e3 * max(times):6.2f} ms")
    with capsys.disabled():
        print("\nrefusal (slowest of gym.make and LaunchedGraph, wrong value and misspelt name) per argument:")
        print(f"  {'argument':<18} {'wrong value':<26} {'misspelt as':<18} {'time':>9}")
        print("\n".join(rows))
    assert not failures, "\n".join(failures)


def test_the_env_takes_world_robot_and_shield_as_its_own_arguments():
    for name in ("world", "world_file", "robot", "shield"):
        _, msg = refused(lambda: gym.make(ENV_ID, launch_args={name: "x"}))
        assert "give it as the env's argument" in msg


def test_all_wrong_arguments_in_one_message():
    _, msg = refused(lambda: check({"obstacles": "lidar", "mode": "fast", "obstacle": "sensed"}))
    assert "3 wrong arguments" in msg and "lidar" in msg and "fast" in msg and "did you mean 'obstacles'" in msg


def test_values_as_roslaunch_reads_them():
    values = check(
        {"shield": True, "gui": "False", "rviz": "TRUE", "control": "", "physics_hz": 1000, "robot": "xarm6"}
        | {"initial_positions": np.zeros(6), "world": str(REPO / "worlds" / "case.yaml")}
    )
    assert values["shield"] == "true" and values["gui"] == "false" and values["rviz"] == "true"
    assert values["physics_hz"] == "1000" and values["initial_positions"] == "[0.0, 0.0, 0.0, 0.0, 0.0, 0.0]"
    assert launch_value(Path("/a/b")) == "/a/b"
    # roslaunch reads "1" and "0" as booleans in if= but a <param> then holds an int, which C++ bool params refuse.
    for text in ("1", "0", "yes"):
        refused(lambda: check({"shield": text}))


def test_a_wrong_robot_config_is_refused_naming_the_file_and_key(tmp_path):
    bad = tmp_path / "my_arm.yaml"
    bad.write_text((REPO / "config/robots/panda.yaml").read_text().replace("acceleration_limits:", "accel_limits:"))
    seconds, msg = refused(lambda: gym.make(ENV_ID, launch_args={"robot_config": str(bad)}))
    assert seconds < LIMIT and str(bad) in msg and "'robot.accel_limits': unknown key" in msg
    assert "did you mean 'acceleration_limits'" in msg and "valid keys: name, urdf, joints" in msg
    _, msg = refused(lambda: gym.make(ENV_ID, backend="bullet", shield=False, launch_args={"robot_config": str(bad)}))
    assert "accel_limits" in msg


class Launched(Exception):
    """Raised where a graph's reaper would start: the arguments got through."""


def checks_until_launch(monkeypatch, make) -> list[list[str]]:
    """The names each check of launch arguments got (one list per check), in process, from make() until a graph's
    reaper would start (it does not: make() stops there)."""
    calls = []
    real = launch_args._check

    def counting(args, whole, base):
        calls.append(sorted(args))
        return real(args, whole, base)

    def launch(*args, **kwargs):
        raise Launched

    monkeypatch.setattr(launch_args, "_check", counting)
    monkeypatch.setattr(reaper.Handle, "__init__", launch)
    monkeypatch.delenv("ROS_MASTER_URI", raising=False)
    with pytest.raises(Launched):
        make()
    return calls


def test_each_value_is_checked_once_on_the_way_to_a_graph(monkeypatch):
    """Issue 54 item 2: the env checks its launch_args once, the ROS backend adds the world and robot (checked then,
    with what they combine with), LaunchedGraph takes the result as it is; roslaunch's own check is another process.
    A graph launched without an env is checked once, by LaunchedGraph."""
    given = {"mode": "realtime", "obstacles": "sensed", "mute_cameras": "[left]", "initial_positions": [0.0] * 6}
    calls = checks_until_launch(
        monkeypatch, lambda: gym.make(ENV_ID, world="human", robot="xarm6", graph="launch", launch_args=given)
    )
    assert calls == [sorted(["shield", *given]), ["robot", "world"]], calls
    calls = checks_until_launch(monkeypatch, lambda: LaunchedGraph({"world": "human", **given, "robot": "xarm6"}))
    assert calls == [sorted(["world", "robot", *given])], calls


def test_a_check_that_needs_the_world_or_the_robot_waits_for_it():
    """The env's launch_args come without the world and the robot: the checks that need them run when they come (the
    joints of the env's robot, not of the default one), and only those; a whole launch takes the defaults."""
    partial = launch_args.checked({"initial_positions": [0.0] * 6, "mute_cameras": "[nope]"})
    assert not partial.whole and partial.values["initial_positions"] == "[0.0, 0.0, 0.0, 0.0, 0.0, 0.0]"
    _, msg = refused(lambda: partial.adding({"world": "human", "robot": "panda"}))
    assert "has 6 numbers; robot panda has 7" in msg and "no camera nope" in msg, msg
    _, msg = refused(lambda: launch_args.checked(partial, whole=True))
    assert "robot panda has 7" in msg and "no camera nope" in msg, msg
    fine = launch_args.checked({"initial_positions": [0.0] * 6}).adding({"world": "human", "robot": "xarm6"}, True)
    assert fine.whole and launch_args.checked(fine, whole=True) is fine
    launched = fine.with_world_file().values
    assert "world" not in launched and launched["world_file"] == str(REPO / "worlds" / "human.yaml")


# -- roslaunch -----------------------------------------------------------------------------------------------------
def roslaunch(*args: str, launch: Path | None = None) -> tuple[float, subprocess.CompletedProcess]:
    """roslaunch --dump-params launch/moverl.launch <args> (reads the files, runs their command params, never starts
    anything); its time and result."""
    t0 = time.perf_counter()
    r = subprocess.run(
        ["roslaunch", "--dump-params", str(launch or launch_file()), *args], capture_output=True, text=True, timeout=60
    )
    return time.perf_counter() - t0, r


def refused_by_roslaunch(r: subprocess.CompletedProcess) -> bool:
    """roslaunch could not load the launch files (--dump-params exits 0 then: it printed no parameter)."""
    return "Unable to load file" in r.stderr and not r.stdout.strip()


def launched_with(r: subprocess.CompletedProcess) -> dict:
    """The checked arguments roslaunch would load (/moverl/launch_args)."""
    assert r.returncode == 0 and r.stdout.strip(), r.stderr
    return yaml.safe_load(r.stdout)["/moverl/launch_args"]


def test_roslaunch_refuses_a_wrong_value_of_each_closed_set_argument(capsys):
    rows, failures = [], []
    for name in CHOICES:
        seconds, r = roslaunch(f"{name}:={WRONG[name][0]}")
        rows.append(f"  {name + ':=' + WRONG[name][0]:<26} {seconds:5.2f} s")
        missing = [w for w in expected(name) if w not in r.stderr]
        if not refused_by_roslaunch(r) or missing or seconds > LIMIT:
            failures.append(f"{name}: code {r.returncode}, {seconds:.2f} s, {missing} not in:\n{r.stderr}")
    with capsys.disabled():
        print("\nroslaunch --dump-params launch/moverl.launch <argument>:=<wrong> refused in (with roslaunch's start):")
        print("\n".join(rows))
    assert not failures, "\n".join(failures)


def test_roslaunch_refuses_a_name_moverl_launch_does_not_declare():
    # roslaunch itself ignores such an argument: obstacles would silently stay objects.
    seconds, r = roslaunch("obstacle:=sensed")
    assert refused_by_roslaunch(r) and "no argument 'obstacle' (did you mean 'obstacles'?)" in r.stderr, r.stderr
    assert seconds < LIMIT


def test_roslaunch_accepts_valid_arguments_and_keeps_them():
    _, r = roslaunch("obstacles:=sensed", "world:=human", "robot:=xarm6", "shield:=False")
    args = launched_with(r)
    assert sorted(args) == sorted(ARGS)
    assert args["obstacles"] == "sensed" and args["robot"] == "xarm6" and args["shield"] == "false"


def test_an_including_launch_file_keeps_its_own_arguments(tmp_path):
    """The names on roslaunch's command line are moverl.launch's only when it launches moverl.launch itself."""
    outer = tmp_path / "outer.launch"
    outer.write_text(
        f'<launch><arg name="mine"/><include file="{launch_file()}"><arg name="obstacles" value="both"/></include>'
        "</launch>"
    )
    _, r = roslaunch("mine:=1", launch=outer)
    assert launched_with(r)["obstacles"] == "both"


# -- one list: moverl.launch and the nodes agree with it -------------------------------------------------------------
def launch_tree() -> ET.Element:
    return ET.parse(launch_file(), parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))).getroot()


def test_moverl_launch_declares_exactly_these_arguments():
    declared = [a.get("name") for a in launch_tree().iter("arg") if a.get("default") is not None]
    assert sorted(declared) == sorted(ARGS)
    assert not set(CHOICES) & set(OPEN)


def test_defaults_and_comments_of_moverl_launch():
    """A closed-set argument's literal default is one of its choices, and the comment above it names every choice
    (booleans excepted), so that the launch file's documentation cannot fall behind the list."""
    comment = ""
    for element in launch_tree():
        if element.tag is ET.Comment:
            comment = element.text
            continue
        name = element.get("name")
        if element.tag == "arg" and name in CHOICES:
            default = element.get("default")
            if "$(" not in default:
                assert default in CHOICES[name], f"{name}'s default {default!r}"
            if CHOICES[name] is not BOOL:
                words = set(re.findall(r"\w+", comment))
                assert {c for c in CHOICES[name] if c} <= words, f"moverl.launch's comment on {name}: {comment}"


def test_the_check_command_passes_every_argument():
    param = [p for p in launch_tree().iter("param") if p.get("name") == "moverl/launch_args"]
    assert len(param) == 1
    tokens = shlex.split(param[0].get("command"))
    assert tokens[0].endswith("/src/moverl_gym/scripts/check_launch_args.py") and "--launch-file" in tokens
    passed = dict(t.split(":=", 1) for t in tokens if ":=" in t)
    assert sorted(passed) == sorted(ARGS)
    assert all(value == f"$(arg {name})" for name, value in passed.items())


def cpp_function(path: Path, signature: str) -> str:
    """The body of the C++ function whose definition starts with `signature`."""
    text = path.read_text()
    start = text.index(signature)
    i = text.index("{", start)
    depth = 0
    for j in range(i, len(text)):
        depth += {"{": 1, "}": -1}.get(text[j], 0)
        if depth == 0:
            return text[i : j + 1]
    raise AssertionError(f"unbalanced braces after {signature} in {path}")


def cpp_enum_names(src: Path, enum: str, name: str) -> set[str]:
    """The names parse<name> (in `src`) accepts: its enumerators of `enum`, named by <name>Name; and <name>Names(),
    the list its error message gives, says the same."""
    cap = name[0].upper() + name[1:]
    names = dict(
        re.findall(rf"case {enum}::(k\w+):\s*return \"(\w+)\";", cpp_function(src, f"std::string {name}Name("))
    )
    parsed = re.findall(rf"{enum}::(k\w+)", cpp_function(src, f"bool parse{cap}("))
    assert parsed and set(parsed) <= set(names), (parsed, names)
    listed = re.search(rf'{name}Names\(\) \{{ return "([^"]*)"; \}}', src.read_text()).group(1).split(", ")
    accepted = {names[k] for k in parsed}
    assert set(listed) == accepted, f"{name}Names() lists {listed}, parse{cap} accepts {accepted}"
    return accepted


def shield_strategies() -> set[str]:
    return cpp_enum_names(REPO / "src/moverl_shield/src/shield_core.cpp", "Strategy", "strategy")


def scene_safeties() -> set[str]:
    return cpp_enum_names(REPO / "src/moverl_planning_scene/src/sensed_margin.cpp", "Safety", "safety")


def shield_profiles() -> set[str]:
    src = REPO / "src/moverl_shield/src/trajectory.cpp"
    names = set(re.findall(r'"(\w+)"', cpp_function(src, "std::string profileName(")))
    parsed = re.findall(r"Profile::(k\w+)", cpp_function(src, "bool parseProfile("))
    assert len(set(parsed)) == len(names), (parsed, names)
    return names


def shield_drivers() -> set[str]:
    return set(re.findall(r'\bname == "(\w+)"', (REPO / "src/moverl_shield/src/shield_node.cpp").read_text()))


def scene_obstacles() -> set[str]:
    text = (REPO / "src/moverl_planning_scene/src/scene_server.cpp").read_text()
    check_line = next(line for line in text.splitlines() if line.count("obstacles_ != ") > 1)
    return set(re.findall(r'obstacles_ != "(\w+)"', check_line))


#: Each node's own list of the values it accepts. The simulator's are its modules' constants, the ones its checks
#: use (moverl_sim.node_config, moverl_sim.core). The C++ nodes' are read from their source: no way to ask them exists
#: without a ROS master (a node reads its parameters from one, and refuses a value only then), no binary prints its
#: list, and no data file is read by both sides; so a reformat of those functions breaks these readers.
NODE_LISTS = {
    "strategy": shield_strategies,
    "safety": scene_safeties,
    "profile": shield_profiles,
    "driver": shield_drivers,
    "obstacles": scene_obstacles,
    "mode": lambda: set(node_config.MODES),
    "control": lambda: set(node_config.CONTROLS),
    "tracker_fault": lambda: set(tracker.FAULTS),
}


@pytest.mark.parametrize("name", NODE_LISTS)
def test_the_nodes_parse_the_same_values(name):
    arg = name.split()[0]
    ours = {c for c in CHOICES[arg] if c}
    theirs = NODE_LISTS[name]()
    assert theirs == ours, (
        f"{arg}: the node accepts {sorted(theirs)}, moverl_gym/launch_args.py's CHOICES {sorted(ours)}: "
        "a value goes into both (and into moverl.launch's comment)"
    )


def test_check_script_runs_without_the_moverl_gym_package(tmp_path):
    """check_launch_args.py under Debian's python3 (catkin's: no gymnasium), as roslaunch may run it."""
    script = REPO / "src/moverl_gym/scripts/check_launch_args.py"
    r = subprocess.run(
        ["/usr/bin/python3", str(script), "obstacles:=lidar"], capture_output=True, text=True, timeout=30
    )
    assert r.returncode == 1 and "obstacles='lidar' is not one of" in r.stderr, r.stderr
    r = subprocess.run([sys.executable, str(script), "mode:=realtime"], capture_output=True, text=True, timeout=30)
    assert r.returncode == 0 and r.stdout == "mode: realtime\n", r.stderr


def test_a_sensed_world_whose_bound_is_below_its_motion_is_refused(tmp_path):
    """Issue 23 item 1: a cell from the documented template (base: table.yaml) with a walking person, whose sensing
    says nothing moves, is refused in the sensed modes before anything starts, naming the file and the key; without
    sensing: it takes the fail-closed defaults and is accepted; in objects mode the bound is not used."""
    cell = tmp_path / "cell.yaml"
    person = (
        "  - {id: torso, shape: cylinder, size: [0.58, 0.165], xyz: [0.8, 0.0, 0.43],\n"
        "     motion: {type: oscillate, axis: [0, 1, 0], amplitude: 0.15, period: 6.0}}\n"
    )
    base = repo_root() / "worlds" / "table.yaml"
    cell.write_text(f"base: {base}\nname: cell\nobjects:\n{person}sensing: {{speed_bound: 0.0}}\n")
    for mode in ("sensed", "octomap", "both"):
        t0 = time.perf_counter()
        with pytest.raises(LaunchArgError) as err:
            check({"obstacles": mode, "world_file": str(cell)})
        assert time.perf_counter() - t0 < 2.0
        assert str(cell) in str(err.value) and "'sensing.speed_bound' = 0 m/s" in str(err.value), err.value
    check({"obstacles": "objects", "world_file": str(cell)})
    cell.write_text(f"base: {base}\nname: cell\nobjects:\n{person}")
    check({"obstacles": "sensed", "world_file": str(cell)})  # ISO's bound, unknown space occupied


@pytest.mark.parametrize(
    "obstacles, strategy", [("objects", "plan"), ("octomap", "retreat"), ("both", "retreat"), ("sensed", "retreat")]
)
def test_the_default_strategy_backs_away_only_where_a_person_is_sensed(obstacles, strategy):
    """With a sensed map a robot held still is walked into (docs/sensing.md): there the default is retreat; with the
    world file's obstacles it is the paper's plan (retreat would do the same there). A given strategy wins."""
    _, proc = roslaunch(f"obstacles:={obstacles}")
    assert proc.returncode == 0, proc.stderr
    assert re.search(rf"^/shield/strategy: {strategy}$", proc.stdout, re.M), proc.stdout
    _, proc = roslaunch(f"obstacles:={obstacles}", "strategy:=discard")
    assert re.search(r"^/shield/strategy: discard$", proc.stdout, re.M), proc.stdout


def test_a_safety_definition_needs_the_cameras_map():
    """safety:= is what the checks against the cameras' map promise: refused with the world file's shapes only, at
    once and naming the obstacle modes that have a map; accepted with each of them."""
    with pytest.raises(LaunchArgError, match="needs obstacles:= one of octomap, both, sensed"):
        check({"safety": "ssm", "obstacles": "objects"})
    with pytest.raises(LaunchArgError, match="obstacles='objects'"):
        check({"safety": "separation"}, whole=True)  # moverl.launch's default obstacles
    for mode in SENSED_OBSTACLES:
        check({"safety": "ssm", "obstacles": mode})
    check({"safety": "", "obstacles": "objects"}, whole=True)  # empty: the YAML's, and no map to promise anything of


def test_tracked_people_need_ssm_and_the_simulators_tracker():
    """people:=tracked is ssm's, and with the simulator only its tracker (obstacle_poses:=tracker) reports them:
    refused at once otherwise, naming what is missing; roslaunch sets the scene's octomap/ssm/tracking/use."""
    tracked = {"people": "tracked", "obstacles": "sensed", "obstacle_poses": "tracker"}
    with pytest.raises(LaunchArgError, match="needs safety:=ssm"):
        check(tracked, whole=True)
    with pytest.raises(LaunchArgError, match="needs obstacle_poses:=tracker"):
        check({**tracked, "safety": "ssm", "obstacle_poses": "world_file"}, whole=True)
    check({**tracked, "safety": "ssm"}, whole=True)
    check({**tracked, "safety": "ssm", "simulator": "false", "obstacle_poses": "world_file"}, whole=True)
    check({"people": "unmonitored", "obstacles": "sensed"}, whole=True)
    _, r = roslaunch("obstacles:=sensed", "safety:=ssm", "people:=tracked", "obstacle_poses:=tracker")
    assert r.returncode == 0, r.stderr
    params = yaml.safe_load(r.stdout)
    assert params["/planning_scene/octomap/ssm/tracking/use"] is True, r.stdout[-3000:]
    _, r = roslaunch("obstacles:=sensed")
    assert yaml.safe_load(r.stdout)["/planning_scene/octomap/ssm/tracking/use"] is False  # the YAML's


def test_tracker_fault_reaches_the_simulators_tracker():
    """tracker_fault:= sets the simulator's tracker/fault; empty keeps config/sim.yaml's (none)."""
    _, r = roslaunch("obstacle_poses:=tracker", "tracker_fault:=frozen")
    assert r.returncode == 0, r.stderr
    assert yaml.safe_load(r.stdout)["/sim/tracker/fault"] == "frozen"
    _, r = roslaunch("obstacle_poses:=tracker")
    assert yaml.safe_load(r.stdout)["/sim/tracker/fault"] == "none"
