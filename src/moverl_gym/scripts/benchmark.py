#!/usr/bin/env python3
"""MoveRL speed benchmark (prints figures; not a test).

    ./run.sh bench [--steps 3000] [--json out.json]

Measures, in one run, each part in its own process (rospy allows one ROS master per process):
  1. env steps/s through the full ROS graph (sim + planning scene + shield), shield on
  2. the same, shield off (unchecked baseline)
  3. the same task stepped in PyBullet without ROS (moverl_sim's core + the same action scaling)
  4. panda-gym PandaReachJoints-v3 as the reference
  5. p50/p99 latency of the shield's state check, path check, and of OMPL planning (scene ~plan service)
Random actions from a fixed seed; episodes reset as usual (resets are included in the step rate).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from moverl_gym.workers import run_json_worker


def _percentiles(xs):
    xs = np.asarray(xs, dtype=float)
    if xs.size == 0:
        return {"p50_ms": float("nan"), "p99_ms": float("nan"), "n": 0}
    return {"p50_ms": float(np.percentile(xs, 50) * 1e3), "p99_ms": float(np.percentile(xs, 99) * 1e3),
            "n": int(xs.size)}


def _rollout(env, steps, seed):
    """Random actions for `steps` env steps; returns (steps/s, infos)."""
    env.action_space.seed(seed)
    env.reset(seed=seed)
    infos = []
    t0 = time.perf_counter()
    for _ in range(steps):
        _, _, term, trunc, info = env.step(env.action_space.sample())
        infos.append((info, dict(getattr(env.unwrapped, "last_timing", {}))))
        if term or trunc:
            env.reset()
    return steps / (time.perf_counter() - t0), infos


def worker_graph(shield: bool, steps: int, seed: int, plans: int, obstacles: str = "objects") -> dict:
    import gymnasium as gym

    import moverl_gym  # noqa: F401

    env = gym.make("MoveRL/PandaReachTable-v0", shield=shield, graph="launch",
                   launch_args={"obstacles": obstacles})
    try:
        _rollout(env, 200, seed)  # warm-up: connections, caches
        rate, infos = _rollout(env, steps, seed)
        out = {"steps_per_s": rate, "steps": steps,
               "verdicts": _count(i["verdict"] for i, _ in infos),
               "contacts": int(sum(max(i["contacts"], 0) for i, _ in infos)),
               "round_trip": _percentiles([t["round_trip"] for _, t in infos])}
        if shield:
            out["state_check"] = _percentiles([t["state_check"] for _, t in infos])
            out["path_check"] = _percentiles([t["path_check"] for i, t in infos if t["path_check"] > 0])
            out["planning"] = _plan_latency(env.unwrapped, plans, seed)
        return out
    finally:
        env.close()


def _plan_latency(env, n: int, seed: int) -> dict:
    """Time the scene's ~plan service on problems the shield really plans for: both ends collision-free, the
    straight segment between them colliding (free straight segments are returned without planning)."""
    import rospy
    from moverl_msgs.srv import CheckPath, PlanPath

    plan = rospy.ServiceProxy("/planning_scene/plan", PlanPath, persistent=True)
    check_path = rospy.ServiceProxy("/planning_scene/check_path", CheckPath, persistent=True)
    rng = np.random.default_rng(seed)
    times, solved, tried = [], 0, 0
    lo, hi = env.limits.lower, env.limits.upper
    while len(times) < n and tried < 200000:
        tried += 1
        a = rng.uniform(lo, hi)
        b = np.clip(a + rng.uniform(-1, 1, a.size) * env.scaler.max_delta * 4, lo, hi)
        if env._backend.check_state(a).outcome or env._backend.check_state(b).outcome:
            continue
        if check_path(start=list(a), goal=list(b)).outcome == 0:
            continue
        res = plan(start=list(a), goal=list(b), planner="", time_limit=0.0)
        times.append(res.planning_time)
        solved += res.outcome == 0
    plan.close()
    check_path.close()
    out = _percentiles(times)
    out["solved"] = solved
    return out


def worker_bullet(steps: int, seed: int) -> dict:
    """The same task without ROS: PyBullet execution with contact checks, same action scaling and dt."""
    import gymnasium as gym

    from moverl_gym.bullet_env import BulletReachEnv

    env = gym.wrappers.TimeLimit(BulletReachEnv(), max_episode_steps=100)
    try:
        rate, infos = _rollout(env, steps, seed)
        return {"steps_per_s": rate, "steps": steps, "contacts": int(sum(i["contacts"] for i, _ in infos))}
    finally:
        env.close()


def worker_pandagym(steps: int, seed: int) -> dict:
    import gymnasium as gym
    import panda_gym  # noqa: F401

    env = gym.make("PandaReachJoints-v3")
    try:
        rate, _ = _rollout(env, steps, seed)
        return {"steps_per_s": rate, "steps": steps}
    finally:
        env.close()


def _count(items):
    out = {}
    for x in items:
        out[x] = out.get(x, 0) + 1
    return out


def run_worker(name: str, args) -> dict:
    return run_json_worker(__file__, ["--worker", name, "--steps", args.steps, "--seed", args.seed, "--plans", args.plans],
                           f"benchmark worker {name}", timeout=1800)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--steps", type=int, default=3000, help="env steps per measurement")
    p.add_argument("--plans", type=int, default=50, help="planning problems (straight path colliding) to time")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", help="also write all figures to this file")
    p.add_argument("--worker", help=argparse.SUPPRESS)
    args = p.parse_args(argv)

    if args.worker:
        fn = {"shield_on": lambda: worker_graph(True, args.steps, args.seed, args.plans),
              "shield_off": lambda: worker_graph(False, args.steps, args.seed, 0),
              "shield_octomap": lambda: worker_graph(True, args.steps, args.seed, 0, "octomap"),
              "bullet": lambda: worker_bullet(args.steps, args.seed),
              "pandagym": lambda: worker_pandagym(args.steps, args.seed)}[args.worker]
        print(json.dumps(fn()))
        return 0

    results = {}
    for name in ("shield_on", "shield_octomap", "shield_off", "bullet", "pandagym"):
        print(f"measuring {name} ({args.steps} steps) ...", flush=True)
        results[name] = run_worker(name, args)
    on, off = results["shield_on"], results["shield_off"]
    print("\n== MoveRL benchmark (random actions, seed %d, %d steps each, %d cores) ==" %
          (args.seed, args.steps, os.cpu_count()))
    print(f"{'configuration':52s} {'env steps/s':>12s}")
    print(f"{'MoveRL, full ROS graph, shield ON':52s} {on['steps_per_s']:12.0f}")
    octo = results["shield_octomap"]
    print(f"{'  same, obstacles sensed (2 depth cameras + OctoMap)':52s} {octo['steps_per_s']:12.0f}")
    print(f"{'MoveRL, full ROS graph, shield OFF':52s} {off['steps_per_s']:12.0f}")
    print(f"{'same task in PyBullet, no ROS, no shield':52s} {results['bullet']['steps_per_s']:12.0f}")
    print(f"{'panda-gym PandaReachJoints-v3 (reference)':52s} {results['pandagym']['steps_per_s']:12.0f}")
    print(f"{'original MoveRL (paper logs)':52s} {'1.2-2.7':>12s}")
    print("\nlatency (shield on)                p50 ms    p99 ms      n")
    for key, label in (("round_trip", "env step round trip"), ("state_check", "state check (self + world)"),
                       ("path_check", "path check (straight segment)"), ("planning", "OMPL planning, straight path colliding")):
        v = on[key]
        print(f"{label:32s} {v['p50_ms']:9.3f} {v['p99_ms']:9.3f} {v['n']:6d}")
    print(f"OctoMap mode: state check p50 {octo['state_check']['p50_ms']:.3f} ms, path check p50 "
          f"{octo['path_check']['p50_ms']:.3f} ms, contacts {octo['contacts']}")
    print(f"\nplanning solved {on['planning']['solved']}/{on['planning']['n']} (planner and time limit: "
          "config/planning_scene.yaml; the time includes path simplification)")
    print(f"verdicts shield on: {on['verdicts']}")
    print(f"ground-truth contacts: shield on {on['contacts']}, shield off {off['contacts']}, "
          f"PyBullet-only {results['bullet']['contacts']}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
