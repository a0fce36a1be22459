#!/usr/bin/env python3
"""What a lockstep step waits for in the sensed mode: each step's wall time, verdict and map age, and each camera's
cloud integration times (the planning scene's ~octomap_status), in one graph. The slowest steps are listed with the
clouds integrated while they ran.

    python src/moverl_gym/tools/lockstep_wait_probe.py --world shared_bench --camera-rate 5 --safety ssm \\
        --strategy discard --steps 100 --goal-q -0.034 -0.489 -0.561 -2.95 -0.421 2.483 -0.2

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
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--max-steps", type=int, default=100, help="steps per episode")
    p.add_argument("--slowest", type=int, default=4, help="list this many of the slowest steps")
    p.add_argument("--json", type=str, default=None, help="write the figures here")
    args = p.parse_args(argv)
    if args.steps < 1:
        p.error("--steps must be at least 1")

    import gymnasium as gym
    import rospy

    import moverl_gym  # noqa: F401
    from moverl_gym.registration import env_id
    from moverl_msgs.msg import OctomapStatus

    launch = {"obstacles": args.obstacles}
    launch.update({"camera_rate": args.camera_rate} if args.camera_rate else {})
    launch.update({"safety": args.safety} if args.safety else {})
    launch.update({"strategy": args.strategy} if args.strategy else {})
    env = gym.make(
        env_id(args.robot, "Human"),
        world=args.world,
        graph="launch",
        launch_args=launch,
        task={"max_episode_steps": args.max_steps},
    )
    u = env.unwrapped
    goal_q = np.asarray(args.goal_q, dtype=float)
    clouds, steps = [], []
    try:
        env.reset(seed=0)
        # The env's graph is this process's ROS master (rospy allows one): its status topic, heard from here on.
        sub = rospy.Subscriber(
            "/planning_scene/octomap_status",
            OctomapStatus,
            lambda m: clouds.append((time.perf_counter(), m.sensor_frame, m.integration_time, m.free_cells)),
            queue_size=200,
        )
        for _ in range(args.steps):
            d = goal_q - u.q[: len(goal_q)]
            action = np.clip(d / max(float(np.abs(d).max()), 1e-9), -1.0, 1.0).astype(np.float32)
            t0 = time.perf_counter()
            _, _, terminated, truncated, info = env.step(action)
            steps.append((t0, time.perf_counter(), info["verdict"], float(info.get("map_age", -1.0))))
            if terminated or truncated:
                env.reset()
        sub.unregister()
    finally:
        env.close()

    wall = np.array([b - a for a, b, _, _ in steps])
    per_camera = {}
    for _, frame, seconds, _ in clouds:
        per_camera.setdefault(frame, []).append(seconds * 1e3)
    result = {
        "command": "python src/moverl_gym/tools/lockstep_wait_probe.py " + " ".join(argv or sys.argv[1:]),
        "steps": len(steps),
        "step_ms": {
            "median": float(np.median(wall) * 1e3),
            "p99": float(np.percentile(wall, 99) * 1e3),
            "max": float(wall.max() * 1e3),
        },
        "clouds": len(clouds),
        "integration_ms": {
            f: {"clouds": len(v), "median": float(np.median(v)), "max": float(max(v))}
            for f, v in sorted(per_camera.items())
        },
        "slowest": [],
    }
    for k in np.argsort(-wall)[: args.slowest]:
        t0, t1, verdict, age = steps[k]
        during = [(round(c[0] - t0, 3), c[1], round(c[2] * 1e3, 1)) for c in clouds if t0 <= c[0] <= t1]
        result["slowest"].append({"ms": float((t1 - t0) * 1e3), "verdict": verdict, "map_age": age, "clouds": during})

    print(
        f"{result['steps']} steps: median {result['step_ms']['median']:.1f} ms, p99 {result['step_ms']['p99']:.0f} ms, "
        f"max {result['step_ms']['max']:.0f} ms; {result['clouds']} clouds integrated"
    )
    print("| camera | clouds | integration median (ms) | max (ms) |\n|---|---:|---:|---:|")
    for f, v in result["integration_ms"].items():
        print(f"| {f} | {v['clouds']} | {v['median']:.1f} | {v['max']:.0f} |")
    for s in result["slowest"]:
        print(
            f"slow step {s['ms']:.0f} ms, {s['verdict']}, map age {s['map_age']:.3f} s; clouds integrated meanwhile "
            f"(s after its start, camera, ms): {s['clouds']}"
        )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result, fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
