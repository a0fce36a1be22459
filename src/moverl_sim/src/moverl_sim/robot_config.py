"""Robot configs (config/robots/*.yaml): strict parsing, the one Python reader of them.

ROS-free. A robot config has one top-level key, ``robot:``, whose keys config/robots/panda.yaml documents one by one.
As for world files (moverl_sim.world), an unknown key is an error, never ignored: a misspelt optional key
(``acceleration_limit:``) would otherwise leave the robot without its limits and nobody would know. Errors name the
file, the key and the valid keys, and come before any process starts: every reader goes through here, among them
``robot_description`` (run by roslaunch while it reads launch/robot.launch), moverl_gym.launch_args (the env and
launch/moverl.launch check their arguments with it), the env's backends (the PyBullet one reads the file, the ROS one
the /robot parameter a graph was launched with), render_world and the audits. The C++ nodes read the same values from
the /robot parameter that launch/robot.launch loads from the file checked here.
"""

import difflib
import math
import os

import yaml

__all__ = ["RobotConfigError", "REQUIRED", "OPTIONAL", "KEYS", "load_robot_config", "parse_robot"]

#: Keys every robot config has (their meaning: config/robots/panda.yaml).
REQUIRED = ("name", "urdf", "joints", "base_link", "ee_link", "home")
#: Keys a robot config may leave out: id_name (needed by the configs that ship in config/robots/, it names their env
#: ids), fixed_joint_positions (robots without uncontrolled joints), acceleration_limits (URDFs carry none).
OPTIONAL = ("id_name", "fixed_joint_positions", "acceleration_limits")
KEYS = REQUIRED + OPTIONAL


class RobotConfigError(ValueError):
    """A robot config is missing or malformed. The message names the file and the offending key."""


def load_robot_config(path):
    """Read and check a robot config file; return its ``robot:`` mapping (a new dict).

    Args:
        path: the file (str or os.PathLike).

    Returns:
        The ``robot:`` section, every key checked.

    Raises:
        RobotConfigError: the file is missing, unreadable or not YAML, or a key is unknown, missing or malformed.
    """
    source = os.fspath(path)
    if not os.path.isfile(source):
        raise RobotConfigError("%s: robot config file not found" % source)
    try:
        with open(source, "r", encoding="utf-8") as fh:
            data = yaml.safe_load(fh)
    except yaml.YAMLError as exc:
        raise RobotConfigError("%s: YAML syntax error: %s" % (source, exc)) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise RobotConfigError("%s: cannot read: %s" % (source, exc)) from None
    if not isinstance(data, dict):
        raise RobotConfigError("%s: expected a mapping with one key, robot:, got %r" % (source, data))
    _unknown_keys(data, ("robot",), source, "")
    if "robot" not in data:
        _fail(source, "robot", "missing required key")
    return parse_robot(data["robot"], source)


def parse_robot(robot, source, prefix="robot."):
    """Check a robot config's ``robot:`` mapping (from a file, or the /robot parameter of a running graph).

    Args:
        robot: the mapping.
        source: where it comes from, for messages (a file name, "/robot parameter").
        prefix: how its keys are named in messages ("robot." for a file's section).

    Returns:
        A new dict with the same keys; lists are copied, numbers are floats.

    Raises:
        RobotConfigError: a key is unknown, missing or malformed (naming the key and the valid keys).
    """
    if not isinstance(robot, dict):
        _fail(source, prefix.rstrip("."), "expected a mapping of %s, got %r" % (", ".join(KEYS), robot))
    _unknown_keys(robot, KEYS, source, prefix)
    missing = [k for k in REQUIRED if k not in robot]
    if missing:
        _fail(source, prefix + missing[0], "missing required key (required: %s)" % ", ".join(REQUIRED))
    out = {}
    for key in ("name", "id_name", "urdf", "base_link", "ee_link"):
        if key in robot:
            out[key] = _string(robot[key], source, prefix + key)
    joints = robot["joints"]
    if not isinstance(joints, list) or not joints:
        _fail(source, prefix + "joints", "expected a non-empty list of joint names, got %r" % (joints,))
    out["joints"] = [_string(j, source, prefix + "joints") for j in joints]
    twice = sorted({j for j in out["joints"] if out["joints"].count(j) > 1})
    if twice:
        _fail(source, prefix + "joints", "joint(s) listed twice: %s" % ", ".join(twice))
    n = len(joints)
    out["home"] = _numbers(robot["home"], source, prefix + "home", n)
    if "acceleration_limits" in robot:
        limits = _numbers(robot["acceleration_limits"], source, prefix + "acceleration_limits", n)
        if any(a <= 0.0 for a in limits):
            _fail(source, prefix + "acceleration_limits", "must be > 0 (rad/s^2), got %r" % (limits,))
        out["acceleration_limits"] = limits
    if "fixed_joint_positions" in robot:
        fixed = robot["fixed_joint_positions"]
        if not isinstance(fixed, dict):
            _fail(source, prefix + "fixed_joint_positions", "expected a mapping joint: position ({} for none)")
        out["fixed_joint_positions"] = {
            _string(j, source, prefix + "fixed_joint_positions"): _number(
                q, source, "%sfixed_joint_positions.%s" % (prefix, j)
            )
            for j, q in fixed.items()
        }
        both = sorted(set(out["fixed_joint_positions"]) & set(out["joints"]))
        if both:
            _fail(source, prefix + "fixed_joint_positions", "controlled joint(s) cannot be fixed: %s" % ", ".join(both))
    return out


def _fail(source, key, msg):
    raise RobotConfigError("%s: '%s': %s" % (source, key, msg))


def _unknown_keys(mapping, valid, source, prefix):
    unknown = sorted(str(k) for k in mapping if k not in valid)
    if unknown:
        close = difflib.get_close_matches(unknown[0], valid, n=1)
        hint = "did you mean '%s'? " % close[0] if close else ""
        _fail(source, prefix + unknown[0], "unknown key (%svalid keys: %s)" % (hint, ", ".join(valid)))


def _string(value, source, key):
    if not isinstance(value, str) or not value.strip():
        _fail(source, key, "expected a non-empty string, got %r" % (value,))
    return value


def _number(value, source, key):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        _fail(source, key, "expected a finite number, got %r" % (value,))
    return float(value)


def _numbers(value, source, key, count):
    if not isinstance(value, list):
        _fail(source, key, "expected a list of %d numbers (one per joint), got %r" % (count, value))
    if len(value) != count:
        _fail(source, key, "expected %d numbers (one per joint), got %d" % (count, len(value)))
    return [_number(v, source, key) for v in value]
