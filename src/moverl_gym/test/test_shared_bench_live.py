"""shared_bench under safety:=ssm (issue 53), on the live graph: the person's hand reaching into the robot's space at
2.0 m/s (ISO 13855's hand speed), the map of five cameras at 30 Hz, lockstep; a scripted policy that drives the joints
straight at the goal and keeps pushing while the shield holds it (tools/sensed_reach_probe.py, whose long run is
docs/sensed_person/shared_bench_probe).

* ssm: no contact while the robot moves (the person may touch it at rest), and the goal is still reached in some
  episodes: ISO's margins leave room while the hand rests.
* real time: the map takes each instant's five clouds as one batch of its hidden space, whatever share of the instants
  this machine integrates (tools/map_wait_probe.py).
"""

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.live

REPO = Path(__file__).resolve().parents[3]
PROBE = REPO / "src" / "moverl_gym" / "tools" / "sensed_reach_probe.py"
GOAL_Q = ["-0.034", "-0.489", "-0.561", "-2.95", "-0.421", "2.483", "-0.2"]  # worlds/shared_bench.yaml's header


def test_ssm_reaches_the_shared_goal_without_moving_into_the_person(tmp_path):
    out = tmp_path / "probe"
    args = ["--world", "shared_bench", "--camera-rates", "30", "--safety", "ssm", "--episodes", "4", "--out", out]
    proc = subprocess.run(
        [sys.executable, str(PROBE), *map(str, args), "--goal-q", *GOAL_Q],
        capture_output=True,
        text=True,
        timeout=900,
        cwd=tmp_path,
    )
    text = proc.stdout + proc.stderr
    assert (out / "probe.json").is_file(), text[-5000:]
    (row,) = json.loads((out / "probe.json").read_text())["rows"]
    print(
        f"\nssm, shared_bench, 30 Hz: {row['reached']} of {row['episodes']} reached, contacts {row['contacts']} "
        f"({row['contacts_moving']} moving), verdicts {row['verdicts']}"
    )
    assert proc.returncode == 0, text[-5000:]
    assert row["contacts_moving"] == 0, row
    assert row["reached"] >= 1, f"ISO's margins left no way to the goal: {row['verdicts']}"


def test_in_real_time_the_map_takes_each_instants_clouds_as_one_batch(tmp_path):
    """Real time, five cameras at 30 Hz, ISO's speeds: the cameras due at an instant render together, and the scene
    opens each batch at the newest instant every camera has a cloud of and closes it once (pending_clouds.h). A batch
    that misses a camera finds what only that camera sees unseen: at ISO's speeds such a close turned most of the map
    possibly occupied. Structural, not a speed target: the clouds per batch, however few batches a loaded machine
    integrates (its long run is docs/sensed_person/map_wait)."""
    out = tmp_path / "wait.json"
    probe = REPO / "src" / "moverl_gym" / "tools" / "map_wait_probe.py"
    args = ["--world", "shared_bench", "--camera-rate", "30", "--mode", "realtime", "--safety", "ssm", "--steps", "60"]
    proc = subprocess.run(
        [sys.executable, str(probe), *args, "--goal-q", *GOAL_Q, "--json", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
    )
    text = proc.stdout + proc.stderr
    assert proc.returncode == 0 and out.is_file(), text[-5000:]
    r = json.loads(out.read_text())
    print(
        f"\nreal time, 30 Hz: the cameras sent {r['clouds_sent']} clouds, the map took {r['clouds']} in {r['batches']} "
        f"batches; map age at the checks {r['map_age_s']}"
    )
    assert r["steps"] == 60
    assert r["batches"] >= 3, r
    assert r["clouds"] / r["batches"] >= 4.5, f"batches of fewer than five cameras' clouds: {r}"
