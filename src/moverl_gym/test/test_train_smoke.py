"""Smoke test of train.py (launches its own graph on a free port): a few hundred steps of PPO, SAC and TD3,
unmodified, with the shield on; the run folder holds the CSV, TensorBoard events, model, config and summary."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

TRAIN = Path(__file__).resolve().parents[1] / "scripts" / "train.py"


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3"])
def test_train_smoke(tmp_path, algo):
    cmd = [sys.executable, str(TRAIN), "--algo", algo, "-n", "300", "--seed", "1", "--log-folder", str(tmp_path),
           "--no-progress", "--checkpoint-freq", "0"]
    if algo != "ppo":  # off-policy: start learning after 100 steps so that gradient updates run in the smoke test
        hp = tmp_path / f"{algo}.yml"
        hp.write_text(yaml.safe_dump({"default": {"policy": "MlpPolicy", "learning_starts": 100, "batch_size": 64,
                                                  "buffer_size": 1000}}))
        cmd += ["--hyperparams", str(hp)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    run = tmp_path / f"{algo}_PandaReachTable-v0_on_s1"
    assert "ground-truth contacts (physics): 0" in proc.stdout, proc.stdout
    assert (run / "model.zip").exists()
    config = yaml.safe_load((run / "config.yaml").read_text())
    assert config["algo"] == algo and config["shield"] is True and config["n_timesteps"] == 300
    rows = list(csv.DictReader(open(run / "episodes.csv")))
    assert rows, "at least one finished episode (episodes last at most 100 steps)"
    assert all(int(r["contacts"]) == 0 for r in rows)
    assert sum(int(r["length"]) for r in rows) <= 300
    assert list(run.glob("events.out.tfevents.*")), "TensorBoard events"
    summary = json.loads((run / "summary.json").read_text())
    assert summary["contacts"] == 0 and summary["steps_per_second"] > 0
