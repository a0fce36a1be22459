"""A short version of tools/soak.py (the long run, 250,000 steps, is a script whose figures are in docs/soak): the
sampling works on every graph it runs (three worlds and the OctoMap mode), every process of the graph is found and
measured, and nothing leaks over the run that a short run can see: no file descriptor or process more at the end,
zero contacts. (Memory growth and latency drift need the long run: short windows on a shared 2-core machine are
noise.)"""

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.live

SOAK = Path(__file__).resolve().parents[1] / "tools" / "soak.py"
GRAPH = {"env", "rosmaster", "rosout", "sim_node", "shield_node"}  # the shield hosts the planning scene


def test_soak_short(tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            str(SOAK),
            "--steps",
            "6000",
            "--octomap-steps",
            "1200",  # >= 2 samples 200 steps apart after soak.py's 1 s warm-up (about 340 steps/s here)
            "--every",
            "200",
            "--out",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        timeout=900,
    )
    runs = json.loads((tmp_path / "soak.json").read_text())
    assert [(r["world"], r["obstacles"]) for r in runs] == [
        ("table", "objects"),
        ("human", "objects"),
        ("case", "objects"),
        ("table", "octomap"),
    ], proc.stderr
    for run in runs:
        assert len(run["samples"]) >= 2, run  # a sample after the warm-up and one at the end: the checks compare them
        first, last = run["samples"][0], run["samples"][-1]
        assert GRAPH <= set(first["processes"]), first["processes"]
        assert last["contacts"] == 0
        assert last["graph_processes"] == first["graph_processes"]
        for name, p in first["processes"].items():
            assert last["processes"][name]["fds"] <= p["fds"], (run["world"], name)
    assert (tmp_path / "soak.png").exists() and (tmp_path / "soak.md").exists()
