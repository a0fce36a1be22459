#!/usr/bin/env python3
"""Random-policy contact audit over every registered env id, shield on and off (a long experiment, not a test).

    python src/moverl_gym/scripts/random_policy_audit.py [--steps 10000] [--ids MoveRL/PandaReachCase-v0 ...]

For each id and shield setting: uniformly random actions from a fixed seed for --steps env steps (episodes
reset as usual), counting the physics engine's ground-truth contacts along every motion and the shield's
verdicts. With the shield on the count must be 0; with it off it shows what the shield prevents. Each run uses
its own process and ROS graph. Writes docs/random_policy/audit.md and .csv; exit code 1 if a shielded run
made any contact. CI runs a short version of this inside the live tests (300-3,000 steps per id).
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


def worker(env_id: str, shield: bool, steps: int, seed: int) -> dict:
    import gymnasium as gym

    import moverl_gym  # noqa: F401

    env = gym.make(env_id, shield=shield, graph="launch")
    try:
        env.action_space.seed(seed)
        env.reset(seed=seed)
        contacts = contact_steps = episodes = 0
        verdicts: dict[str, int] = {}
        t0 = time.perf_counter()
        for _ in range(steps):
            _, _, term, trunc, info = env.step(env.action_space.sample())
            contacts += info["contacts"]
            contact_steps += info["contacts"] > 0
            verdicts[info["verdict"]] = verdicts.get(info["verdict"], 0) + 1
            if term or trunc:
                episodes += 1
                env.reset()
        rate = steps / (time.perf_counter() - t0)
    finally:
        env.close()
    return {"env_id": env_id, "shield": shield, "steps": steps, "episodes": episodes, "contacts": contacts,
            "steps_with_contact": contact_steps, "steps_per_s": round(rate, 1), "verdicts": verdicts}


def main(argv=None) -> int:
    import moverl_gym

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--steps", type=int, default=10000)
    p.add_argument("--ids", nargs="+", default=list(moverl_gym.ENV_IDS))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=DOCS)
    p.add_argument("--worker", nargs=2, metavar=("ENV_ID", "on|off"), help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args.worker[0], args.worker[1] == "on", args.steps, args.seed)))
        return 0

    rows = []
    for env_id in args.ids:
        for shield in ("on", "off"):
            print(f"{env_id} shield {shield}: {args.steps} random steps ...", flush=True)
            rows.append(run_json_worker(__file__, ["--worker", env_id, shield, "--steps", args.steps, "--seed",
                                                   args.seed], f"worker {env_id} shield {shield}"))
            r = rows[-1]
            print(f"  contacts {r['contacts']} in {r['steps_with_contact']} steps; verdicts {r['verdicts']}")
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "audit.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({**r, "verdicts": json.dumps(r["verdicts"])})
    lines = ["# Random-policy contact audit", "", "Command:", "",
             f"    python src/moverl_gym/scripts/random_policy_audit.py --steps {args.steps} --seed {args.seed}", "",
             "Uniformly random actions, episodes reset as usual; contacts = distinct robot contact pairs the physics "
             "engine saw during each step's motion, summed over the steps.", "",
             "| env id | shield | steps | episodes | contacts | steps with contact | verdicts | steps/s |",
             "|---|---|---:|---:|---:|---:|---|---:|"]
    for r in rows:
        v = ", ".join(f"{k} {n}" for k, n in sorted(r["verdicts"].items()))
        lines.append(f"| `{r['env_id']}` | {'on' if r['shield'] else 'off'} | {r['steps']} | {r['episodes']} | "
                     f"**{r['contacts']}** | {r['steps_with_contact']} | {v} | {r['steps_per_s']} |")
    (args.out / "audit.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out / 'audit.md'}")
    bad = [r for r in rows if r["shield"] and r["contacts"] > 0]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
