#!/usr/bin/env python3
"""The experiment study of the paper (Figs. 6 and 7): PPO on every scenario x shield on/off x seed.

    python src/moverl_gym/scripts/study.py            # full: 3 scenarios x on/off x 3 seeds x 40,000 steps
    python src/moverl_gym/scripts/study.py --quick --out /tmp/q   # CI size: table, 1 seed, 1,000 steps
    python src/moverl_gym/scripts/study.py --plot-only            # redraw from what is finished

Every run is one train.py subprocess (its own ROS graph on a free port), --jobs at once; its output goes to
<out>/logs/<run>.log. Runs whose summary.json exists are skipped (resume); a run folder without one (killed
half-way) is deleted and the run restarted. Then it draws fig6_contacts.png and fig7_learning.png and writes
results.md / results.csv into --docs (default docs/study; with --quick: <out>).
"""

from __future__ import annotations

import argparse
import shlex
import shutil
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from moverl_gym import options, study
from moverl_gym.workers import THREADS, run_logged

ROOT = Path(__file__).resolve().parents[3]
TRAIN = Path(__file__).resolve().parent / "train.py"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenarios", nargs="+", default=None, choices=study.SCENARIOS)
    p.add_argument("--seeds", nargs="+", type=int, default=None)
    p.add_argument("--shields", nargs="+", default=list(options.SHIELD), choices=options.SHIELD)
    p.add_argument("-n", "--n-timesteps", type=int, default=None, help="steps per run (default 40000)")
    options.add(p, "algo")
    p.add_argument(
        "--variant",
        default="",
        choices=("", "EE", "Goal", "GoalDense"),
        help="which id of each scenario: MoveRL/PandaReach<Scenario><variant>-v0 (Goal: the goal-conditioned ids, "
        "for SAC or TD3 with HER as config/hyperparams says)",
    )
    options.add(
        p,
        "task",
        task=dict(help="passed to train.py: override a key of config/env.yaml, e.g. --task start_noise=0; repeatable"),
    )
    p.add_argument("--jobs", type=int, default=2, help="trainings at once (one per core)")
    p.add_argument("--out", type=Path, default=None, help="run folders (default runs/study)")
    p.add_argument("--docs", type=Path, default=None, help="figures and tables (default docs/study)")
    p.add_argument(
        "--quick",
        action="store_true",
        help="CI size: table only, seed 0, 1,000 steps, out and docs in a temporary folder by default",
    )
    p.add_argument("--plot-only", action="store_true", help="no training: aggregate what is in --out")
    p.add_argument("--last", type=int, default=200, help="success rate over the last N episodes")
    p.add_argument("--timeout", type=float, default=3600, help="seconds before a run is killed")
    return p


def parse_args(argv=None):
    args = build_parser().parse_args(argv)
    if args.quick:
        args.scenarios = args.scenarios or ["table"]
        args.seeds = args.seeds if args.seeds is not None else [0]
        args.n_timesteps = args.n_timesteps or 1000
        if args.out is None:
            import tempfile

            args.out = Path(tempfile.mkdtemp(prefix="moverl_study_quick_"))
        args.docs = args.docs or args.out
    args.scenarios = args.scenarios or list(study.SCENARIOS)
    args.seeds = args.seeds if args.seeds is not None else [0, 1, 2]
    args.n_timesteps = args.n_timesteps or 40000
    args.out = args.out or ROOT / "runs" / "study"
    args.docs = args.docs or ROOT / "docs" / "study"
    return args


def command_line(argv) -> str:
    return "python src/moverl_gym/scripts/study.py " + " ".join(shlex.quote(a) for a in argv)


def planned(args) -> list[tuple[str, str, int]]:
    """Seed-major order: every scenario x shield of seed 0 first, so a partial study covers every cell."""
    return [(sc, sh, sd) for sd in args.seeds for sc in args.scenarios for sh in args.shields]


def run_all(args, argv) -> int:
    out: Path = args.out
    (out / "logs").mkdir(parents=True, exist_ok=True)
    todo = []
    for sc, sh, sd in planned(args):
        name = study.run_name(args.algo, study.env_id(sc, args.variant), sh, sd)
        folder = out / name
        if (folder / "summary.json").exists():
            print(f"skip {name} (finished)", flush=True)
            continue
        if folder.exists():
            print(f"restart {name} (half-finished: no summary.json)", flush=True)
            shutil.rmtree(folder)
        todo.append((sc, sh, sd, name))
    if not todo:
        print("every run is finished", flush=True)
        return 0
    print(f"{len(todo)} runs to do, {args.jobs} at once, {args.n_timesteps} steps each", flush=True)
    (out / "command.txt").write_text(command_line(argv) + "\n")
    lock = threading.Lock()
    done: list[float] = []
    failed: list[str] = []
    t_start = time.perf_counter()

    def one(item):
        sc, sh, sd, name = item
        cmd = [
            sys.executable,
            str(TRAIN),
            "--env",
            study.env_id(sc, args.variant),
            "--algo",
            args.algo,
            "--seed",
            str(sd),
            "-n",
            str(args.n_timesteps),
            "--shield",
            sh,
            "--log-folder",
            str(out),
            "--no-progress",
            *[a for t in args.task for a in ("--task", t)],
        ]
        log = out / "logs" / f"{name}.log"
        t0 = time.perf_counter()
        with lock:
            print(f"[{time.strftime('%H:%M:%S')}] start {name}", flush=True)
        rc = run_logged(cmd, log, args.timeout, THREADS)
        dt = time.perf_counter() - t0
        with lock:
            if rc == 0:
                done.append(dt)
                left = len(todo) - len(done) - len(failed)
                per = sum(done) / len(done)
                eta = per * left / max(args.jobs, 1)
                print(
                    f"[{time.strftime('%H:%M:%S')}] done  {name} in {dt:.0f} s; {left} left, "
                    f"estimate {eta / 60:.0f} min more ({per:.0f} s per run, {args.jobs} at once)",
                    flush=True,
                )
            else:
                failed.append(name)
                print(f"[{time.strftime('%H:%M:%S')}] FAILED {name} (rc {rc}) after {dt:.0f} s; see {log}", flush=True)

    with ThreadPoolExecutor(max_workers=max(args.jobs, 1)) as pool:
        list(pool.map(one, todo))
    print(
        f"trained {len(done)} runs in {(time.perf_counter() - t_start) / 60:.1f} min; failed: {failed or 'none'}",
        flush=True,
    )
    return 1 if failed else 0


def report(args, argv) -> int:
    runs = study.load_runs(args.out)
    wanted = {(sc, sh, sd) for sc, sh, sd in planned(args)}
    names = {study.run_name(args.algo, study.env_id(sc, args.variant), sh, sd) for sc, sh, sd in wanted}
    runs = [r for r in runs if r.path.name in names]
    finished = [r for r in runs if r.finished]
    partial = [r for r in runs if not r.finished and r.n_episodes > 0]
    missing = study.missing_runs(args.out, args.scenarios, args.shields, args.seeds, args.algo, args.variant)
    args.docs.mkdir(parents=True, exist_ok=True)
    trained_with = (args.out / "command.txt").read_text().strip() if (args.out / "command.txt").exists() else None
    suffix = "" if not missing else f"\n({len(finished)} of {len(wanted)} runs finished)"
    fig6 = study.plot_contacts(finished, args.docs / "fig6_contacts.png", title_suffix=suffix)
    fig7 = study.plot_learning(finished, args.docs / "fig7_learning.png", title_suffix=suffix)
    rows = study.summarize(finished, last=args.last)
    study.write_csv(rows, args.docs / "results.csv")
    lines = [
        "# MoveRL study: collisions (paper Fig. 6) and learning curves (Fig. 7), shield on vs off",
        "",
        "Command (training and this report):" if not trained_with else "Training command:",
        "",
        "```",
        trained_with or command_line(argv),
        "```",
        *(
            []
            if not trained_with or not args.plot_only
            else ["", "This report redrawn with:", "", "```", command_line(argv), "```"]
        ),
        "",
        f"{args.algo.upper()} (config/hyperparams/{args.algo}.yml), {args.n_timesteps} env steps per run, "
        f"ids MoveRL/PandaReach<Scenario>{args.variant}-v0, scenarios {', '.join(args.scenarios)}, "
        f"seeds {' '.join(map(str, args.seeds))}, shield {' and '.join(args.shields)}"
        + (f", task settings {', '.join(args.task)}" if args.task else "")
        + "; "
        f"run folders in `{args.out}`. Contacts are the simulator's ground-truth contact pairs along every step's "
        "motion (not the shield's own check). Success = the last "
        f"{args.last} training episodes (stochastic policy) that reached the goal. "
        "Shield interventions = actions the shield found unsafe and discarded (robot held still) or truncated; "
        "replanned = colliding straight paths replaced by a collision-free plan.",
        "",
        f"Finished runs: {len(finished)} of {len(wanted)}." + (f" Missing: {', '.join(missing)}." if missing else ""),
        "",
        study.markdown_table(rows, last=args.last),
        f"![Fig. 6]({fig6.name})",
        "",
        f"![Fig. 7]({fig7.name})",
        "",
    ]
    if partial:
        lines.insert(
            -5,
            "Unfinished (not in the table or figures): "
            + ", ".join(f"{r.path.name} ({r.n_episodes} episodes so far)" for r in partial)
            + "\n",
        )
    groups = study.settings_groups(finished)
    if len(groups) == 1:
        lines += ["## Settings (every finished run, from its config.yaml)", "", "```", next(iter(groups)), "```", ""]
    elif groups:
        lines += ["## WARNING: the finished runs used different settings (not comparable)", ""]
        lines += [f"- `{k}`: {', '.join(v)}" for k, v in groups.items()] + [""]
        print("WARNING: the finished runs used different settings; see results.md", file=sys.stderr)
    lines += ["## Per run", "", study.per_run_table(runs, last=args.last)]
    (args.docs / "results.md").write_text("\n".join(lines))
    print("\n" + study.markdown_table(rows, last=args.last))
    print(f"finished {len(finished)}/{len(wanted)}; missing: {missing or 'none'}")
    print(f"wrote {fig6}, {fig7}, {args.docs / 'results.md'}, {args.docs / 'results.csv'}")
    return 0


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    rc = 0
    if not args.plot_only:
        rc = run_all(args, argv)
    return report(args, argv) or rc


if __name__ == "__main__":
    sys.exit(main())
