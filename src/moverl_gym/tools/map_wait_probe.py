#!/usr/bin/env python3
"""Does the sensed map keep up, and what does a step wait for? In one graph (lockstep, or --mode realtime): each step's
wall time, verdict and map age, and each camera's cloud integration times (the planning scene's ~octomap_status, a
batch's close included in its last cloud's), how many clouds and batches (instants) the map took in, and how many
the cameras sent. The slowest steps are listed with the clouds integrated while they ran, and the closes are split into
those the scene reports as later than their views' watch covered (OctomapStatus.beyond_watch) and the others, with the
cells each turned stale, and how many batches had the watch widened before their views (watches_ahead).

    python src/moverl_gym/tools/map_wait_probe.py --world shared_bench --camera-rate 5 --safety ssm \\
        --strategy discard --steps 100 --goal-q -0.034 -0.489 -0.561 -2.95 -0.421 2.483 -0.2
    python src/moverl_gym/tools/map_wait_probe.py --world shared_bench --camera-rate 30 --mode realtime --safety ssm \\
        --steps 200 --goal-q -0.034 -0.489 -0.561 -2.95 -0.421 2.483 -0.2

The policy is sensed_reach_probe.py's: it drives the joints straight at --goal-q and keeps pushing (an episode ends
at the task's max steps or on success, and the env resets). Figures depend on this shared machine's load: compare
configurations in the same run.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from moverl_gym.launch_args import CHOICES, SENSED_OBSTACLES


def closes_by_watch(batches) -> dict:
    """batches: [(map time, cells its close turned stale, beyond_watch)] in time order, one per batch (the scene's
    ~octomap_status after the close). Splits the closes into those the scene reports as later than their views' watch
    covered (they count every free cell the views did not look at as hidden) and the others: how many cells each kind
    turned stale."""

    def summary(turned):
        return {
            "closes": len(turned),
            "turned_median": float(np.median(turned)) if turned else None,
            "turned_max": int(max(turned)) if turned else None,
            "over_100k": sum(t > 100_000 for t in turned),
        }

    later = [int(n) for _, n, beyond in batches if beyond]
    others = [int(n) for _, n, beyond in batches if not beyond]
    return {"beyond_watch": summary(later), "others": summary(others)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--robot", default="panda", help="config/robots/<robot>.yaml")
    p.add_argument("--world", default="shared_bench", help="world name (worlds/<name>.yaml) or file")
    p.add_argument("--goal-q", type=float, nargs="+", required=True, help="a configuration whose hand is at the goal")
    p.add_argument(
        "--camera-rate", type=float, default=None, help="renders per simulated second (default: the world's)"
    )
    p.add_argument("--obstacles", choices=SENSED_OBSTACLES, default="sensed")
    p.add_argument("--safety", choices=[c for c in CHOICES["safety"] if c], default=None)
    p.add_argument("--strategy", choices=CHOICES["strategy"], default=None, help="default: the launch file's")
    p.add_argument("--mode", choices=CHOICES["mode"], default=None, help="the simulator's clock (default: lockstep)")
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--max-steps", type=int, default=100, help="steps per episode")
    p.add_argument("--slowest", type=int, default=4, help="list this many of the slowest steps")
    p.add_argument("--json", type=str, default=None, help="write the figures here")
    args = p.parse_args(argv)
    if args.steps < 1:
        p.error("--steps must be at least 1")

    import gymnasium as gym
    import rospy
    from sensor_msgs.msg import PointCloud2

    import moverl_gym  # noqa: F401
    from moverl_gym.registration import env_id
    from moverl_msgs.msg import OctomapStatus

    launch = {"obstacles": args.obstacles}
    launch.update({"camera_rate": args.camera_rate} if args.camera_rate else {})
    launch.update({"safety": args.safety} if args.safety else {})
    launch.update({"strategy": args.strategy} if args.strategy else {})
    launch.update({"mode": args.mode} if args.mode else {})
    env = gym.make(
        env_id(args.robot, "Human"),
        world=args.world,
        graph="launch",
        launch_args=launch,
        task={"max_episode_steps": args.max_steps},
    )
    u = env.unwrapped
    goal_q = np.asarray(args.goal_q, dtype=float)
    clouds, steps, sent = [], [], []
    try:
        env.reset(seed=0)
        # The env's graph is this process's ROS master (rospy allows one): its topics, heard from here on.
        sub = rospy.Subscriber(
            "/planning_scene/octomap_status",
            OctomapStatus,
            lambda m: clouds.append(
                (
                    time.perf_counter(),
                    m.sensor_frame,
                    m.integration_time,
                    m.map_time,
                    m.hidden_cells,
                    m.turned_stale,
                    m.beyond_watch,
                    m.watches_ahead,
                )
            ),
            queue_size=1000,
        )
        sent_sub = rospy.Subscriber(
            "/sim/points", PointCloud2, lambda m: sent.append(m.header.frame_id), queue_size=1000
        )
        started, after_reset = time.perf_counter(), True
        for _ in range(args.steps):
            d = goal_q - u.q[: len(goal_q)]
            action = np.clip(d / max(float(np.abs(d).max()), 1e-9), -1.0, 1.0).astype(np.float32)
            t0 = time.perf_counter()
            _, _, terminated, truncated, info = env.step(action)
            steps.append((t0, time.perf_counter(), info["verdict"], float(info.get("map_age", -1.0)), after_reset))
            after_reset = terminated or truncated
            if after_reset:
                env.reset()
        seconds = time.perf_counter() - started
        sub.unregister()
        sent_sub.unregister()
    finally:
        env.close()

    wall = np.array([b - a for a, b, _, _, _ in steps])
    per_camera = {}
    for _, frame, integration, *_ in clouds:
        per_camera.setdefault(frame, []).append(integration * 1e3)
    ages = np.array([a for _, _, _, a, _ in steps if a >= 0.0])
    result = {
        "command": "python src/moverl_gym/tools/map_wait_probe.py " + " ".join(argv or sys.argv[1:]),
        "mode": args.mode or "lockstep",
        "seconds": seconds,
        "steps": len(steps),
        "step_ms": {
            "median": float(np.median(wall) * 1e3),
            "p99": float(np.percentile(wall, 99) * 1e3),
            "max": float(wall.max() * 1e3),
        },
        "map_age_s": {"median": float(np.median(ages)), "max": float(ages.max())} if len(ages) else None,
        "clouds_sent": len(sent),
        "clouds": len(clouds),
        "batches": len({c[3] for c in clouds}),
        "integration_ms": {
            f: {"clouds": len(v), "median": float(np.median(v)), "max": float(max(v))}
            for f, v in sorted(per_camera.items())
        },
        "slowest": [],
    }
    last_close = {}  # map time -> what its batch's close turned stale, and whether it was beyond its watch
    for c in clouds:
        last_close[c[3]] = (c[5], c[6])
    result["closes"] = closes_by_watch([(t, *v) for t, v in sorted(last_close.items())])
    # Batches whose watch the scene widened before their views (later after the one before than the watch covered).
    result["watches_ahead"] = int(clouds[-1][7] - clouds[0][7]) if clouds else 0
    for k in np.argsort(-wall)[: args.slowest]:
        t0, t1, verdict, age, first = steps[k]
        during = [(round(c[0] - t0, 3), c[1], round(c[2] * 1e3, 1), c[4], c[5]) for c in clouds if t0 <= c[0] <= t1]
        result["slowest"].append(
            {
                "ms": float((t1 - t0) * 1e3),
                "step": int(k),
                "first_of_episode": bool(first),
                "verdict": verdict,
                "map_age": age,
                "clouds": during,
            }
        )

    print(
        f"{result['steps']} steps in {seconds:.1f} s ({result['mode']}): median {result['step_ms']['median']:.1f} ms, "
        f"p99 {result['step_ms']['p99']:.0f} ms, max {result['step_ms']['max']:.0f} ms; the cameras sent "
        f"{result['clouds_sent']} clouds, the map integrated {result['clouds']} in {result['batches']} batches"
    )
    if result["map_age_s"]:
        a = result["map_age_s"]
        print(f"map age at the steps' checks: median {a['median']:.3f} s, max {a['max']:.3f} s")
    print("| camera | clouds | integration median (ms) | max (ms) |\n|---|---:|---:|---:|")
    for f, v in result["integration_ms"].items():
        print(f"| {f} | {v['clouds']} | {v['median']:.1f} | {v['max']:.0f} |")
    for kind, c in result["closes"].items():
        print(
            f"closes, {kind.replace('_', ' ')}: {c['closes']}, cells turned stale median {c['turned_median']}, "
            f"max {c['turned_max']}, over 100,000 in {c['over_100k']}"
        )
    print(f"batches with the watch widened before their views: {result['watches_ahead']}")
    for s in result["slowest"]:
        print(
            f"slow step {s['ms']:.0f} ms (step {s['step']}{', after a reset' if s['first_of_episode'] else ''}), "
            f"{s['verdict']}, map age {s['map_age']:.3f} s; clouds integrated meanwhile "
            f"(s after its start, camera, ms, the last close's hidden cells and those turned stale): {s['clouds']}"
        )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result, fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
