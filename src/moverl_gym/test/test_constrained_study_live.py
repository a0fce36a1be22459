"""Live, CI size of the constrained-RL comparison (issue 27): constrained_study.py --quick trains the four methods for
300 steps on the table (the shield's run in its own graph, the unshielded ones in-process), evaluates every policy in a
graph with the shield on and one with it off, writes the report; a second call finds everything done."""

import csv
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from moverl_gym import constrained_study as cs

pytestmark = pytest.mark.live

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "constrained_study.py"


def test_constrained_study_quick(tmp_path):
    out = tmp_path / "q"
    cmd = [sys.executable, str(SCRIPT), "--quick", "--out", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=170)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    for f in ("results.md", "results.csv", "deployment.csv", "runs.csv", "curves.csv", "fig_table.png", "lagrange.png"):
        assert (out / f).exists() and (out / f).stat().st_size > 0, f
    for method, spec in cs.METHODS.items():
        run = out / cs.run_name(method, "table", 0)
        for f in ("episodes.csv", "summary.json", "config.yaml", "model.zip", "eval_on.csv", "eval_off.csv"):
            assert (run / f).exists(), run / f
        assert (run / "lagrange.csv").exists() == (spec.algo == "ppolag")
        config = yaml.safe_load((run / "config.yaml").read_text())
        assert config["backend"] == ("ros" if spec.shield else "bullet") and config["n_timesteps"] == 300
        assert config["hyperparams"]["learning_rate"] == 0.0005  # the paper's PPO for every method
        if spec.knob in config["task"]:
            assert config["task"][spec.knob] == spec.default
        assert len(list(csv.DictReader(open(run / "eval_on.csv")))) == 2
    results = {r["method"]: r for r in csv.DictReader(open(out / "results.csv"))}
    assert set(results) == set(cs.METHODS)
    assert float(results["ppo_shield"]["train_contacts_mean"]) == 0, "the shield let a contact through in training"
    deployed = list(csv.DictReader(open(out / "deployment.csv")))
    assert len(deployed) == 2 * len(cs.METHODS)
    for row in deployed:
        if row["deployed_with_shield"] == "True":
            assert float(row["contacts_per_episode_mean"]) == 0, f"{row['method']} made contact with the shield on"
    assert "constrained_study.py --quick --out" in (out / "results.md").read_text()
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert again.returncode == 0, again.stdout[-3000:] + again.stderr[-3000:]
    assert "0 of 4 training runs to do" in again.stdout and "0 evaluations to do" in again.stdout, again.stdout
