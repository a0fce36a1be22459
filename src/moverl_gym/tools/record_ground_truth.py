#!/usr/bin/env python3
"""Record what the simulator received on a live graph with the shield off, and the contacts it counted at every
physics substep: the fixtures of src/moverl_sim/test/test_ground_truth_identity.py.

    python src/moverl_gym/tools/record_ground_truth.py                 # every run below, into the fixtures folder
    python src/moverl_gym/tools/record_ground_truth.py --runs case_pushing --steps 200 --out /tmp/gt

Each run launches the env's graph (shield off, so every action is executed as commanded), steps it with a seeded
policy (random actions in the table, human and case worlds; the pushing policy of pushing_policy_audit.py, which
drives the arm into the obstacles, in the case world with its 5 mm walls) and records, from the shield's ~events
topic, every trajectory the shield sent to the simulator (positions, times; the state and sim time it started from),
and every reset. Then it replays them through a moverl_sim Simulator in this process, one physics substep at a time
(moverl_sim.ground_truth.replay_by_substep), and checks the replay against the live graph: every trajectory starts
where the previous one ended or where the env reset the robot, at the sim time the live graph stamped, and every step
has exactly the contact pairs and substeps in contact the live simulator reported (info["contacts"],
info["contact_substeps"]). Only then is the per-substep trace written, with the inputs, actions and the code's commit.

The recording made before issue 26's speed work is the reference: re-recording it with later code would compare that
code with itself. Re-record only when the inputs must change (a new robot model, a new world), and say why.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[2]
FIXTURES = REPO / "src" / "moverl_sim" / "test" / "fixtures" / "ground_truth"
#: name -> (world, policy, steps). Random actions near home touch the table and the arm itself; the pushing policy
#: touches the case's thin walls and (human_pushing) the walking person, a moving multibody, which random actions never
#: reach. Step counts keep the fixtures near 1 MB in all (every depth is a double that does not compress).
RUNS = {
    "table_random": ("table", "random", 600),
    "human_random": ("human", "random", 600),
    "case_random": ("case", "random", 600),
    "case_pushing": ("case", "pushing", 400),
    "human_pushing": ("human", "pushing", 300),
}
ENV_IDS = {
    "table": "MoveRL/PandaReachTable-v0",
    "human": "MoveRL/PandaReachHuman-v0",
    "case": "MoveRL/PandaReachCase-v0",
}
ROBOT = "panda"
EVENT_WAIT = 10.0  # s: an event not received by then fails the recording (the shield publishes it with the response)


def _pushing_module():
    from moverl_gym.paths import load_script

    return load_script(HERE / "pushing_policy_audit.py")


def make_sim(world: str):
    """A Simulator of the robot and world as the simulator node builds it (same URDF text, settings, home)."""
    from moverl_gym.paths import robot_config_file, world_file
    from moverl_sim.robot_config import load_robot_config
    from moverl_sim.settings import simulator_for
    from moverl_sim.world import load_world

    rc = load_robot_config(robot_config_file(ROBOT))
    sim = simulator_for(rc, load_world(str(world_file(world))))
    sim.reset_robot(rc["home"])  # the node's start-up configuration (/robot/home)
    return sim


def record(name: str, steps: int, seed: int) -> dict:
    import gymnasium as gym
    import rospy

    import moverl_gym  # noqa: F401
    from moverl_msgs.msg import ShieldEvent

    world, policy_name, _ = RUNS[name]
    env = gym.make(ENV_IDS[world], shield=False)
    events, lock = [], threading.Condition()

    def on_event(msg):
        with lock:
            events.append(msg)
            lock.notify_all()

    try:
        u = env.unwrapped
        sub = rospy.Subscriber("/shield/events", ShieldEvent, on_event, queue_size=10000, tcp_nodelay=True)
        deadline = time.monotonic() + 30.0
        while sub.get_num_connections() == 0:
            if time.monotonic() > deadline:
                raise RuntimeError("no connection to /shield/events within 30 s")
            time.sleep(0.05)
        time.sleep(0.5)  # the shield's side of the connection (it publishes only while it counts a subscriber)
        rng = np.random.default_rng(seed)
        if policy_name == "pushing":
            mod = _pushing_module()
            sim = make_sim(world)

            def contacts(q):
                sim.reset_robot(q)
                return sim.contacts_now().world_pairs

            targets, _ = mod.pushing_targets(contacts, u._backend.home, sim.lower, sim.upper, rng)
            sim.close()
            pusher = mod.PushingPolicy(targets, u.scaler.max_delta, rng)
        env.reset(seed=seed)
        env.action_space.seed(seed)
        joints = list(u._backend.joints)
        inputs, actions, live, pending_reset = [], [], [], True
        for k in range(steps):
            a = pusher.act(u.q) if policy_name == "pushing" else env.action_space.sample()
            actions.append([float(x) for x in a])
            _, _, term, trunc, info = env.step(a)
            with lock:
                if not lock.wait_for(lambda: len(events) > k, timeout=EVENT_WAIT):
                    raise RuntimeError(f"step {k}: no ~events message within {EVENT_WAIT} s")
                ev = events[k]
            if list(ev.joint_names) != joints:
                raise RuntimeError(f"the shield's joints {list(ev.joint_names)} are not the env's {joints}")
            if pending_reset:
                inputs.append({"reset": list(ev.start)})
                pending_reset = False
            if ev.executed.points:
                inputs.append(
                    {
                        "execute": {
                            "times": [p.time_from_start.to_sec() for p in ev.executed.points],
                            "positions": [list(p.positions) for p in ev.executed.points],
                        },
                        "stamp_ns": ev.header.stamp.to_nsec(),
                        "start": list(ev.start),
                        "step": k,
                    }
                )
                live.append((info["contacts"], info["contact_substeps"]))
            if policy_name == "pushing":
                pusher.feedback(info["discarded"])
            if term or trunc:
                env.reset()
                pending_reset = True
                if policy_name == "pushing":
                    pusher.reset()
        sub.unregister()
    finally:
        env.close()

    # The replay must be the live graph's simulation: same starts, same sim times, same contacts per step.
    from moverl_sim.ground_truth import replay_by_substep

    sim = make_sim(world)
    try:
        q = None
        for ev in inputs:
            if "reset" in ev:
                q = ev["reset"]
            elif q is not None and ev["start"] != q:
                raise RuntimeError(f"step {ev['step']} starts at {ev['start']}, the previous move ended at {q}")
            if "execute" in ev:
                q = ev["execute"]["positions"][-1]
        trace, counts = replay_by_substep(sim, inputs)
    finally:
        sim.close()
    steps_of = [ev["step"] for ev in inputs if "execute" in ev]
    wrong = [(s, c, lv) for s, c, lv in zip(steps_of, counts, live) if tuple(c) != tuple(lv)]
    if wrong:
        raise RuntimeError(
            f"{name}: the replay's (pairs, substeps in contact) differ from the live graph's: {wrong[:5]}"
        )
    commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True).stdout
    dirty = subprocess.run(
        ["git", "-C", str(REPO), "status", "--porcelain", "--untracked-files=no", "src/moverl_sim"],
        capture_output=True,
        text=True,
    ).stdout
    # The last commit that changed the simulator's code (this tool and the replay module aside): what was recorded.
    simulator = subprocess.run(
        [
            "git",
            "-C",
            str(REPO),
            "log",
            "-1",
            "--format=%H",
            "--",
            "src/moverl_sim/src/moverl_sim",
            "src/moverl_sim/scripts",
            ":!src/moverl_sim/src/moverl_sim/ground_truth.py",
        ],
        capture_output=True,
        text=True,
    ).stdout
    return {
        "name": name,
        "world": world,
        "robot": ROBOT,
        "policy": policy_name,
        "seed": seed,
        "steps": steps,
        "commit": commit.strip() + (" (src/moverl_sim modified)" if dirty.strip() else ""),
        "simulator_commit": simulator.strip(),
        "actions": actions,
        "events": inputs,
        "live_counts": live,
        "trace": trace,
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--runs", nargs="+", choices=sorted(RUNS), default=list(RUNS))
    p.add_argument("--steps", type=int, default=None, help="env steps per run (default: each run's own)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=FIXTURES)
    p.add_argument("--worker", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:  # one run per process: rospy allows one master per process
        from moverl_sim.ground_truth import save

        steps = args.steps or RUNS[args.worker][2]
        r = record(args.worker, steps, args.seed)
        args.out.mkdir(parents=True, exist_ok=True)
        save(args.out / f"{args.worker}.json.gz", r)
        substeps = len({row[0] for row in r["trace"]})
        print(
            f"{args.worker}: {steps} steps, {sum('execute' in e for e in r['events'])} trajectories, "
            f"{sum('reset' in e for e in r['events'])} resets, {len(r['trace'])} pair-substeps in {substeps} substeps "
            f"in contact; replay = live graph on every step -> {args.out / (args.worker + '.json.gz')}",
            flush=True,
        )
        return 0
    for name in args.runs:
        cmd = [sys.executable, __file__, "--worker", name, "--seed", str(args.seed)]
        cmd += ["--steps", str(args.steps)] if args.steps else []
        if subprocess.run(cmd + ["--out", str(args.out)]).returncode != 0:
            print(f"{name}: FAILED", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
