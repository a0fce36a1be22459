#!/usr/bin/env python3
"""Pushing-policy contact audit: a policy that keeps driving the arm into the obstacles, shield on and off.

    python src/moverl_gym/tools/pushing_policy_audit.py --worlds case --steps 3000
    python src/moverl_gym/tools/pushing_policy_audit.py --robot-config my_arm.yaml --worlds table human case
    python src/moverl_gym/tools/pushing_policy_audit.py --worlds table human case --shield on --control dynamic \
        --out docs/dynamic_control/pushing
    python src/moverl_gym/tools/pushing_policy_audit.py --worlds human --shield on --obstacles octomap \
        --mode realtime --out docs/sensed_person/realtime

Random actions near home rarely reach the obstacles; this policy does. Before the run it samples configurations
within +-spread rad of the robot's home in which a link penetrates a world object by at least 5 mm (PyBullet, in
this process; the same number of targets for every object it can reach). Every episode (and every --switch steps) it
picks one of them and drives all joints straight at it (the action keeps the direction of target - q), with
noise, and goes on pushing when the shield holds the arm still, creeping: the push halves after every held step
(down to 1/16 of full speed) and doubles after an executed one, so the arm closes in on the padded obstacles.
Contacts are the physics engine's ground truth along every motion (info["contacts"]): with the shield on they
must be 0; with it off they show that the policy does push into the obstacles.

Each run (robot config x world x shield) uses its own process and ROS graph. Writes docs/pushing_policy/audit.md and
.csv (or --out); exit code 1 if a shielded run made any contact. --control dynamic runs the simulator's
position-controlled motors (the mode closest to hardware); any error the env raises fails the run. --obstacles octomap
makes the shield know the obstacles only through the world's depth cameras (the sensed mode); --mode realtime runs the
simulator in real time (the shield's window covers its own thinking time).
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

from moverl_gym.workers import run_json_worker
from moverl_sim.robot_config import load_robot_config

MIN_DEPTH = 0.005  # a target configuration penetrates an obstacle by at least this (m)


class PushingPolicy:
    """Straight joint-space drive at a colliding target configuration, with noise, that creeps (ROS-free).

    The push runs at full speed; after a discarded step (feedback(True)) it halves, down to 1/16, and after an
    executed one it doubles again: held at the boundary of the padded obstacles, the arm creeps up to it in smaller
    and smaller steps and slides along it with the noise.

    Args:
        targets: configurations to drive at (one is picked at reset and every `switch` steps).
        max_delta: the env's largest joint motion per step for action 1 (rad, per joint).
        rng: numpy Generator.
        noise: standard deviation of the Gaussian noise added to the action.
        switch: steps between target changes.
    """

    def __init__(self, targets, max_delta, rng, noise: float = 0.3, switch: int = 50):
        if len(targets) == 0:
            raise ValueError("no target configuration to push at")
        self.targets = [np.asarray(t, dtype=float) for t in targets]
        self.max_delta = np.asarray(max_delta, dtype=float)
        self.rng, self.noise, self.switch = rng, noise, switch
        self.reset()

    MIN_SCALE = 1.0 / 16

    def reset(self) -> None:
        self.target = self.targets[self.rng.integers(len(self.targets))]
        self.k = 0
        self.scale = 1.0

    def feedback(self, discarded: bool) -> None:
        """The shield's verdict on the last action: held (discarded) or executed."""
        self.scale = max(self.MIN_SCALE, self.scale / 2) if discarded else min(1.0, self.scale * 2)

    def act(self, q) -> np.ndarray:
        self.k += 1
        if self.k % self.switch == 0:
            self.target = self.targets[self.rng.integers(len(self.targets))]
        need = (self.target - np.asarray(q, dtype=float)) / self.max_delta  # actions that would get there in 1 step
        a = need / max(1.0, float(np.max(np.abs(need))))  # full speed, same direction
        return np.clip(self.scale * a + self.noise * self.rng.normal(size=a.size), -1.0, 1.0)


def pushing_targets(
    contacts, home, lower, upper, rng, n: int = 200, spread: float = 1.0, tries: int = 20000
) -> tuple[list, dict]:
    """Up to n configurations, among `tries` uniform ones within +-spread of home (clipped to the limits), that
    penetrate a world object by at least MIN_DEPTH, as evenly spread over the objects as they can be (n / objects
    each). contacts(q) returns a dict {(link, object): depth}. Returns (targets, {object: how many})."""
    home, lower, upper = (np.asarray(x, dtype=float) for x in (home, lower, upper))
    lo, hi = np.maximum(lower, home - spread), np.minimum(upper, home + spread)
    by_object: dict[str, list] = {}
    for _ in range(tries):
        q = rng.uniform(lo, hi)
        deep = {obj for (_, obj), depth in contacts(q).items() if depth >= MIN_DEPTH}
        for obj in deep:
            by_object.setdefault(obj, []).append(q)
    per = max(1, n // max(1, len(by_object)))
    targets = [q for qs in by_object.values() for q in qs[:per]]
    return targets, {obj: min(len(qs), per) for obj, qs in by_object.items()}


def worker(
    robot_config: str,
    world: str,
    shield: bool,
    steps: int,
    seed: int,
    spread: float,
    switch: int,
    noise: float,
    control: str | None = None,
    obstacles: str | None = None,
    mode: str | None = None,
    motion_time_scale: float | None = None,
    strategy: str | None = None,
    camera_rate: float | None = None,
    safety: str | None = None,
) -> dict:
    from gymnasium.wrappers import TimeLimit

    from moverl_gym.env import MoveRLReachEnv
    from moverl_gym.paths import config_file, world_file
    from moverl_gym.task import TaskConfig
    from moverl_sim.settings import simulator_for
    from moverl_sim.world import load_world

    rc = load_robot_config(robot_config)
    rng = np.random.default_rng(seed)
    sim = simulator_for(rc, load_world(str(world_file(world))))
    try:

        def contacts(q):
            sim.reset_robot(q)
            return sim.contacts_now().world_pairs

        targets, per_object = pushing_targets(contacts, rc["home"], sim.lower, sim.upper, rng, spread=spread)
    finally:
        sim.close()
    max_steps = TaskConfig.from_yaml(config_file("env.yaml")).max_episode_steps
    env = TimeLimit(
        MoveRLReachEnv(
            world=world,
            shield=shield,
            graph="launch",
            launch_args={
                "robot_config": str(robot_config),
                **({"control": control} if control else {}),
                **({"obstacles": obstacles} if obstacles else {}),
                **({"mode": mode} if mode else {}),
                **({"motion_time_scale": motion_time_scale} if motion_time_scale else {}),
                **({"camera_rate": camera_rate} if camera_rate else {}),
                **({"strategy": strategy} if strategy else {}),
                **({"safety": safety} if safety else {}),
            },
        ),
        max_episode_steps=max_steps,
    )
    try:
        inner = env.unwrapped
        policy = PushingPolicy(targets, inner.scaler.max_delta, rng, noise=noise, switch=switch)
        env.reset(seed=seed)
        contacts_total = contact_steps = episodes = unsensed = unsensed_moves = at_limit = 0
        moving = resting = 0  # who moved: contact pairs while the robot moved / rested
        lower, upper = inner.scaler.limits.lower, inner.scaler.limits.upper
        verdicts: dict[str, int] = {}
        used = ""  # the strategy the shield reports (the launch file's default unless one was given)
        t0 = time.perf_counter()
        for _ in range(steps):
            action = policy.act(inner.q)
            target = inner.scaler.command(inner.q, action)
            at_limit += bool(np.any((target <= lower) | (target >= upper)))  # motors overshoot there (dynamic)
            _, _, term, trunc, info = env.step(action)
            if info["contacts"] < 0:  # the driver has not reported contacts yet (no motion since the start)
                unsensed += 1
                unsensed_moves += not info["discarded"]
            policy.feedback(info["discarded"])
            contacts_total += max(info["contacts"], 0)
            moving += max(info["contacts_moving"], 0)
            resting += max(info["contacts_resting"], 0)
            contact_steps += info["contacts"] > 0
            verdicts[info["verdict"]] = verdicts.get(info["verdict"], 0) + 1
            used = info.get("strategy") or used
            if term or trunc:
                episodes += 1
                env.reset()
                policy.reset()
        rate = steps / (time.perf_counter() - t0)
    finally:
        env.close()
    return {
        "robot": rc["name"],
        "world": world,
        "control": control or "",
        "obstacles": obstacles or "objects",
        "mode": mode or "lockstep",
        **({"motion_time_scale": motion_time_scale} if motion_time_scale else {}),
        **({"camera_rate": camera_rate} if camera_rate else {}),
        "strategy": used if shield else "",
        "safety": (safety or "") if shield else "",
        "shield": shield,
        "steps": steps,
        "episodes": episodes,
        "contacts": contacts_total,
        "contacts_moving": moving,
        "contacts_resting": resting,
        "steps_with_contact": contact_steps,
        "unsensed_steps": unsensed,
        "unsensed_moves": unsensed_moves,
        "steps_at_limit": at_limit,
        "steps_per_s": round(rate, 1),
        "verdicts": verdicts,
        "targets": per_object,
    }


def shield_cell(r: dict) -> str:
    """The table's shield column: off, or on with its strategy (and safety definition when one was given)."""
    if not r["shield"]:
        return "off"
    return f"on ({r['strategy']}" + (f", {r['safety']}" if r.get("safety") else "") + ")"


def main(argv=None) -> int:
    from moverl_gym.launch_args import CHOICES
    from moverl_gym.paths import config_file, repo_root

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument(
        "--robot-config",
        action="append",
        help="robot config file(s) (format of config/robots/*.yaml); default: every config/robots/*.yaml",
    )
    p.add_argument("--worlds", nargs="+", default=["case"])
    p.add_argument("--shield", choices=["on", "off", "both"], default="both")
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--spread", type=float, default=1.0, help="targets within +-spread rad of home")
    p.add_argument("--switch", type=int, default=50, help="steps between target changes")
    p.add_argument("--noise", type=float, default=0.3, help="standard deviation of the noise added to the actions")
    p.add_argument(
        "--control",
        choices=[c for c in CHOICES["control"] if c],
        default=None,
        help="the simulator's control mode (default: config/sim.yaml's)",
    )
    p.add_argument(
        "--obstacles",
        choices=CHOICES["obstacles"],
        default=None,
        help="what the shield knows: the world file's objects (default), only what the depth cameras see (octomap), "
        "both, or the static objects plus what the cameras see (sensed)",
    )
    p.add_argument(
        "--motion-time-scale",
        type=float,
        default=None,
        help="experiments: the simulator plays the obstacles' motions this many times faster than the world says",
    )
    p.add_argument("--mode", choices=CHOICES["mode"], default=None, help="the simulator's clock")
    p.add_argument(
        "--camera-rate",
        type=float,
        default=None,
        help="renders per simulated second of every camera (default: the world file's rates)",
    )
    p.add_argument(
        "--strategy",
        nargs="+",
        choices=CHOICES["strategy"],
        default=None,
        help="the shield's strategies to compare, each in runs of their own with the same seed (default: the launch "
        "file's)",
    )
    p.add_argument(
        "--safety",
        choices=[c for c in CHOICES["safety"] if c],
        default=None,
        help="what the checks against the cameras' map promise, with sensed obstacles (default: "
        "config/planning_scene.yaml's octomap/safety)",
    )
    p.add_argument("--out", type=Path, default=None, help="output folder (default: <repo>/docs/pushing_policy)")
    p.add_argument("--worker", nargs=3, metavar=("CONFIG", "WORLD", "on|off"), help=argparse.SUPPRESS)
    p.add_argument("--worker-strategy", default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        config, world, shield = args.worker
        print(
            json.dumps(
                worker(
                    config,
                    world,
                    shield == "on",
                    args.steps,
                    args.seed,
                    args.spread,
                    args.switch,
                    args.noise,
                    args.control,
                    args.obstacles,
                    args.mode,
                    args.motion_time_scale,
                    args.worker_strategy,
                    args.camera_rate,
                    args.safety,
                )
            )
        )
        return 0

    configs = (
        [Path(c).resolve() for c in args.robot_config]
        if args.robot_config
        else sorted(config_file("robots").glob("*.yaml"))
    )
    shields = ["on", "off"] if args.shield == "both" else [args.shield]
    # (shield, strategy) runs: the unshielded baseline once, each strategy with the shield on.
    runs = [(s, strategy) for s in shields for strategy in (args.strategy or [None] if s == "on" else [None])]
    rows = []
    for config in configs:
        for world in args.worlds:
            for shield, strategy in runs:
                what = f"shield {shield}" + (f" ({strategy})" if strategy else "")
                print(f"{config.name} in {world}, {what}: {args.steps} pushing steps ...", flush=True)
                r = run_json_worker(
                    __file__,
                    [
                        "--worker",
                        str(config),
                        world,
                        shield,
                        "--steps",
                        args.steps,
                        "--seed",
                        args.seed,
                        "--spread",
                        args.spread,
                        "--switch",
                        args.switch,
                        "--noise",
                        args.noise,
                        *(["--control", args.control] if args.control else []),
                        *(["--obstacles", args.obstacles] if args.obstacles else []),
                        *(["--mode", args.mode] if args.mode else []),
                        *(["--motion-time-scale", args.motion_time_scale] if args.motion_time_scale else []),
                        *(["--camera-rate", args.camera_rate] if args.camera_rate else []),
                        *(["--safety", args.safety] if args.safety else []),
                        *(["--worker-strategy", strategy] if strategy else []),
                    ],
                    f"worker {config.name} {world} {what}",
                )
                rows.append(r)
                print(
                    f"  contacts {r['contacts']} ({r['contacts_moving']} with the robot moving, "
                    f"{r['contacts_resting']} at rest) in {r['steps_with_contact']} steps; verdicts {r['verdicts']}; "
                    f"targets per object {r['targets']}; {r['steps_per_s']} steps/s",
                    flush=True,
                )
    out = args.out or repo_root() / "docs" / "pushing_policy"
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "audit.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({**r, "verdicts": json.dumps(r["verdicts"]), "targets": json.dumps(r["targets"])})
    cmd = "python src/moverl_gym/tools/pushing_policy_audit.py"
    if args.robot_config:
        cmd += "".join(f" --robot-config {c}" for c in args.robot_config)
    cmd += " --worlds " + " ".join(args.worlds) + f" --steps {args.steps}"
    for name in (
        "shield",
        "seed",
        "spread",
        "switch",
        "noise",
        "control",
        "obstacles",
        "mode",
        "motion_time_scale",
        "camera_rate",
        "safety",
    ):
        if getattr(args, name) != p.get_default(name):
            cmd += f" --{name.replace('_', '-')} {getattr(args, name)}"
    if args.strategy:
        cmd += " --strategy " + " ".join(args.strategy)
    if args.out:
        cmd += f" --out {args.out}"
    lines = [
        "# Pushing-policy contact audit",
        "",
        "Command:",
        "",
        f"    {cmd}",
        "",
        "A policy that drives the joints straight at configurations where a link penetrates a world "
        f"object (>= 5 mm, within +-{args.spread} rad of home, spread over the objects), with noise (sd "
        f"{args.noise}), and keeps pushing when the shield holds the arm, creeping (the push halves after a "
        "held step, down to 1/16, and doubles after an executed one); new target every episode and every "
        f"{args.switch} steps. contacts = distinct robot contact pairs the physics engine saw during each step's "
        "motion, summed over the steps (must be 0 with the shield on), split by who moved: made while the robot "
        "moved, or while it rested (a person walking into a parked arm). Steps before the first executed motion "
        "of a run report no contact information (the driver has not reported yet); they did not move "
        "(unsensed moves must be 0). at limit = steps whose command put a joint onto its URDF limit (with dynamic "
        "control the motors overshoot there; the env must not raise).",
        "",
        "| robot | world | control | obstacles | cameras | clock | shield | steps | episodes | contacts | "
        "robot moving | robot at rest | steps with contact | unsensed moves | at limit | verdicts | "
        "targets per object | steps/s |",
        "|---|---|---|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|---|---:|",
    ]
    for r in rows:
        v = ", ".join(f"{k} {n}" for k, n in sorted(r["verdicts"].items()))
        t = ", ".join(f"{k} {n}" for k, n in sorted(r["targets"].items()))
        lines.append(
            f"| {r['robot']} | {r['world']} | {r['control'] or 'sim.yaml'} | {r['obstacles']} | "
            f"{'%g Hz' % r['camera_rate'] if r.get('camera_rate') else 'world file'} | {r['mode']} | "
            f"{shield_cell(r)} | "
            f"{r['steps']} | {r['episodes']} | **{r['contacts']}** | {r['contacts_moving']} | "
            f"{r['contacts_resting']} | {r['steps_with_contact']} | "
            f"{r['unsensed_moves']} | {r['steps_at_limit']} | {v} | {t} | {r['steps_per_s']} |"
        )
    (out / "audit.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / 'audit.md'}")
    bad = [r for r in rows if r["shield"] and (r["contacts"] > 0 or r["unsensed_moves"] > 0)]
    if bad:
        print(f"FAIL: {len(bad)} shielded run(s) made contacts")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
