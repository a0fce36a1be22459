"""The command-line options of MoveRL's front-ends, defined once: same names, units and choices everywhere.

train.py (SB3) and rllib_train.py (RLlib) take every option of TRAINING; evaluate.py, study.py and
constrained_study.py take the ones that apply to them (add() with the names). The choices of a launch argument
(--obstacles) come from moverl_gym.launch_args, its one list. A front-end that cannot honour an option it shares
refuses it when it is given (refuse()), naming why and what can, rather than ignoring it.

Units: -n/--n-timesteps and --checkpoint-freq count env steps, over all parallel envs; --n-envs counts envs, each in its
own process with its own ROS graph (SB3's SubprocVecEnv, or one RLlib env runner each).
"""

from __future__ import annotations

import argparse
import difflib
from dataclasses import fields
from pathlib import Path

import yaml

from .launch_args import ARGS, CHOICES
from .registration import ENV_IDS
from .task import TaskConfig

#: Learning algorithms of train.py (SB3); rllib_train.py trains PPO only.
ALGOS = ("ppo", "sac", "td3")
#: Shield on or off.
SHIELD = ("on", "off")
#: Attach to the graph at $ROS_MASTER_URI, launch one on a free port, or auto (attach if it serves MoveRL).
GRAPH = ("auto", "launch", "attach")
#: The env's recovery from a failed graph (auto: on when the env launched the graph with the simulator).
RECOVER = ("auto", "on", "off")
#: Env id of the front-ends by default.
DEFAULT_ENV = "MoveRL/PandaReachTable-v0"


def _count(minimum: int):
    """An argparse type: an integer >= minimum."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {value}")
        return value

    parse.__name__ = "integer"  # what argparse names in "invalid integer value"
    return parse


def task_item(text: str) -> str:
    """An argparse type for --task KEY=VALUE: refuses a malformed item or an unknown key of config/env.yaml (naming the
    keys), and returns the text as given (so a study can pass it on to train.py)."""
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"takes KEY=VALUE, got {text!r}")
    known = [f.name for f in fields(TaskConfig)]
    if key not in known:
        close = difflib.get_close_matches(key, known, n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        raise argparse.ArgumentTypeError(f"unknown key {key!r}{hint}; config/env.yaml's keys: {', '.join(known)}")
    return text


def task_dict(items: list[str]) -> dict:
    """--task items (checked by task_item) as the env's task= overrides, each value read as YAML."""
    out = {}
    for item in items:
        key, _, value = item.partition("=")
        out[key] = yaml.safe_load(value)
    return out


#: moverl.launch's arguments that --launch does not take: the env's own (world, robot, shield) and --obstacles'.
LAUNCH_OWN = {
    "world": "--world or the env id",
    "world_file": "--world",
    "robot": "the env id",
    "shield": "--shield",
    "obstacles": "--obstacles",
}


def launch_item(text: str) -> str:
    """An argparse type for --launch NAME=VALUE: refuses a malformed item, an unknown argument of moverl.launch (with
    the closest one) and the arguments that have an option of their own; the value is checked with the others when the
    env is made (moverl_gym.launch_args.check, before anything starts)."""
    name, sep, _ = text.partition("=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"takes NAME=VALUE, got {text!r}")
    if name in LAUNCH_OWN:
        raise argparse.ArgumentTypeError(f"{name}: give it as {LAUNCH_OWN[name]}")
    if name not in ARGS:
        close = difflib.get_close_matches(name, ARGS, n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        raise argparse.ArgumentTypeError(
            f"no launch argument {name!r}{hint}; launch/moverl.launch's: {', '.join(ARGS)}"
        )
    return text


def launch_dict(items: list[str]) -> dict:
    """--launch items (checked by launch_item) as the env's launch_args, the values as given."""
    return dict(item.partition("=")[::2] for item in items)


def recover_value(text: str) -> "bool | str":
    """--recover as the env's recover= argument."""
    return {"auto": "auto", "on": True, "off": False}[text]


#: Every shared option: name (its argparse dest) -> (flags, add_argument keywords). One definition each.
OPTIONS: dict[str, tuple[tuple[str, ...], dict]] = {
    "env": (
        ("--env",),
        dict(
            default=DEFAULT_ENV,
            choices=ENV_IDS,
            metavar="ID",
            help=f"env id, one of {', '.join(ENV_IDS)} (default: %(default)s)",
        ),
    ),
    "algo": (("--algo",), dict(default="ppo", choices=ALGOS, help="learning algorithm (default: %(default)s)")),
    "seed": (("--seed",), dict(type=int, default=0, help="training seed; env i of --n-envs is seeded seed + i")),
    "n_timesteps": (
        ("-n", "--n-timesteps"),
        dict(
            type=_count(1),
            default=None,
            help="env steps in all, over every parallel env (default: n_timesteps of the hyper-parameter file)",
        ),
    ),
    "n_envs": (
        ("--n-envs",),
        dict(
            type=_count(1),
            default=None,
            metavar="N",
            help="parallel envs, each in its own process with its own ROS graph (default: n_envs of the "
            "hyper-parameter file, else 1); env i is seeded with seed + i",
        ),
    ),
    "shield": (("--shield",), dict(default="on", choices=SHIELD, help="the shield on or off (default: %(default)s)")),
    "obstacles": (
        ("--obstacles",),
        dict(
            default="objects",
            choices=CHOICES["obstacles"],
            help="what the shield knows (launched graph only): the world file's objects, the OctoMap built from the "
            "world's depth cameras, both, or sensed (the static objects plus the OctoMap for what moves)",
        ),
    ),
    "launch": (
        ("--launch",),
        dict(
            type=launch_item,
            action="append",
            default=[],
            metavar="NAME=VALUE",
            help="an argument of launch/moverl.launch for the launched graph, e.g. --launch camera_rate=30 --launch "
            "obstacle_poses=tracker --launch mode=realtime; repeatable",
        ),
    ),
    "task": (
        ("--task",),
        dict(
            type=task_item,
            action="append",
            default=[],
            metavar="KEY=VALUE",
            help="override a key of config/env.yaml, e.g. --task start_noise=0 (starts uniform over the whole "
            "joint range); repeatable",
        ),
    ),
    "graph": (
        ("--graph",),
        dict(
            default="auto",
            choices=GRAPH,
            help="attach to $ROS_MASTER_URI's graph or launch one on a free port (auto: attach if it serves MoveRL)",
        ),
    ),
    "recover": (
        ("--recover",),
        dict(
            default="auto",
            choices=RECOVER,
            help="when a component of the graph fails, end the episode and relaunch the graph at the next reset "
            "instead of stopping (auto: on when the env launches its graph with the simulator, never with "
            "a real robot); every relaunch is logged",
        ),
    ),
    "log_folder": (("--log-folder",), dict(default="runs", help="where the run's folder goes (default: %(default)s)")),
    "hyperparams": (
        ("--hyperparams",),
        dict(type=Path, default=None, help="YAML keyed by env id (default: src/moverl_gym/config/hyperparams/)"),
    ),
    "checkpoint_freq": (
        ("--checkpoint-freq",),
        dict(
            type=_count(0),
            default=10000,
            metavar="STEPS",
            help="env steps (over every parallel env) between checkpoints in <run>/checkpoints/ (0: none; "
            "default: %(default)s)",
        ),
    ),
    "no_progress": (("--no-progress",), dict(action="store_true", help="no progress bar")),
    "device": (("--device",), dict(default="cpu", help="torch device of the learner (default: %(default)s)")),
    "video": (
        ("--video",),
        dict(
            type=_count(0),
            default=0,
            metavar="N",
            help="record N evaluation episodes of the trained policy to <run>/videos (mp4)",
        ),
    ),
}
#: The options of the training front-ends (train.py, rllib_train.py), in the order of their --help.
TRAINING = (
    "env",
    "algo",
    "seed",
    "n_timesteps",
    "n_envs",
    "shield",
    "obstacles",
    "task",
    "graph",
    "recover",
    "log_folder",
    "hyperparams",
    "checkpoint_freq",
    "no_progress",
    "device",
    "video",
)


def add(parser: argparse.ArgumentParser, *names: str, **changes: dict) -> None:
    """Add the shared options `names` to parser.

    Args:
        parser: the front-end's parser (or an argument group).
        names: keys of OPTIONS.
        changes: per option name, add_argument keywords that replace the shared ones for this front-end (a default
            such as evaluate.py's "as trained", its help, more flags); the choices and types stay the shared ones.
    """
    for name in names:
        flags, kwargs = OPTIONS[name]
        kwargs = dict(kwargs)
        change = dict(changes.get(name, {}))
        flags = flags + tuple(change.pop("flags", ()))
        if {"choices", "type"} & set(change):
            raise ValueError(f"option {name}: its choices and type are shared (moverl_gym.options.OPTIONS)")
        kwargs.update(change)
        parser.add_argument(*flags, dest=name, **kwargs)
    unknown = set(changes) - set(names)
    if unknown:
        raise ValueError(f"changes for options not added: {sorted(unknown)}")


def refuse(parser: argparse.ArgumentParser, args: argparse.Namespace, cannot: dict) -> None:
    """Exit through parser.error (status 2) when an option the front-end cannot honour is given.

    Args:
        cannot: option name -> (the values it can honour, why not the others). An option whose value is not among
            them is refused with the reason.
    """
    for name, (honoured, why) in cannot.items():
        value = getattr(args, name)
        if value not in honoured:
            flag = OPTIONS[name][0][-1]
            shown = " ".join(value) if isinstance(value, list) else value
            parser.error(f"{flag} {shown}: {why}")
