#!/usr/bin/env python3
"""Train an unmodified stable-baselines3 agent on a MoveRL env (RL Zoo style).

    ./run.sh train --env MoveRL/PandaReachTable-v0 --algo ppo --seed 0 -n 40000 --shield on --log-folder runs

Writes to <log-folder>/<algo>_<env>_<shield>_s<seed>/: episodes.csv (per-episode return, length, success,
shield interventions by type, ground-truth contacts, the sub-env it ran in), TensorBoard events, checkpoints, the
final model and config.yaml (the resolved configuration). Prints a summary with steps/s at the end.

Parallel envs (`--n-envs N`, or `n_envs` in the hyper-parameter file, RL Zoo style): N envs, each in its own process
(SB3's SubprocVecEnv) with its own ROS graph on its own free port; env i is seeded with seed + i. As in RL Zoo,
PPO's n_steps is per env (a rollout is n_steps * N steps).

Goal-conditioned ids (MoveRL/PandaReach<Scenario>Goal[Dense]-v0) train with SAC or TD3 and HER as in RL Zoo: the
hyper-parameter file names the buffer (`replay_buffer_class: HerReplayBuffer`, `replay_buffer_kwargs`) and the policy
(`MultiInputPolicy`), e.g. config/hyperparams/sac.yml:

    ./run.sh train --env MoveRL/PandaReachTableGoal-v0 --algo sac -n 40000

--video N records N evaluation episodes of the trained policy (deterministic actions, a fresh env with
render_mode="rgb_array", Gymnasium's RecordVideo) to <run>/videos/.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import yaml

import moverl_gym  # noqa: F401  (registers the env ids)
from moverl_gym.launch_args import CHOICES
from moverl_gym.training import EpisodeLogger, load_hyperparams

ALGOS = ("ppo", "sac", "td3")


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", default="MoveRL/PandaReachTable-v0", help=f"env id, one of {moverl_gym.ENV_IDS}")
    p.add_argument("--algo", default="ppo", choices=ALGOS)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("-n", "--n-timesteps", type=int, default=None, help="default: from the hyper-parameter file")
    p.add_argument(
        "--n-envs",
        type=int,
        default=None,
        help="parallel envs, one process and one ROS graph each (default: n_envs of the hyper-parameter "
        "file, else 1); env i is seeded with seed + i",
    )
    p.add_argument("--shield", default="on", choices=("on", "off"))
    p.add_argument(
        "--obstacles",
        default="objects",
        choices=CHOICES["obstacles"],
        help="what the shield knows (launched graph only): the world file's objects, the OctoMap built "
        "from the world's depth cameras, both, or sensed (the static objects plus the OctoMap for what moves)",
    )
    p.add_argument(
        "--task",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a key of config/env.yaml for this run, e.g. --task start_noise=0 (starts uniform over the whole "
        "joint range); repeatable",
    )
    p.add_argument("--log-folder", default="runs")
    p.add_argument("--hyperparams", type=Path, default=None, help="YAML keyed by env id (default: config/hyperparams)")
    p.add_argument(
        "--graph",
        default="auto",
        choices=("auto", "launch", "attach"),
        help="attach to $ROS_MASTER_URI's graph or launch one on a free port",
    )
    p.add_argument(
        "--recover",
        default="auto",
        choices=("auto", "on", "off"),
        help="when a component of the graph fails, end the episode and relaunch the graph at the next reset "
        "instead of stopping (auto: on when the env launches its graph with the simulator, never with "
        "a real robot); every relaunch is logged (episodes.csv graph_failure, graph_restarts)",
    )
    p.add_argument("--checkpoint-freq", type=int, default=10000, help="steps between checkpoints (0: none)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--device", default="cpu")
    p.add_argument(
        "--video", type=int, default=0, metavar="N", help="record N evaluation episodes to <run>/videos (mp4)"
    )
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.env not in moverl_gym.ENV_IDS:
        print(f"unknown env id {args.env}; registered: {moverl_gym.ENV_IDS}", file=sys.stderr)
        return 2
    from stable_baselines3 import PPO, SAC, TD3
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    hp = load_hyperparams(args.algo, args.env, args.hyperparams)
    n_timesteps = int(args.n_timesteps or hp.pop("n_timesteps", 40000))
    hp.pop("n_timesteps", None)
    n_envs = int(args.n_envs or hp.pop("n_envs", 1))
    hp.pop("n_envs", None)
    if n_envs < 1:
        print(f"--n-envs must be at least 1, got {n_envs}", file=sys.stderr)
        return 2
    policy = hp.pop("policy", "MlpPolicy")
    if isinstance(hp.get("replay_buffer_class"), str):  # RL Zoo style: the class by name
        import stable_baselines3

        hp["replay_buffer_class"] = getattr(stable_baselines3, hp["replay_buffer_class"])
    if args.video < 0:
        print(f"--video must be >= 0, got {args.video}", file=sys.stderr)
        return 2
    shield = args.shield == "on"
    run = Path(args.log_folder) / f"{args.algo}_{args.env.split('/')[-1]}_{args.shield}_s{args.seed}"
    run.mkdir(parents=True, exist_ok=True)

    launch_args = {} if args.obstacles == "objects" else {"obstacles": args.obstacles}
    task = {}
    for item in args.task:
        key, sep, value = item.partition("=")
        if not sep or not key:
            print(f"--task takes KEY=VALUE, got {item!r}", file=sys.stderr)
            return 2
        task[key] = yaml.safe_load(value)
    recover = {"auto": "auto", "on": True, "off": False}[args.recover]
    if n_envs > 1 and args.graph == "attach":
        print(
            "--n-envs > 1 needs one graph per env: use --graph launch (or auto without a graph at ROS_MASTER_URI)",
            file=sys.stderr,
        )
        return 2
    make = [
        _env_factory(
            args.env, dict(shield=shield, graph=args.graph, launch_args=launch_args, recover=recover, task=task)
        )
        for _ in range(n_envs)
    ]
    # One env: in this process, as before. More: one process each (rospy allows one ROS master per process).
    env = DummyVecEnv(make) if n_envs == 1 else SubprocVecEnv(make)
    try:
        env.seed(args.seed)  # env i: seed + i, applied at the first reset
        env.action_space.seed(args.seed)
        config = {
            "env": args.env,
            "algo": args.algo,
            "seed": args.seed,
            "n_envs": n_envs,
            "env_seeds": [args.seed + i for i in range(n_envs)],
            "n_timesteps": n_timesteps,
            "shield": shield,
            "obstacles": args.obstacles,
            "policy": policy,
            "hyperparams": {k: getattr(v, "__name__", v) for k, v in hp.items()},
            "task": vars(env.get_attr("config", [0])[0]),
            "world": env.get_attr("world_name", [0])[0],
            "recover": env.get_attr("recover", [0])[0],
        }
        (run / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
        algo_cls = {"ppo": PPO, "sac": SAC, "td3": TD3}[args.algo]
        model = algo_cls(policy, env, seed=args.seed, device=args.device, verbose=0, **hp)
        model.set_logger(configure(str(run), ["tensorboard"]))
        episodes = EpisodeLogger(run / "episodes.csv")
        callbacks = [episodes]
        if args.checkpoint_freq > 0:
            callbacks.append(CheckpointCallback(args.checkpoint_freq, str(run / "checkpoints"), name_prefix="model"))
        t0 = time.perf_counter()
        model.learn(n_timesteps, callback=CallbackList(callbacks), progress_bar=not args.no_progress)
        wall = time.perf_counter() - t0
        model.save(run / "model")
    finally:
        env.close()
    if args.video:
        record_videos(
            model, args.env, dict(shield=shield, graph=args.graph, launch_args=launch_args, task=task), run, args
        )

    s = episodes.summary(last=200)
    s.update(wall_time=wall, steps_per_second=n_timesteps / wall, run=str(run), shield=shield)
    (run / "summary.json").write_text(json.dumps(s, indent=2))
    envs = f", {n_envs} envs" if n_envs > 1 else ""
    print(
        f"\n== {args.algo.upper()} on {args.env}, shield {args.shield}, seed {args.seed}{envs}: {n_timesteps} steps "
        f"in {wall:.1f} s ({s['steps_per_second']:.0f} steps/s, training included)"
    )
    print(f"episodes: {s['episodes']}   success rate (last {s['last_n']} episodes): {s['success_rate_last']:.1%}")
    print(
        f"shield interventions (discarded actions): {s['interventions']}  {s['by_type']}   "
        f"replanned paths: {s['replanned']}   truncated moves: {s['truncated']}"
    )
    print(f"ground-truth contacts (physics): {s['contacts']} contact pairs, {s['contact_substeps']} substeps")
    if s["graph_failures"]:
        print(
            f"graph failures: {s['graph_failures']} (each ended its episode; {s['graph_restarts']} relaunches): "
            + "; ".join(s["failures"])
        )
    print(f"outputs: {run}/episodes.csv, TensorBoard in {run}, model {run}/model.zip")
    return 0


def record_videos(model, env_id: str, kwargs: dict, run: Path, args) -> None:
    """args.video evaluation episodes of the trained policy (deterministic), recorded by Gymnasium's RecordVideo."""
    from moverl_gym.training import recording_env

    folder = run / "videos"
    env = recording_env(env_id, kwargs, folder, args.video)
    try:
        for episode in range(args.video):
            obs, _ = env.reset(seed=args.seed + 10_000 + episode)
            done = False
            while not done:
                action, _ = model.predict(obs, deterministic=True)
                obs, _, terminated, truncated, _ = env.step(action)
                done = terminated or truncated
    finally:
        env.close()
    print(f"videos: {args.video} evaluation episodes in {folder}")


def _env_factory(env_id: str, kwargs: dict):
    """A picklable env constructor for SB3's vec envs (the sub-process imports moverl_gym itself)."""

    def make():
        import gymnasium as gym
        from stable_baselines3.common.monitor import Monitor

        import moverl_gym  # noqa: F401  (registers the env ids in the sub-process)

        return Monitor(gym.make(env_id, **kwargs))

    return make


if __name__ == "__main__":
    sys.exit(main())
