#!/usr/bin/env python3
"""Random-policy contact audit over every registered env id, shield on and off (a long experiment, not a test).

    python src/moverl_gym/tools/random_policy_audit.py [--steps 10000] [--ids MoveRL/PandaReachCase-v0 ...]
    python src/moverl_gym/tools/random_policy_audit.py --control dynamic --shield on --steps 3000 \
        --ids MoveRL/PandaReachTable-v0 MoveRL/PandaReachHuman-v0 MoveRL/PandaReachCase-v0 --out docs/dynamic_control

For each id and shield setting: uniformly random actions from a fixed seed for --steps env steps (episodes
reset as usual), counting the physics engine's ground-truth contacts along every motion and the shield's
verdicts. With the shield on the count must be 0; with it off it shows what the shield prevents. Each run uses
its own process and ROS graph. Writes docs/random_policy/audit.md and .csv (or --out); exit code 1 if a shielded
run made any contact. Any error the env raises (for example a reported state beyond a joint limit that the shield
refuses) ends the run and fails the audit. CI runs a short version of this inside the live tests (300-3,000 steps
per id).

--control dynamic drives the simulator's position-controlled motors (config/sim.yaml, the mode closest to
hardware): the arm lags and overshoots its commands, and the reported states can lie a little beyond the joint
limits (the shield clamps states within config/shield.yaml's limit_tolerance and refuses those beyond it). The
"at limit" column counts the steps that commanded a joint onto its limit, where that happens; no run may raise.
--world replaces every id's world (a name in worlds/ or a YAML path), e.g. the live tests' moving wall; --start
fixes every episode's start configuration (reset option "start"), e.g. one clear of that wall's swing:

    python src/moverl_gym/tools/random_policy_audit.py --control dynamic --shield on --steps 3000 \
        --ids MoveRL/PandaReachTable-v0 --world src/moverl_gym/test/worlds/moving_wall.yaml \
        --start -0.65 -0.785 0 -2.356 0 1.571 0.785 --out docs/dynamic_control/moving_wall
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

from moverl_gym.workers import run_json_worker

DOCS = Path(__file__).resolve().parents[3] / "docs" / "random_policy"


def worker(
    env_id: str,
    shield: bool,
    steps: int,
    seed: int,
    control: str | None = None,
    world: str | None = None,
    start: list | None = None,
) -> dict:
    import gymnasium as gym
    import numpy as np

    import moverl_gym  # noqa: F401

    kwargs = {"launch_args": {"control": control}} if control else {}
    if world:
        kwargs["world"] = world
    env = gym.make(env_id, shield=shield, graph="launch", **kwargs)
    try:
        scaler = env.unwrapped.scaler
        env.action_space.seed(seed)
        options = {"start": start} if start else None
        env.reset(seed=seed, options=options)
        contacts = contact_steps = episodes = 0
        at_limit = 0  # steps that commanded a joint onto its limit (where position-controlled motors overshoot)
        verdicts: dict[str, int] = {}
        t0 = time.perf_counter()
        for _ in range(steps):
            action = env.action_space.sample()
            target = scaler.command(env.unwrapped.q, action)
            at_limit += bool(np.any((target <= scaler.limits.lower) | (target >= scaler.limits.upper)))
            _, _, term, trunc, info = env.step(action)
            contacts += max(info["contacts"], 0)
            contact_steps += info["contacts"] > 0
            verdicts[info["verdict"]] = verdicts.get(info["verdict"], 0) + 1
            if term or trunc:
                episodes += 1
                env.reset(options=options)
        rate = steps / (time.perf_counter() - t0)
    finally:
        env.close()
    return {
        "env_id": env_id,
        "world": world or "",
        "control": control or "",
        "start": start or "",
        "shield": shield,
        "steps": steps,
        "episodes": episodes,
        "contacts": contacts,
        "steps_with_contact": contact_steps,
        "steps_at_limit": at_limit,
        "steps_per_s": round(rate, 1),
        "verdicts": verdicts,
    }


def main(argv=None) -> int:
    import moverl_gym
    from moverl_gym.launch_args import CHOICES

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--steps", type=int, default=10000)
    p.add_argument("--ids", nargs="+", default=list(moverl_gym.ENV_IDS))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--shield", choices=["on", "off", "both"], default="both")
    p.add_argument(
        "--control",
        choices=[c for c in CHOICES["control"] if c],
        default=None,
        help="the simulator's control mode (default: config/sim.yaml's)",
    )
    p.add_argument("--world", default=None, help="run every id in this world instead of its own")
    p.add_argument(
        "--start",
        type=float,
        nargs="+",
        default=None,
        help="every episode's start configuration (default: sampled as the id's task says)",
    )
    p.add_argument("--out", type=Path, default=DOCS)
    p.add_argument("--worker", nargs=2, metavar=("ENV_ID", "on|off"), help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        print(
            json.dumps(
                worker(
                    args.worker[0], args.worker[1] == "on", args.steps, args.seed, args.control, args.world, args.start
                )
            )
        )
        return 0

    rows = []
    extra = (
        (["--control", args.control] if args.control else [])
        + (["--world", args.world] if args.world else [])
        + (["--start", *args.start] if args.start else [])
    )
    for env_id in args.ids:
        for shield in ("on", "off") if args.shield == "both" else (args.shield,):
            print(f"{env_id} shield {shield}: {args.steps} random steps ...", flush=True)
            rows.append(
                run_json_worker(
                    __file__,
                    ["--worker", env_id, shield, "--steps", args.steps, "--seed", args.seed, *extra],
                    f"worker {env_id} shield {shield}",
                )
            )
            r = rows[-1]
            print(
                f"  contacts {r['contacts']} in {r['steps_with_contact']} steps; verdicts {r['verdicts']}; "
                f"{r['steps_at_limit']} steps at a limit; {r['steps_per_s']} steps/s",
                flush=True,
            )
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "audit.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({**r, "verdicts": json.dumps(r["verdicts"])})
    cmd = f"python src/moverl_gym/tools/random_policy_audit.py --steps {args.steps} --seed {args.seed}"
    if args.ids != p.get_default("ids"):
        cmd += " --ids " + " ".join(args.ids)
    for name in ("shield", "control", "world"):
        if getattr(args, name) != p.get_default(name):
            cmd += f" --{name} {getattr(args, name)}"
    if args.start:
        cmd += " --start " + " ".join(f"{v:g}" for v in args.start)
    if args.out != DOCS:
        cmd += f" --out {args.out}"
    lines = [
        "# Random-policy contact audit",
        "",
        "Command:",
        "",
        f"    {cmd}",
        "",
        "Uniformly random actions, episodes reset as usual; contacts = distinct robot contact pairs the physics "
        "engine saw during each step's motion, summed over the steps. at limit = steps whose command put a joint "
        "onto its URDF limit (with dynamic control the motors overshoot there; the env must not raise).",
        "",
        "| env id | world | control | shield | steps | episodes | contacts | steps with contact | "
        "at limit | verdicts | steps/s |",
        "|---|---|---|---|---:|---:|---:|---:|---:|---|---:|",
    ]
    for r in rows:
        v = ", ".join(f"{k} {n}" for k, n in sorted(r["verdicts"].items()))
        lines.append(
            f"| `{r['env_id']}` | {Path(r['world']).stem if r['world'] else 'its own'} | "
            f"{r['control'] or 'sim.yaml'} | "
            f"{'on' if r['shield'] else 'off'} | {r['steps']} | {r['episodes']} | **{r['contacts']}** | "
            f"{r['steps_with_contact']} | {r['steps_at_limit']} | {v} | {r['steps_per_s']} |"
        )
    (args.out / "audit.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out / 'audit.md'}")
    bad = [r for r in rows if r["shield"] and r["contacts"] > 0]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
