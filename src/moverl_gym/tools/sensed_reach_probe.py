#!/usr/bin/env python3
"""Can the goal be reached at all in the sensed mode? A scripted policy drives the joints straight at a goal
configuration (--policy joint) or the end effector straight at the goal (--policy cartesian) and keeps pushing while
the shield holds the arm; per camera rate in simulated time and per safety definition (launch argument safety),
against the same policy with the shield off. Each missed episode is counted by the refusal most of its discarded
steps got (the table, the map, a self collision, ...).

    python src/moverl_gym/tools/sensed_reach_probe.py --world human --camera-rates 2 5 10 \
        --goal-q -0.022 0.052 0.023 -2.379 -0.002 2.431 0.003 --out docs/sensed_person/reach_probe
    python src/moverl_gym/tools/sensed_reach_probe.py --world shared_bench --camera-rates 30 --mode realtime \
        --safety ssm --people unmonitored tracked --shield-off --policy cartesian --episodes 300 \
        --out docs/sensed_person/shared_bench_cartesian_realtime_300
    python src/moverl_gym/tools/sensed_reach_probe.py --world shared_bench --camera-rates 30 --mode realtime \
        --safety separation ssm --shield-off --goal-q 0.024 -0.539 -0.416 -2.944 -0.319 2.418 -0.096

The goal configuration is the one a world file's header gives as evidence for its goal (worlds/human.yaml). The
shield inflates the robot against the sensed cells by speed_bound x (map age + step + latency): the map age grows up
to one camera period between renders, so the camera rate decides how close the hand may come to a sensed person.
Each rate runs in its own ROS graph (--obstacles, default sensed), with the world's cameras set to that rate (launch
argument camera_rate). Writes <out>/probe.md and probe.json: per rate, episodes that reach the
goal (the env's is_success), steps to get there, the closest distance, the shield's verdicts, ground-truth contacts,
steps/s. It also gives the goal configuration's clearance from each moving world object where the world file puts
it (motion time 0: the person at rest), in the simulator the node runs: what ISO's margin must stay below for the goal
to be held.
"""

from __future__ import annotations

import argparse
import collections
import json
import re
import sys
import time
from pathlib import Path

import numpy as np

from moverl_gym.launch_args import CHOICES, SENSED_OBSTACLES
from moverl_gym.workers import run_json_worker


def worker(args) -> dict:
    import gymnasium as gym

    import moverl_gym  # noqa: F401
    from moverl_gym.registration import env_id

    goal_q = np.asarray(args.goal_q, dtype=float) if args.goal_q else None
    safety = args.worker_safety
    env = gym.make(
        env_id(args.robot, "Human"),
        world=args.world,
        graph="launch",
        shield=safety != "off",
        launch_args={
            "obstacles": args.obstacles if safety != "off" else "objects",
            "camera_rate": args.worker_rate,
            **({"strategy": args.strategy} if args.strategy and safety != "off" else {}),
            **({"safety": safety} if safety not in ("", "off") else {}),
            **({"people": args.worker_people} if args.worker_people else {}),
            **({"obstacle_poses": "tracker"} if args.worker_people == "tracked" else {}),
            **({"mode": args.mode} if args.mode else {}),
        },
        task={"max_episode_steps": args.max_steps},
    )
    u = env.unwrapped
    fixed = {"goal": u.task.goal.copy()} if goal_q is not None else {}  # the world's goal, not its goal_region
    reacher = CartesianReacher(args.robot, args.world, u.scaler.max_delta) if args.policy == "cartesian" else None
    episodes, t0, steps = [], time.perf_counter(), 0
    try:
        for ep in range(args.episodes):
            env.reset(seed=args.seed + ep, options=fixed)
            target = goal_q if goal_q is not None else u.goal_configuration
            if target is None:
                raise SystemExit(f"world {args.world!r} has no goal_region: give --goal-q")
            verdicts, contacts, moving, closest, reached_at = {}, 0, 0, float("inf"), None
            refusals = collections.Counter()  # the discarded steps by what the shield's message names
            done = False
            while not done:
                if reacher is not None:
                    action = reacher.action(u.q[: len(target)], u.task.goal)
                else:
                    d = target - u.q[: len(target)]
                    action = np.clip(d / max(float(np.abs(d).max()), 1e-9), -1.0, 1.0).astype(np.float32)
                _, _, terminated, truncated, info = env.step(action)
                steps += 1
                done = terminated or truncated
                verdicts[info["verdict"]] = verdicts.get(info["verdict"], 0) + 1
                if info["verdict"].startswith("discarded"):
                    refusals[refusal_kind(info.get("message", ""))] += 1
                contacts += max(info.get("contacts", 0), 0)
                moving += max(info.get("contacts_moving", 0), 0)
                closest = min(closest, float(info["distance"]))
                if info.get("is_success") and reached_at is None:
                    reached_at = sum(verdicts.values())
            episodes.append(
                {
                    "success": bool(info.get("is_success")),
                    "steps": sum(verdicts.values()),
                    "reached_at": reached_at,
                    "closest": closest,
                    "verdicts": verdicts,
                    "contacts": contacts,
                    "contacts_moving": moving,
                    "goal": [float(v) for v in u.task.goal],
                    "goal_q": [float(v) for v in target],
                    "refusals": dict(refusals.most_common()),
                }
            )
    finally:
        env.close()
        if reacher is not None:
            reacher.close()
    return {"episodes": episodes, "steps_per_s": steps / (time.perf_counter() - t0)}


def refusal_kind(message: str) -> str:
    """What a shield message refused, without its links and numbers: its first clause up to the colon, the world
    objects it names (table, octomap, ...), and "held still" when the robot held (e.g. "goal collides with the world:
    octomap, table; held still"), so that an episode's refusals can be counted by kind."""
    head, _, rest = message.partition(":")
    objects = sorted(set(re.findall(r"\w+ / (\w+)", rest.split(";")[0]))) if "world" in head else []
    return head + (": " + ", ".join(objects) if objects else "") + ("; held still" if "held still" in message else "")


class CartesianReacher:
    """--policy cartesian: the end effector (the robot config's ee_link) driven straight at the goal. The joint step
    is the damped least-squares solution of J dq = goal - ee (PyBullet's Jacobian, in the simulator the node runs),
    scaled down to action 1 on its largest joint when it is longer than one step. Unlike the joint policy it does not
    swing the base around to a goal configuration sampled anywhere in the joint limits."""

    def __init__(self, robot: str, world: str, max_delta, damping: float = 0.05):
        from moverl_gym.paths import robot_config_file, world_file
        from moverl_sim.robot_config import load_robot_config
        from moverl_sim.settings import simulator_for
        from moverl_sim.world import load_world

        config = load_robot_config(robot_config_file(robot))
        self.sim = simulator_for(config, load_world(world_file(world)))
        self.max_delta, self.damping = np.asarray(max_delta, dtype=float), damping
        p, body = self.sim.client, self.sim.robot
        self._ee = self.sim.link_index[config["ee_link"]]
        self._movable = [j for j in range(p.getNumJoints(body)) if p.getJointInfo(body, j)[2] != p.JOINT_FIXED]
        self._columns = [self._movable.index(j) for j in self.sim.joint_indices]

    def action(self, q, goal) -> np.ndarray:
        sim, p, body = self.sim, self.sim.client, self.sim.robot
        sim.reset_robot(q)
        ee = np.asarray(p.getLinkState(body, self._ee, computeForwardKinematics=True)[4])
        positions = [p.getJointState(body, j)[0] for j in self._movable]
        zeros = [0.0] * len(positions)
        jac = np.asarray(p.calculateJacobian(body, self._ee, [0.0, 0.0, 0.0], positions, zeros, zeros)[0])
        jac = jac[:, self._columns]
        e = np.asarray(goal[:3], dtype=float) - ee
        dq = jac.T @ np.linalg.solve(jac @ jac.T + self.damping**2 * np.eye(3), e)
        a = dq / self.max_delta
        return (a / max(1.0, float(np.abs(a).max()))).astype(np.float32)

    def close(self):
        self.sim.close()


def goal_clearance(robot: str, world: str, goal_q) -> dict:
    """{object id: metres} from the robot at goal_q to each moving world object at motion time 0 (PyBullet's closest
    points between collision shapes, within 2 m; farther ones left out). The static ones are left out too: the sensed
    modes know them exactly and keep no margin from them."""
    return goal_clearances(robot, world, [goal_q])[0]


def goal_clearances(robot: str, world: str, configurations) -> list:
    """goal_clearance of each configuration, in one simulator."""
    import pybullet

    from moverl_gym.paths import robot_config_file, world_file
    from moverl_sim.robot_config import load_robot_config
    from moverl_sim.settings import simulator_for
    from moverl_sim.world import load_world

    w = load_world(world_file(world))
    moving = {o.id for o in w.objects if o.motion is not None}
    sim = simulator_for(load_robot_config(robot_config_file(robot)), w)
    try:
        found = []
        for q in configurations:
            sim.reset_robot(list(q))
            out = {}
            for oid, (body, link) in sim.object_bodies.items():
                if oid not in moving:
                    continue
                pts = pybullet.getClosestPoints(sim.robot, body, 2.0, linkIndexB=link, physicsClientId=sim.client_id)
                if pts:
                    out[oid] = round(float(min(p[8] for p in pts)), 4)
            found.append(dict(sorted(out.items(), key=lambda kv: kv[1])))
        return found
    finally:
        sim.close()


#: m: the bins of a goal configuration's clearance from the nearest moving object (probe.md's last column)
CLEARANCE_BINS = (0.3, 0.45)


def by_clearance(episodes) -> list:
    """[reached, episodes] per clearance bin: below CLEARANCE_BINS[0], between, from CLEARANCE_BINS[-1] on."""
    edges = (-np.inf, *CLEARANCE_BINS, np.inf)
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        inside = [e for e in episodes if e["clearance"] is not None and lo <= e["clearance"] < hi]
        out.append([sum(e["reached_at"] is not None for e in inside), len(inside)])
    return out


def misses_by_refusal(episodes) -> dict:
    """{refusal kind: missed episodes} by the kind most of a missed episode's discarded steps got ("none": it was
    never refused, the time ran out)."""
    kinds = collections.Counter(
        max(e["refusals"], key=e["refusals"].get) if e["refusals"] else "none" for e in episodes if not e["success"]
    )
    return dict(kinds.most_common())


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--robot", default="panda", help="config/robots/<robot>.yaml")
    p.add_argument("--world", default="human", help="world name (worlds/<name>.yaml) or file")
    p.add_argument(
        "--goal-q",
        type=float,
        nargs="+",
        default=None,
        help="a configuration whose hand is at the world's goal (default: the goals the env samples in the world's "
        "goal_region, each driven at the configuration it came from)",
    )
    p.add_argument("--camera-rates", type=float, nargs="+", default=[2.0], help="renders per simulated second")
    p.add_argument("--obstacles", choices=SENSED_OBSTACLES, default="sensed")
    p.add_argument("--strategy", choices=CHOICES["strategy"], default=None, help="default: the launch file's")
    p.add_argument(
        "--safety",
        nargs="+",
        choices=[c for c in CHOICES["safety"] if c],
        default=[""],
        help="safety definitions to compare, each in its own graph (default: config/planning_scene.yaml's)",
    )
    p.add_argument(
        "--people",
        nargs="+",
        choices=[c for c in CHOICES["people"] if c],
        default=[""],
        help="with ssm: the people unmonitored or tracked (launch argument people; tracked runs the simulator's "
        "tracker, obstacle_poses:=tracker), each in its own graph (default: config/planning_scene.yaml's)",
    )
    p.add_argument(
        "--policy",
        choices=("joint", "cartesian"),
        default="joint",
        help="the scripted policy: joint drives the joints straight at the goal configuration; cartesian drives the "
        "end effector straight at the goal (CartesianReacher)",
    )
    p.add_argument("--shield-off", action="store_true", help="add the same policy with the shield off (a baseline)")
    p.add_argument("--mode", choices=CHOICES["mode"], default=None, help="the simulator's clock (default: lockstep)")
    p.add_argument("--episodes", type=int, default=6)
    p.add_argument("--max-steps", type=int, default=100, help="steps per episode")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=None, help="write probe.md and probe.json here")
    p.add_argument("--worker-rate", type=float, help=argparse.SUPPRESS)
    p.add_argument("--worker-safety", default="", help=argparse.SUPPRESS)
    p.add_argument("--worker-people", default="", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker_rate is not None:
        print(json.dumps(worker(args)))
        return 0
    clearance = goal_clearance(args.robot, args.world, args.goal_q) if args.goal_q else None
    if clearance is not None:
        print("goal configuration's clearance (m): " + ", ".join(f"{k} {v:.3f}" for k, v in clearance.items()))
    rows = []
    runs = [
        (rate, safety, people if safety == "ssm" else "")
        for rate in args.camera_rates
        for safety in args.safety
        for people in (args.people if safety == "ssm" else [""])
    ]
    runs += [(args.camera_rates[0], "off", "")] if args.shield_off else []
    for rate, safety, people in runs:
        what = f"camera rate {rate:g} Hz" + (f", safety {safety}" if safety else "") + (f", {people}" if people else "")
        print(f"{what}: {args.episodes} episodes ...", flush=True)
        worker_args = [*(argv if argv is not None else sys.argv[1:]), "--worker-rate", str(rate)]
        worker_args += ["--worker-safety", safety, "--worker-people", people]
        r = run_json_worker(__file__, worker_args, what, timeout=600 + 120 * args.episodes)
        eps = r["episodes"]
        for e, c in zip(eps, goal_clearances(args.robot, args.world, [e["goal_q"] for e in eps])):
            e["clearance"] = min(c.values()) if c else None  # from the nearest moving object
        verdicts = {}
        for e in eps:
            for k, v in e["verdicts"].items():
                verdicts[k] = verdicts.get(k, 0) + v
        reached = [e["reached_at"] for e in eps if e["reached_at"] is not None]
        rows.append(
            {
                "camera_rate": rate,
                "safety": safety or "(yaml)",
                "people": people or ("-" if safety != "ssm" else "(yaml)"),
                "episodes": len(eps),
                "reached": len(reached),
                "steps_to_goal_mean": float(np.mean(reached)) if reached else None,
                "closest_mean": float(np.mean([e["closest"] for e in eps])),
                "contacts": int(sum(e["contacts"] for e in eps)),
                "contacts_moving": int(sum(e["contacts_moving"] for e in eps)),
                "verdicts": dict(sorted(verdicts.items())),
                "steps_per_s": r["steps_per_s"],
                "reached_by_clearance": by_clearance(eps),
                "misses_by_refusal": misses_by_refusal(eps),
                "per_episode": eps,
            }
        )
        print(json.dumps({k: v for k, v in rows[-1].items() if k != "per_episode"}), flush=True)
    command = "python src/moverl_gym/tools/sensed_reach_probe.py " + " ".join(
        argv if argv is not None else sys.argv[1:]
    )
    lines = [
        "# Reaching the goal in the sensed mode, per camera rate and safety definition",
        "",
        "Command:",
        "",
        "    " + command,
        "",
        (
            "A scripted policy drives the end effector straight at the goal (CartesianReacher: damped least squares, "
            "at most action 1 per joint) "
            if args.policy == "cartesian"
            else "A scripted policy drives the joints straight at the goal configuration (max-norm action 1 toward it) "
        )
        + "and keeps pushing while the shield holds the arm. reached: episodes whose end effector came within the "
        "task's goal tolerance; steps to goal: mean over those; closest: the smallest distance to the goal, mean over "
        "episodes. contacts: ground truth, of them moving: while the robot moved (safety ssm allows the others). "
        "safety off: the shield off (the world file's objects unchecked).",
        "",
        (
            "The goal configuration's clearance from the world's moving objects at rest (m): "
            + ", ".join(f"{k} {v:.3f}" for k, v in clearance.items())
            if clearance is not None
            else "Goals sampled in the world's goal_region (seeded; each row keeps the samples its own check finds "
            "free, so the rows' goals differ where the sensed map refuses some). by clearance: "
            "reached / episodes whose goal configuration's clearance from the nearest moving object at rest is below "
            f"{CLEARANCE_BINS[0]} m, {CLEARANCE_BINS[0]}-{CLEARANCE_BINS[1]} m, from {CLEARANCE_BINS[1]} m on."
        ),
        "",
        "| camera rate (per simulated s) | safety | people | episodes | reached | steps to goal | closest (m) | "
        "contacts | moving | verdicts | steps/s | by clearance |",
        "|---:|---|---|---:|---:|---:|---:|---:|---:|---|---:|---|",
    ]
    for r in rows:
        steps = "-" if r["steps_to_goal_mean"] is None else f"{r['steps_to_goal_mean']:.1f}"
        verdicts = ", ".join(f"{k} {v}" for k, v in r["verdicts"].items())
        lines.append(
            f"| {r['camera_rate']:g} | {r['safety']} | {r['people']} | {r['episodes']} | **{r['reached']}** | "
            f"{steps} | "
            f"{r['closest_mean']:.3f} | {r['contacts']} | {r['contacts_moving']} | {verdicts} | "
            f"{r['steps_per_s']:.1f} | {' · '.join(f'{a}/{b}' for a, b in r['reached_by_clearance'])} |"
        )
    if any(r["misses_by_refusal"] for r in rows):
        lines += ["", "Missed episodes by the refusal most of their discarded steps got:", ""]
        for r in rows:
            if r["misses_by_refusal"]:
                kinds = "; ".join(f"{k} **{v}**" for k, v in r["misses_by_refusal"].items())
                lines.append(f"- {r['camera_rate']:g} Hz, {r['safety']}, {r['people']}: {kinds}")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "probe.md").write_text(text)
        (args.out / "probe.json").write_text(
            json.dumps({"command": command, "goal_clearance": clearance, "rows": rows}, indent=2) + "\n"
        )
    shielded = [r for r in rows if r["safety"] != "off"]
    return 1 if any(r["contacts_moving"] if r["safety"] == "ssm" else r["contacts"] for r in shielded) else 0


if __name__ == "__main__":
    sys.exit(main())
