#!/usr/bin/env python3
"""Soak: run the graph for long and watch memory, file descriptors, processes, latency and contacts.

    python src/moverl_gym/tools/soak.py --out docs/soak                 # 200,000 + 50,000 steps (about 20 min)
    python src/moverl_gym/tools/soak.py --steps 3000 --octomap-steps 1000 --every 1000 --out /tmp/soak  # short

A random policy with the shield on, 200,000 steps over the three worlds (table, human walking, case: a third each) and
50,000 in the OctoMap mode (table world, sensed obstacles), each world in its own worker process and graph. Every
`--every` steps (10,000) it samples the resident memory (RSS) and open file descriptors of the env's process and of
every process of its graph (found in the env process's own tree, named by their command line), the number of those
processes, the env step's round-trip latency p50 / p99 over the steps since the last sample, and the ground-truth
contacts. The first sample is taken after the first `--every` steps and at least WARMUP_SECONDS of stepping (warm-up:
topic connections are made asynchronously, and a fast env can reach its first sample before one of them is, which
would count as a file descriptor opened during the run).

Checks (exit code 1 if one fails): memory growth from the first to the last sample under 5 % for every process,
no growth in file descriptors or processes, p99 latency of the last window within 20 % of the first, zero contacts.
Writes soak.json, soak.md and soak.png into --out.
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

WARMUP_SECONDS = 1.0  # s of stepping before the first sample
NAMES = ("sim_node", "world_server", "planning_scene_node", "shield_node", "rosmaster", "rosout", "roslaunch")
PAGE = os.sysconf("SC_PAGE_SIZE")


def tree(root: int) -> list[int]:
    """The pids of every process below root (moverl_gym.proctree: its own tree, from /proc's parent links)."""
    from moverl_gym.proctree import tree as proc_tree

    return [p.pid for p in proc_tree(root) if p.pid != root]


def proc_sample(pid: int) -> "dict | None":
    try:
        with open(f"/proc/{pid}/statm") as f:
            rss = int(f.read().split()[1]) * PAGE
        fds = len(os.listdir(f"/proc/{pid}/fd"))
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            cmd = f.read().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return None
    name = next((n for n in NAMES if n in cmd), None)
    return {"name": name, "rss_mib": rss / 2**20, "fds": fds} if name else None


def sample(step: int, latencies: list[float], contacts: int) -> dict:
    procs = {"env": proc_sample_self()}
    for pid in tree(os.getpid()):
        s = proc_sample(pid)
        if s is not None:
            procs[s["name"]] = {"rss_mib": s["rss_mib"], "fds": s["fds"]}
    lat = np.asarray(latencies) * 1e3
    return {
        "step": step,
        "processes": procs,
        "graph_processes": len(tree(os.getpid())),
        "p50_ms": float(np.percentile(lat, 50)),
        "p99_ms": float(np.percentile(lat, 99)),
        "contacts": contacts,
    }


def proc_sample_self() -> dict:
    with open("/proc/self/statm") as f:
        rss = int(f.read().split()[1]) * PAGE
    return {"rss_mib": rss / 2**20, "fds": len(os.listdir("/proc/self/fd"))}


def worker(world: str, steps: int, every: int, obstacles: str, seed: int) -> dict:
    import gymnasium as gym

    import moverl_gym  # noqa: F401

    env_id = {
        "table": "MoveRL/PandaReachTable-v0",
        "human": "MoveRL/PandaReachHuman-v0",
        "case": "MoveRL/PandaReachCase-v0",
    }[world]
    env = gym.make(env_id, launch_args={"obstacles": obstacles})
    try:
        env.action_space.seed(seed)
        env.reset(seed=seed)
        samples, latencies, contacts, t0 = [], [], 0, time.monotonic()
        for k in range(1, steps + 1):
            _, _, term, trunc, info = env.step(env.action_space.sample())
            latencies.append(env.unwrapped.last_timing["round_trip"])
            contacts += max(0, info["contacts"])
            if term or trunc:
                env.reset()
            if k % every == 0 and (samples or time.monotonic() - t0 >= WARMUP_SECONDS or k == steps):
                samples.append(sample(k, latencies, contacts))
                latencies = []
        return {
            "world": world,
            "obstacles": obstacles,
            "steps": steps,
            "seconds": time.monotonic() - t0,
            "samples": samples,
        }
    finally:
        env.close()


def checks(run: dict) -> list[str]:
    """What failed in one run (empty: all held)."""
    s = run["samples"]
    if len(s) < 2:
        return []
    first, last = s[0], s[-1]
    bad = []
    for name, p0 in first["processes"].items():
        p1 = last["processes"].get(name)
        if p1 is None:
            bad.append(f"{name} is gone")
            continue
        growth = p1["rss_mib"] / p0["rss_mib"] - 1.0
        if growth >= 0.05:
            bad.append(f"{name} RSS grew {growth:.1%} ({p0['rss_mib']:.1f} -> {p1['rss_mib']:.1f} MiB)")
        if p1["fds"] > p0["fds"]:
            bad.append(f"{name} file descriptors {p0['fds']} -> {p1['fds']}")
    if last["graph_processes"] > first["graph_processes"]:
        bad.append(f"processes {first['graph_processes']} -> {last['graph_processes']}")
    if last["p99_ms"] > 1.2 * first["p99_ms"]:
        bad.append(f"p99 latency {first['p99_ms']:.2f} -> {last['p99_ms']:.2f} ms")
    if last["contacts"] > 0:
        bad.append(f"{last['contacts']} contact pairs")
    return bad


def plot(runs: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(runs), 3, figsize=(15, 3.2 * len(runs)), squeeze=False)
    for row, run in zip(axes, runs):
        steps = [s["step"] for s in run["samples"]]
        label = f"{run['world']} ({run['obstacles']})"
        for name in run["samples"][0]["processes"]:
            row[0].plot(
                steps,
                [s["processes"].get(name, {}).get("rss_mib", np.nan) for s in run["samples"]],
                marker=".",
                label=name,
            )
            row[1].plot(
                steps, [s["processes"].get(name, {}).get("fds", np.nan) for s in run["samples"]], marker=".", label=name
            )
        row[2].plot(steps, [s["p50_ms"] for s in run["samples"]], marker=".", label="p50")
        row[2].plot(steps, [s["p99_ms"] for s in run["samples"]], marker=".", label="p99")
        row[0].set_ylabel(f"{label}\nRSS (MiB)")
        row[1].set_ylabel("open file descriptors")
        row[2].set_ylabel("env step round trip (ms)")
        for ax in row:
            ax.set_xlabel("env steps")
            ax.grid(alpha=0.3)
        row[0].legend(fontsize=7, ncol=2)
        row[2].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--steps", type=int, default=200000, help="shield-on steps over the three worlds (a third each)")
    p.add_argument("--octomap-steps", type=int, default=50000, help="steps in the OctoMap mode (table world)")
    p.add_argument("--every", type=int, default=10000, help="steps between samples")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", help="write soak.json, soak.md and soak.png here")
    p.add_argument("--worker", nargs=3, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        world, steps, obstacles = args.worker
        print(json.dumps(worker(world, int(steps), args.every, obstacles, args.seed)))
        return 0
    plan = [(w, args.steps // 3, "objects") for w in ("table", "human", "case")]
    if args.octomap_steps:
        plan.append(("table", args.octomap_steps, "octomap"))
    runs = []
    for world, steps, obstacles in plan:
        print(f"soak: {world} ({obstacles}), {steps} steps ...", flush=True)
        runs.append(
            run_json_worker(
                __file__,
                ["--worker", world, steps, obstacles, "--every", args.every, "--seed", args.seed],
                f"soak {world} {obstacles}",
                timeout=14400,
            )
        )
    lines = [
        "| world | mode | steps | steps/s | process | RSS first -> last (MiB) | growth | fds first -> last | "
        "p50 / p99 first (ms) | p50 / p99 last (ms) | contacts |",
        "|---|---|---:|---:|---|---|---:|---|---|---|---:|",
    ]
    failed = []
    for run in runs:
        s0, s1 = run["samples"][0], run["samples"][-1]
        for name, p0 in s0["processes"].items():
            p1 = s1["processes"].get(name, {"rss_mib": float("nan"), "fds": -1})
            lines.append(
                f"| {run['world']} | {run['obstacles']} | {run['steps']} | {run['steps'] / run['seconds']:.0f} "
                f"| {name} | {p0['rss_mib']:.1f} -> {p1['rss_mib']:.1f} | "
                f"{p1['rss_mib'] / p0['rss_mib'] - 1:+.1%} | {p0['fds']} -> {p1['fds']} | "
                f"{s0['p50_ms']:.2f} / {s0['p99_ms']:.2f} | {s1['p50_ms']:.2f} / {s1['p99_ms']:.2f} | "
                f"{s1['contacts']} |"
            )
        failed += [f"{run['world']} ({run['obstacles']}): {b}" for b in checks(run)]
    table = "\n".join(lines)
    print("\n" + table)
    print("\nchecks: " + ("all held" if not failed else "; ".join(failed)))
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "soak.json").write_text(json.dumps(runs, indent=2))
        plot(runs, out / "soak.png")
        cmd = "python src/moverl_gym/tools/soak.py " + " ".join(argv if argv is not None else sys.argv[1:])
        (out / "soak.md").write_text(
            f"# Soak\n\nCommand: `{cmd}` (see its docstring). First sample after "
            f"{args.every} steps (warm-up), last at the end of each run.\n\n{table}\n\n"
            f"Checks: {'all held' if not failed else '; '.join(failed)}\n\n"
            "![soak](soak.png)\n"
        )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
