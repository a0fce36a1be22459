#!/usr/bin/env python3
"""OMPL planner benchmark on MoveRL's scenes (the paper's Fig. 4 on our worlds).

    python src/moverl_gym/tools/planner_benchmark.py --worlds table human case --pairs 50 --time-limit 0.1

Problems: for each world, `pairs` start/goal pairs where both ends are free (/planning_scene/check_state VALID)
but the straight joint-space segment collides (/planning_scene/check_path not VALID): exactly the problems the
shield hands to the planner (PATH_COLLISION). Half of them (--short-fraction) are short: goal = start + U(-0.3,
0.3) rad per joint (clipped to the limits), like a few env steps; the rest are long: start and goal independent
and uniform within the joint limits. Fixed seed; every planner gets the same pairs, in the same order
(pairs outer loop, planners inner loop, so that load from other processes hits all planners alike).

Each problem: /planning_scene/plan with the planner and time limit (the scene's simplification shares that
budget). Recorded: outcome, planning_time (reported by the scene), wall time of the call, path_length (rad)
and whether every segment of the returned path passes /planning_scene/check_path (independent re-check).
Planners the scene rejects as unknown are skipped with a note.

Writes docs/planners/planners.csv (world x planner x pair), docs/planners/summary.csv (world x planner, plus
world "all"), docs/planners/planners.png, and prints a recommendation: best solved rate over all worlds, ties
broken by median planning time of the solved problems, then by median path length.
Each world runs in its own process (rospy: one ROS master per process) with its own graph on a free port.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import time
from pathlib import Path

from moverl_gym.workers import run_json_worker
from moverl_msgs.srv import CheckPathResponse, CheckStateResponse, PlanPathResponse

DEFAULT_PLANNERS = ["RRT", "RRTConnect", "RRTstar", "BiTRRT", "PRM", "EST", "KPIECE1", "LBKPIECE1", "SBL", "TRRT"]
SHORT_DELTA = 0.3  # rad per joint, short pairs
PLAN_SUCCESS, PLAN_INVALID_REQUEST = PlanPathResponse.SUCCESS, PlanPathResponse.INVALID_REQUEST
#: PlanPath outcome names by code (from the generated message class: the .srv is the one source of the codes).
OUTCOMES = {
    getattr(PlanPathResponse, n): n
    for n in dir(PlanPathResponse)
    if n.isupper() and isinstance(getattr(PlanPathResponse, n), int)
}
ROW_FIELDS = [
    "world",
    "planner",
    "pair",
    "kind",
    "outcome",
    "solved",
    "planning_time",
    "call_time",
    "path_length",
    "straight_length",
    "straight_collision",
    "waypoints",
    "path_valid",
]
SUMMARY_FIELDS = [
    "world",
    "planner",
    "problems",
    "solved",
    "solved_rate",
    "time_median_solved",
    "time_p90_solved",
    "time_max",
    "over_limit",
    "path_length_median",
    "straight_length_median",
    "invalid_paths",
]
LATE_SLACK = 0.02  # s: a planning_time above time_limit + this counts as over the limit


# ----------------------------------------------------------------------------- pure functions (tested)
def estimate_seconds(
    pairs: int, planners: int, worlds: int, time_limit: float, startup: float = 8.0, generation: float = 2.0
) -> float:
    """Worst case: every call uses its whole time limit; plus graph start-up and pair generation per world."""
    return worlds * (startup + generation + pairs * planners * (time_limit + 0.005))


def short_goal(start, lower, upper, rng, delta: float = SHORT_DELTA):
    import numpy as np

    return np.clip(np.asarray(start) + rng.uniform(-delta, delta, len(start)), lower, upper)


def pair_kinds(pairs: int, short_fraction: float):
    """The kind of each problem, short and long interleaved (a truncated run keeps the mix);
    floor(pairs * short_fraction) of them short."""
    f = min(max(float(short_fraction), 0.0), 1.0)
    return ["short" if math.floor((i + 1) * f + 1e-9) > math.floor(i * f + 1e-9) else "long" for i in range(pairs)]


def _percentile(xs, q):
    xs = sorted(xs)
    if not xs:
        return float("nan")
    k = (len(xs) - 1) * q / 100.0
    f = math.floor(k)
    c = min(f + 1, len(xs) - 1)
    return xs[f] + (xs[c] - xs[f]) * (k - f)


def summarize(rows, time_limit: float):
    """Per (world, planner) and per planner over all worlds ("all")."""
    groups = {}
    for r in rows:
        for w in (r["world"], "all"):
            groups.setdefault((w, r["planner"]), []).append(r)
    out = []
    for (w, planner), rs in groups.items():
        solved = [r for r in rs if r["solved"]]
        times = [r["planning_time"] for r in solved]
        out.append(
            {
                "world": w,
                "planner": planner,
                "problems": len(rs),
                "solved": len(solved),
                "solved_rate": round(len(solved) / len(rs), 4) if rs else float("nan"),
                "time_median_solved": round(_percentile(times, 50), 5),
                "time_p90_solved": round(_percentile(times, 90), 5),
                "time_max": round(max(r["planning_time"] for r in rs), 5),
                "over_limit": sum(r["planning_time"] > time_limit + LATE_SLACK for r in rs),
                "path_length_median": round(_percentile([r["path_length"] for r in solved], 50), 4),
                "straight_length_median": round(_percentile([r["straight_length"] for r in rs], 50), 4),
                "invalid_paths": sum(r["solved"] and not r["path_valid"] for r in rs),
            }
        )
    order = {w: i for i, w in enumerate(dict.fromkeys([r["world"] for r in rows] + ["all"]))}
    out.sort(key=lambda s: (order[s["world"]], s["planner"]))
    return out


def _nan_last(x):
    return math.inf if x is None or (isinstance(x, float) and math.isnan(x)) else x


def rank(summary, world: str = "all"):
    """Planners of one world, best first: solved rate (desc), median planning time, median path length."""
    rows = [s for s in summary if s["world"] == world]
    return sorted(
        rows,
        key=lambda s: (
            -s["solved_rate"],
            _nan_last(s["time_median_solved"]),
            _nan_last(s["path_length_median"]),
            s["planner"],
        ),
    )


def format_summary(summary, time_limit: float) -> str:
    head = (
        f"{'world':8s} {'planner':11s} {'solved':>9s} {'rate':>6s} {'t50 ms':>8s} {'t90 ms':>8s} "
        f"{'tmax ms':>8s} {'>limit':>6s} {'len50':>7s} {'straight50':>10s} {'bad paths':>9s}"
    )
    lines = [head, "-" * len(head)]
    for s in summary:
        lines.append(
            f"{s['world']:8s} {s['planner']:11s} {s['solved']:4d}/{s['problems']:<4d} "
            f"{100 * s['solved_rate']:5.0f}% {1e3 * s['time_median_solved']:8.1f} "
            f"{1e3 * s['time_p90_solved']:8.1f} {1e3 * s['time_max']:8.1f} {s['over_limit']:6d} "
            f"{s['path_length_median']:7.2f} {s['straight_length_median']:10.2f} {s['invalid_paths']:9d}"
        )
    lines.append(
        f"(times of solved problems; >limit: planning_time > time limit {time_limit} s + {LATE_SLACK} s; "
        "len50: median path length of solved, rad; straight50: median straight start-goal distance)"
    )
    return "\n".join(lines)


# ----------------------------------------------------------------------------- worker (one world, one process)
def worker(world_path: str, args) -> dict:
    import numpy as np
    import rospy

    from moverl_gym import ros_backend as ros
    from moverl_gym.graph import LaunchedGraph
    from moverl_msgs.srv import CheckPath, CheckState, PlanPath

    world = Path(world_path).stem
    g = LaunchedGraph(
        {"world_file": world_path, "robot": args.robot},
        wait_for=ros.REQUIRED_SERVICES + ("/planning_scene/plan", "/planning_scene/check_path"),
    )
    notes = []
    try:
        ros.init_node(g.uri)
        check = rospy.ServiceProxy("/planning_scene/check_state", CheckState, persistent=True)
        path_check = rospy.ServiceProxy("/planning_scene/check_path", CheckPath, persistent=True)
        plan = rospy.ServiceProxy("/planning_scene/plan", PlanPath, persistent=True)
        lower, upper = _limits(args.robot)
        rng = np.random.default_rng(args.seed)

        # ---- problems
        problems, attempts = [], 0
        max_attempts = 2000 * args.pairs
        for kind in pair_kinds(args.pairs, args.short_fraction):
            while attempts < max_attempts:
                attempts += 1
                a = rng.uniform(lower, upper)
                if check(positions=a.tolist()).outcome != CheckStateResponse.VALID:
                    continue
                b = short_goal(a, lower, upper, rng) if kind == "short" else rng.uniform(lower, upper)
                if check(positions=b.tolist()).outcome != CheckStateResponse.VALID:
                    continue
                pc = path_check(start=a.tolist(), goal=b.tolist()).outcome
                if pc in (0, 3):
                    continue
                problems.append((kind, a, b, "self" if pc == 1 else "world"))
                break
        if len(problems) < args.pairs:
            notes.append(f"{world}: only {len(problems)} of {args.pairs} problems found in {attempts} samples")

        # ---- planners: drop those the scene does not know
        planners = []
        if problems:
            kind, a, b, _ = problems[0]
            for name in args.planners:
                res = plan(start=a.tolist(), goal=b.tolist(), planner=name, time_limit=1e-3)
                if res.outcome == PLAN_INVALID_REQUEST and "unknown planner" in res.message:
                    notes.append(f"planner {name} skipped: the scene rejects it ({res.message})")
                else:
                    planners.append(name)

        # ---- benchmark: pairs outer, planners inner
        rows = []
        t_start = time.perf_counter()
        for i, (kind, a, b, straight) in enumerate(problems):
            for name in planners:
                t0 = time.perf_counter()
                res = plan(start=a.tolist(), goal=b.tolist(), planner=name, time_limit=args.time_limit)
                call = time.perf_counter() - t0
                solved = res.outcome == PLAN_SUCCESS
                valid = False
                if solved:
                    pts = [list(p.positions) for p in res.path.points]
                    valid = len(pts) >= 2 and all(
                        path_check(start=p, goal=q).outcome == CheckPathResponse.VALID
                        for p, q in zip(pts[:-1], pts[1:])
                    )
                    valid = valid and np.allclose(pts[0], a, atol=1e-6) and np.allclose(pts[-1], b, atol=1e-6)
                rows.append(
                    {
                        "world": world,
                        "planner": name,
                        "pair": i,
                        "kind": kind,
                        "outcome": OUTCOMES.get(res.outcome, str(res.outcome)),
                        "solved": int(solved),
                        "planning_time": round(res.planning_time, 6),
                        "call_time": round(call, 6),
                        "path_length": round(res.path_length, 5) if solved else float("nan"),
                        "straight_length": round(float(np.linalg.norm(b - a)), 5),
                        "straight_collision": straight,
                        "waypoints": len(res.path.points),
                        "path_valid": int(valid),
                    }
                )
        bench_wall = time.perf_counter() - t_start
        for p in (check, path_check, plan):
            p.close()
    finally:
        g.close()
    return {"rows": rows, "notes": notes, "attempts": attempts, "bench_wall": bench_wall}


def _limits(robot: str):
    import numpy as np

    from moverl_gym.paths import robot_config_file
    from moverl_gym.robot import JointLimits
    from moverl_sim.robot_config import load_robot_config
    from moverl_sim.urdf import resolve_uri

    rc = load_robot_config(robot_config_file(robot))
    with open(resolve_uri(rc["urdf"])) as f:
        lim = JointLimits.from_urdf(f.read(), rc["joints"])
    return np.asarray(lim.lower, dtype=float), np.asarray(lim.upper, dtype=float)


# ----------------------------------------------------------------------------- plot
def plot(rows, summary, worlds, planners, time_limit: float, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    colours = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd"]
    rate = {(s["world"], s["planner"]): s for s in summary}
    import matplotlib.transforms as mtransforms

    fig, axes = plt.subplots(2, 1, figsize=(max(9, 1.5 * len(planners) + 1), 9), sharex=True)
    t_all = [1e3 * r["planning_time"] for r in rows if r["solved"]]
    t_top = max([1e3 * time_limit * 1.1] + t_all) * 1.05
    nw = len(worlds)
    width = 0.8 / nw
    for panel, (ax, key, label) in enumerate(
        zip(
            axes,
            ("planning_time", "path_length"),
            (
                f"planning time of solved problems (ms, limit {1e3 * time_limit:.0f} ms)",
                "path length of solved problems (rad)",
            ),
        )
    ):
        for wi, w in enumerate(worlds):
            data, pos = [], []
            for pi, name in enumerate(planners):
                vals = [
                    r[key] * (1e3 if key == "planning_time" else 1.0)
                    for r in rows
                    if r["world"] == w and r["planner"] == name and r["solved"]
                ]
                data.append(vals if vals else [float("nan")])
                pos.append(pi + (wi - (nw - 1) / 2) * width)
            bp = ax.boxplot(
                data,
                positions=pos,
                widths=width * 0.85,
                patch_artist=True,
                showfliers=True,
                flierprops={"markersize": 2, "markeredgecolor": colours[wi % len(colours)]},
                medianprops={"color": "black"},
            )
            for box in bp["boxes"]:
                box.set_facecolor(colours[wi % len(colours)])
                box.set_alpha(0.75)
            if panel == 0:  # solved rate in a strip above the panel, one line per world
                trans = mtransforms.blended_transform_factory(ax.transData, ax.transAxes)
                for pi, name in enumerate(planners):
                    s = rate.get((w, name))
                    if s is not None:
                        ax.text(
                            pi,
                            1.02 + 0.055 * (nw - 1 - wi),
                            f"{100 * s['solved_rate']:.0f}%",
                            ha="center",
                            va="bottom",
                            fontsize=8,
                            color=colours[wi % len(colours)],
                            transform=trans,
                            fontweight="bold",
                        )
        ax.set_ylabel(label)
        ax.grid(axis="y", alpha=0.3)
        for x in range(1, len(planners)):
            ax.axvline(x - 0.5, color="grey", lw=0.5, alpha=0.4)
    axes[0].axhline(1e3 * time_limit, color="red", lw=0.8, ls="--")
    axes[0].set_ylim(0, t_top)
    axes[0].text(
        1.0,
        1e3 * time_limit,
        " limit",
        color="red",
        fontsize=8,
        va="center",
        transform=mtransforms.blended_transform_factory(axes[0].transAxes, axes[0].transData),
    )
    axes[0].set_title(
        "OMPL planners on MoveRL scenes, problems whose straight path collides\n"
        "solved rate per world (coloured %) above the panel; boxes: solved problems only",
        fontsize=10,
        pad=12 + 14 * nw,
    )
    axes[1].set_xticks(range(len(planners)))
    axes[1].set_xticklabels(planners, rotation=0)
    axes[1].set_xlim(-0.6, len(planners) - 0.4)
    axes[1].legend(
        handles=[Patch(facecolor=colours[i % len(colours)], alpha=0.75, label=w) for i, w in enumerate(worlds)],
        loc="upper right",
        title="world",
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def read_rows(path: Path):
    """planners.csv back into rows (numbers parsed)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        for k in ("pair", "solved", "waypoints", "path_valid"):
            r[k] = int(r[k])
        for k in ("planning_time", "call_time", "path_length", "straight_length"):
            r[k] = float(r[k])
    return rows


# ----------------------------------------------------------------------------- main
def run_world(world_path: str, argv) -> dict:
    return run_json_worker(
        __file__, ["--worker", world_path, *argv], f"planner benchmark worker for {world_path}", timeout=7200
    )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--worlds", nargs="+", default=["table"], help="world names (worlds/<name>.yaml) or paths")
    p.add_argument("--pairs", type=int, default=50, help="start/goal problems per world")
    p.add_argument("--time-limit", type=float, default=0.1, help="seconds per planning call")
    p.add_argument("--planners", nargs="+", default=DEFAULT_PLANNERS)
    p.add_argument(
        "--short-fraction",
        type=float,
        default=0.5,
        help=f"share of short problems (goal within +-{SHORT_DELTA} rad per joint of the start)",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--robot", default="panda")
    p.add_argument("--out", default=None, help="output folder (default: <repo>/docs/planners)")
    p.add_argument("--plot-only", action="store_true", help="redraw planners.png from an existing planners.csv")
    p.add_argument("--worker", help=argparse.SUPPRESS)
    args = p.parse_args(argv)

    if args.worker:
        print(json.dumps(worker(args.worker, args)))
        return 0

    from moverl_gym.paths import repo_root, world_file

    out_dir = Path(args.out) if args.out else repo_root() / "docs" / "planners"
    if args.plot_only:
        rows = read_rows(out_dir / "planners.csv")
        worlds = list(dict.fromkeys(r["world"] for r in rows))
        planners = [pl for pl in args.planners if any(r["planner"] == pl for r in rows)]
        plot(rows, summarize(rows, args.time_limit), worlds, planners, args.time_limit, out_dir / "planners.png")
        print(f"wrote {out_dir / 'planners.png'}")
        return 0
    worlds, notes = [], []
    for w in args.worlds:
        path = world_file(w)
        if path.is_file():
            worlds.append((w, str(path)))
        else:
            notes.append(f"world '{w}' skipped: {path} does not exist (yet)")
            print("note: " + notes[-1])
    est = estimate_seconds(args.pairs, len(args.planners), len(worlds), args.time_limit)
    print(
        f"{len(worlds)} world(s) x {len(args.planners)} planners x {args.pairs} pairs x {args.time_limit} s: "
        f"at most ~{est / 60:.1f} min (every call using its full time limit, plus start-up)",
        flush=True,
    )
    fwd = [
        "--pairs",
        str(args.pairs),
        "--time-limit",
        str(args.time_limit),
        "--seed",
        str(args.seed),
        "--short-fraction",
        str(args.short_fraction),
        "--robot",
        args.robot,
        "--planners",
        *args.planners,
    ]
    rows = []
    t0 = time.perf_counter()
    for w, path in worlds:
        print(f"benchmarking {w} ...", flush=True)
        r = run_world(path, fwd)
        for row in r["rows"]:
            row["world"] = w
        rows += r["rows"]
        for n in r["notes"]:
            if n not in notes:
                notes.append(n)
                print("note: " + n)
        print(
            f"  {len(r['rows'])} planning calls in {r['bench_wall']:.0f} s "
            f"({r['attempts']} samples to find the problems)",
            flush=True,
        )
    if not rows:
        print("nothing benchmarked")
        return 1
    world_names = [w for w, _ in worlds]
    planners = [pl for pl in args.planners if any(r["planner"] == pl for r in rows)]
    summary = summarize(rows, args.time_limit)

    out_dir.mkdir(parents=True, exist_ok=True)
    with open(out_dir / "planners.csv", "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=ROW_FIELDS)
        wr.writeheader()
        wr.writerows(rows)
    with open(out_dir / "summary.csv", "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=SUMMARY_FIELDS)
        wr.writeheader()
        wr.writerows(summary)
    plot(rows, summary, world_names, planners, args.time_limit, out_dir / "planners.png")

    print(
        f"\n== OMPL planners, {args.pairs} problems per world (straight path collides; "
        f"{args.short_fraction:.0%} short), time limit {args.time_limit} s, seed {args.seed}, "
        f"{time.perf_counter() - t0:.0f} s =="
    )
    print(format_summary(summary, args.time_limit))
    for n in notes:
        print("note: " + n)
    best = rank(summary)
    b = best[0]
    print(
        f"\nrecommendation: {b['planner']} (all worlds: solved {b['solved']}/{b['problems']} = "
        f"{100 * b['solved_rate']:.0f}%, median planning time {1e3 * b['time_median_solved']:.1f} ms, "
        f"median path length {b['path_length_median']:.2f} rad)"
    )
    print("ranking: " + ", ".join(f"{s['planner']} {100 * s['solved_rate']:.0f}%" for s in best))
    for w in world_names:
        print(f"  best in {w}: {rank(summary, w)[0]['planner']}")
    late = [s for s in summary if s["world"] != "all" and s["over_limit"]]
    for s in late:
        print(
            f"WARNING: {s['planner']} in {s['world']}: {s['over_limit']} call(s) over the time limit "
            f"(max {1e3 * s['time_max']:.0f} ms)"
        )
    bad = [s for s in summary if s["world"] != "all" and s["invalid_paths"]]
    for s in bad:
        print(f"WARNING: {s['planner']} in {s['world']}: {s['invalid_paths']} returned path(s) fail check_path")
    print(f"\nwrote {out_dir / 'planners.csv'}, {out_dir / 'summary.csv'}, {out_dir / 'planners.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
