"""Collision parity in CI (issue #15): for every robot config the repo ships (config/robots/*.yaml) and the test
robots (src/moverl_gym/test/robots/*.yaml), short runs of the two long audits against the live graph:

* tools/collision_audit.py on every repo world: random states, near-boundary states, short paths and paths through
  contacts; no collision the physics engine sees may be missed by the scene, and each kind must have met contacts
  (so the run tested something); the test robots' known bad states (<robot>_states.yaml) are checked too;
* tools/pushing_policy_audit.py in the case world: a policy that pushes into the obstacles makes 0 contacts with the
  shield on, and many with it off (so it does push).

The long versions (10,000 states per world, 3,000 steps) and their figures: docs/audit, docs/pushing_policy.
"""

import csv
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

pytestmark = pytest.mark.live

REPO = Path(__file__).resolve().parents[3]
TOOLS = REPO / "src" / "moverl_gym" / "tools"
TEST_ROBOTS = REPO / "src" / "moverl_gym" / "test" / "robots"
CONFIGS = sorted((REPO / "config" / "robots").glob("*.yaml")) + sorted(
    p for p in TEST_ROBOTS.glob("*.yaml") if isinstance(yaml.safe_load(p.read_text()), dict)
)
WORLDS = sorted(p.stem for p in (REPO / "worlds").glob("*.yaml"))
DEADLINE = 600  # s per script run


def _run(args, cwd):
    proc = subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True, timeout=DEADLINE, cwd=cwd)
    return proc, proc.stdout + proc.stderr


@pytest.mark.parametrize("config", CONFIGS, ids=lambda p: p.stem)
def test_collision_parity_short(config, tmp_path):
    states = TEST_ROBOTS / f"{config.stem}_states.yaml"
    args = [
        TOOLS / "collision_audit.py",
        "--robot-config",
        config,
        "--worlds",
        *WORLDS,
        "-n",
        500,
        "--boundary",
        100,
        "--paths",
        10,
        "--crossings",
        10,
        "--out",
        tmp_path,
    ]
    if states.is_file():
        args += ["--states", states]
    proc, out = _run(args, tmp_path)
    assert proc.returncode == 0, out[-5000:]
    rows = [r for f in tmp_path.glob("*.csv") for r in csv.DictReader(open(f))]
    assert {r["world"] for r in rows} == set(WORLDS), out[-3000:]
    assert sum(int(r["missed"]) for r in rows) == 0
    for world in WORLDS:
        kinds = {r["kind"]: r for r in rows if r["world"] == world}
        for kind in ("random", "boundary_inside", "crossings"):
            assert int(kinds[kind]["physics_collide"]) > 0, f"{world}: no contact among the {kind} samples\n{out}"
        assert int(kinds["paths"]["samples"]) == 10
    if states.is_file():
        given = [r for r in rows if r["kind"] == "states"]
        n = len(yaml.safe_load(states.read_text()))
        assert sum(int(r["samples"]) for r in given) == n * len(WORLDS)


@pytest.mark.parametrize("config", CONFIGS, ids=lambda p: p.stem)
def test_pushing_policy_short(config, tmp_path):
    on, out_on = _run(
        [
            TOOLS / "pushing_policy_audit.py",
            "--robot-config",
            config,
            "--worlds",
            "case",
            "--shield",
            "on",
            "--steps",
            300,
            "--out",
            tmp_path / "on",
        ],
        tmp_path,
    )
    assert on.returncode == 0, out_on[-5000:]
    off, out_off = _run(
        [
            TOOLS / "pushing_policy_audit.py",
            "--robot-config",
            config,
            "--worlds",
            "case",
            "--shield",
            "off",
            "--steps",
            100,
            "--out",
            tmp_path / "off",
        ],
        tmp_path,
    )
    assert off.returncode == 0, out_off[-5000:]
    (r_on,) = csv.DictReader(open(tmp_path / "on" / "audit.csv"))
    (r_off,) = csv.DictReader(open(tmp_path / "off" / "audit.csv"))
    assert int(r_on["contacts"]) == 0 and int(r_on["unsensed_moves"]) == 0, out_on
    assert int(r_off["contacts"]) > 0, "the pushing policy did not push into anything:\n" + out_off
