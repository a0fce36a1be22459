"""Per-substep ground-truth contacts of a recorded stream of simulator inputs: replay, record format, comparison.

ROS-free. The contacts the simulator reports are what every safety claim rests on, so a change to how they are
computed (the simulator's hot path, how its node serves a request) must leave them exactly as they were: the same
pairs at the same physics substeps with the same depths. This module replays what a simulator node received on a live
graph (its resets and trajectories, recorded by ``src/moverl_gym/tools/record_ground_truth.py``) through a
``Simulator`` in this process and lists every contact pair counted at every substep.

``replay_by_substep`` needs nothing but the Simulator's public API (``prepare``, ``advance`` one substep at a time with
a fresh ``ContactStats`` per substep, ``finish``), the calls the simulator node made, in its order: it gave the
recorded traces with the code before issue 26's speed work, and gives them with any later code that keeps that API.

Inputs (``events``): a list of dicts, in the order the simulator served them:

* ``{"reset": [q...]}``: ``~reset_robot``: the robot teleported to q, the obstacles' motions restarted;
* ``{"execute": {"times": [...], "positions": [[...], ...]}, "stamp_ns": int}``: ``~execute`` of a trajectory
  (positions in the simulator's joint order), started at sim time ``stamp_ns`` (the recorded state's stamp; checked).

A trace is a list of ``(substep, kind, a, b, depth, moving)``: ``substep`` the simulator's running substep count after
the substep (1 = the first since start-up), ``kind`` "world" (a = robot link, b = object id) or "self" (a <= b, link
names), ``depth`` the pair's deepest penetration at that substep (m, positive), ``moving`` whether it counted as made
while the robot moved (``ContactStats.moving_pairs``). Sorted by substep, then kind, a, b.
"""

from __future__ import annotations

import gzip
import json

from .core import ContactStats

__all__ = ["replay_by_substep", "stats_rows", "compare", "load", "save"]


def stats_rows(substep: int, stats: ContactStats) -> list:
    """The trace rows of one substep's ContactStats."""
    rows = [(substep, "world", a, b, d, (a, b) in stats.moving_pairs) for (a, b), d in stats.world_pairs.items()]
    rows += [(substep, "self", a, b, d, (a, b) in stats.moving_pairs) for (a, b), d in stats.self_pairs.items()]
    rows.sort(key=lambda r: r[:4])
    return rows


def replay_by_substep(sim, events, check_stamps: bool = True) -> tuple[list, list]:
    """Replay events through sim one physics substep at a time; return (trace, per-event (pairs, substeps in contact)).

    Each execute's pairs are its distinct pairs (world + self) and substeps in contact as the node reported them for
    the whole motion (info["contacts"] and info["contact_substeps"] of the env's step). With check_stamps, every
    execute must start at its recorded sim time (ValueError otherwise: the recording missed an input)."""
    trace, counts = [], []
    for ev in events:
        if "reset" in ev:
            sim.reset_robot(ev["reset"])
            sim.restart_motions()
            continue
        if check_stamps and abs(sim.substeps_total / sim.physics_hz * 1e9 - ev["stamp_ns"]) > 1.0:
            raise ValueError(
                "execute recorded at sim time %.9f s, replayed at %.9f s: an input is missing"
                % (ev["stamp_ns"] * 1e-9, sim.sim_time)
            )
        ex = ev["execute"]
        n = len(ex["times"])
        motion = sim.prepare(ex["times"], ex["positions"], [], [[]] * n, [[]] * n)
        pairs, in_contact = set(), 0
        while not motion.done:
            motion.stats = ContactStats()
            sim.advance(motion, 1)
            rows = stats_rows(sim.substeps_total, motion.stats)
            trace += rows
            pairs.update((r[1], r[2], r[3]) for r in rows)
            in_contact += motion.stats.substeps_in_contact
        sim.finish(motion)
        counts.append((len(pairs), in_contact))
    return trace, counts


def compare(expected, actual, depth_tol: float = 1e-9) -> list:
    """Differences between two traces (empty: identical): rows missing from either side, or whose depth differs by
    more than depth_tol (m) or whose moving flag differs. Each difference is a short sentence."""
    exp = {tuple(r[:4]): r for r in expected}
    act = {tuple(r[:4]): r for r in actual}
    out = []
    for key in sorted(exp.keys() - act.keys()):
        out.append("missing %s" % (exp[key],))
    for key in sorted(act.keys() - exp.keys()):
        out.append("extra %s" % (act[key],))
    for key in sorted(exp.keys() & act.keys()):
        e, a = exp[key], act[key]
        if abs(e[4] - a[4]) > depth_tol or bool(e[5]) != bool(a[5]):
            out.append("differs: expected %s, got %s" % (e, a))
    return out


def save(path, record: dict) -> None:
    """Write a recording (a dict with "events", "trace" and anything else JSON can hold) as gzipped JSON. Floats
    are written as Python's repr, which reads back to the same double."""
    with gzip.open(path, "wt", encoding="utf-8") as f:
        json.dump(record, f, separators=(",", ":"))


def load(path) -> dict:
    """Read a recording written by save(); trace rows come back as tuples."""
    with gzip.open(path, "rt", encoding="utf-8") as f:
        record = json.load(f)
    record["trace"] = [tuple(r) for r in record["trace"]]
    return record
