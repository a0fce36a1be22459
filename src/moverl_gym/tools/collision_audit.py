#!/usr/bin/env python3
"""Collision parity audit: the planning scene's verdicts against the physics engine's ground truth, for any robot.

    python src/moverl_gym/tools/collision_audit.py --worlds table human case -n 10000
    python src/moverl_gym/tools/collision_audit.py --robot-config my_arm.yaml --worlds table case -n 10000
    python src/moverl_gym/tools/collision_audit.py --worlds table human case -n 10000 --obstacles octomap

Run it on your own arm before trusting the shield with it (README, "Checking your own arm"). First it compares the
link shapes themselves (moverl_gym.geometry_parity: every point of PyBullet's shape of a link must be inside the
scene's shape of that link; printed per link). Then, for each world, in
its own process and ROS graph (launch/moverl.launch with the robot config, on a free port), and a moverl_sim
Simulator built in this process from the same robot config and world file (contacts_now(): the contacts the
simulator counts, i.e. penetrating contacts, adjacent links excluded), it compares:

  random       n configurations uniform within the joint limits: /planning_scene/check_state vs physics
  boundary     near-boundary states: bisection in physics between a random free and a random colliding
               configuration down to --boundary-tol rad; the state just inside contact (penetrating by a hair)
               and the one just outside are both checked. The inside ones are where a scene shape smaller than
               the simulator's shows first.
  paths        short random straight paths (each joint moves up to --path-length rad) from scene-free states:
               /planning_scene/check_path vs physics sampled every --path-step rad along the path
  crossings    straight paths whose two ends are free (physics free, scene free) but which pass through a
               contact in between: through a near-boundary contact state (bisection towards a state colliding with
               the world, if any) along a random direction, both ways until free. Their contacts are short (grazing
               passes, thin obstacles such as the case's 5 mm walls, link edges): the path check's sampling must
               not step over them. Every one must be flagged by check_path.
  states       configurations listed in --states (YAML list of joint vectors), e.g. states that once went wrong

    MISSED       physics collides, scene says free      -> a contact the shield would let through (must be 0)
    false alarm  physics free, scene says collision     -> conservatism (padding, convex hulls)

The false-alarm rate is false alarms / physics-free samples: the share of actions the shield refuses that the
simulator would have allowed (random: about the padding's share of the free space; boundary (outside): nearly all,
since those states are a hair from contact). Self/world split: the scene checks self collisions first and the
world only when self-free, so the world split counts only samples the scene found self-free; a split miss on a
sample the scene still rejects is not a safety miss (the exit code counts only overall misses).

Obstacle modes (--obstacles, the launch arg): objects (the world file's shapes) or octomap (the scene knows only
what the world's depth cameras saw at start-up, robot at home) or both. The ground truth is the same physics.

Writes <out>/audit[_<robot>][_<mode>].csv and .md (one row per world and kind; <robot> for a robot config other
than the default one). Exit code 1 if anything was missed.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

from moverl_gym.launch_args import CHOICES
from moverl_gym.workers import run_json_worker
from moverl_sim.robot_config import load_robot_config

# CheckState / CheckPath outcomes (moverl_msgs)
VALID, SELF, WORLD, INVALID = 0, 1, 2, 3

KINDS = ("random", "boundary_inside", "boundary_outside", "paths", "crossings", "states")
KIND_NOTES = {
    "random": "uniform random configurations",
    "boundary_inside": "near-boundary states, contact side (physics penetrates by a hair)",
    "boundary_outside": "near-boundary states, free side (a hair from contact)",
    "paths": "short random straight paths (check_path vs physics sampled densely)",
    "crossings": "straight paths with free ends through a short contact (grazing passes, thin walls)",
    "states": "configurations from --states",
}

FIELDS = [
    "world",
    "kind",
    "samples",
    "invalid_requests",
    "physics_collide",
    "scene_collide",
    "missed",
    "false_alarm",
    "agree_collide",
    "agree_free",
    "false_alarm_rate_of_free",
    "self_physics",
    "self_scene",
    "self_missed",
    "self_false_alarm",
    "world_checked",
    "world_physics",
    "world_scene",
    "world_missed",
    "world_false_alarm",
    "self_pairs_unnamed",
    "fa_self_gap_mm_p50",
    "fa_self_gap_mm_max",
    "fa_world_gap_mm_p50",
    "fa_world_gap_mm_max",
    "check_ms_p50",
    "seed",
]

MODE_NOTES = {
    "objects": "obstacles: objects (the scene checks the world file's shapes, padded).",
    "octomap": (
        "obstacles: octomap (the scene knows no object: only the occupied cells of the OctoMap built from "
        "the world's depth cameras at start-up, robot at home, self-filtered; robot links padded against "
        "the cells). Unknown (never seen) cells count as the world's sensing: says (unknown_occupied, occupied by "
        "default)."
    ),
    "both": "obstacles: both (the world file's shapes plus the OctoMap from the depth cameras).",
    "sensed": (
        "obstacles: sensed (the world file's static shapes, exactly; everything that moves only as the OctoMap "
        "from the depth cameras, with the world's predictive margin, given per world in the notes)."
    ),
}

assert set(MODE_NOTES) == set(CHOICES["obstacles"]), "a note per obstacle mode (moverl_gym.launch_args.CHOICES)"


# ----------------------------------------------------------------------------- pure functions (tested)
def new_counts() -> dict:
    return {
        k: 0
        for k in FIELDS
        if k not in ("world", "kind", "false_alarm_rate_of_free", "check_ms_p50", "seed") and not k.startswith("fa_")
    }


def classify(counts: dict, phys_self: bool, phys_world: bool, outcome: int, phys_self_pairs=(), scene_pairs=()) -> str:
    """Add one sample to counts; returns its class: 'invalid', 'missed', 'false_alarm', 'agree_collide'
    or 'agree_free'. phys_self_pairs / scene_pairs: iterables of (a, b) name pairs (any order)."""
    counts["samples"] += 1
    if outcome == INVALID:
        counts["invalid_requests"] += 1
        return "invalid"
    phys = phys_self or phys_world
    scene = outcome in (SELF, WORLD)
    counts["physics_collide"] += phys
    counts["scene_collide"] += scene
    # self split (all samples: self is always checked)
    counts["self_physics"] += phys_self
    counts["self_scene"] += outcome == SELF
    counts["self_missed"] += phys_self and outcome != SELF
    counts["self_false_alarm"] += (not phys_self) and outcome == SELF
    if phys_self and outcome == SELF:
        named = {tuple(sorted(p)) for p in scene_pairs}
        counts["self_pairs_unnamed"] += sum(tuple(sorted(p)) not in named for p in phys_self_pairs)
    # world split (only where the scene went on to check the world)
    if outcome != SELF:
        counts["world_checked"] += 1
        counts["world_physics"] += phys_world
        counts["world_scene"] += outcome == WORLD
        counts["world_missed"] += phys_world and outcome != WORLD
        counts["world_false_alarm"] += (not phys_world) and outcome == WORLD
    if phys and not scene:
        counts["missed"] += 1
        return "missed"
    if scene and not phys:
        counts["false_alarm"] += 1
        return "false_alarm"
    key = "agree_collide" if phys else "agree_free"
    counts[key] += 1
    return key


def gap_stats(gaps) -> tuple:
    """(p50, max) in mm of a list of distances in metres; NaN when empty."""
    if not len(gaps):
        return float("nan"), float("nan")
    s = sorted(gaps)
    mid = len(s) // 2
    p50 = s[mid] if len(s) % 2 else 0.5 * (s[mid - 1] + s[mid])
    return round(1e3 * p50, 2), round(1e3 * s[-1], 2)


def finish_row(
    world: str, counts: dict, check_ms_p50: float, seed: int, self_gaps=(), world_gaps=(), kind: str = "random"
) -> dict:
    row = {"world": world, "kind": kind, **counts}
    row["fa_self_gap_mm_p50"], row["fa_self_gap_mm_max"] = gap_stats(list(self_gaps))
    row["fa_world_gap_mm_p50"], row["fa_world_gap_mm_max"] = gap_stats(list(world_gaps))
    free = counts["false_alarm"] + counts["agree_free"]
    row["false_alarm_rate_of_free"] = round(counts["false_alarm"] / free, 4) if free else float("nan")
    row["check_ms_p50"] = round(check_ms_p50, 4)
    row["seed"] = seed
    return row


def fa_pairs_note(world: str, top, false_alarms: int) -> str:
    """One line: the pairs (closest flagged pair per false alarm) behind most false alarms of a world."""
    if not top:
        return f"{world}: no false alarms"
    parts = [
        f"{pair} {cnt} ({cnt / max(false_alarms, 1):.0%}, physics gap p50 {p50:.1f} mm, max {mx:.1f} mm)"
        for pair, cnt, p50, mx in top
    ]
    return f"{world}: false alarms (random states) mostly from " + "; ".join(parts)


def _rate(r: dict) -> str:
    rate = r["false_alarm_rate_of_free"]
    return "-" if rate != rate else f"{100 * rate:.1f}%"  # NaN: no physics-free sample


def format_table(rows) -> str:
    """Plain-text table for the terminal."""
    head = (
        f"{'world':10s} {'kind':16s} {'samples':>8s} {'phys coll':>9s} {'scene coll':>10s} {'MISSED':>7s} "
        f"{'false al.':>9s} {'% of free':>9s} {'self miss':>9s} {'world miss':>10s} {'invalid':>7s}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r['world']:10s} {r.get('kind', 'random'):16s} {r['samples']:8d} {r['physics_collide']:9d} "
            f"{r['scene_collide']:10d} {r['missed']:7d} {r['false_alarm']:9d} {_rate(r):>9s} "
            f"{r['self_missed']:9d} {r['world_missed']:10d} {r['invalid_requests']:7d}"
        )
    return "\n".join(lines)


def format_markdown(rows, command: str, skipped=(), extra_notes=(), obstacles: str = "objects", robot: str = "") -> str:
    title = "" if obstacles == "objects" else f" ({obstacles} mode)"
    who = f" ({robot})" if robot else ""
    out = [
        f"# Collision audit{title}{who}: planning scene vs physics ground truth",
        "",
        "Command:",
        "",
        f"    {command}",
        "",
        "Per world and kind of sample (see the script's header): the scene's verdict "
        "(`/planning_scene/check_state`, or `check_path` for paths, as configured in config/planning_scene.yaml) "
        "against the simulator's contacts "
        "(`moverl_sim.Simulator.contacts_now()`: penetrating contacts, adjacent links excluded; paths sampled "
        "densely) with the same robot config and world file.",
        "",
        "| world | kind | samples | physics collide | scene collide | **missed** | false alarms | false alarms, % "
        "of physics-free | self missed | self false alarms | world missed | world false alarms | invalid |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        rate = _rate(r).replace("%", " %")
        out.append(
            f"| {r['world']} | {r.get('kind', 'random')} | {r['samples']} | {r['physics_collide']} | "
            f"{r['scene_collide']} | **{r['missed']}** | {r['false_alarm']} | {rate} | "
            f"{r['self_missed']} | {r['self_false_alarm']} | {r['world_missed']} | "
            f"{r['world_false_alarm']} | {r['invalid_requests']} |"
        )
    out += [
        "",
        "- **missed**: physics collides, scene says free (a contact the shield would allow; must be 0).",
        "- **false alarm**: physics free, scene says collision (conservatism: world padding, self padding, "
        "convex hulls); the rate is over the physics-free samples.",
        "- kinds: " + "; ".join(f"{k}: {v}" for k, v in KIND_NOTES.items()) + ".",
        "- self split over all samples; world split only over samples the scene found self-free (the scene "
        "checks self first and stops). A self-split miss on a sample the scene rejects for the world is not "
        "a safety miss.",
        f"- {MODE_NOTES[obstacles]}",
    ]
    for w, why in skipped:
        out.append(f"- world `{w}` skipped: {why}")
    out += [f"- {n}" for n in extra_notes]
    return "\n".join(out) + "\n"


def bisect_boundary(collides, q_free, q_coll, tol: float):
    """Bisection on the straight segment between q_free (collides() False) and q_coll (True) until the two ends are
    within tol (max-norm, rad). Returns (outside, inside, evaluations): the last free and the first colliding state."""
    import numpy as np

    lo, hi = np.asarray(q_free, dtype=float), np.asarray(q_coll, dtype=float)
    evaluations = 0
    while np.max(np.abs(hi - lo)) > tol:
        mid = 0.5 * (lo + hi)
        evaluations += 1
        if collides(mid):
            hi = mid
        else:
            lo = mid
    return lo, hi, evaluations


def segment_states(q0, q1, step: float):
    """States from q0 to q1 (both included), no joint moving more than step (rad) between two of them."""
    import numpy as np

    q0, q1 = np.asarray(q0, dtype=float), np.asarray(q1, dtype=float)
    n = max(1, int(np.ceil(np.max(np.abs(q1 - q0)) / step)))
    return q0 + np.linspace(0.0, 1.0, n + 1)[:, None] * (q1 - q0)


def crossing_through(
    collides,
    scene_free,
    q_contact,
    direction,
    lower,
    upper,
    step: float = 2e-3,
    max_span: float = 1.0,
    max_beyond: float = 0.2,
):
    """A straight path through a contact whose two ends are free, for the scene to check.

    From q_contact (colliding in physics; from a near-boundary bisection it penetrates by a hair, so most lines
    through it graze the obstacle or cross it where it is thin), steps of `step` rad (largest joint motion) along
    -direction and +direction until out of contact (at most max_span rad in all) and on until a state is free in
    physics and in the scene (at most max_beyond rad further on each side). Returns (q_start, q_end, span): the two
    free ends and the length (rad, largest joint motion) of the contact interval, or None when a side leaves the
    joint limits or does not get free within those bounds."""
    import numpy as np

    q_contact = np.asarray(q_contact, dtype=float)
    d = np.asarray(direction, dtype=float)
    if not np.max(np.abs(d)) > 0:
        return None
    d = d / np.max(np.abs(d))  # max-norm 1: s is the largest joint motion
    lower, upper = np.asarray(lower), np.asarray(upper)
    ends, span = [], 0.0
    for sign in (-1.0, 1.0):
        s, exited = 0.0, None
        while True:
            s += step
            q = q_contact + sign * s * d
            if np.any(q < lower) or np.any(q > upper):
                return None
            if exited is None:
                if not collides(q):
                    exited = s
                    span += s
                elif span + s > max_span:
                    return None  # too deep to pass through here
            if exited is not None:
                if not collides(q) and scene_free(q):
                    ends.append(q)
                    break
                if s - exited > max_beyond:
                    return None
    return ends[0], ends[1], span


# ----------------------------------------------------------------------------- worker (one world, one process)
def robot_config_path(robot: str, robot_config: str | None) -> Path:
    from moverl_gym.paths import robot_config_file

    return Path(robot_config).resolve() if robot_config else robot_config_file(robot)


def make_simulator(config_path, world_path: str):
    from moverl_sim.settings import simulator_for
    from moverl_sim.world import load_world

    rc = load_robot_config(config_path)
    return simulator_for(rc, load_world(world_path))


SENSED = "octomap"  # the scene's name for the sensed map in colliding pairs


def physics_gap(sim, a: str, b: str, horizon: float = 0.2) -> float:
    """Physics distance (m) between robot link a and robot link b or world object b (SENSED: the nearest world
    object) in the current configuration (PyBullet closest points; negative when penetrating; horizon when
    farther)."""
    import pybullet

    links = sim.link_index
    if a not in links:
        a, b = b, a
    la = links[a]
    if b in links:
        targets = [(sim.robot, links[b])]
    elif b == SENSED:
        targets = list(sim.object_bodies.values())  # (body, link): grouped movers are links
    else:
        targets = [sim.object_bodies[b]]
    gaps = [
        pt[8]
        for body, lb in targets
        for pt in pybullet.getClosestPoints(
            sim.robot, body, horizon, linkIndexA=la, linkIndexB=lb, physicsClientId=sim.client_id
        )
    ]
    return min(gaps, default=horizon)


class _Audit:
    """The comparisons of one world: physics (a Simulator in this process) against the live scene's services."""

    def __init__(self, sim, check_state, check_path, seed: int, show: int):
        self.sim, self.check_state, self.check_path, self.show = sim, check_state, check_path, show
        self.counts = {k: new_counts() for k in KINDS}
        self.times = {k: [] for k in KINDS}
        self.misses: list[dict] = []
        self.physics_evaluations = 0

    def physics(self, q):
        self.sim.reset_robot(q)
        self.physics_evaluations += 1
        return self.sim.contacts_now()

    def collides(self, q) -> bool:
        st = self.physics(q)
        return bool(st.self_pairs or st.world_pairs)

    def scene_free(self, q) -> bool:
        return self.check_state(positions=[float(x) for x in q]).outcome == VALID

    def record(self, kind, q, st, res, q1=None, extra=None) -> str:
        self.times[kind].append(res.check_time)
        c = classify(
            self.counts[kind],
            bool(st.self_pairs),
            bool(st.world_pairs),
            res.outcome,
            st.self_pairs.keys(),
            [(p.a, p.b) for p in res.pairs],
        )
        if c == "missed" and len(self.misses) < self.show:
            m = {
                "kind": kind,
                "q": [round(float(x), 6) for x in q],
                "scene": int(res.outcome),
                "physics_self": {" / ".join(k): round(v, 5) for k, v in st.self_pairs.items()},
                "physics_world": {" / ".join(k): round(v, 5) for k, v in st.world_pairs.items()},
            }
            if q1 is not None:
                m["q1"] = [round(float(x), 6) for x in q1]
            m.update(extra or {})
            self.misses.append(m)
        if c == "invalid" and self.counts[kind]["invalid_requests"] <= 3:
            print(f"INVALID_REQUEST ({kind}) at {list(q)}: {res.message}", file=sys.stderr)
        return c

    def path_physics(self, q0, q1, step):
        """Physics along the straight path: the union of its contacts at states every `step` rad, and the first
        colliding state (None when free)."""
        from moverl_sim.core import ContactStats

        total, first = ContactStats(), None
        for q in segment_states(q0, q1, step):
            st = self.physics(q)
            if st.self_pairs or st.world_pairs:
                first = q if first is None else first
                for k, v in st.self_pairs.items():
                    total.self_pairs[k] = max(total.self_pairs.get(k, 0.0), v)
                for k, v in st.world_pairs.items():
                    total.world_pairs[k] = max(total.world_pairs.get(k, 0.0), v)
        return total, first


def worker(
    world_path: str,
    n: int,
    seed: int,
    robot_config: str,
    show: int,
    obstacles: str = "objects",
    boundary: int = 0,
    boundary_tol: float = 1e-5,
    paths: int = 0,
    path_length: float = 0.25,
    path_step: float = 2.5e-4,
    crossings: int = 0,
    states: list | None = None,
) -> dict:
    import numpy as np
    import rospy

    from moverl_gym import ros_backend as ros
    from moverl_gym.graph import LaunchedGraph
    from moverl_msgs.srv import CheckPath, CheckState
    from moverl_sim.world import load_world

    sim = make_simulator(robot_config, world_path)
    lower, upper = np.array(sim.lower), np.array(sim.upper)
    rng = np.random.default_rng(seed)
    Q = rng.uniform(lower, upper, size=(n, lower.size))
    # octomap/both: the scene offers its services only after integrating the cameras' first views (fail closed).
    g = LaunchedGraph(
        {"world_file": world_path, "robot_config": robot_config, "obstacles": obstacles}, wait_for=ros.REQUIRED_SERVICES
    )
    try:
        ros.init_node(g.uri)
        map_info = None
        if obstacles != "objects":
            from moverl_msgs.msg import OctomapStatus

            # one view from every camera of the world file (the scene starts once each is in)
            cameras = len(load_world(world_path).cameras)
            deadline = time.monotonic() + 30.0
            st = rospy.wait_for_message("/planning_scene/octomap_status", OctomapStatus, timeout=30)
            while st.clouds < cameras:
                if time.monotonic() > deadline:
                    raise RuntimeError(f"the scene integrated {st.clouds} of {cameras} camera views in 30 s")
                st = rospy.wait_for_message("/planning_scene/octomap_status", OctomapStatus, timeout=30)
            map_info = {"clouds": st.clouds, "occupied_leaves": st.occupied_leaves, "resolution": st.resolution}
        scene_joints = rospy.get_param("/planning_scene/joint_names", None)
        if scene_joints is not None and list(scene_joints) != list(sim.joint_names):
            raise RuntimeError(f"joint order differs: scene {scene_joints}, sim {sim.joint_names}")
        check = rospy.ServiceProxy("/planning_scene/check_state", CheckState, persistent=True)
        check_path = rospy.ServiceProxy("/planning_scene/check_path", CheckPath, persistent=True)
        if map_info is not None:
            # The predictive margin of every check below (the simulator stands still: the map's age does not change).
            map_info["sensed_margin"] = check(positions=[float(x) for x in (lower + upper) / 2]).sensed_margin
        a = _Audit(sim, check, check_path, seed, show)
        self_gaps, world_gaps, fa_pairs = [], [], {}
        free_q, coll_q, world_coll_q, scene_free_q = [], [], [], []
        t0 = time.perf_counter()
        # random states
        for q in Q:
            st = a.physics(q)
            res = check(positions=q.tolist())
            kind = a.record("random", q, st, res)
            (coll_q if (st.self_pairs or st.world_pairs) else free_q).append(q)
            if st.world_pairs:
                world_coll_q.append(q)
            if res.outcome == VALID:
                scene_free_q.append(q)
            if kind == "false_alarm" and res.pairs:
                # how far apart (in physics) is the closest pair the scene flagged: padding explains <= 2 x 8 mm
                # (self) or 10 mm (world) plus convex hull vs mesh differences
                pair_gaps = [(physics_gap(sim, pr.a, pr.b), pr.a, pr.b) for pr in res.pairs]
                gap, pa, pb = min(pair_gaps)
                (self_gaps if res.outcome == SELF else world_gaps).append(gap)
                fa_pairs.setdefault(f"{pa} / {pb}", []).append(gap)
        seconds = {"random": time.perf_counter() - t0}
        t1 = time.perf_counter()
        # near-boundary states
        for _ in range(boundary if free_q and coll_q else 0):
            qf = free_q[rng.integers(len(free_q))]
            qc = coll_q[rng.integers(len(coll_q))]
            out, inside, _ = bisect_boundary(a.collides, qf, qc, boundary_tol)
            for kind, q in (("boundary_inside", inside), ("boundary_outside", out)):
                a.record(kind, q, a.physics(q), check(positions=q.tolist()))
        seconds["boundary"], t1 = time.perf_counter() - t1, time.perf_counter()
        # short random paths from scene-free states
        for _ in range(paths if scene_free_q else 0):
            q0 = scene_free_q[rng.integers(len(scene_free_q))]
            q1 = np.clip(q0 + rng.uniform(-path_length, path_length, size=q0.size), lower, upper)
            st, first = a.path_physics(q0, q1, path_step)
            a.record(
                "paths",
                q0,
                st,
                check_path(start=q0.tolist(), goal=q1.tolist()),
                q1,
                None if first is None else {"first_contact": [round(float(x), 6) for x in first]},
            )
        seconds["paths"], t1 = time.perf_counter() - t1, time.perf_counter()
        # paths through a contact (grazing passes, thin walls, link edges) with free ends
        spans, attempts, found = [], 0, 0
        targets = world_coll_q or coll_q  # world contacts first: the obstacles
        while found < crossings and free_q and targets and attempts < 20 * max(crossings, 1):
            attempts += 1
            qf = free_q[rng.integers(len(free_q))]
            _, contact, _ = bisect_boundary(a.collides, qf, targets[rng.integers(len(targets))], boundary_tol)
            st = a.physics(contact)  # right after the bisection: PyBullet's cached contacts make a hair's breadth
            if not (st.self_pairs or st.world_pairs):  # depend on the previous query
                continue
            hit = crossing_through(a.collides, a.scene_free, contact, rng.normal(size=contact.size), lower, upper)
            if hit is None:
                continue
            q0, q1, span = hit
            found += 1
            spans.append(span)
            a.record(
                "crossings",
                q0,
                st,
                check_path(start=q0.tolist(), goal=q1.tolist()),
                q1,
                {"contact": [round(float(x), 6) for x in contact], "span_rad": span},
            )
        seconds["crossings"] = time.perf_counter() - t1
        # given states
        for q in states or []:
            q = np.asarray(q, dtype=float)
            a.record("states", q, a.physics(q), check(positions=q.tolist()))
        check.close()
        check_path.close()
        wall = time.perf_counter() - t0
    finally:
        g.close()
        sim.close()
    world = Path(world_path).stem
    rows = []
    for kind in KINDS:
        c = a.counts[kind]
        if c["samples"] == 0:
            continue
        t = a.times[kind]
        rows.append(
            finish_row(
                world,
                c,
                float(np.median(t) * 1e3) if t else float("nan"),
                seed,
                self_gaps if kind == "random" else (),
                world_gaps if kind == "random" else (),
                kind,
            )
        )
    top = sorted(fa_pairs.items(), key=lambda kv: -len(kv[1]))[:5]
    crossing_info = {
        "found": found,
        "attempts": attempts,
        "span_rad_p50": float(np.median(spans)) if spans else float("nan"),
        "span_rad_min": float(np.min(spans)) if spans else float("nan"),
    }
    return {
        "rows": rows,
        "misses": a.misses,
        "wall_s": wall,
        "map": map_info,
        "crossings": crossing_info,
        "physics_evaluations": a.physics_evaluations,
        "seconds": {k: round(v, 1) for k, v in seconds.items()},
        "fa_pairs": [[k, len(v), *gap_stats(v)] for k, v in top],
    }


# ----------------------------------------------------------------------------- main
def run_world(world_path: str, args) -> dict:
    return run_json_worker(
        __file__,
        [
            "--worker",
            world_path,
            "-n",
            args.n,
            "--seed",
            args.seed,
            "--robot-config",
            str(robot_config_path(args.robot, args.robot_config)),
            "--show",
            args.show,
            "--obstacles",
            args.obstacles,
            "--boundary",
            args.boundary,
            "--boundary-tol",
            args.boundary_tol,
            "--paths",
            args.paths,
            "--path-length",
            args.path_length,
            "--path-step",
            args.path_step,
            "--crossings",
            args.crossings,
            *(["--states", args.states] if args.states else []),
        ],
        f"audit worker for {world_path}",
    )


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--worlds", nargs="+", default=["table"], help="world names (worlds/<name>.yaml) or paths")
    p.add_argument("-n", type=int, default=10000, help="random configurations per world")
    p.add_argument("--boundary", type=int, default=1000, help="near-boundary bisections per world (2 states each)")
    p.add_argument("--boundary-tol", type=float, default=1e-5, help="bisection stops at this joint distance (rad)")
    p.add_argument("--paths", type=int, default=500, help="short random paths per world")
    p.add_argument("--path-length", type=float, default=0.25, help="each joint moves up to this much (rad) per path")
    p.add_argument(
        "--path-step",
        type=float,
        default=2.5e-4,
        help="physics samples along paths and crossings every this many rad of the largest joint motion",
    )
    p.add_argument("--crossings", type=int, default=200, help="paths through a contact with free ends per world")
    p.add_argument("--states", help="YAML file: a list of configurations to check as well")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--robot", default="panda", help="config/robots/<robot>.yaml")
    p.add_argument("--robot-config", help="a robot config file (format of config/robots/*.yaml); overrides --robot")
    p.add_argument("--show", type=int, default=5, help="print the first this many misses per world")
    p.add_argument("--out", default=None, help="output folder (default: <repo>/docs/audit)")
    p.add_argument(
        "--obstacles",
        choices=CHOICES["obstacles"],
        default="objects",
        help="where the scene's obstacles come from (launch arg obstacles): the world file's objects, "
        "the OctoMap built from the world's depth cameras, or both",
    )
    p.add_argument("--worker", help=argparse.SUPPRESS)
    return p


def command_line(args, defaults) -> str:
    """The command that reproduces this run (options that differ from the defaults)."""
    parts = ["python src/moverl_gym/tools/collision_audit.py"]
    if args.robot_config:
        parts.append(f"--robot-config {args.robot_config}")
    elif args.robot != defaults.robot:
        parts.append(f"--robot {args.robot}")
    parts.append("--worlds " + " ".join(args.worlds))
    parts.append(f"-n {args.n}")
    for name in (
        "boundary",
        "boundary_tol",
        "paths",
        "path_length",
        "path_step",
        "crossings",
        "states",
        "seed",
        "obstacles",
    ):
        if getattr(args, name) != getattr(defaults, name):
            parts.append(f"--{name.replace('_', '-')} {getattr(args, name)}")
    return " ".join(parts)


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    defaults = parser.parse_args([])

    if args.worker:
        states = None
        if args.states:
            import yaml

            with open(args.states) as f:
                states = yaml.safe_load(f)
        print(
            json.dumps(
                worker(
                    args.worker,
                    args.n,
                    args.seed,
                    args.robot_config,
                    args.show,
                    args.obstacles,
                    args.boundary,
                    args.boundary_tol,
                    args.paths,
                    args.path_length,
                    args.path_step,
                    args.crossings,
                    states,
                )
            )
        )
        return 0

    from moverl_gym.geometry_parity import compare, format_report
    from moverl_gym.paths import repo_root, world_file
    from moverl_sim.urdf import resolve_uri

    config = robot_config_path(args.robot, args.robot_config)
    robot_name = load_robot_config(config)["name"]
    default_robot = args.robot_config is None and args.robot == defaults.robot
    out_dir = Path(args.out) if args.out else repo_root() / "docs" / "audit"
    rows, skipped, all_misses, notes = [], [], {}, []
    rc = load_robot_config(config)
    print(f"comparing the link shapes of {robot_name} (scene vs PyBullet) ...", flush=True)
    geometry = compare(
        resolve_uri(rc["urdf"]), rc["joints"], rc["base_link"], rc.get("fixed_joint_positions"), seed=args.seed
    )
    print(format_report(geometry), flush=True)

    for w in args.worlds:
        path = world_file(w)
        if not path.is_file():
            print(f"note: world '{w}' skipped: {path} does not exist (yet)")
            skipped.append(
                (
                    w,
                    f"{path.relative_to(repo_root()) if path.is_relative_to(repo_root()) else path} "
                    "did not exist at audit time",
                )
            )
            continue
        print(
            f"auditing {robot_name} in {w}: {args.n} random states, {args.boundary} bisections, {args.paths} paths, "
            f"{args.crossings} crossings ...",
            flush=True,
        )
        r = run_world(str(path), args)
        for row in r["rows"]:
            row["world"] = w
        rows += r["rows"]
        all_misses[w] = r["misses"]
        random_row = next((row for row in r["rows"] if row["kind"] == "random"), None)
        notes.append(fa_pairs_note(w, r["fa_pairs"], random_row["false_alarm"] if random_row else 0))
        c = r["crossings"]
        if args.crossings:
            notes.append(
                f"{w}: {c['found']} crossings found in {c['attempts']} attempts; contact span p50 "
                f"{c['span_rad_p50']:.4f} rad, min {c['span_rad_min']:.4f} rad (largest joint motion "
                "through the contact)"
            )
        if r.get("map"):
            m = r["map"]
            notes.append(
                f"{w}: OctoMap of {m['clouds']} clouds, {m['occupied_leaves']} occupied cells of "
                f"{m['resolution']:.3f} m; sensed predictive margin {m.get('sensed_margin', 0.0):.3f} m "
                "(the false alarms above include it)"
            )
        print(
            f"  done in {r['wall_s']:.1f} s ({r['physics_evaluations']} physics states; seconds {r['seconds']})",
            flush=True,
        )

    print(f"\n== Collision audit of {robot_name}: planning scene vs PyBullet ground truth (seed {args.seed}) ==")
    if not geometry["contained"]:
        print("LINK SHAPES: some of PyBullet's link shape lies outside the scene's (table above)")
    print(format_table(rows))
    print(
        "(false al. % of free: false alarms / physics-free samples; self split over all samples, world split over "
        "scene-self-free samples)"
    )
    print(f"note: {MODE_NOTES[args.obstacles]}")
    for w, why in skipped:
        print(f"note: world '{w}' skipped: {why}")
    for note in notes:
        print("note: " + note)
    for w, ms in all_misses.items():
        for m in ms:
            print(f"MISS in {w}: {json.dumps(m)}")

    out_dir.mkdir(parents=True, exist_ok=True)
    stem = (
        "audit"
        + ("" if default_robot else f"_{robot_name}")
        + ("" if args.obstacles == "objects" else f"_{args.obstacles}")
    )
    with open(out_dir / f"{stem}.csv", "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=FIELDS)
        wr.writeheader()
        wr.writerows(rows)
    md = format_markdown(rows, command_line(args, defaults), skipped, notes, args.obstacles, robot_name)
    md += (
        "\nLink shapes (moverl_gym.geometry_parity, scene vs PyBullet at 3 configurations):\n\n```\n"
        + format_report(geometry)
        + "\n```\n"
    )
    (out_dir / f"{stem}.md").write_text(md)
    print(f"\nwrote {out_dir / (stem + '.csv')} and {out_dir / (stem + '.md')}")
    missed = sum(r["missed"] for r in rows)
    total = sum(r["samples"] for r in rows)
    ok = missed == 0 and geometry["contained"]
    print(
        f"{'OK' if ok else 'FAIL'}: {missed} missed collision(s) in {total} samples; link shapes contained: "
        f"{geometry['contained']}"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
