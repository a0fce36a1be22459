#!/usr/bin/env python3
"""Check launch/moverl.launch's arguments before roslaunch starts anything (moverl_gym.launch_args).

moverl.launch runs this as a command param, with every argument it was given, while roslaunch reads the file:

    check_launch_args.py --launch-file <moverl.launch> 'world:=table' 'obstacles:=objects' ...

It prints the checked arguments as YAML (the param's value, /moverl/launch_args); a wrong one is reported on stderr
with the valid names or choices and exits 1, and roslaunch then starts nothing. roslaunch ignores command-line
arguments that the launch file does not declare, so with --launch-file the names on the command line of the roslaunch
that runs this check are checked too, when it was asked to launch that file itself (not when rostest or another launch
file includes it: their own arguments are theirs).
"""

import argparse
import os
import sys
import types
from pathlib import Path

import yaml

# moverl_gym's modules without its __init__, which imports gymnasium to register the env ids: 0.3 s on every roslaunch,
# and Debian's python3 (catkin's) has no gymnasium. A package object whose path is the source package stands in.
if "moverl_gym" not in sys.modules:
    _pkg = types.ModuleType("moverl_gym")
    _pkg.__path__ = [str(Path(__file__).resolve().parents[1] / "src" / "moverl_gym")]
    sys.modules["moverl_gym"] = _pkg
from moverl_gym.launch_args import LaunchArgError, check  # noqa: E402


def roslaunch_arg_names(launch_file: Path, pid: int) -> list[str]:
    """The names of the ``name:=value`` arguments on process pid's command line, if that process (roslaunch) was
    asked to launch launch_file itself; [] otherwise (rostest, a launch file that includes it, another program)."""
    try:
        argv = [a.decode(errors="replace") for a in Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0") if a]
        cwd = os.readlink(f"/proc/{pid}/cwd")
    except OSError:
        return []
    files = [a for a in argv if ":=" not in a and a.endswith((".launch", ".test", ".xml"))]
    if len(files) != 1 or Path(cwd, files[0]).resolve() != launch_file.resolve():
        return []
    # roslaunch's own remappings and private parameters (__name:=, _param:=) start with "_".
    return [a.split(":=", 1)[0] for a in argv if ":=" in a and not a.startswith("_")]


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--launch-file", type=Path, help="also check the names given to the roslaunch that runs this")
    p.add_argument("args", nargs="*", metavar="name:=value")
    opts = p.parse_args(argv)
    given = {}
    for a in opts.args:
        name, sep, value = a.partition(":=")
        if not sep:
            p.error(f"expected name:=value, got {a!r}")
        given[name] = value
    if opts.launch_file is not None:
        for name in roslaunch_arg_names(opts.launch_file, os.getppid()):
            given.setdefault(name, "")  # a name the file does not declare: check() refuses it
    try:
        values = check(given)
    except LaunchArgError as exc:
        sys.stderr.write(f"\n{exc}\n\n")
        return 1
    sys.stdout.write(yaml.safe_dump(values, default_flow_style=False))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
