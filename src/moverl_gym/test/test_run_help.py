"""./run.sh: the command list, and every command's help (--help and -h) instead of running it.

run.sh sources env.sh, and a sourced script sees the positional parameters of whoever sources it: ROS's setup script
once received run.sh's arguments, and `./run.sh train --help` printed only "setup.sh.XXXX: line 1: usage:: command not
found". The commands are read from run.sh's own header, so a new command needs a help check here.
"""

import re
import subprocess

import pytest

from moverl_gym.paths import repo_root

pytestmark = pytest.mark.core

RUN = repo_root() / "run.sh"
COMMANDS = re.findall(r"^#   \./run\.sh (\w+)", RUN.read_text(), flags=re.M)
#: What each command's help starts with: the usage of the program the command runs.
USAGE = {
    "demo": "usage: ./run.sh demo [train.py options]",
    "test": "Every MoveRL test, in tiers",
    "lint": "Style checks: clang-format",
    "bench": "usage: benchmark.py",
    "train": "usage: train.py",
    "rllib": "usage: rllib_train.py",
    "scaling": "usage: scaling.py",
    "study": "usage: study.py",
    "eval": "usage: evaluate.py",
}
#: Commands whose help takes seconds (their scripts import SB3 / RLlib first): -h is asked of the others only (run.sh
#: treats -h and --help alike; the programs' argparse and usage functions too).
SLOW = ("demo", "train", "rllib")


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(RUN), *args], capture_output=True, text=True, timeout=120)


def test_every_command_has_a_help_check():
    assert sorted(COMMANDS) == sorted(USAGE)


@pytest.mark.parametrize(
    "command,flag", [(c, f) for c in USAGE for f in ("--help", "-h") if f == "--help" or c not in SLOW]
)
def test_command_help(command, flag):
    r = run(command, flag)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(USAGE[command]), r.stdout[:300]
    assert "command not found" not in r.stderr and "setup.sh" not in r.stderr, r.stderr


def test_command_list():
    for args, code, out in ((("--help",), 0, "stdout"), (("-h",), 0, "stdout"), ((), 2, "stderr")):
        r = run(*args)
        text = getattr(r, out)
        assert r.returncode == code and all(f"./run.sh {c}" in text for c in COMMANDS), (args, r)
    r = run("trian")
    assert r.returncode == 2 and "no command 'trian'" in r.stderr and "./run.sh train" in r.stderr


def test_unknown_options_of_test_and_lint_are_refused():
    # They used to be ignored: `./run.sh test --no-lvie` ran every tier (an hour).
    for command, option in (("test", "--no-lvie"), ("lint", "--fx")):
        r = run(command, option)
        assert r.returncode == 2 and f"unknown option '{option}'" in r.stderr, r
