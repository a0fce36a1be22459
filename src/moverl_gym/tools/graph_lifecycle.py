#!/usr/bin/env python3
"""What a launched graph leaves behind and where it listens (prints figures; not a test; ~4 min).

    python src/moverl_gym/tools/graph_lifecycle.py [--reps 3] [--steps 1000] [--expose-host ADDR]
                                                     [--sections 1,2,3,4,5] [--json out.json]

Measures, counting the processes of each graph's own tree (LaunchedGraph.processes()):
  1. listening sockets (TCP LISTEN, unconnected UDP) of each component: default (loopback shim), without the shim
     with ROS_HOSTNAME=127.0.0.1 (the env before issue #10), without it with ROS_IP=127.0.0.1, and exposed
     (expose=<this host's address>, the sanctioned exception);
  2. close(): seconds, processes before and after, processes SIGKILLed: clean, and with /sim or
     /shield stopped by SIGSTOP;
  3. the close() this replaced (roslaunch in its own session, SIGINT to its group, 10 s, SIGKILL to the group;
     git show 23d22b7:src/moverl_gym/src/moverl_gym/graph.py), clean and with /shield stopped; its leftovers are
     found by the graph's marker variable and killed afterwards;
  4. the owner killed by SIGKILL, alone or after its reaper (what Ray does to a dead worker's direct children):
     seconds until no process of its graph runs;
  5. the shim's cost: graph start-up time, env steps/s and the step round trip's median (shield on, random
     actions) with and without it, and
     socket()+bind()+close() per second in a loop (bind 0.0.0.0 with the shim, 127.0.0.1 without).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import time
import uuid
import xmlrpc.client
from pathlib import Path

from moverl_gym import graph, reaper
from moverl_gym import ros_backend as ros
from moverl_gym.paths import launch_file, repo_root, world_file
from moverl_gym.workers import run_json_worker

NODES = ("/sim", "/shield")  # the default graph: the shield hosts the planning scene
COMPONENTS = ("master", "/rosout") + NODES


def table_args() -> dict:
    return {"world_file": str(world_file("table"))}


def node_pid(uri: str, node: str) -> int:
    if node == "master":
        return xmlrpc.client.ServerProxy(uri).getPid("/graph_lifecycle")[2]
    _, _, node_uri = xmlrpc.client.ServerProxy(uri).lookupNode("/graph_lifecycle", node)
    return xmlrpc.client.ServerProxy(node_uri).getPid("/graph_lifecycle")[2]


def alive(procs) -> list:
    now = reaper.proc_table()
    return [p for p in procs if p.pid in now and now[p.pid].start == p.start and now[p.pid].state != "Z"]


def wait_gone(procs, timeout: float) -> float:
    t0 = time.monotonic()
    while alive(procs) and time.monotonic() - t0 < timeout:
        time.sleep(0.02)
    return time.monotonic() - t0


class RosIpGraph(graph.LaunchedGraph):
    """Without the shim, with ROS_IP=127.0.0.1 instead of ROS_HOSTNAME (what the issue also measured)."""

    def _environment(self, host: str) -> dict:
        env = super()._environment(host)
        env.pop("ROS_HOSTNAME")
        env["ROS_IP"] = host
        return env


def sockets_by_component(g) -> dict:
    pids = {c: node_pid(g.uri, c) for c in COMPONENTS}
    pids["roslaunch"] = next(p.pid for p in g.processes() if p.name == "roslaunch")
    out = {c: sorted({f"{s.proto} {s.address}" for s in g.sockets() if s.pid == pid}) for c, pid in pids.items()}
    out["all_loopback"] = all(reaper.is_loopback(s.address) for s in g.sockets())
    return out


def measure_sockets(expose_host: str | None) -> dict:
    modes = {
        "shim (default)": lambda: graph.LaunchedGraph(table_args(), wait_for=ros.REQUIRED_SERVICES),
        "no shim, ROS_HOSTNAME=127.0.0.1": lambda: graph.LaunchedGraph(
            table_args(), wait_for=ros.REQUIRED_SERVICES, expose="127.0.0.1"
        ),
        "no shim, ROS_IP=127.0.0.1": lambda: RosIpGraph(
            table_args(), wait_for=ros.REQUIRED_SERVICES, expose="127.0.0.1"
        ),
    }
    if expose_host:
        modes[f"exposed ({expose_host})"] = lambda: graph.LaunchedGraph(
            table_args(), wait_for=ros.REQUIRED_SERVICES, expose=expose_host
        )
    out = {}
    for name, make in modes.items():
        g = make()
        try:
            out[name] = sockets_by_component(g)
        finally:
            g.close()
    return out


def measure_close(stop: str | None) -> dict:
    t0 = time.monotonic()
    g = graph.LaunchedGraph(table_args(), wait_for=ros.REQUIRED_SERVICES)
    startup = time.monotonic() - t0
    try:
        procs = g.processes()
        if stop:
            os.kill(node_pid(g.uri, stop), signal.SIGSTOP)
    finally:
        g.close()
    return dict(
        seconds=g.last_close["seconds"],
        startup_s=startup,
        before=len(procs),
        after=len(alive(procs)),
        marked_after=len(reaper.graph_processes(g.graph_id, None)),
        sigkilled=g.last_close["sigkilled"],
    )


def measure_old_close(stop: str | None) -> dict:
    """The close() of 23d22b7 (roslaunch started the master itself, in its own session)."""
    import ctypes

    graph_id = uuid.uuid4().hex
    port = graph.free_port()
    uri = f"http://127.0.0.1:{port}"
    log_dir = Path(os.environ.get("TMPDIR", "/tmp")) / f"moverl_old_close_{graph_id}"
    log_dir.mkdir()
    env = dict(
        os.environ,
        ROS_MASTER_URI=uri,
        ROS_HOSTNAME="127.0.0.1",
        ROS_LOG_DIR=str(log_dir),
        MOVERL_ROOT=str(repo_root()),
        **{reaper.MARKER: graph_id},
    )

    def own_session_dies_with_parent():
        os.setsid()
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)

    t0 = time.monotonic()
    with open(log_dir / "roslaunch.log", "wb") as log:
        cmd = ["roslaunch", "-p", str(port), str(launch_file()), f"world_file:={world_file('table')}"]
        proc = subprocess.Popen(
            cmd,
            env=env,
            stdout=log,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            preexec_fn=own_session_dies_with_parent,
        )
    deadline = time.monotonic() + 60
    while not all(graph.service_exists(uri, s) for s in ros.REQUIRED_SERVICES):
        if time.monotonic() > deadline or proc.poll() is not None:
            raise RuntimeError(f"old-style graph did not come up; log in {log_dir}")
        time.sleep(0.1)
    startup = time.monotonic() - t0
    procs = reaper.graph_processes(graph_id, None)
    if stop:
        os.kill(node_pid(uri, stop), signal.SIGSTOP)
    t0 = time.monotonic()
    try:  # the old close(), verbatim
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(timeout=10)
    except (subprocess.TimeoutExpired, ProcessLookupError):
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait(timeout=5)
    seconds = time.monotonic() - t0
    time.sleep(1.0)  # what is still there a second later stays
    left = alive(procs)
    reaper.stop_processes(graph_id, None, None, 0.0, 5.0)  # clean up what it left
    return dict(
        seconds=seconds, startup_s=startup, before=len(procs), after=len(left), left=sorted(p.name for p in left)
    )


OWNER = """
import json, sys, time
from moverl_gym import graph, backend as ros
from moverl_gym.paths import world_file
g = graph.LaunchedGraph({"world_file": str(world_file("table"))}, wait_for=ros.REQUIRED_SERVICES)
print(json.dumps([list(p) for p in g.processes()]), flush=True)
time.sleep(600)
"""


def measure_owner_sigkill(reaper_too: bool) -> dict:
    owner = subprocess.Popen([sys.executable, "-c", OWNER], stdout=subprocess.PIPE, text=True)
    try:
        procs = [reaper.Proc(*p) for p in json.loads(owner.stdout.readline())]
        if reaper_too:  # first: only roslaunch's own escalation (after PR_SET_PDEATHSIG's SIGTERM) is left
            os.kill(procs[0].pid, signal.SIGKILL)
    finally:
        owner.kill()
        owner.wait()
    seconds = wait_gone(procs, graph.GRACE + graph.KILL_TIMEOUT + 5)
    return dict(seconds=seconds, before=len(procs), after=len(alive(procs)))


def worker_steps(shim: bool, steps: int, seed: int) -> dict:
    """In a fresh process: start-up time and env steps/s, with or without the shim."""
    import gymnasium as gym

    import moverl_gym  # noqa: F401

    if not shim:
        os.environ[graph.EXPOSE_ENV] = "127.0.0.1"
    t0 = time.perf_counter()
    env = gym.make("MoveRL/PandaReachTable-v0", graph="launch")
    startup = time.perf_counter() - t0
    try:
        env.action_space.seed(seed)
        env.reset(seed=seed)
        round_trips = []
        t0 = time.perf_counter()
        for _ in range(steps):
            _, _, term, trunc, _ = env.step(env.action_space.sample())
            round_trips.append(env.unwrapped.last_timing["round_trip"])
            if term or trunc:
                env.reset()
        rate = steps / (time.perf_counter() - t0)
        preloaded = "LD_PRELOAD" in open(f"/proc/{graph_node_pid(env)}/environ", "rb").read().decode(errors="replace")
    finally:
        env.close()
    return dict(
        startup_s=startup,
        steps_per_s=rate,
        round_trip_p50_ms=1e3 * statistics.median(round_trips),
        shim_in_shield=preloaded,
    )


def graph_node_pid(env) -> int:
    return node_pid(env.unwrapped._graph.uri, "/shield")


BIND_LOOP = """
import socket, sys, time
n = 50000
t0 = time.perf_counter()
for _ in range(n):
    s = socket.socket()
    s.bind((sys.argv[1], 0))
    s.close()
print(n / (time.perf_counter() - t0))
"""


def measure_bind_rate(shim: bool) -> float:
    """socket()+bind()+close() per second. Like for like: with the shim bind 0.0.0.0 (which it turns into
    127.0.0.1), without it bind 127.0.0.1 (the kernel's work differs between the two addresses)."""
    env = dict(os.environ)
    if shim:
        env["LD_PRELOAD"] = str(graph.loopback_shim())
    address = "0.0.0.0" if shim else "127.0.0.1"
    out = subprocess.run(
        [sys.executable, "-c", BIND_LOOP, address], env=env, capture_output=True, text=True, check=True
    )
    return float(out.stdout)


def host_address() -> str | None:
    """This host's address on its default route (None when it has none)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.connect(("192.0.2.1", 9))  # no packet is sent: only picks the outgoing interface
            return s.getsockname()[0]
        except OSError:
            return None


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reps", type=int, default=3, help="repetitions of each close() measurement")
    p.add_argument("--steps", type=int, default=1000, help="env steps per steps/s measurement")
    p.add_argument(
        "--expose-host",
        default=host_address(),
        help="address for the exposed mode (default: this host's address on its default route)",
    )
    p.add_argument("--json", help="also write all figures to this file")
    p.add_argument("--sections", default="1,2,3,4,5", help="which of the measurements above to run")
    p.add_argument("--worker", choices=["shim", "noshim"], help=argparse.SUPPRESS)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    if args.worker:
        print(json.dumps(worker_steps(args.worker == "shim", args.steps, args.seed)))
        return

    sections = {int(x) for x in args.sections.split(",")}
    out = {}
    if 1 in sections:
        report_sockets(args, out)
    if 2 in sections:
        report_close(args, out)
    if 3 in sections:
        report_old_close(args, out)
    if 4 in sections:
        report_owner_sigkill(args, out)
    if 5 in sections:
        report_cost(args, out)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))


def report_sockets(args, out: dict) -> None:
    out["sockets"] = measure_sockets(args.expose_host)
    print("\n1. listening sockets per component (proto address)")
    for mode, comps in out["sockets"].items():
        print(f"  {mode}: all on loopback: {comps['all_loopback']}")
        for c in ("master", "roslaunch") + COMPONENTS[1:]:
            print(f"    {c:16s} {', '.join(comps[c])}")


def report_close(args, out: dict) -> None:
    print("\n2. close(): seconds, processes of the graph before -> after, SIGKILLed")
    out["close"] = {}
    for stop in (None,) + NODES:
        runs = [measure_close(stop) for _ in range(args.reps)]
        out["close"][stop or "clean"] = runs
        secs = ", ".join(f"{r['seconds']:.2f}" for r in runs)
        startup = ", ".join(f"{r['startup_s']:.2f}" for r in runs)
        print(
            f"  {'stopped ' + stop if stop else 'clean':24s} {secs} s; processes {runs[0]['before']} -> "
            f"{max(r['after'] + r['marked_after'] for r in runs)}; SIGKILLed {runs[0]['sigkilled']}; "
            f"(start-up {startup} s)"
        )


def report_old_close(args, out: dict) -> None:
    print("\n3. the close() this replaced: seconds, processes before -> after (1 s later)")
    out["old_close"] = {}
    for stop in (None, "/shield"):
        runs = [measure_old_close(stop) for _ in range(args.reps)]
        out["old_close"][stop or "clean"] = runs
        secs = ", ".join(f"{r['seconds']:.2f}" for r in runs)
        startup = ", ".join(f"{r['startup_s']:.2f}" for r in runs)
        print(
            f"  {'stopped ' + stop if stop else 'clean':24s} {secs} s; processes {runs[0]['before']} -> "
            f"{max(r['after'] for r in runs)} {runs[-1]['left']} (start-up {startup} s)"
        )


def report_owner_sigkill(args, out: dict) -> None:
    print("\n4. owner killed by SIGKILL: seconds until none of its graph's processes runs")
    for victims, reaper_too in (("owner", False), ("reaper and owner", True)):
        runs = [measure_owner_sigkill(reaper_too) for _ in range(args.reps)]
        out[f"sigkill {victims}"] = runs
        secs = ", ".join(f"{r['seconds']:.2f}" for r in runs)
        print(f"  {victims:24s} {secs} s; processes {runs[0]['before']} -> {max(r['after'] for r in runs)}")


def report_cost(args, out: dict) -> None:
    print(f"\n5. the shim's cost (env: {args.steps} random steps, shield on; alternating, {args.reps} runs each)")
    out["cost"] = {"shim": [], "noshim": []}
    for _ in range(args.reps):
        for mode in ("noshim", "shim"):
            out["cost"][mode].append(
                run_json_worker(
                    __file__, ["--worker", mode, "--steps", args.steps, "--seed", args.seed], f"steps ({mode})"
                )
            )
    for mode, runs in out["cost"].items():
        assert all(r["shim_in_shield"] == (mode == "shim") for r in runs)
        startup = ", ".join(f"{r['startup_s']:.2f}" for r in runs)
        rates = ", ".join(f"{r['steps_per_s']:.0f}" for r in runs)
        p50 = ", ".join(f"{r['round_trip_p50_ms']:.2f}" for r in runs)
        print(f"  {mode:7s} start-up {startup} s; steps/s {rates}; step round trip p50 {p50} ms")
    out["bind_per_s"] = {"noshim": [], "shim": []}
    for _ in range(3 * args.reps):
        for mode in ("noshim", "shim"):
            out["bind_per_s"][mode].append(measure_bind_rate(mode == "shim"))
    for mode, rates in out["bind_per_s"].items():
        print(
            f"  {mode:7s} socket()+bind()+close() per s, {len(rates)} runs of 50,000: median "
            f"{statistics.median(rates):.0f} (min {min(rates):.0f}, max {max(rates):.0f})"
        )


if __name__ == "__main__":
    main()
