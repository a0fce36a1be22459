"""A night-long run survives a failed graph (train.py launches its own graph on a free port).

The simulator is killed (SIGKILL) in the middle of a PPO run. With recovery on (train.py's default with the simulator)
the episode ends, the graph is relaunched at the next reset, the run finishes its steps, and the restart is in the
episode log and the summary. With recovery off the run stops with a clear error.
"""

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from moverl_gym import proctree

pytestmark = pytest.mark.live

TRAIN = Path(__file__).resolve().parents[1] / "scripts" / "train.py"
STEPS = 1000


def train_and_kill_the_simulator(tmp_path, recover: str):
    cmd = [
        sys.executable,
        str(TRAIN),
        "--algo",
        "ppo",
        "-n",
        str(STEPS),
        "--seed",
        "2",
        "--log-folder",
        str(tmp_path),
        "--no-progress",
        "--checkpoint-freq",
        "0",
        "--recover",
        recover,
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    episodes = tmp_path / "ppo_PandaReachTable-v0_on_s2" / "episodes.csv"
    deadline = time.monotonic() + 120
    killed = None
    while time.monotonic() < deadline and proc.poll() is None:
        if episodes.exists() and len(episodes.read_text().splitlines()) > 3:  # training is under way
            sims = [p.pid for p in proctree.tree(proc.pid) if "sim_node" in proctree.cmdline(p.pid)]
            assert len(sims) == 1, sims
            os.kill(sims[0], signal.SIGKILL)
            killed = sims[0]
            break
        time.sleep(0.2)
    assert killed, "the run did not get under way"
    out, err = proc.communicate(timeout=300)
    return proc.returncode, out, err, episodes


def test_recovery_on_finishes_the_run_and_logs_the_restart(tmp_path):
    code, out, err, episodes = train_and_kill_the_simulator(tmp_path, "on")
    assert code == 0, err[-3000:]
    assert "graph failures: 1" in out, out
    rows = list(csv.DictReader(open(episodes)))
    failed = [r for r in rows if r["graph_failure"] == "1"]
    assert len(failed) == 1, rows
    assert int(rows[-1]["graph_restarts"]) == 1
    assert sum(int(r["length"]) for r in rows) <= STEPS
    assert all(int(r["contacts"]) == 0 for r in rows)
    print("\n" + [line for line in out.splitlines() if line.startswith("graph failures")][0])


def test_recovery_off_stops_with_a_clear_error(tmp_path):
    code, out, err, _ = train_and_kill_the_simulator(tmp_path, "off")
    assert code != 0
    # Whichever call the kill lands in (a connection refused, or closed while the answer was awaited), the error says
    # that the graph went down, not only which call failed.
    assert "MoveRLError" in err and "graph is down" in err, err[-3000:]
