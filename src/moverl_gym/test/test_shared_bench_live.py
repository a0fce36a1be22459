"""shared_bench under safety:=ssm (issue 53), on the live graph: the person's hand reaching into the robot's space at
2.0 m/s (ISO 13855's hand speed), the map of five cameras at 30 Hz, lockstep; a scripted policy that drives the joints
straight at the goal and keeps pushing while the shield holds it (tools/sensed_reach_probe.py, whose long run is
docs/sensed_person/shared_bench_probe).

* ssm: no contact while the robot moves (the person may touch it at rest), and the goal is still reached in some
  episodes: ISO's margins leave room while the hand rests.

Real time is measured, not tested here: how many of the instants the map takes depends on the machine
(2026-12-07: two of the first seven runs fell behind, 2.3 and 3.75 clouds per batch, where about 20 others made
4.95-5.0), so tools/map_wait_probe.py prints it and its committed run is docs/sensed_person/map_wait/realtime_30hz.json;
which instant the integrator takes whole is gtested (PendingClouds.*).
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
