"""A person the robot sees only through its depth cameras (issue 16), short versions of the long runs in
docs/sensed_person (tools/pushing_policy_audit.py --obstacles sensed):

* the human scenario in the sensed mode (the planning scene knows the table from the world file, and the person only
  from the OctoMap built from the world's three cameras, with the predictive margin), shield on, a policy that keeps
  pushing toward the walking person and the table: no contact, in lockstep and in real time; and the policy does get
  near them (the shield discards many of its steps).

A person faster than the world's bound is not covered; test_retreat_live.py shows it with a visitor that walks into
a parked robot three times faster than declared.
"""

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.live

REPO = Path(__file__).resolve().parents[3]
AUDIT = REPO / "src" / "moverl_gym" / "tools" / "pushing_policy_audit.py"
DEADLINE = 600  # s per run


def _audit(tmp_path, world, steps, *extra):
    out = tmp_path / "out"
    args = [
        AUDIT,
        "--robot-config",
        REPO / "config" / "robots" / "panda.yaml",
        "--worlds",
        world,
        "--shield",
        "on",
        "--obstacles",
        "sensed",
    ]
    args += ["--steps", steps, "--out", out, *extra]
    proc = subprocess.run(
        [sys.executable, *map(str, args)], capture_output=True, text=True, timeout=DEADLINE, cwd=tmp_path
    )
    text = proc.stdout + proc.stderr
    assert (out / "audit.csv").is_file(), text[-5000:]
    (row,) = csv.DictReader(open(out / "audit.csv"))
    return proc, row, text


def _discarded(row):
    return sum(n for v, n in json.loads(row["verdicts"]).items() if v.startswith("discarded"))


def test_pushing_at_the_sensed_person_lockstep(tmp_path):
    proc, row, text = _audit(tmp_path, "human", 400)
    assert proc.returncode == 0, text[-5000:]
    assert int(row["contacts"]) == 0 and int(row["unsensed_moves"]) == 0, text[-5000:]
    assert _discarded(row) > 50, "the policy did not push near anything: " + row["verdicts"]


def test_pushing_at_the_sensed_person_realtime(tmp_path):
    proc, row, text = _audit(tmp_path, "human", 200, "--mode", "realtime")
    assert proc.returncode == 0, text[-5000:]
    assert int(row["contacts"]) == 0 and int(row["unsensed_moves"]) == 0, text[-5000:]
    assert _discarded(row) > 20, "the policy did not push near anything: " + row["verdicts"]
