"""Smoke test of train.py (launches its own graph on a free port): a few hundred steps of PPO, SAC and TD3,
unmodified, with the shield on; the run folder holds the CSV, TensorBoard events, model, config and summary."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

pytestmark = pytest.mark.live

TRAIN = Path(__file__).resolve().parents[1] / "scripts" / "train.py"


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3"])
def test_train_smoke(tmp_path, algo):
    cmd = [
        sys.executable,
        str(TRAIN),
        "--algo",
        algo,
        "-n",
        "300",
        "--seed",
        "1",
        "--log-folder",
        str(tmp_path),
        "--no-progress",
        "--checkpoint-freq",
        "0",
    ]
    if algo != "ppo":  # off-policy: start learning after 100 steps so that gradient updates run in the smoke test
        hp = tmp_path / f"{algo}.yml"
        hp.write_text(
            yaml.safe_dump(
                {"default": {"policy": "MlpPolicy", "learning_starts": 100, "batch_size": 64, "buffer_size": 1000}}
            )
        )
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


EVALUATE = TRAIN.parent / "evaluate.py"


def test_train_two_envs_then_evaluate(tmp_path):
    """--n-envs 2: two env processes, each with its own graph, seeded seed + i, both logged per env in episodes.csv;
    evaluate.py reads the output; no process of either graph (nor the env processes) outlives the run."""
    from moverl_gym.proctree import TreeWatch

    cmd = [
        sys.executable,
        str(TRAIN),
        "--algo",
        "ppo",
        "-n",
        "400",
        "--n-envs",
        "2",
        "--seed",
        "5",
        "--log-folder",
        str(tmp_path),
        "--no-progress",
        "--checkpoint-freq",
        "0",
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    with TreeWatch(proc.pid) as watch:
        try:
            out, err = proc.communicate(timeout=300)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    assert proc.returncode == 0, err[-3000:]
    sims = watch.matching("sim_node __name:=sim ")  # the node re-executes itself with the venv's python
    assert len(sims) == 2, f"one simulator per env process: {watch.cmdlines}"
    left = watch.wait_gone(30)
    assert not left, f"processes of the run still running: {left}"
    run = tmp_path / "ppo_PandaReachTable-v0_on_s5"
    config = yaml.safe_load((run / "config.yaml").read_text())
    assert config["n_envs"] == 2 and config["env_seeds"] == [5, 6]
    rows = list(csv.DictReader(open(run / "episodes.csv")))
    assert {r["env"] for r in rows} == {"0", "1"}, rows
    for e in ("0", "1"):  # each env's own episodes: its steps add up to at most its share
        assert sum(int(r["length"]) for r in rows if r["env"] == e) <= 200
    assert all(int(r["contacts"]) == 0 for r in rows)
    assert "2 envs" in out and "ground-truth contacts (physics): 0" in out, out
    # The two envs started from different seeds: their first episodes differ.
    first = {e: next(r for r in rows if r["env"] == e) for e in ("0", "1")}
    assert first["0"]["return"] != first["1"]["return"], first

    ev = subprocess.run(
        [sys.executable, str(EVALUATE), str(run), "--episodes", "2"], capture_output=True, text=True, timeout=180
    )
    assert ev.returncode == 0, ev.stderr[-3000:]
    result = json.loads((run / "eval.json").read_text())
    assert result["episodes"] == 2 and result["contacts_total"] == 0 and result["algo"] == "ppo"
