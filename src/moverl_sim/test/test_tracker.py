"""The tracker model (moverl_sim.tracker): measurement times, latency, noise, bursty dropouts, options. No roscore."""

import math
import statistics

import pytest

from moverl_sim.tracker import MAX_BACKLOG, Tracker, TrackerOptions, TrackerOptionsError

pytestmark = pytest.mark.core

OPTIONS = dict(
    rate=30.0, latency=0.05, noise=0.01, dropout=0.2, dropout_burst=4.0, seed=3, fault="none", fault_offset=0.0
)


def walk(t):
    """Two objects: one moving along y at 0.1 m/s, one still."""
    return {"a": (0.8, 0.1 * t, 0.4, 0.0, 0.0, 0.0, 1.0), "b": (0.5, -0.3, 0.2, 0.0, 0.0, 0.0, 1.0)}


def run(options, seconds, step=0.05):
    tracker = Tracker(["a", "b"], TrackerOptions(**options))
    out, now = [], 0.0
    while now < seconds:
        now += step
        delivered = tracker.advance(now, walk)
        for m in delivered:
            assert m.stamp + options["latency"] <= now + 1e-12, "delivered before its latency passed"
        out += [(now, m) for m in delivered]
    return tracker, out


def test_measured_at_the_rate_delivered_after_the_latency_with_the_noise():
    opts = dict(OPTIONS, dropout=0.0)
    tracker, out = run(opts, 60.0)
    stamps = sorted({m.stamp for _, m in out if m.id == "a"})
    gaps = [b - a for a, b in zip(stamps, stamps[1:])]
    assert max(abs(g - 1 / 30) for g in gaps) < 1e-9  # every measurement, on the grid k / rate
    # delivered at the first advance() at or after stamp + latency: never earlier, at most one call later
    delays = [now - m.stamp for now, m in out]
    assert min(delays) >= 0.05 - 1e-12 and max(delays) <= 0.05 + 0.05 + 1e-9
    errors = [m.pose[1] - walk(m.stamp)["a"][1] for _, m in out if m.id == "a"]
    assert abs(statistics.mean(errors)) < 0.001
    assert statistics.pstdev(errors) == pytest.approx(0.01, rel=0.05)
    assert all(m.pose[3:] == (0.0, 0.0, 0.0, 1.0) for _, m in out)  # orientation as measured


def test_dropouts_have_the_long_run_fraction_and_come_in_bursts():
    tracker, out = run(OPTIONS, 600.0)
    assert tracker.dropped / (2 * tracker.taken) == pytest.approx(0.2, abs=0.02)
    stamps = sorted(m.stamp for _, m in out if m.id == "a")
    runs = [round((b - a) * 30) - 1 for a, b in zip(stamps, stamps[1:]) if (b - a) * 30 > 1.5]
    assert statistics.mean(runs) == pytest.approx(4.0, rel=0.15)  # mean burst length: dropout_burst


def test_seeded_and_noise_free_when_asked():
    _, one = run(OPTIONS, 5.0)
    _, two = run(OPTIONS, 5.0)
    assert one == two
    _, exact = run(dict(OPTIONS, noise=0.0, dropout=0.0, latency=0.0), 2.0)
    assert all(m.pose == walk(m.stamp)[m.id] for _, m in exact)


@pytest.mark.parametrize("start", [0.0, 0.1])
def test_what_it_measured_at_a_reset_of_the_truth_is_taken_again_from_the_new_truth(start):
    """The simulator's reset teleports the objects at time `at` (their motions restart): the measurements stamped at
    or after it, taken before the teleport and not delivered yet, are dropped and taken again from the new truth;
    the ones before it are delivered as they were."""
    opts = dict(OPTIONS, noise=0.0, dropout=0.0, latency=0.1)
    tracker = Tracker(["a", "b"], TrackerOptions(**opts), start=start)
    at = start + 45 / 30  # a measurement time, as the sum the tracker computes it from
    now = 0.0
    while now < at:  # up to the reset's instant: the measurement due then is taken, from the old truth
        now = min(at, now + 0.05)
        tracker.advance(now, walk)
    assert any(m.stamp == at for _, m in tracker._pending)

    def moved(t):  # after the teleport: every object 1 m further along x
        return {oid: (p[0] + 1.0, *p[1:]) for oid, p in walk(t).items()}

    # Pending: the measurements of the last 0.1 s (the latency), 2 objects each; the ones at `at` are dropped.
    waiting = [m for _, m in tracker._pending if m.stamp < at]
    assert len(waiting) >= 2
    assert tracker.retake_from(at) == 2
    delivered = []
    while now < at + 1.0:
        now += 0.05
        delivered += tracker.advance(now, moved)
    before = [m for m in delivered if m.stamp < at]
    after = [m for m in delivered if m.stamp >= at]
    assert before == waiting and all(m.pose == walk(m.stamp)[m.id] for m in before)
    assert min(m.stamp for m in after) == at  # taken again
    assert all(m.pose == moved(m.stamp)[m.id] for m in after)
    stamps = sorted(m.stamp for m in delivered if m.id == "a")
    assert max(abs(b - a - 1 / 30) for a, b in zip(stamps, stamps[1:])) < 1e-9  # none twice, none missed


def test_a_clock_that_jumps_does_not_flood():
    tracker = Tracker(["a", "b"], TrackerOptions(**dict(OPTIONS, dropout=0.0, latency=0.0)))
    out = tracker.advance(100.0, walk)
    assert len(out) <= 2 * (MAX_BACKLOG * 30 + 1)
    assert min(m.stamp for m in out) >= 100.0 - MAX_BACKLOG - 1e-9


@pytest.mark.parametrize(
    "change, says",
    [
        (dict(rate=0.0), "rate"),
        (dict(latency=-0.1), "latency"),
        (dict(noise=math.nan), "noise"),
        (dict(dropout_burst=0.5), "dropout_burst"),
        (dict(dropout=0.9), "dropout must be a fraction in [0, 0.8)"),
        (dict(dropout=-0.1), "dropout"),
    ],
)
def test_bad_options_are_refused_naming_the_key(change, says):
    with pytest.raises(TrackerOptionsError, match=r"tracker\." + says.split()[0]) as err:
        TrackerOptions.from_dict(dict(OPTIONS, **change))
    assert says in str(err.value)


def test_unknown_and_missing_keys_are_refused_naming_the_keys():
    with pytest.raises(TrackerOptionsError, match="unknown key.*rates.*missing key.*rate.*the keys: rate, latency"):
        opts = dict(OPTIONS)
        opts["rates"] = opts.pop("rate")
        TrackerOptions.from_dict(opts, "~tracker")


def test_config_sim_yaml_has_valid_options():
    """The simulator's and the stand-in's model: config/sim.yaml's tracker section."""
    from pathlib import Path

    import yaml

    cfg = yaml.safe_load((Path(__file__).resolve().parents[3] / "config" / "sim.yaml").read_text())
    opts = TrackerOptions.from_dict(cfg["tracker"], "config/sim.yaml tracker")
    assert opts.latency > 0 and opts.noise > 0 and opts.dropout > 0  # a tracker, not the script


def test_a_lying_tracker_freezes_or_offsets_what_it_reports():
    """tracker/fault (a test of what a lie can do): frozen repeats each object's first pose with fresh stamps, offset
    moves every position by fault_offset along y; a fault it does not know is refused naming the valid ones."""
    exact = dict(OPTIONS, dropout=0.0, noise=0.0)
    _, frozen = run(dict(exact, fault="frozen"), 3.0)
    a = [m for _, m in frozen if m.id == "a"]
    assert len(a) > 60 and {m.pose for m in a} == {walk(0.0)["a"]}, "the walk at 0.1 m/s reported still"
    assert a[-1].stamp > 2.8, "freshly stamped"
    _, offset = run(dict(exact, fault="offset", fault_offset=0.5), 1.0)
    for _, m in offset:
        truth = walk(m.stamp)[m.id]
        assert m.pose[1] == pytest.approx(truth[1] + 0.5) and m.pose[0] == truth[0]
    with pytest.raises(TrackerOptionsError, match="fault must be one of none, frozen, offset"):
        TrackerOptions(**dict(OPTIONS, fault="lying")).check()
