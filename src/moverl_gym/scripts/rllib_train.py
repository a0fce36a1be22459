#!/usr/bin/env python3
"""Train PPO with Ray RLlib (new API stack) on a MoveRL env: N env runners, each its own process with one env and one
ROS graph, on a Ray cluster of its own on this machine (default) or on an existing cluster (--address).

    ./run.sh rllib --env MoveRL/PandaReachTable-v0 --num-env-runners 2 -n 40000 --log-folder runs
    ./run.sh rllib ... --address <head host>:<port>          # a cluster started with `ray start` (README)
    ./run.sh rllib ... --resume runs/rllib_ppo_PandaReachTable-v0_on_s0/checkpoint

Writes to <log-folder>/rllib_ppo_<env>_<shield>_s<seed>/: config.yaml, progress.jsonl (one line per iteration: steps,
return, success, contacts, interventions by type, cost, graph failures and relaunches, env runner restarts, the node
of every runner), TensorBoard events (every scalar of RLlib's result), checkpoints/model_<steps>_steps after the
iteration that passes each multiple of --checkpoint-freq env steps, the final checkpoint in checkpoint/ (resume from
it, or `./run.sh eval` it), summary.json. Hyper-parameters: src/moverl_gym/config/hyperparams/rllib_ppo.yml keyed by
env id.

The options are train.py's (moverl_gym.options: same names, units and choices; --n-envs is the number of env runners,
--num-env-runners its RLlib name), plus the RLlib ones below. What RLlib cannot do is refused, not ignored: --algo
other than ppo, goal-conditioned env ids (Dict observations), --graph attach (every runner launches its own graph),
--device other than cpu.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import signal
import sys
import time
from pathlib import Path

import yaml

import moverl_gym
from moverl_gym import options
from moverl_gym.env import DISCARDED_COUNTERS
from moverl_gym.training import load_hyperparams

#: Keys of rllib_ppo.yml that are not PPOConfig.training() arguments.
RUN_KEYS = ("n_envs", "n_timesteps", "fcnet_hiddens", "fcnet_activation")
#: Shared options (moverl_gym.options) that RLlib honours only with some values -> (those values, why not others).
CANNOT = {
    "algo": (("ppo",), "rllib_train.py trains PPO only (sac and td3: train.py)"),
    "env": (
        tuple(moverl_gym.FLAT_ENV_IDS),
        "the goal-conditioned ids (Dict observations, HER) train with train.py --algo sac or td3; RLlib's default "
        "model takes a flat observation",
    ),
    "graph": (("auto", "launch"), "every env runner launches its own graph on a free port (--graph launch or auto)"),
    "device": (("cpu",), "rllib_train.py's learner runs on the CPU, in the driver's process"),
}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    options.add(
        p,
        *options.TRAINING,
        n_envs=dict(
            flags=("--num-env-runners",),
            help="parallel envs, one env runner each (a Ray actor process with "
            "one env and one ROS graph); default: n_envs of the hyper-parameter file",
        ),
        no_progress=dict(help="no progress output (a line per iteration)"),
    )
    r = p.add_argument_group("RLlib")
    r.add_argument(
        "--address",
        default=None,
        help="an existing Ray cluster (<host>:<port> of its head, as `ray start --head` prints); default: "
        "start a cluster of our own on this machine (127.0.0.1, free ports, own temp dir)",
    )
    r.add_argument(
        "--local-nodes",
        type=int,
        default=1,
        help="nodes of the local cluster: 1 (default), or N > 1 for a multi-node cluster on this host (a "
        "head without CPUs plus N nodes sharing the runners, so runners run on different nodes)",
    )
    r.add_argument("--resume", type=Path, default=None, help="a checkpoint folder of an earlier run to continue")
    r.add_argument(
        "--runner-restart-delay",
        type=float,
        default=5.0,
        help="seconds before RLlib brings a restarted env runner back (RLlib's default is 60)",
    )
    r.add_argument(
        "--sample-timeout",
        type=float,
        default=120.0,
        help="seconds a runner may take for one sample() before RLlib gives up on it",
    )
    return p


def parse_args(argv=None):
    p = build_parser()
    args = p.parse_args(argv)
    options.refuse(p, args, CANNOT)
    if args.address and args.local_nodes != 1:
        p.error("--local-nodes: the nodes of a local cluster; with --address the cluster is the one given")
    return args


def env_kwargs(args) -> dict:
    """The keyword arguments of gym.make for every runner's env: one graph each, launched on a free port."""
    kwargs = dict(shield=args.shield == "on", graph="launch", recover=options.recover_value(args.recover))
    if args.obstacles != "objects":
        kwargs["launch_args"] = {"obstacles": args.obstacles}
    if args.task:
        kwargs["task"] = options.task_dict(args.task)
    return kwargs


def build_config(args, hp: dict, num_env_runners: int):
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig

    from moverl_gym import rllib

    training = {k: v for k, v in hp.items() if k not in RUN_KEYS}
    return (
        PPOConfig()
        .environment(rllib.ENV_NAME, env_config={"env_id": args.env, **env_kwargs(args)})
        .env_runners(
            num_env_runners=num_env_runners,
            num_envs_per_env_runner=1,
            gym_env_vectorize_mode="sync",
            num_cpus_per_env_runner=1,
            sample_timeout_s=args.sample_timeout,
        )
        .learners(num_learners=0)  # the learner runs in this process
        .training(**training)
        .rl_module(
            model_config=DefaultModelConfig(
                fcnet_hiddens=list(hp.get("fcnet_hiddens", [64, 64])),
                fcnet_activation=hp.get("fcnet_activation", "tanh"),
            )
        )
        .fault_tolerance(
            restart_failed_env_runners=True,
            max_num_env_runner_restarts=100,
            delay_between_env_runner_restarts_s=args.runner_restart_delay,
            num_consecutive_env_runner_failures_tolerance=3,
            restart_failed_sub_environments=False,
        )
        .callbacks(rllib.metrics_callback())
        .debugging(seed=args.seed)
    )


def flatten(d: dict, prefix: str = "") -> dict:
    """Numeric leaves of a nested result dict as {"a/b/c": value}."""
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, key + "/"))
        elif isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
            out[key] = v
    return out


def summarize(result: dict, wall: float) -> dict:
    """The figures of one iteration that progress.jsonl keeps."""
    from moverl_gym.rllib import LIFETIME_COUNTERS

    runners = result.get("env_runners", {})
    m = runners.get("moverl", {})
    return {
        "iteration": int(result.get("training_iteration", 0)),
        "env_steps": int(runners.get("num_env_steps_sampled_lifetime", 0)),
        "episodes": int(runners.get("num_episodes_lifetime", 0)),
        "episode_return_mean": runners.get("episode_return_mean"),
        "success_rate": m.get("success_rate"),
        # The run's lifetime counters (moverl_gym.rllib, their one list), as integers; cost below, as a float.
        **{k: int(m.get(k, 0)) for k in LIFETIME_COUNTERS if k != "cost"},
        "cost": float(m.get("cost", 0.0)),
        "env_runner_restarts": int(result.get("moverl", {}).get("env_runner_restarts", 0)),
        "healthy_env_runners": int(result.get("moverl", {}).get("healthy_env_runners", 0)),
        "wall_time": round(wall, 2),
    }


def runner_nodes(algo) -> list[dict]:
    """Where every runner runs: its index, Ray node id, host, process id."""

    def where(runner):
        import socket

        import ray

        return {
            "worker_index": runner.worker_index,
            "node_id": ray.get_runtime_context().get_node_id(),
            "host": socket.gethostname(),
            "pid": os.getpid(),
        }

    return sorted(
        algo.env_runner_group.foreach_env_runner(where, local_env_runner=False), key=lambda r: r["worker_index"]
    )


def main(argv=None) -> int:
    args = parse_args(argv)
    hp = load_hyperparams("rllib_ppo", args.env, args.hyperparams)
    if "num_env_runners" in hp:
        print("rllib_ppo.yml: num_env_runners is called n_envs (as in train.py's files)", file=sys.stderr)
        return 2
    n_timesteps = int(args.n_timesteps or hp.get("n_timesteps", 40000))
    num_env_runners = int(args.n_envs or hp.get("n_envs", 2))
    if num_env_runners < 1:
        print("n_envs must be at least 1 (the env never runs in the driver)", file=sys.stderr)
        return 2
    run = Path(args.log_folder) / f"rllib_ppo_{args.env.split('/')[-1]}_{args.shield}_s{args.seed}"
    run.mkdir(parents=True, exist_ok=True)

    cluster = None
    algo = None
    try:
        if args.address:
            import ray

            ray.init(address=args.address, log_to_driver=True)
        else:
            from moverl_gym.rllib import LocalCluster, node_layout

            cluster = LocalCluster(node_layout(num_env_runners, args.local_nodes))
        from moverl_gym import rllib

        rllib.register()
        config = build_config(args, hp, num_env_runners)
        algo = config.build_algo()
        # SIGTERM (a job scheduler, `timeout`) ends the run like Ctrl-C: the finally blocks stop the runners (their
        # graphs) and the cluster. Set after Ray started: Ray's core installs a handler that aborts the process
        # (before this point the cluster's guard and the graphs' reapers stop everything when this process dies).
        signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
        if args.resume:
            algo.restore_from_path(str(Path(args.resume).resolve()))
        nodes = runner_nodes(algo)
        (run / "config.yaml").write_text(
            yaml.safe_dump(
                {
                    "framework": "rllib",
                    "algo": "ppo",
                    "env": args.env,
                    "seed": args.seed,
                    "n_timesteps": n_timesteps,
                    "shield": args.shield == "on",
                    "obstacles": args.obstacles,
                    "task": options.task_dict(args.task),
                    "recover": args.recover,
                    "n_envs": num_env_runners,
                    "hyperparams": hp,
                    "address": args.address or f"local cluster, {args.local_nodes} node(s)",
                    "resumed_from": str(args.resume) if args.resume else None,
                    "runners": nodes,
                },
                sort_keys=False,
            )
        )
        print(f"runners: {nodes}", flush=True)
        from torch.utils.tensorboard import SummaryWriter

        writer = SummaryWriter(str(run))
        progress = open(run / "progress.jsonl", "a")
        from ray.rllib.utils.metrics import ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME

        steps0 = int(algo.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0))  # resumed
        t0 = time.perf_counter()
        row = summarize({}, 0.0)
        saved = steps0 // args.checkpoint_freq if args.checkpoint_freq else 0  # multiples of it passed so far
        while True:
            result = algo.train()
            row = summarize(result, time.perf_counter() - t0)
            row["runners"] = runner_nodes(algo)
            progress.write(json.dumps(row) + "\n")
            progress.flush()
            for key, value in flatten(result).items():
                writer.add_scalar(key, value, row["env_steps"])
            writer.flush()
            if not args.no_progress:
                print(
                    f"iter {row['iteration']}: {row['env_steps']} steps, return {row['episode_return_mean']}, success "
                    f"{row['success_rate']}, contacts {row['contacts']}, interventions {row['interventions']}, graph "
                    f"restarts {row['graph_restarts']}, runner restarts {row['env_runner_restarts']}",
                    flush=True,
                )
            # Env steps, as train.py counts them: a checkpoint after the iteration that passes each multiple.
            if args.checkpoint_freq and row["env_steps"] // args.checkpoint_freq > saved:
                saved = row["env_steps"] // args.checkpoint_freq
                algo.save_to_path(str((run / "checkpoints" / f"model_{row['env_steps']}_steps").resolve()))
            if row["env_steps"] >= n_timesteps:
                break
        wall = time.perf_counter() - t0
        algo.save_to_path(str((run / "checkpoint").resolve()))
        writer.close()
        progress.close()
    finally:
        try:
            if algo is not None:
                algo.stop()  # the runners close their envs: every graph stops
        finally:
            if cluster is not None:
                cluster.shutdown()
    if args.video:
        from moverl_gym.rllib import CheckpointPolicy
        from moverl_gym.training import record_episodes

        kwargs = {k: v for k, v in env_kwargs(args).items() if k != "recover"}
        policy = functools.partial(CheckpointPolicy, run / "checkpoint")  # of the recording env's action space
        record_episodes(policy, args.env, kwargs, run / "videos", args.video, args.seed + 10_000)
        print(f"videos: {args.video} evaluation episodes in {run / 'videos'}")

    steps = row["env_steps"] - steps0  # this run's steps (a resumed run started at steps0)
    summary = dict(
        row,
        wall_time=wall,
        steps_this_run=steps,
        steps_per_second=steps / wall if wall > 0 else float("nan"),
        run=str(run),
        checkpoint=str(run / "checkpoint"),
    )
    (run / "summary.json").write_text(json.dumps(summary, indent=2))
    print(
        f"\n== RLlib PPO on {args.env}, shield {args.shield}, seed {args.seed}, {num_env_runners} env runners: "
        f"{steps} steps in {wall:.1f} s ({summary['steps_per_second']:.0f} steps/s, training included)"
        + (f", resumed at {steps0} steps" if steps0 else "")
    )
    print(f"episodes: {row['episodes']}   success rate (last 100 episodes): {row['success_rate']}")
    print(
        f"shield interventions (discarded actions): {row['interventions']}  "
        + str({k: row[k] for k in DISCARDED_COUNTERS})
        + f"   replanned paths: {row['replanned']}   truncated moves: {row['truncated']}"
    )
    print(f"ground-truth contacts (physics): {row['contacts']} contact pairs, {row['contact_substeps']} substeps")
    print(
        f"graph failures: {row['graph_failures']}, graph relaunches (env recovery): {row['graph_restarts']}, "
        f"env runner restarts (RLlib): {row['env_runner_restarts']}"
    )
    print(f"outputs: {run}/progress.jsonl, TensorBoard in {run}, checkpoint {run}/checkpoint")
    return 0


if __name__ == "__main__":
    sys.exit(main())
