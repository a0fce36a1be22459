#!/usr/bin/env python3
"""Where the CPU of one env step goes: CPU milliseconds and context switches per step of each process of the env and
of the graph it launched (the env's own process, the simulator, the shield hosting the planning scene, ...), for
several ids in one run, interleaved (this VM varies by 30 % between runs: compare ids within one run).

    python src/moverl_gym/tools/step_cost.py --ids MoveRL/PandaReachTable-v0 MoveRL/PandaReachHuman-v0 --reps 2

An id may carry launch arguments after commas, e.g. the person sensed by cameras at 10 Hz:

    python src/moverl_gym/tools/step_cost.py --ids MoveRL/PandaReachHuman-v0 \
        MoveRL/PandaReachHuman-v0,obstacles=sensed,camera_rate=10 --steps 300

With a sensed map, the planning scene's own account of its integration time (~octomap_status.integration_time of
every cloud) is summed too; that is wall time, and its pool runs parts of a cloud on a second core, so the shield's
CPU is also split by thread: the integration's threads name themselves (its loop and its pool's workers; any thread
whose name is not its process's is listed), and the shield's other threads are its services (the checks) and ROS's
own. The simulator's CPU is mostly rendering then. The steps' verdicts are counted as well (info["verdict"]): a
configuration whose steps discard more moves does less (no motion, no render) and looks faster than it is.

--profile NAME (sim, shield, env, ...: a process of the graph, named as in the table) also samples that process
while it is measured: py-spy (`pip install py-spy`, not part of the set-up) for a Python process, perf for a C++ one;
the frames with the largest shares of the samples are printed (py-spy: of the samples that held the GIL, inclusive;
perf: self time by thread, library and symbol).

Random actions from a fixed seed, episodes reset as usual (resets included); 200 warm-up steps first. Each id runs in
its own process (rospy allows one ROS master per process).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time

from moverl_gym.workers import run_json_worker


def parse_id(text: str) -> tuple[str, dict]:
    """ "ID[,key=value...]" -> (ID, launch arguments), as given (main checks them before any worker starts; a worker's
    env checks them once more, in its own process)."""
    env_id, *pairs = text.split(",")
    launch_args = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep:
            raise SystemExit(f"step_cost.py: {pair!r} in {text!r} is not key=value")
        launch_args[key] = value
    return env_id, launch_args


class Profiler:
    """py-spy (Python processes) or perf (others) attached to one process from start() to stop()."""

    def __init__(self, pid: int, python: bool, folder: str):
        import shutil

        self.python, self.out = python, os.path.join(folder, "profile.raw" if python else "perf.data")
        tool = "py-spy" if python else "perf"
        if shutil.which(tool) is None:
            raise SystemExit(f"step_cost.py --profile: {tool} is not installed" + (" (pip install py-spy)" * python))
        if python:
            cmd = [
                "py-spy",
                "record",
                "--gil",
                "--nonblocking",
                "-r",
                "1000",
                "-f",
                "raw",
                "-o",
                self.out,
                "-p",
                str(pid),
            ]
        else:
            cmd = ["perf", "record", "-F", "2000", "-g", "-o", self.out, "-p", str(pid)]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(1.0)  # attached

    def stop(self, top: int = 30) -> list[str]:
        self.proc.send_signal(signal.SIGINT)  # both write their output on SIGINT
        try:
            self.proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        if self.python:
            return _top_frames(self.out, top)
        r = subprocess.run(
            ["perf", "report", "-i", self.out, "--no-children", "--sort", "comm,dso,symbol", "--stdio", "-g", "none"],
            capture_output=True,
            text=True,
            timeout=120,
        )
        return [line.rstrip()[:150] for line in r.stdout.splitlines() if "%" in line and not line.startswith("#")][:top]


def _top_frames(path: str, top: int) -> list[str]:
    """py-spy's raw (collapsed) stacks -> the frames with the largest inclusive shares of the samples."""
    shares: dict[str, int] = {}
    total = 0
    with open(path) as f:
        for line in f:
            stack, _, count = line.rstrip().rpartition(" ")
            n = int(count)
            total += n
            for frame in set(stack.split(";")):
                if "threading.py" not in frame:
                    shares[frame] = shares.get(frame, 0) + n
    ranked = sorted(shares.items(), key=lambda kv: -kv[1])[:top]
    return [f"{100.0 * n / max(total, 1):5.1f} %  {frame[:140]}" for frame, n in ranked] + [f"({total} samples)"]


def worker(text: str, steps: int, seed: int, profile: str | None = None) -> dict:
    import gymnasium as gym

    import moverl_gym  # noqa: F401
    from moverl_gym.proctree import cmdline, context_switches, cpu_seconds, thread_cpu_seconds, tree

    env_id, launch_args = parse_id(text)
    env = gym.make(env_id, launch_args=launch_args)
    integration = None  # ~octomap_status.integration_time of each cloud, while measuring (a sensed map only)
    verdicts: dict[str, int] = {}  # the steps' verdicts while measuring (info["verdict"]): what the steps did
    measuring = threading.Event()
    if launch_args.get("obstacles", "objects") != "objects":
        import rospy

        from moverl_msgs.msg import OctomapStatus

        integration = []

        def on_status(msg):
            if measuring.is_set():
                integration.append(msg.integration_time)

        rospy.Subscriber("/planning_scene/octomap_status", OctomapStatus, on_status)
    try:
        env.reset(seed=seed)
        env.action_space.seed(seed)

        def run(n):
            for _ in range(n):
                _, _, term, trunc, info = env.step(env.action_space.sample())
                if measuring.is_set():
                    verdicts[info["verdict"]] = verdicts.get(info["verdict"], 0) + 1
                if term or trunc:
                    env.reset()

        run(200)
        procs = tree(os.getpid())
        names = {}
        for p in procs:
            line = cmdline(p.pid)
            name = "env" if p.pid == os.getpid() else next((w for w in line.split() if w.startswith("__name:=")), "")
            names[(p.pid, p.start)] = name.replace("__name:=", "/") or os.path.basename(
                line.split()[0] if line else "?"
            )
        profiler = None
        if profile:
            target = [key for key, name in names.items() if name.lstrip("/") == profile.lstrip("/")]
            if not target:
                raise SystemExit(
                    f"step_cost.py --profile {profile}: no such process (processes: {sorted(names.values())})"
                )
            pid = target[0][0]
            folder = tempfile.mkdtemp(prefix="moverl_profile_")
            profiler = Profiler(pid, "python" in cmdline(pid).split()[0], folder)
        c0, s0, n0 = cpu_seconds(procs), context_switches(procs), thread_cpu_seconds(procs, renamed_only=True)
        measuring.set()
        t0 = time.perf_counter()
        run(steps)
        wall = time.perf_counter() - t0
        measuring.clear()
        frames = profiler.stop() if profiler is not None else None
        c1, s1, n1 = cpu_seconds(procs), context_switches(procs), thread_cpu_seconds(procs, renamed_only=True)
    finally:
        env.close()
    per, switches = {}, {}
    for key, t in c1.items():
        if key in c0:
            per[names[key]] = per.get(names[key], 0.0) + 1000.0 * (t - c0[key]) / steps
    for key, n in s1.items():
        if key in s0:
            switches[names[key]] = switches.get(names[key], 0.0) + (n - s0[key]) / steps
    # The threads that name themselves (moverl_planning_scene's integration loop and its pool's workers), and the rest
    # of their process: a process's CPU split by what its threads do.
    threads = {}
    for key, by_name in n1.items():
        named = {n: t - n0[key].get(n, 0.0) for n, t in by_name.items() if key in n0}
        if named and key in c0:
            for n, t in named.items():
                threads[f"{names[key]} {n}"] = 1000.0 * t / steps
            threads[f"{names[key]} (other threads)"] = 1000.0 * ((c1[key] - c0[key]) - sum(named.values())) / steps
    out = {
        "env_id": text,
        "steps_per_s": steps / wall,
        "ms_per_step": per,
        "total_ms": sum(per.values()),
        "switches_per_step": switches,
        "verdicts": verdicts,
        "thread_ms_per_step": threads,
    }
    if frames is not None:
        out["profile"] = {"process": profile, "frames": frames}
    if integration is not None:
        out["clouds_per_step"] = len(integration) / steps
        out["integration_ms_per_step"] = 1000.0 * sum(integration) / steps
    return out


def _column(text: str) -> str:
    """An id's column header: the id without its namespace, its launch arguments shortened."""
    name = text.split("/")[-1].replace("obstacles=", "").replace("camera_rate=", "cam ")
    return name[-27:].rjust(28)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--ids", nargs="+", default=["MoveRL/PandaReachTable-v0", "MoveRL/PandaReachHuman-v0"])
    p.add_argument("--steps", type=int, default=2000)
    p.add_argument("--reps", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--profile", metavar="NAME", help="sample this process of the graph while measuring (sim, shield, env)"
    )
    p.add_argument("--worker", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args.worker, args.steps, args.seed, args.profile)))
        return 0
    from moverl_gym.launch_args import LaunchArgError, check

    for text in args.ids:  # a wrong launch argument is refused before anything starts
        try:
            check(parse_id(text)[1])
        except LaunchArgError as exc:
            raise SystemExit(f"step_cost.py: {text}: {exc}") from None
    results: dict[str, list] = {i: [] for i in args.ids}
    for rep in range(args.reps):
        for env_id in args.ids:
            profile = ["--profile", args.profile] if args.profile and rep == 0 else []
            r = run_json_worker(
                __file__, ["--worker", env_id, "--steps", args.steps, "--seed", args.seed, *profile], env_id
            )
            results[env_id].append(r)
            print(
                f"rep {rep}: {env_id}: {r['steps_per_s']:.0f} steps/s, {r['total_ms']:.2f} ms CPU per step", flush=True
            )
    for env_id in args.ids:
        prof = results[env_id][0].get("profile")
        if prof:
            print(f"\n{env_id}: where {prof['process']} spends its time while measured (first repetition):")
            print("\n".join("  " + line for line in prof["frames"]))
    print("\nCPU ms per env step, mean over reps (processes under 0.02 ms left out):")
    names = sorted({n for rs in results.values() for r in rs for n in r["ms_per_step"]})
    print("process".ljust(24) + "".join(_column(i) for i in args.ids))
    for n in names:
        vals = [sum(r["ms_per_step"].get(n, 0.0) for r in results[i]) / len(results[i]) for i in args.ids]
        if max(vals) >= 0.02:
            print(n.ljust(24) + "".join(f"{v:28.3f}" for v in vals))
    totals = [sum(r["total_ms"] for r in results[i]) / len(results[i]) for i in args.ids]
    print("total".ljust(24) + "".join(f"{v:28.3f}" for v in totals))
    threads = sorted({n for rs in results.values() for r in rs for n in r.get("thread_ms_per_step", {})})
    if threads:
        print(
            "\nCPU ms per env step of the threads that name themselves and the rest of their process, mean over reps:"
        )
        print("thread".ljust(32) + "".join(_column(i) for i in args.ids))
        for n in threads:
            vals = [sum(r.get("thread_ms_per_step", {}).get(n, 0.0) for r in results[i]) for i in args.ids]
            vals = [v / len(results[i]) for v, i in zip(vals, args.ids)]
            print(n.ljust(32) + "".join(f"{v:28.3f}" for v in vals))
    if any("integration_ms_per_step" in r for rs in results.values() for r in rs):
        print("\nthe planning scene's integration of clouds (its ~octomap_status.integration_time), mean over reps:")
        for key, label in (("clouds_per_step", "clouds per step"), ("integration_ms_per_step", "integration ms/step")):
            vals = [sum(r.get(key, 0.0) for r in results[i]) / len(results[i]) for i in args.ids]
            print(label.ljust(24) + "".join(f"{v:28.3f}" for v in vals))
    # What the steps did: a faster step that discards more moves is not a faster env (fewer motions, fewer renders).
    print("\nthe steps' verdicts (info['verdict']), summed over reps:")
    kinds = sorted({k for rs in results.values() for r in rs for k in r.get("verdicts", {})})
    for k in kinds:
        vals = [sum(r.get("verdicts", {}).get(k, 0) for r in results[i]) for i in args.ids]
        print(k.ljust(24) + "".join(f"{v:28d}" for v in vals))
    # Each context switch is a thread put to sleep and woken: what a hand-off between threads costs on the step's path.
    print("\ncontext switches per env step (every thread of each process), mean over reps (under 0.05 left out):")
    print("process".ljust(24) + "".join(_column(i) for i in args.ids))
    for n in names:
        vals = [sum(r["switches_per_step"].get(n, 0.0) for r in results[i]) / len(results[i]) for i in args.ids]
        if max(vals) >= 0.05:
            print(n.ljust(24) + "".join(f"{v:28.2f}" for v in vals))
    return 0


if __name__ == "__main__":
    sys.exit(main())
