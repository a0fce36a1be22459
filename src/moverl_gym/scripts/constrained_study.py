#!/usr/bin/env python3
"""The shield against constrained RL (issue 27): PPO + shield (ours), PPO with a contact penalty, PPO-Lagrangian with
cost limits 0 and 1, on the table, human and case worlds; contacts during training, success, and every final policy
deployed with the shield on and off.

    python src/moverl_gym/scripts/constrained_study.py              # full: tuning, 3 worlds x 4 methods x 5 seeds
    python src/moverl_gym/scripts/constrained_study.py --quick      # CI size: table, seed 0, 300 steps, no tuning
    python src/moverl_gym/scripts/constrained_study.py --plot-only  # redraw from what is finished

1. Tuning, the same budget for every method: its one knob (methods in moverl_gym.constrained_study.METHODS: the
   shield's safety_penalty, the contact_penalty, PPO-Lagrangian's lagrange_lr) at each of 3 values, one run each
   (table, seed --tune-seed, --tune-steps steps); the value is chosen by one rule for all (select_value).
2. Training: every world x method x seed, --n-timesteps steps, PPO's hyper-parameters from config/hyperparams/ppo.yml
   (the paper's) for every method. The shield's runs use the ROS graph; the unshielded ones the env's PyBullet backend
   (same robot, world, reward and physics, in-process).
3. Evaluation: every final policy, deterministic, --eval-episodes episodes from the same starts, in the ROS graph with
   the shield on and with it off (one graph per world and mode).
4. Report into --docs: results.md, the tables as CSV, curves.csv, one figure per world, lagrange.png.

Every run is a subprocess (this script with --worker), --jobs at once; output in <out>/logs/. Finished runs
(summary.json) and evaluations (eval_<mode>.csv) are kept: a killed study resumes where it stopped; a run folder
without summary.json is deleted and the run restarted.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from moverl_gym import constrained_study as cs
from moverl_gym import options
from moverl_gym.study import env_id
from moverl_gym.workers import THREADS, run_logged

ROOT = Path(__file__).resolve().parents[3]
#: Evaluation episode i starts from reset(seed=EVAL_SEED + i): the same starts for every policy of a world.
EVAL_SEED = 10_000


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--worlds", nargs="+", default=None, choices=cs.WORLDS)
    p.add_argument("--methods", nargs="+", default=list(cs.METHODS), choices=list(cs.METHODS))
    p.add_argument("--seeds", nargs="+", type=int, default=None, help="default 0 1 2 3 4")
    p.add_argument("-n", "--n-timesteps", type=int, default=None, help="steps per run (default 100000)")
    p.add_argument("--tune-steps", type=int, default=50_000, help="steps per tuning run")
    p.add_argument("--tune-seed", type=int, default=100, help="seed of the tuning runs (not one of --seeds)")
    p.add_argument("--tune-world", default="table", choices=cs.WORLDS)
    p.add_argument("--no-tune", action="store_true", help="every method with its default knob value")
    p.add_argument("--eval-episodes", type=int, default=None, help="per policy and shield mode (default 100)")
    p.add_argument("--jobs", type=int, default=2, help="processes at once (one per core)")
    p.add_argument("--out", type=Path, default=None, help="run folders (default runs/constrained)")
    p.add_argument("--docs", type=Path, default=None, help="figures, tables and CSVs (default docs/constrained)")
    p.add_argument(
        "--quick", action="store_true", help="CI size: table, seed 0, 300 steps, 2 evaluation episodes, no tuning"
    )
    p.add_argument("--plot-only", action="store_true", help="no training: report what is in --out")
    p.add_argument("--last", type=int, default=200, help="final success = the last N training episodes")
    p.add_argument("--timeout", type=float, default=4 * 3600, help="seconds before a worker is killed")
    p.add_argument(
        "--pause-while",
        type=Path,
        default=None,
        metavar="FILE",
        help="before starting each process, wait while FILE exists (someone measuring speed)",
    )
    p.add_argument("--worker", choices=("train", "eval"), help=argparse.SUPPRESS)
    p.add_argument("--method", help=argparse.SUPPRESS)
    p.add_argument("--world", help=argparse.SUPPRESS)
    p.add_argument("--seed", type=int, help=argparse.SUPPRESS)
    p.add_argument("--value", type=float, help=argparse.SUPPRESS)
    p.add_argument("--folder", type=Path, help=argparse.SUPPRESS)
    p.add_argument("--mode", choices=options.SHIELD, help=argparse.SUPPRESS)
    p.add_argument("--runs", nargs="*", type=Path, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.quick:
        args.worlds = args.worlds or ["table"]
        args.seeds = args.seeds if args.seeds is not None else [0]
        args.n_timesteps = args.n_timesteps or 300
        args.eval_episodes = args.eval_episodes or 2
        args.no_tune = True
        if args.out is None and not args.worker:
            args.out = Path(tempfile.mkdtemp(prefix="moverl_constrained_quick_"))
        args.docs = args.docs or args.out
    args.worlds = args.worlds or list(cs.WORLDS)
    args.seeds = args.seeds if args.seeds is not None else [0, 1, 2, 3, 4]
    args.n_timesteps = args.n_timesteps or 100_000
    args.eval_episodes = args.eval_episodes or 100
    args.out = args.out or ROOT / "runs" / "constrained"
    args.docs = args.docs or ROOT / "docs" / "constrained"
    if args.tune_seed in args.seeds and not args.no_tune:
        p.error(f"--tune-seed {args.tune_seed} is one of --seeds: tune on a seed that is not reported")
    return args


def command_line(argv) -> str:
    return "python src/moverl_gym/scripts/constrained_study.py " + " ".join(shlex.quote(a) for a in argv)


# -- workers (one process each) -----------------------------------------------------------------------------------
def provenance() -> dict:
    """What code a run used: the commit, the files changed in the checkout (other work in progress), and when the C++
    binaries the graph runs were built (the shield and the planning scene are the checkout's devel space)."""

    def git(*cmd) -> str:
        try:
            return subprocess.run(["git", *cmd], cwd=ROOT, capture_output=True, text=True, timeout=30).stdout.rstrip()
        except (OSError, subprocess.SubprocessError):
            return ""

    built = {}
    for rel in (
        "devel/lib/moverl_shield/shield_node",
        "devel/lib/libmoverl_shield_core.so",
        "devel/lib/moverl_planning_scene/planning_scene_node",
        "devel/lib/libmoverl_planning_scene_core.so",
    ):
        path = ROOT / rel
        if path.exists():
            built[Path(rel).name] = time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(path.stat().st_mtime))
    changed = [line[3:] for line in git("status", "--porcelain", "--untracked-files=no").splitlines()]
    return {"commit": git("rev-parse", "HEAD"), "changed_files": changed, "binaries_built_utc": built}


def _make_env(world: str, shield: bool, task: dict):
    """The training env: the ROS graph with the shield, or the in-process PyBullet backend without it."""

    def make():
        import gymnasium as gym
        from stable_baselines3.common.monitor import Monitor

        import moverl_gym  # noqa: F401  (registers the ids)

        kwargs = dict(graph="launch", recover="auto") if shield else dict(backend="bullet")
        return Monitor(gym.make(env_id(world), shield=shield, task=task, **kwargs))

    return make


def train_worker(args) -> int:
    """One training run into args.folder; summary.json is written last."""
    import numpy as np
    import yaml
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.vec_env import DummyVecEnv

    from moverl_gym.constrained import PPOLagrangian
    from moverl_gym.training import EpisodeLogger, load_hyperparams

    spec = cs.METHODS[args.method]
    hp = load_hyperparams("ppo", env_id(args.world))
    for key in ("n_timesteps", "n_envs"):
        hp.pop(key, None)
    policy = hp.pop("policy", "MlpPolicy")
    task, algo_kwargs = {}, {}
    if spec.algo == "ppolag":
        algo_kwargs = dict(cost_limit=spec.cost_limit, lagrange_lr=args.value)
    else:
        task[spec.knob] = args.value
    folder: Path = args.folder
    folder.mkdir(parents=True, exist_ok=True)
    env = DummyVecEnv([_make_env(args.world, spec.shield, task)])
    try:
        env.seed(args.seed)
        env.action_space.seed(args.seed)
        config = {
            "method": args.method,
            "label": spec.label,
            "algo": spec.algo,
            "world": args.world,
            "env": env_id(args.world),
            "seed": args.seed,
            "shield": spec.shield,
            "backend": "ros" if spec.shield else "bullet",
            "knob": spec.knob,
            "value": args.value,
            "n_timesteps": args.n_timesteps,
            "policy": policy,
            "hyperparams": hp,
            "algo_kwargs": algo_kwargs,
            "task": vars(env.get_attr("config", [0])[0]),
            "code": provenance(),
        }
        (folder / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
        cls = PPOLagrangian if spec.algo == "ppolag" else PPO
        model = cls(policy, env, seed=args.seed, device="cpu", verbose=0, **algo_kwargs, **hp)
        model.set_logger(configure(str(folder), ["csv"]))
        episodes = EpisodeLogger(folder / "episodes.csv")
        t0 = time.perf_counter()
        model.learn(args.n_timesteps, callback=episodes, progress_bar=False)
        wall = time.perf_counter() - t0
        model.save(folder / "model")
    finally:
        env.close()
    s = episodes.summary(last=200)
    s.update(wall_time=wall, steps_per_second=args.n_timesteps / wall)
    if spec.algo == "ppolag":
        log = model.lagrange_log
        cs.write_csv(log, folder / "lagrange.csv")
        tail = [x["episode_cost"] for x in log[-max(len(log) // 10, 1) :]]
        s.update(multiplier=model.multiplier, episode_cost_last=float(np.nanmean(tail)) if tail else math.nan)
    (folder / "summary.json").write_text(json.dumps(s, indent=2))
    print(
        f"{folder.name}: {args.n_timesteps} steps in {wall:.0f} s, success {s['success_rate_last']:.1%}, "
        f"contacts {s['contacts']}, interventions {s['interventions']}"
    )
    return 0


def eval_worker(args) -> int:
    """Every run in args.runs, deterministic, args.eval_episodes episodes, in one ROS graph of args.world with the
    shield args.mode; each run's eval_<mode>.csv is written when its episodes are done."""
    import csv

    import gymnasium as gym
    import numpy as np
    import yaml
    from stable_baselines3 import PPO

    import moverl_gym  # noqa: F401
    from moverl_gym.constrained import PPOLagrangian

    env = gym.make(env_id(args.world), shield=args.mode == "on", graph="launch", recover=False)
    try:
        for folder in args.runs:
            out = folder / f"eval_{args.mode}.csv"
            if out.exists():
                continue
            config = yaml.safe_load((folder / "config.yaml").read_text())
            cls = PPOLagrangian if config["algo"] == "ppolag" else PPO
            model = cls.load(folder / "model.zip", device="cpu")
            rows = []
            t0 = time.perf_counter()
            for i in range(args.eval_episodes):
                obs, _ = env.reset(seed=EVAL_SEED + i)
                row = dict(episode=i, seed=EVAL_SEED + i, success=0, length=0, contacts=0, contact_steps=0.0)
                row.update(interventions=0, **{"return": 0.0})
                done = False
                while not done:
                    action, _ = model.predict(obs, deterministic=True)
                    obs, reward, terminated, truncated, info = env.step(action)
                    done = terminated or truncated
                    row["length"] += 1
                    row["return"] += float(reward)
                    row["contacts"] += max(int(info["contacts"]), 0)
                    row["contact_steps"] += float(info["cost_contact"])
                    row["interventions"] += int(bool(info["discarded"]))
                row["success"] = int(bool(info["is_success"]))
                row["return"] = round(row["return"], 4)
                rows.append(row)
            meta = dict(episodes=args.eval_episodes, first_seed=EVAL_SEED, deterministic=True, code=provenance())
            folder.joinpath(f"eval_{args.mode}.json").write_text(json.dumps(meta, indent=2))
            tmp = out.with_suffix(".tmp")
            with open(tmp, "w", newline="") as f:
                w = csv.DictWriter(f, fieldnames=cs.EVAL_FIELDS)
                w.writeheader()
                w.writerows(rows)
            tmp.replace(out)
            print(
                f"{folder.name} shield {args.mode}: success {np.mean([r['success'] for r in rows]):.1%}, "
                f"contacts {sum(r['contacts'] for r in rows)}, interventions {sum(r['interventions'] for r in rows)} "
                f"({time.perf_counter() - t0:.0f} s)",
                flush=True,
            )
    finally:
        env.close()
    return 0


# -- the study ----------------------------------------------------------------------------------------------------
class Pool:
    """Worker subprocesses, --jobs at once, each with its log file; waits while --pause-while exists."""

    def __init__(self, args, argv):
        self.args = args
        self.lock = threading.Lock()
        self.failed: list[str] = []
        (args.out / "logs").mkdir(parents=True, exist_ok=True)

    def _wait_quiet(self, name: str) -> None:
        path = self.args.pause_while
        said = False
        while path is not None and path.exists():
            if not said:
                print(f"[{time.strftime('%H:%M:%S')}] {path} exists: waiting before {name}", flush=True)
                said = True
            time.sleep(60)

    def run(self, items: list[tuple[str, list[str]]]) -> None:
        """items: (name, worker arguments)."""

        def one(item):
            name, worker_args = item
            self._wait_quiet(name)
            cmd = [sys.executable, str(Path(__file__).resolve()), *worker_args]
            log = self.args.out / "logs" / f"{name}.log"
            t0 = time.perf_counter()
            with self.lock:
                print(f"[{time.strftime('%H:%M:%S')}] start {name}", flush=True)
            rc = run_logged(cmd, log, self.args.timeout, THREADS)
            with self.lock:
                dt = time.perf_counter() - t0
                if rc == 0:
                    print(f"[{time.strftime('%H:%M:%S')}] done  {name} in {dt:.0f} s", flush=True)
                else:
                    self.failed.append(name)
                    print(
                        f"[{time.strftime('%H:%M:%S')}] FAILED {name} (rc {rc}) after {dt:.0f} s; see {log}", flush=True
                    )

        if items:
            with ThreadPoolExecutor(max_workers=max(self.args.jobs, 1)) as pool:
                list(pool.map(one, items))


def _train_items(args, runs: list[tuple[str, str, int, float, Path]], steps: int) -> list[tuple[str, list[str]]]:
    items = []
    for method, world, seed, value, folder in runs:
        if (folder / "summary.json").exists():
            continue
        if folder.exists():
            print(f"restart {folder.name} (half-finished: no summary.json)", flush=True)
            shutil.rmtree(folder)
        worker = ["--worker", "train", "--method", method, "--world", world, "--seed", str(seed)]
        worker += ["--value", repr(value), "-n", str(steps), "--folder", str(folder)]
        items.append((folder.name, worker))
    return items


def tune(args, pool: Pool) -> dict[str, float]:
    """The tuning phase: every method's grid on the tuning world and seed; the chosen values (tuning/selected.json)."""
    root = args.out / "tuning"
    plan = [
        (m, args.tune_world, args.tune_seed, v, root / cs.run_name(m, args.tune_world, args.tune_seed, v))
        for m in args.methods
        for v in cs.METHODS[m].grid
    ]
    pool.run(_train_items(args, plan, args.tune_steps))
    chosen, table = {}, []
    for method in args.methods:
        candidates = {}
        for m, _, _, value, folder in plan:
            run = cs.load_run(folder) if m == method else None
            if run is not None and run.finished:
                candidates[value] = dict(
                    success=cs.success_last(run, args.last), contacts=cs.total(run.episodes, "contacts")
                )
                summary = run.summary
                table.append(
                    dict(
                        method=method,
                        knob=cs.METHODS[method].knob,
                        value=value,
                        success=candidates[value]["success"],
                        contacts=candidates[value]["contacts"],
                        contact_steps=cs.total(run.episodes, "cost_contact"),
                        interventions=cs.total(run.episodes, "interventions"),
                        wall_time=summary.get("wall_time", math.nan),
                        multiplier=summary.get("multiplier", math.nan),
                    )
                )
        if len(candidates) < len(cs.METHODS[method].grid):
            raise RuntimeError(f"tuning of {method}: only {len(candidates)} of its runs finished (see {root}/../logs)")
        chosen[method] = cs.select_value(candidates)
    for row in table:
        row["selected"] = row["value"] == chosen[row["method"]]
    cs.write_csv(table, root / "tuning.csv")
    (root / "selected.json").write_text(json.dumps(chosen, indent=2))
    return chosen


def run_study(args, argv) -> int:
    args.out.mkdir(parents=True, exist_ok=True)
    cmd_file = args.out / "command.txt"
    if not cmd_file.exists():
        cmd_file.write_text(command_line(argv) + "\n")
    pool = Pool(args, argv)
    values = {m: cs.METHODS[m].default for m in args.methods} if args.no_tune else tune(args, pool)
    print("knob values: " + ", ".join(f"{m} {cs.METHODS[m].knob}={v:g}" for m, v in values.items()), flush=True)
    plan = [
        (m, w, s, values[m], args.out / cs.run_name(m, w, s))
        for s in args.seeds
        for w in args.worlds
        for m in args.methods
    ]
    items = _train_items(args, plan, args.n_timesteps)
    print(f"{len(items)} of {len(plan)} training runs to do, {args.jobs} at once", flush=True)
    pool.run(items)
    evals = []
    for world in args.worlds:
        for mode in ("on", "off"):
            folders = [f for m, w, s, v, f in plan if w == world and (f / "summary.json").exists()]
            todo = [f for f in folders if not (f / f"eval_{mode}.csv").exists()]
            if todo:
                worker = ["--worker", "eval", "--world", world, "--mode", mode]
                worker += ["--eval-episodes", str(args.eval_episodes), "--runs", *map(str, todo)]
                evals.append((f"eval_{world}_{mode}", worker))
    print(f"{len(evals)} evaluations to do", flush=True)
    pool.run(evals)
    print(f"failed: {pool.failed or 'none'}", flush=True)
    return 1 if pool.failed else 0


def report(args, argv) -> int:
    runs = [
        r
        for r in cs.load_runs(args.out)
        if r.world in args.worlds and r.method in args.methods and r.seed in args.seeds
    ]
    finished = [r for r in runs if r.finished]
    docs: Path = args.docs
    docs.mkdir(parents=True, exist_ok=True)
    rows = cs.summarize(finished, last=args.last)
    rows2 = cs.summarize_2x2(finished)
    cs.write_csv(rows, docs / "results.csv")
    cs.write_csv(rows2, docs / "deployment.csv")
    cs.write_csv(cs.per_run_rows(finished, last=args.last), docs / "runs.csv")
    cs.curves_csv(finished, docs / "curves.csv")
    planned = len(args.worlds) * len(args.methods) * len(args.seeds)
    suffix = "" if len(finished) == planned else f" ({len(finished)} of {planned} runs)"
    figs = [cs.plot_world(finished, w, docs / f"fig_{w}.png", title_suffix=suffix) for w in args.worlds]
    lag = cs.lagrange_curves(finished, docs / "lagrange.png") if any(r.lagrange for r in finished) else None
    tuning = args.out / "tuning" / "tuning.csv"
    if tuning.exists():
        shutil.copyfile(tuning, docs / "tuning.csv")
    trained_with = (args.out / "command.txt").read_text().strip() if (args.out / "command.txt").exists() else None
    lines = [
        "# The shield against constrained RL: contacts during training, success, deployment with and without it",
        "",
        "Command (training and report):" if not args.plot_only else "Training command:",
        "",
        "```",
        trained_with or command_line(argv),
        "```",
        *([] if not args.plot_only else ["", "Report drawn with:", "", "```", command_line(argv), "```"]),
        "",
        f"Worlds {', '.join(args.worlds)}; seeds {' '.join(map(str, args.seeds))}; {args.n_timesteps:,} env steps per "
        "run; PPO's hyper-parameters from config/hyperparams/ppo.yml (the paper's) for every method; run folders in "
        f"`{args.out}`. Finished runs: {len(finished)} of {planned}. Mean ± half-width of the 95 % t-interval over "
        f"seeds. Final success: the last {args.last} training episodes (stochastic policy). Contacts: the physics "
        "engine's distinct robot contact pairs per step, summed (steps with contact = the sum of info"
        '["cost_contact"]). Evaluation: the final policy, deterministic, '
        f"{args.eval_episodes} episodes from the same starts, in the ROS graph.",
        "",
        cs.markdown_table(rows, last=args.last),
        "## Deployment: every final policy with the shield on and off",
        "",
        cs.markdown_2x2(rows2),
    ]
    if tuning.exists():
        lines += [
            "## Tuning (same budget per method: its knob at 3 values, one run each)",
            "",
            cs.markdown_tuning(tuning),
        ]
    lines += [f"![{f.stem}]({f.name})\n" for f in figs]
    if lag is not None:
        lines += [f"![PPO-Lagrangian multiplier and cost]({lag.name})\n"]
    lines += ["## Per run", "", cs.markdown_runs(cs.per_run_rows(runs, last=args.last))]
    (docs / "results.md").write_text("\n".join(lines))
    print("\n" + cs.markdown_table(rows, last=args.last) + "\n" + cs.markdown_2x2(rows2))
    print(
        f"finished {len(finished)}/{planned}; wrote results.md, results.csv, deployment.csv, runs.csv, curves.csv "
        f"into {docs}"
    )
    return 0


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    if args.worker == "train":
        return train_worker(args)
    if args.worker == "eval":
        return eval_worker(args)
    rc = 0 if args.plot_only else run_study(args, argv)
    return report(args, argv) or rc


if __name__ == "__main__":
    sys.exit(main())
