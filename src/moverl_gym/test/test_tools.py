"""Unit tests of the pure functions of tools/collision_audit.py and tools/planner_benchmark.py (no ROS)."""

import math
from pathlib import Path

import numpy as np
import pytest

from moverl_gym.paths import load_script

pytestmark = pytest.mark.core

TOOLS = Path(__file__).resolve().parents[1] / "tools"


def _load(name):
    return load_script(TOOLS / f"{name}.py")


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
    assert "| table | random | 3 |" in md and "obstacles: objects" in md and "`case` skipped" in md
    md = audit.format_markdown([row], "cmd", obstacles="octomap")
    assert md.startswith("# Collision audit (octomap mode)") and "OctoMap built from the world's depth cameras" in md
    assert row["kind"] == "random"
    assert "(my_arm)" in audit.format_markdown([row], "cmd", robot="my_arm")


def _wall(lo=0.5, hi=0.505):
    """A thin wall across joint 0 in a toy 2-joint configuration space: collides for lo <= q0 <= hi."""
    return lambda q: lo <= q[0] <= hi


def test_bisect_boundary_brackets_the_contact():
    collides = _wall()
    out, inside, evaluations = audit.bisect_boundary(collides, [0.0, 0.0], [0.502, 0.3], 1e-6)
    assert not collides(out) and collides(inside)
    assert np.max(np.abs(inside - out)) <= 1e-6 and abs(inside[0] - 0.5) < 1e-6
    assert 15 <= evaluations <= 25


def test_segment_states_respect_the_step():
    s = audit.segment_states([0.0, 0.0], [0.1, -0.05], 0.03)
    assert s.shape == (5, 2) and np.allclose(s[0], 0) and np.allclose(s[-1], [0.1, -0.05])
    assert np.max(np.abs(np.diff(s, axis=0))) <= 0.03


def test_crossing_through_a_thin_wall_has_scene_free_ends():
    collides = _wall()

    def scene_free(q):
        return not (0.49 <= q[0] <= 0.515)  # the scene pads the wall by 1 cm

    lower, upper = [-1.0, -1.0], [1.0, 1.0]
    q0, q1, span = audit.crossing_through(collides, scene_free, [0.5001, 0.0], [1.0, 0.3], lower, upper)
    for q in (q0, q1):
        assert not collides(q) and scene_free(q)
    assert q0[0] < 0.49 and q1[0] > 0.515
    assert span == pytest.approx(0.005, abs=4e-3)  # to two steps of 2e-3 rad
    assert any(collides(q) for q in audit.segment_states(q0, q1, 1e-4))

    # no crossing when the obstacle is too thick along that line, or a side leaves the joint limits
    assert audit.crossing_through(_wall(-0.5, 0.7), scene_free, [0.5, 0.0], [1.0, 0.0], lower, upper) is None
    assert audit.crossing_through(collides, scene_free, [0.5001, 0.99], [0.01, 1.0], lower, upper) is None


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
    return {
        "world": world,
        "planner": planner,
        "solved": solved,
        "planning_time": t,
        "path_length": length if solved else float("nan"),
        "straight_length": 1.0,
        "path_valid": solved,
    }


def test_summarize_and_rank():
    rows = [
        _row("w", "A", 1, 0.01, 2.0),
        _row("w", "A", 0, 0.1, 0),
        _row("w", "B", 1, 0.05, 1.0),
        _row("w", "B", 1, 0.03, 3.0),
        _row("w", "C", 1, 0.02, 1.0),
        _row("w", "C", 1, 0.02, 1.0),
        _row("w", "D", 0, 0.2, 0),
        _row("w", "D", 0, 0.1, 0),
    ]
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


# ----------------------------------------------------------------------------- pushing policy
push = _load("pushing_policy_audit")


def test_pushing_policy_drives_straight_at_the_target_at_full_speed():
    rng = np.random.default_rng(0)
    pol = push.PushingPolicy([np.array([1.0, -0.5, 0.0])], np.array([0.1, 0.1, 0.2]), rng, noise=0.0, switch=50)
    a = pol.act(np.zeros(3))
    assert np.allclose(a, [1.0, -0.5, 0.0])  # largest need at full speed, the others in proportion
    assert np.allclose(pol.act([0.995, -0.5, 0.0]), [0.05, 0.0, 0.0])  # close: exactly what is left
    pol.feedback(True)
    pol.feedback(True)
    assert np.allclose(pol.act(np.zeros(3)), [0.25, -0.125, 0.0])  # held twice: creeping at a quarter
    for _ in range(10):
        pol.feedback(True)
    assert pol.scale == push.PushingPolicy.MIN_SCALE
    pol.feedback(False)
    assert pol.scale == 2 * push.PushingPolicy.MIN_SCALE
    pol.reset()
    assert pol.scale == 1.0
    noisy = push.PushingPolicy([np.ones(3)], np.full(3, 0.1), rng, noise=0.5)
    assert all(np.all(np.abs(noisy.act(np.zeros(3))) <= 1.0) for _ in range(100))
    with pytest.raises(ValueError):
        push.PushingPolicy([], np.ones(3), rng)


def test_pushing_targets_penetrate_and_spread_over_objects():
    # a toy world: object "wall" where q0 > 0.5 (depth grows with q0), object "floor" where q1 < -0.8
    def contacts(q):
        out = {}
        if q[0] > 0.5:
            out[("link", "wall")] = 0.1 * (q[0] - 0.5)
        if q[1] < -0.8:
            out[("link", "floor")] = 0.1
        return out

    rng = np.random.default_rng(1)
    targets, per = push.pushing_targets(contacts, [0.0, 0.0], [-1.0, -1.0], [1.0, 1.0], rng, n=40, tries=4000)
    assert set(per) == {"wall", "floor"} and per["wall"] == per["floor"] == 20
    assert all(any(d >= push.MIN_DEPTH for d in contacts(q).values()) for q in targets)
    assert all(q[0] >= 0.55 or q[1] < -0.8 for q in targets)  # deep enough


# ----------------------------------------------------------------------------- map wait probe
def test_closes_by_watch_splits_the_closes_the_scene_reports_beyond_their_watch():
    probe = _load("map_wait_probe")
    period = 1 / 30
    batches = [(k * period, 0, False) for k in range(10)] + [(12 * period, 500_000, True), (13 * period, 7, False)]
    out = probe.closes_by_watch(batches)
    assert out["beyond_watch"] == {"closes": 1, "turned_median": 500_000.0, "turned_max": 500_000, "over_100k": 1}
    assert out["others"] == {"closes": 11, "turned_median": 0.0, "turned_max": 7, "over_100k": 0}
