#!/usr/bin/env python3
"""Scaling benchmark: 1, 2 and 4 parallel envs with SB3's SubprocVecEnv and with RLlib env runners (MoveRL, one ROS
graph per env), and panda-gym with SubprocVecEnv for reference, in one run (prints figures; not a test).

    ./run.sh scaling [--envs 1 2 4] [--steps 2000] [--out docs/scaling]

Each measurement runs in its own process (rospy: one ROS master per process; Ray: one driver). Random actions from a
fixed seed (no policy: what is measured is the envs), episodes reset as usual, after a warm-up; graph start-up is not
counted. Per measurement:
  * aggregate env steps/s: steps of all envs / wall time;
  * CPU seconds per env step: user + system CPU time of every process of one env (the env's process and its whole
    graph: reaper, master, rosout, roslaunch, simulator, planning scene, shield), over the steps that env made,
    averaged over the envs; and, apart, what the stepping process (SubprocVecEnv's parent) or the Ray cluster
    (GCS, raylets, agents, the driver) spent per env step;
  * memory of one graph (resident set, and proportional set: shared pages split between their users) and of one env
    process, averaged over the envs.
SubprocVecEnv steps its envs in lockstep (a step waits for the slowest env); RLlib runners sample independently.
On a machine with fewer cores than envs the envs share cores: steps/s then stops growing, CPU per step does not.
Writes <out>/scaling.json, <out>/scaling.txt (the printed table) and <out>/scaling.png.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from moverl_gym.workers import run_json_worker

ENV_ID = "MoveRL/PandaReachTable-v0"
PANDA_GYM_ID = "PandaReachJoints-v3"
SYSTEMS = ("subproc", "rllib", "pandagym")
LABELS = {
    "subproc": "MoveRL, SB3 SubprocVecEnv",
    "rllib": "MoveRL, RLlib env runners",
    "pandagym": "panda-gym PandaReachJoints-v3, SubprocVecEnv",
}


def _per_env_costs(env_pids: list[int], steps: list[int], run) -> dict:
    """Run run() and measure, per env, the CPU of its process and its graph (the process's tree) per step."""
    from moverl_gym.proctree import cpu_seconds, memory_bytes, tree

    trees = [tree(pid) for pid in env_pids]
    before = [cpu_seconds(t) for t in trees]
    t0 = time.perf_counter()
    out = run()
    wall = time.perf_counter() - t0
    after = [cpu_seconds(t) for t in trees]
    made = steps if steps else out
    cpu = []
    for b, a, n in zip(before, after, made):
        cpu.append(sum(a[k] - b[k] for k in b if k in a) / max(n, 1))
    graphs = [memory_bytes(t[1:]) for t in trees]  # the env process's descendants: its graph
    envs = [memory_bytes(t[:1]) for t in trees]
    return {
        "wall": wall,
        "steps_per_env": list(map(int, made)),
        "cpu_per_step": cpu,
        "graph_processes": [len(t) - 1 for t in trees],
        "graph_rss": float(np.mean([g["rss"] for g in graphs])),
        "graph_pss": float(np.mean([g["pss"] for g in graphs])),
        "env_rss": float(np.mean([e["rss"] for e in envs])),
        "env_pss": float(np.mean([e["pss"] for e in envs])),
        "result": out,
    }


def _own_cpu(pids) -> float:
    from moverl_gym.proctree import cpu_seconds
    from moverl_gym.reaper import read_proc

    procs = [p for p in (read_proc(pid) for pid in pids) if p is not None]
    return sum(cpu_seconds(procs).values())


def worker_subproc(env_id: str, n: int, steps: int, seed: int) -> dict:
    """n envs in SB3's SubprocVecEnv, stepped with random actions for `steps` steps each."""
    import gymnasium as gym
    from stable_baselines3.common.vec_env import SubprocVecEnv

    def factory():
        import gymnasium as gym

        if env_id.startswith("MoveRL/"):
            import moverl_gym  # noqa: F401

            return gym.make(env_id, graph="launch")
        import panda_gym  # noqa: F401

        return gym.make(env_id)

    vec = SubprocVecEnv([factory] * n)
    try:
        vec.seed(seed)
        vec.reset()
        space = gym.spaces.Box(-1.0, 1.0, shape=vec.action_space.shape, dtype=np.float32)
        space.seed(seed)

        def run(k):
            for _ in range(k):
                vec.step(np.stack([space.sample() for _ in range(n)]))

        run(200)  # warm-up: connections, caches
        pids = [p.pid for p in vec.processes]
        me = os.getpid()
        c0 = _own_cpu([me])
        m = _per_env_costs(pids, [steps] * n, lambda: run(steps))
        m["stepper_cpu_per_step"] = (_own_cpu([me]) - c0) / (steps * n)
        m["steps_per_s"] = steps * n / m["wall"]
        m.pop("result")
        return m
    finally:
        vec.close()


def worker_rllib(n: int, steps: int, seed: int) -> dict:
    """n RLlib env runners (one env each) on a local Ray cluster, sampling `steps` steps each with random actions."""
    from ray.rllib.algorithms.ppo import PPOConfig

    from moverl_gym import rllib
    from moverl_gym.proctree import cpu_seconds

    cluster = rllib.LocalCluster(rllib.node_layout(n, 1))
    algo = None
    try:
        rllib.register()
        config = (
            PPOConfig()
            .environment(rllib.ENV_NAME, env_config={"env_id": ENV_ID, "graph": "launch"})
            .env_runners(num_env_runners=n, num_envs_per_env_runner=1, gym_env_vectorize_mode="sync")
            .learners(num_learners=0)
            .callbacks(rllib.metrics_callback())  # as in training
            .debugging(seed=seed)
        )
        algo = config.build_algo()
        group = algo.env_runner_group

        def sample(k):
            def fn(runner):
                return sum(len(e) for e in runner.sample(num_timesteps=k, random_actions=True))

            return group.foreach_env_runner(fn, local_env_runner=False, timeout_seconds=900)

        sample(200)  # warm-up
        pids = group.foreach_env_runner(lambda r: os.getpid(), local_env_runner=False)
        runner_trees = set()
        from moverl_gym.proctree import tree

        for pid in pids:
            runner_trees |= {(p.pid, p.start) for p in tree(pid)}
        others = [p for p in cluster.processes() if (p.pid, p.start) not in runner_trees]
        from moverl_gym.reaper import read_proc

        me = read_proc(os.getpid())
        c0 = cpu_seconds(others + [me])
        m = _per_env_costs(pids, [], lambda: sample(steps))
        c1 = cpu_seconds(others + [me])
        total = sum(m["steps_per_env"])
        m["stepper_cpu_per_step"] = sum(c1[k] - c0[k] for k in c0 if k in c1) / total
        m["steps_per_s"] = total / m["wall"]
        m.pop("result")
        return m
    finally:
        if algo is not None:
            algo.stop()
        cluster.shutdown()


def plot(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    for system in SYSTEMS:
        rows = results.get(system, {})
        ns = sorted(int(k) for k in rows)
        if not ns:
            continue
        a.plot(ns, [rows[str(k)]["steps_per_s"] for k in ns], "o-", label=LABELS[system])
        b.plot(ns, [1e3 * np.mean(rows[str(k)]["cpu_per_step"]) for k in ns], "o-", label=LABELS[system])
    cores = results["meta"]["cores"]
    for ax in (a, b):
        ax.axvline(cores, color="grey", ls=":", lw=1)
        ax.set_xlabel("parallel envs")
        ax.set_xticks(sorted({int(k) for s in SYSTEMS for k in results.get(s, {})}))
        ax.grid(alpha=0.3)
    a.set_ylabel("aggregate env steps/s")
    a.set_title(f"throughput ({cores} cores: dotted line)")
    b.set_ylabel("CPU ms per env step (env + its graph)")
    b.set_title("cost per step")
    b.set_ylim(bottom=0)
    a.set_ylim(bottom=0)
    a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def table(results: dict) -> str:
    meta = results["meta"]
    lines = [
        f"== scaling ({meta['steps']} random-action steps per env after a 200-step warm-up, seed {meta['seed']}, "
        f"{meta['cores']} cores, load average before {meta['load_before']}, after {meta['load_after']}) ==",
        f"{'system':46s} {'envs':>4s} {'steps/s':>8s} {'CPU ms/step':>12s} {'stepper ms/step':>16s} "
        f"{'graph RSS MB':>13s} {'graph PSS MB':>13s} {'env RSS MB':>11s}",
    ]
    for system in SYSTEMS:
        for n, r in sorted(results.get(system, {}).items(), key=lambda kv: int(kv[0])):
            graph = r["graph_rss"] / 2**20 if r["graph_processes"][0] else float("nan")
            gpss = r["graph_pss"] / 2**20 if r["graph_processes"][0] else float("nan")
            lines.append(
                f"{LABELS[system]:46s} {int(n):4d} {r['steps_per_s']:8.0f} "
                f"{1e3 * np.mean(r['cpu_per_step']):12.3f} {1e3 * r['stepper_cpu_per_step']:16.3f} "
                f"{graph:13.0f} {gpss:13.0f} {r['env_rss'] / 2**20:11.0f}"
            )
    lines.append(
        "CPU ms/step: the env's process + its graph, per step of that env (mean over envs); stepper: "
        "SubprocVecEnv's parent, or the Ray cluster (GCS, raylets, agents, driver), per env step"
    )
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--envs", type=int, nargs="+", default=[1, 2, 4])
    p.add_argument("--steps", type=int, default=2000, help="steps per env per measurement")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--systems", nargs="+", default=list(SYSTEMS), choices=SYSTEMS)
    p.add_argument("--out", type=Path, default=None, help="folder for scaling.json/.txt/.png (default: print only)")
    p.add_argument("--worker", nargs=2, help=argparse.SUPPRESS)
    args = p.parse_args(argv)

    if args.worker:
        system, n = args.worker[0], int(args.worker[1])
        if system == "rllib":
            out = worker_rllib(n, args.steps, args.seed)
        else:
            out = worker_subproc(ENV_ID if system == "subproc" else PANDA_GYM_ID, n, args.steps, args.seed)
        print(json.dumps(out))
        return 0

    results = {
        "meta": {
            "steps": args.steps,
            "seed": args.seed,
            "cores": os.cpu_count(),
            "load_before": round(os.getloadavg()[0], 2),
            "command": " ".join(sys.argv),
        }
    }
    for system in args.systems:
        results[system] = {}
        for n in args.envs:
            print(f"measuring {LABELS[system]} with {n} env(s) ...", flush=True)
            results[system][str(n)] = run_json_worker(
                __file__,
                ["--worker", system, n, "--steps", args.steps, "--seed", args.seed],
                f"scaling worker {system} x{n}",
                timeout=1800,
            )
    results["meta"]["load_after"] = round(os.getloadavg()[0], 2)
    text = table(results)
    print("\n" + text)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "scaling.json").write_text(json.dumps(results, indent=2))
        (args.out / "scaling.txt").write_text(text + "\n")
        plot(results, args.out / "scaling.png")
        print(f"wrote {args.out}/scaling.json, scaling.txt, scaling.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
