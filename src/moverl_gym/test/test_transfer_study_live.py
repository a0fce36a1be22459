"""Live, CI size of the transfer experiment (issue 25): transfer_study.py --quick trains PPO on the human world's file
for 300 steps and in the sensed mode for 100, evaluates the first in lockstep with the world file and both in the cell
(30 Hz cameras, the simulated tracker, real time), and writes the report: the evaluations read the tracker (track ages
in the JSON), the shield lets no contact through; a second call finds everything done."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.live

SCRIPT = Path(__file__).resolve().parents[1] / "tools" / "transfer_study.py"


def test_transfer_study_quick(tmp_path):
    out, docs = tmp_path / "runs", tmp_path / "docs"
    cmd = [sys.executable, str(SCRIPT), "--quick", "--out", str(out), "--docs", str(docs)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=400)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    rows = {(r["policy"], r["condition"]): r for r in csv.DictReader(open(docs / "runs.csv"))}
    assert set(rows) == {("world_file", "world_file"), ("world_file", "cell"), ("sensed30", "cell")}
    for (policy, cond), r in rows.items():
        assert int(r["contacts_total"]) == 0, f"{policy} in {cond}: the shield let a contact through"
        e = json.loads(Path(r["json"]).read_text())
        assert e["episodes"] == 2 and e["deterministic"]
        if cond == "cell":
            assert e["launch"] == {"camera_rate": "30", "obstacle_poses": "tracker", "mode": "realtime"}
            assert e["obstacles"] == "sensed" and 0.05 <= e["mean_track_age"] < 0.5, e["mean_track_age"]
        else:
            assert e["launch"] == {} and e["mean_track_age"] is None
    text = (docs / "results.md").read_text()
    assert "transfer_study.py --quick" in text and "| world_file | cell | 1 |" in text
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert again.returncode == 0, again.stdout[-3000:] + again.stderr[-3000:]
    assert "training: 0 runs" in again.stdout and "0 in lockstep, 0 in real time" in again.stdout, again.stdout
