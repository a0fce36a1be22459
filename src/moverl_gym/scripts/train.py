#!/usr/bin/env python3
"""Train an unmodified stable-baselines3 agent on a MoveRL env (RL Zoo style).

    ./run.sh train --env MoveRL/PandaReachTable-v0 --algo ppo --seed 0 -n 40000 --shield on --log-folder runs

Writes to <log-folder>/<algo>_<env>_<shield>_s<seed>/: episodes.csv (per-episode return, length, success,
shield interventions by type, ground-truth contacts, the sub-env it ran in), TensorBoard events, checkpoints (every
--checkpoint-freq env steps), the final model and config.yaml (the resolved configuration). Prints a summary with
steps/s at the end. The options are rllib_train.py's too (moverl_gym.options): same names, units and choices.

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

from moverl_gym import options
from moverl_gym.training import EpisodeLogger, load_hyperparams, record_episodes

ALGOS = ("ppo", "sac", "td3")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    options.add(p, *options.TRAINING)  # the options rllib_train.py shares (moverl_gym.options)
    options.add(p, "launch")
    return p


def parse_args(argv=None):
    return build_parser().parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
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
        print(f"n_envs must be at least 1, got {n_envs} (hyper-parameter file)", file=sys.stderr)
        return 2
    if n_envs > 1 and args.graph == "attach":
        print("n_envs > 1 needs one graph per env: use --graph launch (or auto)", file=sys.stderr)
        return 2
    policy = hp.pop("policy", "MlpPolicy")
    if isinstance(hp.get("replay_buffer_class"), str):  # RL Zoo style: the class by name
        import stable_baselines3

        hp["replay_buffer_class"] = getattr(stable_baselines3, hp["replay_buffer_class"])
    shield = args.shield == "on"
    run = Path(args.log_folder) / f"{args.algo}_{args.env.split('/')[-1]}_{args.shield}_s{args.seed}"
    run.mkdir(parents=True, exist_ok=True)

    launch_args = {} if args.obstacles == "objects" else {"obstacles": args.obstacles}
    launch_args.update(options.launch_dict(args.launch))
    task = options.task_dict(args.task)
    recover = options.recover_value(args.recover)
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
            "launch": options.launch_dict(args.launch),
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
            # SB3's save_freq counts calls, each a step of every env: --checkpoint-freq counts env steps over all envs.
            every = max(args.checkpoint_freq // n_envs, 1)
            callbacks.append(CheckpointCallback(every, str(run / "checkpoints"), name_prefix="model"))
        t0 = time.perf_counter()
        model.learn(n_timesteps, callback=CallbackList(callbacks), progress_bar=not args.no_progress)
        wall = time.perf_counter() - t0
        model.save(run / "model")
    finally:
        env.close()
    if args.video:
        env_kwargs = dict(shield=shield, graph=args.graph, launch_args=launch_args, task=task)
        record_episodes(model, args.env, env_kwargs, run / "videos", args.video, args.seed + 10_000)
        print(f"videos: {args.video} evaluation episodes in {run / 'videos'}")

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
