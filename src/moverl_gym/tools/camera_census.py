#!/usr/bin/env python3
"""How much of the robot's reach do a world's cameras see? The sensed map's census right after start-up, per world.

    python src/moverl_gym/tools/camera_census.py --worlds human src/moverl_gym/test/worlds/human_left_camera.yaml

Each world runs in its own ROS graph (obstacles:=sensed, lockstep, the robot at home): once the cameras' first views
are in the map, the planning scene's ~sensed_census (moverl_msgs/SensedCensus) counts the cells within the robot's
reach that no camera has seen, and the ones seen free, above the robot's base and below it (under a table nothing
reaches). Then the env's first reset shows whether a start is free. Prints a table (and --out writes census.md and
census.json): the share of the reach above the base no camera sees, per octant, and whether the first reset found a
start. Where unseen space counts as occupied (sensing: unknown_occupied), a robot whose reach its cameras do not see
has no free start: docs/sensing.md, "Placing your cameras".
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from moverl_gym.workers import run_json_worker

OCTANTS = ("behind-right", "in front-right", "behind-left", "in front-left")  # index & 3, x forward, y left


def worker(args) -> dict:
    import gymnasium as gym

    import moverl_gym  # noqa: F401
    from moverl_gym.errors import MoveRLError
    from moverl_gym.registration import env_id

    t0 = time.perf_counter()
    env = gym.make(env_id(args.robot, "Human"), world=args.world, graph="launch", launch_args={"obstacles": "sensed"})
    try:
        started = time.perf_counter() - t0
        census = env.unwrapped._backend.sensed_census()
        t1 = time.perf_counter()
        try:
            env.reset(seed=0)
            reset, message = True, ""
        except MoveRLError as exc:
            reset, message = False, str(exc)
        out = {
            "world": args.world,
            "started_s": started,
            "reset": reset,
            "reset_s": time.perf_counter() - t1,
            "message": message,
        }
        if census is not None:
            above = [4 + k for k in range(4)]
            cells = sum(census.cells_by_octant[k] for k in above)
            hidden = sum(census.hidden_by_octant[k] for k in above)
            out.update(
                radius=census.radius,
                unseen_share=census.hidden / max(1, census.cells),
                above_share=hidden / max(1, cells),
                octants={OCTANTS[k - 4]: census.hidden_by_octant[k] / max(1, census.cells_by_octant[k]) for k in above},
            )
        return out
    finally:
        env.close()


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1])
    p.add_argument("--worlds", nargs="+", default=["human"], help="world names (worlds/) or world files")
    p.add_argument("--robot", default="panda", help="robot name (config/robots/)")
    p.add_argument("--out", type=Path, help="write census.md and census.json here")
    p.add_argument("--worker-world", dest="world", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.world is not None:
        print(json.dumps(worker(args)))
        return 0
    rows = []
    for world in args.worlds:
        rows.append(run_json_worker(__file__, ["--worker-world", world, "--robot", args.robot], f"census of {world}"))
    head = "| world | unseen, reach above the base | " + " | ".join(OCTANTS) + " | first reset | started (s) |"
    lines = [head, "|---|---:|" + "---:|" * len(OCTANTS) + "---|---:|"]
    for r in rows:
        octants = " | ".join(f"{100 * r['octants'][o]:.0f} %" for o in OCTANTS) if "octants" in r else " | " * 3
        reset = f"a free start ({r['reset_s']:.1f} s)" if r["reset"] else f"no free start ({r['reset_s']:.1f} s)"
        share = f"{100 * r['above_share']:.0f} %" if "above_share" in r else "-"
        lines.append(f"| {Path(r['world']).stem} | {share} | {octants} | {reset} | {r['started_s']:.1f} |")
    text = "\n".join(lines)
    print(text)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        cmd = "python src/moverl_gym/tools/camera_census.py " + " ".join(sys.argv[1:])
        (args.out / "census.md").write_text(f"`{cmd}`\n\n{text}\n")
        (args.out / "census.json").write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
