#!/usr/bin/env python3
"""Collision audit: the planning scene's verdict against the physics engine's ground truth.

    python src/moverl_gym/scripts/collision_audit.py --worlds table human case -n 10000
    python src/moverl_gym/scripts/collision_audit.py --worlds table human case -n 10000 --obstacles octomap

For each world, n configurations are sampled uniformly within the joint limits (fixed seed). Each one is
checked by the planning scene (/planning_scene/check_state: self + world, as the shield does) and by a
moverl_sim Simulator built in this process from the same robot config and world file (contacts_now(): the
ground truth the simulator reports as contacts, i.e. penetrating contacts, adjacent links excluded).

    MISSED       physics collides, scene says free      -> a contact the shield would let through (must be 0)
    false alarm  physics free, scene says collision     -> conservatism (padding, convex hulls)
    agreement    both free or both colliding

Split by kind. The scene checks self collisions first and the world only when the state is self-free, so
  self:  physics self contact  vs  scene SELF_COLLISION                  (all samples)
  world: physics world contact vs  scene WORLD_COLLISION                 (samples the scene found self-free)
A self-split miss whose state the scene still rejects for the world (or vice versa) is not a safety miss;
the exit code counts only overall misses. Pair level: self pairs in contact in the physics engine that the
scene did not name although it reported a self collision (ACM/pair coverage).

Obstacle modes (--obstacles, the launch arg): objects (the world file's shapes) or octomap (the scene knows only
what the world's depth cameras saw, integrated into its OctoMap; the graph starts with the robot at home, the
scene integrates the cameras' first views, then the map stays fixed while the configurations are checked: one
view per camera, the robot at home occluding what it occludes) or both. The ground truth is the same physics.

Each world runs in its own process (rospy allows one ROS master per process) with its own graph
(launch/moverl.launch on a free port). Worlds whose file does not exist are skipped with a note.

Writes docs/audit/audit.csv and audit.md (objects mode; audit_<mode>.csv / .md for the other modes), one row per
world. Exit code 1 if any miss.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

from moverl_gym.workers import run_json_worker

# CheckState outcomes (moverl_msgs/CheckState)
VALID, SELF, WORLD, INVALID = 0, 1, 2, 3

FIELDS = ["world", "samples", "invalid_requests",
          "physics_collide", "scene_collide",
          "missed", "false_alarm", "agree_collide", "agree_free", "false_alarm_rate_of_free",
          "self_physics", "self_scene", "self_missed", "self_false_alarm",
          "world_checked", "world_physics", "world_scene", "world_missed", "world_false_alarm",
          "self_pairs_unnamed", "fa_self_gap_mm_p50", "fa_self_gap_mm_max", "fa_world_gap_mm_p50",
          "fa_world_gap_mm_max", "check_ms_p50", "seed"]

MODE_NOTES = {
    "objects": "obstacles: objects (the scene checks the world file's shapes, padded).",
    "octomap": ("obstacles: octomap (the scene knows no object: only the occupied cells of the OctoMap built from "
                "the world's depth cameras at start-up, robot at home, self-filtered; robot links padded against "
                "the cells). Unknown (never seen) cells count as free."),
    "both": "obstacles: both (the world file's shapes plus the OctoMap from the depth cameras).",
}


# ----------------------------------------------------------------------------- pure functions (tested)
def new_counts() -> dict:
    return {k: 0 for k in FIELDS if k not in ("world", "false_alarm_rate_of_free", "check_ms_p50", "seed")
            and not k.startswith("fa_")}


def classify(counts: dict, phys_self: bool, phys_world: bool, outcome: int,
             phys_self_pairs=(), scene_pairs=()) -> str:
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


def finish_row(world: str, counts: dict, check_ms_p50: float, seed: int, self_gaps=(), world_gaps=()) -> dict:
    row = {"world": world, **counts}
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
    parts = [f"{pair} {cnt} ({cnt / max(false_alarms, 1):.0%}, physics gap p50 {p50:.1f} mm, max {mx:.1f} mm)"
             for pair, cnt, p50, mx in top]
    return f"{world}: false alarms mostly from " + "; ".join(parts)


def format_table(rows) -> str:
    """Plain-text table for the terminal."""
    head = (f"{'world':10s} {'samples':>8s} {'phys coll':>9s} {'scene coll':>10s} {'MISSED':>7s} "
            f"{'false al.':>9s} {'% of free':>9s} {'self miss':>9s} {'self FA':>8s} {'world miss':>10s} "
            f"{'world FA':>8s} {'unnamed':>7s} {'invalid':>7s}")
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r['world']:10s} {r['samples']:8d} {r['physics_collide']:9d} {r['scene_collide']:10d} "
                     f"{r['missed']:7d} {r['false_alarm']:9d} {100 * r['false_alarm_rate_of_free']:8.1f}% "
                     f"{r['self_missed']:9d} {r['self_false_alarm']:8d} {r['world_missed']:10d} "
                     f"{r['world_false_alarm']:8d} {r['self_pairs_unnamed']:7d} {r['invalid_requests']:7d}")
    return "\n".join(lines)


def format_markdown(rows, command: str, skipped=(), extra_notes=(), obstacles: str = "objects") -> str:
    title = "" if obstacles == "objects" else f" ({obstacles} mode)"
    out = [f"# Collision audit{title}: planning scene vs physics ground truth", "",
           "Command:", "", f"    {command}", "",
           "n random configurations per world, uniform within the joint limits (fixed seed). Scene: "
           "`/planning_scene/check_state` (self + world, as configured in config/planning_scene.yaml). Ground "
           "truth: `moverl_sim.Simulator.contacts_now()` (penetrating contacts, adjacent links excluded) with the "
           "same URDF and world file.", "",
           "| world | samples | physics collide | scene collide | **missed** | false alarms | false alarms, % of "
           "physics-free | self missed | self false alarms | world missed | world false alarms | invalid |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        out.append(f"| {r['world']} | {r['samples']} | {r['physics_collide']} | {r['scene_collide']} | "
                   f"**{r['missed']}** | {r['false_alarm']} | {100 * r['false_alarm_rate_of_free']:.1f} % | "
                   f"{r['self_missed']} | {r['self_false_alarm']} | {r['world_missed']} | "
                   f"{r['world_false_alarm']} | {r['invalid_requests']} |")
    out += ["", "- **missed**: physics collides, scene says free (a contact the shield would allow; must be 0).",
            "- **false alarm**: physics free, scene says collision (conservatism: world padding, self padding, "
            "convex hulls).",
            "- self split over all samples; world split only over samples the scene found self-free (the scene "
            "checks self first and stops). A self-split miss on a state the scene rejects for the world is not "
            "a safety miss.",
            f"- {MODE_NOTES[obstacles]}"]
    for w, why in skipped:
        out.append(f"- world `{w}` skipped: {why}")
    out += [f"- {n}" for n in extra_notes]
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------------------- worker (one world, one process)
def robot_config(robot: str) -> dict:
    import yaml

    from moverl_gym.paths import config_file

    with open(config_file(f"robots/{robot}.yaml")) as f:
        return yaml.safe_load(f)["robot"]


def make_simulator(robot: str, world_path: str):
    from moverl_sim.core import Simulator
    from moverl_sim.urdf import resolve_uri
    from moverl_sim.world import load_world

    rc = robot_config(robot)
    return Simulator(resolve_uri(rc["urdf"]), rc["joints"], rc["base_link"], rc.get("fixed_joint_positions"),
                     load_world(world_path))


SENSED = "octomap"   # the scene's name for the sensed map in colliding pairs


def physics_gap(sim, a: str, b: str, horizon: float = 0.2) -> float:
    """Physics distance (m) between robot link a and robot link b or world object b (SENSED: the nearest world
    object) in the current configuration (PyBullet closest points; negative when penetrating; horizon when
    farther). Uses the Simulator's internals (diagnostics only)."""
    import pybullet

    links = sim._link_index
    if a not in links:
        a, b = b, a
    la = links[a]
    if b in links:
        targets = [(sim.robot, links[b])]
    elif b == SENSED:
        targets = [(body, -1) for body in sim._object_bodies.values()]
    else:
        targets = [(sim._object_bodies[b], -1)]
    gaps = [pt[8] for body, lb in targets
            for pt in pybullet.getClosestPoints(sim.robot, body, horizon, linkIndexA=la, linkIndexB=lb,
                                                physicsClientId=sim._cid)]
    return min(gaps, default=horizon)


def worker(world_path: str, n: int, seed: int, robot: str, show: int, obstacles: str = "objects") -> dict:
    import numpy as np
    import rospy
    from moverl_msgs.srv import CheckState

    from moverl_sim.world import load_world

    from moverl_gym import backend as ros
    from moverl_gym.graph import LaunchedGraph

    sim = make_simulator(robot, world_path)
    lower, upper = np.array(sim.lower), np.array(sim.upper)
    rng = np.random.default_rng(seed)
    Q = rng.uniform(lower, upper, size=(n, lower.size))
    # octomap/both: the scene offers its services only after integrating the cameras' first views (fail closed).
    g = LaunchedGraph({"world_file": world_path, "robot": robot, "obstacles": obstacles},
                      wait_for=ros.REQUIRED_SERVICES)
    try:
        ros.init_node(g.uri)
        map_info = None
        if obstacles != "objects":
            from moverl_msgs.msg import OctomapStatus
            # one view from every camera of the world file (the scene starts after startup_clouds of them)
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
        counts = new_counts()
        misses, times, self_gaps, world_gaps, fa_pairs = [], [], [], [], {}
        t0 = time.perf_counter()
        for q in Q:
            sim.reset_robot(q)
            st = sim.contacts_now()
            res = check(positions=q.tolist())
            times.append(res.check_time)
            kind = classify(counts, bool(st.self_pairs), bool(st.world_pairs), res.outcome,
                            st.self_pairs.keys(), [(p.a, p.b) for p in res.pairs])
            if kind == "missed" and len(misses) < show:
                misses.append({"q": [round(float(x), 6) for x in q], "scene": res.outcome,
                               "physics_self": {" / ".join(k): round(v, 5) for k, v in st.self_pairs.items()},
                               "physics_world": {" / ".join(k): round(v, 5) for k, v in st.world_pairs.items()}})
            if kind == "false_alarm" and res.pairs:
                # how far apart (in physics) is the closest pair the scene flagged: padding explains <= 2 x 8 mm
                # (self) or 10 mm (world) plus convex hull vs mesh differences
                pair_gaps = [(physics_gap(sim, pr.a, pr.b), pr.a, pr.b) for pr in res.pairs]
                gap, a, b = min(pair_gaps)
                (self_gaps if res.outcome == SELF else world_gaps).append(gap)
                fa_pairs.setdefault(f"{a} / {b}", []).append(gap)
            if kind == "invalid" and counts["invalid_requests"] <= 3:
                print(f"INVALID_REQUEST at {q.tolist()}: {res.message}", file=sys.stderr)
        check.close()
        wall = time.perf_counter() - t0
    finally:
        g.close()
        sim.close()
    world = Path(world_path).stem
    row = finish_row(world, counts, float(np.median(times) * 1e3) if times else float("nan"), seed,
                     self_gaps, world_gaps)
    top = sorted(fa_pairs.items(), key=lambda kv: -len(kv[1]))[:5]
    return {"row": row, "misses": misses, "wall_s": wall, "map": map_info,
            "fa_pairs": [[k, len(v), *gap_stats(v)] for k, v in top]}


# ----------------------------------------------------------------------------- main
def run_world(world_path: str, args) -> dict:
    return run_json_worker(__file__, ["--worker", world_path, "-n", args.n, "--seed", args.seed, "--robot", args.robot,
                                      "--show", args.show, "--obstacles", args.obstacles],
                           f"audit worker for {world_path}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--worlds", nargs="+", default=["table"], help="world names (worlds/<name>.yaml) or paths")
    p.add_argument("-n", type=int, default=10000, help="random configurations per world")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--robot", default="panda", help="config/robots/<robot>.yaml")
    p.add_argument("--show", type=int, default=5, help="print the first this many misses per world")
    p.add_argument("--out", default=None, help="output folder (default: <repo>/docs/audit)")
    p.add_argument("--obstacles", choices=sorted(MODE_NOTES), default="objects",
                   help="where the scene's obstacles come from (launch arg obstacles): the world file's objects, "
                        "the OctoMap built from the world's depth cameras, or both")
    p.add_argument("--worker", help=argparse.SUPPRESS)
    args = p.parse_args(argv)

    if args.worker:
        print(json.dumps(worker(args.worker, args.n, args.seed, args.robot, args.show, args.obstacles)))
        return 0

    from moverl_gym.paths import repo_root, world_file

    out_dir = Path(args.out) if args.out else repo_root() / "docs" / "audit"
    rows, skipped, all_misses, fa_notes = [], [], {}, []
    for w in args.worlds:
        path = world_file(w)
        if not path.is_file():
            print(f"note: world '{w}' skipped: {path} does not exist (yet)")
            skipped.append((w, f"{path.relative_to(repo_root()) if path.is_relative_to(repo_root()) else path} "
                               "did not exist at audit time"))
            continue
        print(f"auditing {w}: {args.n} configurations ...", flush=True)
        r = run_world(str(path), args)
        r["row"]["world"] = w
        rows.append(r["row"])
        all_misses[w] = r["misses"]
        fa_notes.append(fa_pairs_note(w, r["fa_pairs"], r["row"]["false_alarm"]))
        if r.get("map"):
            m = r["map"]
            fa_notes.append(f"{w}: OctoMap of {m['clouds']} clouds, {m['occupied_leaves']} occupied cells of "
                            f"{m['resolution']:.3f} m")
        print(f"  done in {r['wall_s']:.1f} s", flush=True)

    print("\n== Collision audit: planning scene (check_state) vs PyBullet ground truth "
          f"(n={args.n} per world, seed {args.seed}) ==")
    print(format_table(rows))
    print("(false al. % of free: false alarms / physics-free configurations; self split over all samples, "
          "world split over scene-self-free samples; unnamed: physics self pairs the scene did not name)")
    print(f"note: {MODE_NOTES[args.obstacles]}")
    for w, why in skipped:
        print(f"note: world '{w}' skipped: {why}")
    for note in fa_notes:
        print("note: " + note)
    for w, ms in all_misses.items():
        for m in ms:
            print(f"MISS in {w}: q={m['q']} scene outcome={m['scene']} physics self={m['physics_self']} "
                  f"world={m['physics_world']}")

    out_dir.mkdir(parents=True, exist_ok=True)
    stem = "audit" if args.obstacles == "objects" else f"audit_{args.obstacles}"
    with open(out_dir / f"{stem}.csv", "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=FIELDS)
        wr.writeheader()
        wr.writerows(rows)
    command = "python src/moverl_gym/scripts/collision_audit.py --worlds " + " ".join(args.worlds) + f" -n {args.n}"
    if args.seed != 0:
        command += f" --seed {args.seed}"
    if args.obstacles != "objects":
        command += f" --obstacles {args.obstacles}"
    (out_dir / f"{stem}.md").write_text(format_markdown(rows, command, skipped, fa_notes, args.obstacles))
    print(f"\nwrote {out_dir / (stem + '.csv')} and {out_dir / (stem + '.md')}")
    missed = sum(r["missed"] for r in rows)
    if missed:
        print(f"FAIL: {missed} missed collision(s)")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
