"""The study's pure functions on small synthetic run folders, and (live) `study.py --quick` end to end."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from moverl_gym import study
from moverl_gym.training import EPISODE_FIELDS

pytestmark = pytest.mark.live

STUDY = Path(__file__).resolve().parents[1] / "scripts" / "study.py"


def make_run(
    root: Path, scenario: str, shield: str, seed: int, success, contacts, length=50, finished=True, wall=100.0
):
    name = study.run_name("ppo", study.env_id(scenario), shield, seed)
    folder = root / name
    folder.mkdir(parents=True)
    with open(folder / "episodes.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=EPISODE_FIELDS)
        w.writeheader()
        for i, (s, c) in enumerate(zip(success, contacts)):
            row = {k: 0 for k in EPISODE_FIELDS}
            row.update(
                episode=i + 1,
                timesteps=(i + 1) * length,
                length=length,
                success=int(s),
                contacts=int(c),
                interventions=2 if shield == "on" else 0,
                replanned=1 if shield == "on" else 0,
                **{"return": 10.0 * s - 5},
            )
            w.writerow(row)
    (folder / "config.yaml").write_text(f"task:\n  start_noise: {0.5 if seed < 5 else 0.0}\nhyperparams: {{}}\n")
    if finished:
        steps = len(success) * length
        (folder / "summary.json").write_text(json.dumps({"wall_time": wall, "steps_per_second": steps / wall}))
    return folder


def test_names():
    assert study.env_id("table") == "MoveRL/PandaReachTable-v0"
    assert study.env_id("case", "EE") == "MoveRL/PandaReachCaseEE-v0"
    assert study.scenario_of("MoveRL/PandaReachHumanEE-v0") == "human"
    assert study.run_name("ppo", "MoveRL/PandaReachCase-v0", "on", 2) == "ppo_PandaReachCase-v0_on_s2"
    with pytest.raises(ValueError):
        study.scenario_of("CartPole-v1")


def test_smooth_and_grid():
    np.testing.assert_allclose(study.smooth([1, 3, 5, 7], 2), [1, 2, 4, 6])
    np.testing.assert_allclose(study.smooth([1, 2, 3], 1), [1, 2, 3])
    assert study.smooth([], 5).size == 0
    c = study.curve_on_grid([100, 200, 300], [0, 1, 0], [0, 100, 150, 300, 400], window=1)
    assert np.isnan(c[0]) and np.isnan(c[-1])
    np.testing.assert_allclose(c[1:4], [0, 0.5, 0])
    agg = study.aggregate_curves([[0, 1, np.nan], [2, 3, np.nan]])
    np.testing.assert_allclose(agg["mean"][:2], [1, 2])
    np.testing.assert_allclose(agg["min"][:2], [0, 1])
    assert list(agg["n"]) == [2, 2, 0] and np.isnan(agg["mean"][2])


def test_read_episodes_empty(tmp_path):
    p = tmp_path / "episodes.csv"
    p.write_text(",".join(EPISODE_FIELDS) + "\n")
    data = study.read_episodes(p)
    assert set(data) == set(EPISODE_FIELDS) and data["success"].size == 0
    p.write_text("episode,success,return\n1,True,-1.5\n2,0,\n")
    data = study.read_episodes(p)
    np.testing.assert_allclose(data["success"], [1, 0])
    assert data["return"][0] == -1.5 and np.isnan(data["return"][1])
    assert study.read_episodes(tmp_path / "none.csv") == {}


def test_summarize_table_and_missing(tmp_path):
    make_run(tmp_path, "table", "on", 0, success=[0] * 100 + [1] * 200, contacts=[0] * 300)
    make_run(tmp_path, "table", "on", 1, success=[0] * 100 + [1] * 100 + [0] * 100, contacts=[0] * 300, wall=300)
    make_run(tmp_path, "table", "off", 0, success=[1] * 300, contacts=[3] * 300)
    make_run(tmp_path, "case", "off", 0, success=[1] * 10, contacts=[1] * 10, finished=False)
    (tmp_path / "logs").mkdir()
    (tmp_path / "not_a_run").mkdir()
    runs = study.load_runs(tmp_path)
    assert [(r.scenario, r.shield, r.seed, r.finished) for r in runs] == [
        ("table", "on", 0, True),
        ("table", "on", 1, True),
        ("table", "off", 0, True),
        ("case", "off", 0, False),
    ]
    assert study.success_last(runs[1], 200) == pytest.approx(0.5)
    rows = study.summarize(runs, last=200)
    assert [(r["scenario"], r["shield"]) for r in rows] == [("table", "on"), ("table", "off")]
    on, off = rows
    assert on["success_last_mean"] == pytest.approx(0.75) and on["success_last_std"] == pytest.approx(0.25)
    assert on["contacts_total"] == 0 and on["runs_with_contacts"] == 0
    assert on["interventions_total"] == 2 * 600 and on["replanned_total"] == 600
    assert on["wall_time_mean"] == pytest.approx(200) and on["wall_time_max"] == pytest.approx(300)
    assert off["contacts_total"] == 900 and off["contacts_per_episode"] == pytest.approx(3.0)
    md = study.markdown_table(rows)
    assert "| table | on | 2 (0 1) | 75.0 ± 25.0 % |" in md and md.count("\n") == 4
    study.write_csv(rows, tmp_path / "out" / "results.csv")
    back = list(csv.DictReader(open(tmp_path / "out" / "results.csv")))
    assert back[1]["contacts_total"] == "900"
    assert len(study.settings_groups(runs)) == 1
    make_run(tmp_path, "human", "on", 7, success=[1], contacts=[0])
    groups = study.settings_groups(study.load_runs(tmp_path))
    assert sorted(len(v) for v in groups.values()) == [1, 4]
    missing = study.missing_runs(tmp_path, ["table", "case"], ["on", "off"], [0, 1])
    assert missing == [
        "ppo_PandaReachTable-v0_off_s1",
        "ppo_PandaReachCase-v0_on_s0",
        "ppo_PandaReachCase-v0_on_s1",
        "ppo_PandaReachCase-v0_off_s0",
        "ppo_PandaReachCase-v0_off_s1",
    ]


def test_figures(tmp_path):
    rng = np.random.default_rng(0)
    for sc in ("table", "case"):
        for seed in (0, 1):
            make_run(
                tmp_path / "runs", sc, "on", seed, success=rng.random(200) < np.linspace(0, 1, 200), contacts=[0] * 200
            )
            make_run(
                tmp_path / "runs",
                sc,
                "off",
                seed,
                success=rng.random(190) < np.linspace(0, 1, 190),
                contacts=rng.poisson(np.linspace(20, 1, 190)),
            )
    runs = study.load_runs(tmp_path / "runs")
    for fn, name in ((study.plot_contacts, "fig6.png"), (study.plot_learning, "fig7.png")):
        p = fn(runs, tmp_path / name)
        assert p.exists() and p.stat().st_size > 10000
    assert study.plot_contacts([], tmp_path / "empty.png").exists()


def test_parse_args_quick(tmp_path):
    sys.path.insert(0, str(STUDY.parent))
    try:
        import importlib

        mod = importlib.import_module("study")
    finally:
        sys.path.remove(str(STUDY.parent))
    a = mod.parse_args(["--quick", "--out", str(tmp_path)])
    assert a.scenarios == ["table"] and a.seeds == [0] and a.n_timesteps == 1000 and a.docs == tmp_path
    a = mod.parse_args([])
    assert a.scenarios == list(study.SCENARIOS) and a.seeds == [0, 1, 2] and a.n_timesteps == 40000
    assert a.out.name == "study" and a.docs.parts[-2:] == ("docs", "study")


def test_study_quick(tmp_path):
    """Live (2 short trainings, own graphs): study.py --quick trains, then writes figures and tables; rerun skips."""
    out = tmp_path / "q"
    proc = subprocess.run(
        [sys.executable, str(STUDY), "--quick", "--out", str(out)], capture_output=True, text=True, timeout=170
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    for f in ("fig6_contacts.png", "fig7_learning.png", "results.md", "results.csv"):
        assert (out / f).exists() and (out / f).stat().st_size > 0, f
    for shield in ("on", "off"):
        run = out / f"ppo_PandaReachTable-v0_{shield}_s0"
        for f in ("episodes.csv", "summary.json", "config.yaml", "model.zip"):
            assert (run / f).exists(), run / f
    rows = {r["shield"]: r for r in csv.DictReader(open(out / "results.csv"))}
    assert rows["on"]["contacts_total"] == "0", "the shield let a contact through"
    assert "study.py --quick --out" in (out / "results.md").read_text()
    again = subprocess.run(
        [sys.executable, str(STUDY), "--quick", "--out", str(out)], capture_output=True, text=True, timeout=60
    )
    assert again.returncode == 0 and "every run is finished" in again.stdout, again.stdout + again.stderr


def test_study_hard_starts_tiny(tmp_path):
    """Live, CI size of the hard-start study (docs/study/hard_starts): SAC + HER on the table's goal id, starts uniform
    over the whole joint range (--task start_noise=0), shield on; the run records the setting, the report is written."""
    out = tmp_path / "h"
    cmd = [sys.executable, str(STUDY), "--quick", "--algo", "sac", "--variant", "Goal", "--task", "start_noise=0"]
    cmd += ["--shields", "on", "-n", "300", "--out", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=170)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    run = out / "sac_PandaReachTableGoal-v0_on_s0"
    config = (run / "config.yaml").read_text()
    assert "start_noise: 0" in config and "HerReplayBuffer" in config
    rows = list(csv.DictReader(open(out / "results.csv")))
    assert len(rows) == 1 and rows[0]["contacts_total"] == "0"
    assert "--variant Goal --task start_noise=0" in (out / "results.md").read_text()
