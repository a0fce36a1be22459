"""Unit tests of the pure functions of scripts/collision_audit.py and scripts/planner_benchmark.py (no ROS)."""

import importlib.util
import math
from pathlib import Path

import numpy as np

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"


def _load(name):
    spec = importlib.util.spec_from_file_location(name, SCRIPTS / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


audit = _load("collision_audit")
bench = _load("planner_benchmark")


# ----------------------------------------------------------------------------- collision audit
def test_classify_overall_and_splits():
    c = audit.new_counts()
    assert audit.classify(c, False, False, audit.VALID) == "agree_free"
    assert audit.classify(c, True, False, audit.SELF) == "agree_collide"
    assert audit.classify(c, False, True, audit.VALID) == "missed"
    assert audit.classify(c, False, False, audit.WORLD) == "false_alarm"
    assert audit.classify(c, True, False, audit.INVALID) == "invalid"
    assert c["samples"] == 5 and c["invalid_requests"] == 1
    assert (c["missed"], c["false_alarm"], c["agree_free"], c["agree_collide"]) == (1, 1, 1, 1)
    assert c["world_missed"] == 1 and c["world_false_alarm"] == 1 and c["self_missed"] == 0
    # the world split only counts samples the scene found self-free (3 valid/world outcomes)
    assert c["world_checked"] == 3


def test_self_contact_reported_as_world_is_not_a_safety_miss():
    c = audit.new_counts()
    assert audit.classify(c, True, True, audit.WORLD) == "agree_collide"
    assert c["missed"] == 0 and c["self_missed"] == 1 and c["world_missed"] == 0


def test_unnamed_self_pairs_are_order_insensitive():
    c = audit.new_counts()
    audit.classify(c, True, False, audit.SELF, [("b", "a"), ("c", "d")], [("a", "b")])
    assert c["self_pairs_unnamed"] == 1


def test_finish_row_and_outputs():
    c = audit.new_counts()
    for outcome in (audit.VALID, audit.VALID, audit.SELF):
        audit.classify(c, False, False, outcome)
    row = audit.finish_row("table", c, 0.05, 0, self_gaps=[0.019, 0.02], world_gaps=[])
    assert math.isclose(row["false_alarm_rate_of_free"], 1 / 3, rel_tol=1e-3)
    assert row["fa_self_gap_mm_p50"] == 19.5 and row["fa_self_gap_mm_max"] == 20.0
    assert math.isnan(row["fa_world_gap_mm_p50"])
    assert set(row) == set(audit.FIELDS)
    assert "table" in audit.format_table([row])
    md = audit.format_markdown([row], "cmd", skipped=[("case", "missing")])
    assert "| table | 3 |" in md and "obstacles: objects" in md and "`case` skipped" in md
    md = audit.format_markdown([row], "cmd", obstacles="octomap")
    assert md.startswith("# Collision audit (octomap mode)") and "OctoMap built from the world's depth cameras" in md


# ----------------------------------------------------------------------------- planner benchmark
def test_pair_kinds_mix():
    k = bench.pair_kinds(50, 0.5)
    assert len(k) == 50 and k.count("short") == 25 and k[:2] == ["long", "short"]
    assert bench.pair_kinds(4, 0.0) == ["long"] * 4
    assert bench.pair_kinds(4, 1.0) == ["short"] * 4


def test_short_goal_stays_close_and_within_limits():
    rng = np.random.default_rng(0)
    lo, hi = np.array([-1.0, 0.0]), np.array([1.0, 0.1])
    for _ in range(100):
        a = rng.uniform(lo, hi)
        b = bench.short_goal(a, lo, hi, rng)
        assert np.all(b >= lo) and np.all(b <= hi) and np.all(np.abs(b - a) <= bench.SHORT_DELTA + 1e-12)


def _row(world, planner, solved, t, length):
    return {"world": world, "planner": planner, "solved": solved, "planning_time": t,
            "path_length": length if solved else float("nan"), "straight_length": 1.0, "path_valid": solved}


def test_summarize_and_rank():
    rows = [_row("w", "A", 1, 0.01, 2.0), _row("w", "A", 0, 0.1, 0), _row("w", "B", 1, 0.05, 1.0),
            _row("w", "B", 1, 0.03, 3.0), _row("w", "C", 1, 0.02, 1.0), _row("w", "C", 1, 0.02, 1.0),
            _row("w", "D", 0, 0.2, 0), _row("w", "D", 0, 0.1, 0)]
    s = bench.summarize(rows, time_limit=0.1)
    by = {(x["world"], x["planner"]): x for x in s}
    assert by[("w", "A")]["solved_rate"] == 0.5 and by[("all", "A")]["problems"] == 2
    assert by[("w", "B")]["time_median_solved"] == 0.04
    assert by[("w", "D")]["over_limit"] == 1 and math.isnan(by[("w", "D")]["time_median_solved"])
    # B and C solve everything; C is faster; D solves nothing and is last
    assert [x["planner"] for x in bench.rank(s)] == ["C", "B", "A", "D"]
    assert "C" in bench.format_summary(s, 0.1)


def test_rank_ties_on_time_broken_by_length():
    rows = [_row("w", "A", 1, 0.02, 2.0), _row("w", "B", 1, 0.02, 1.0)]
    assert bench.rank(bench.summarize(rows, 0.1))[0]["planner"] == "B"


def test_estimate_grows_with_the_work():
    e = bench.estimate_seconds(50, 10, 3, 0.1)
    assert 150 < e < 300
    assert bench.estimate_seconds(50, 10, 3, 0.2) > e
