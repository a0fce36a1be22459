#!/usr/bin/env python3
"""Evaluate a trained MoveRL agent: run episodes with the run's env id and shield setting (own ROS graph).

    python src/moverl_gym/scripts/evaluate.py runs/study/ppo_PandaReachTable-v0_on_s0 --episodes 50 --deterministic
    python src/moverl_gym/scripts/evaluate.py runs/rllib_ppo_PandaReachTable-v0_on_s0   # an RLlib run (rllib_train.py)

Reads config.yaml of the run (algo, env, shield, the task settings it trained with), prints and writes JSON (default
<run>/eval.json): success rate, mean return and length, ground-truth contacts (total and per episode), shield
interventions. The model is an SB3 run folder or .zip (train.py, any --n-envs), or an RLlib run folder or checkpoint
folder (rllib_train.py: its RLModule is restored without starting Ray). --video N records the first N episodes to
<run>/videos (Gymnasium's RecordVideo).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from pathlib import Path

import gymnasium as gym
import numpy as np
import yaml

from moverl_gym import options


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument(
        "model",
        type=Path,
        help="a run folder (with model.zip or an RLlib checkpoint/, and config.yaml), a "
        "model .zip or an RLlib checkpoint folder",
    )
    p.add_argument("--episodes", type=int, default=50)
    p.add_argument("--deterministic", action="store_true", help="mean action instead of sampling")
    # The options train.py and rllib_train.py share (moverl_gym.options); a default of None: as in training.
    options.add(
        p,
        "seed",
        "shield",
        "obstacles",
        "launch",
        "task",
        "graph",
        "video",
        seed=dict(default=1000, help="env seed: episode i starts from reset(seed=seed + i); not a training seed"),
        shield=dict(default=None, help="default: as in training"),
        obstacles=dict(default=None, help="what the planning scene knows of the obstacles (default: as in training)"),
        launch=dict(
            help="an argument of launch/moverl.launch for the evaluation's graph (not the training's), e.g. --launch "
            "obstacle_poses=tracker --launch camera_rate=30 --launch mode=realtime; repeatable"
        ),
        task=dict(
            help="override a key of the task as trained (config/env.yaml then, with the run's --task), e.g. "
            "--task start_noise=0; repeatable"
        ),
        video=dict(help="record the first N episodes to <run>/videos (mp4)"),
    )
    p.add_argument("--world", default=None, help="another world (name in worlds/ or file) than the env id's")
    p.add_argument("--out", type=Path, default=None, help="JSON file (default <run>/eval.json)")
    return p


def parse_args(argv=None):
    return build_parser().parse_args(argv)


def resolve(path: Path) -> tuple[Path, dict]:
    """(model zip or RLlib checkpoint folder, training config) from a run folder, a model file or a checkpoint."""
    from moverl_gym.rllib import is_checkpoint

    path = path.resolve()
    if is_checkpoint(path) or is_checkpoint(path / "checkpoint"):
        model = path if is_checkpoint(path) else path / "checkpoint"
    else:
        model = path / "model.zip" if path.is_dir() else path
    run = model.parent
    if run.name == "checkpoints":  # a checkpoint: the config is in the run folder
        run = run.parent
    if not model.exists():
        raise FileNotFoundError(f"no model at {model}")
    cfg = run / "config.yaml"
    if not cfg.exists():
        raise FileNotFoundError(f"no config.yaml next to {model} (expected {cfg})")
    return model, yaml.safe_load(cfg.read_text())


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        model_path, config = resolve(args.model)
    except FileNotFoundError as e:
        print(e, file=sys.stderr)
        return 2
    algo = config["algo"]
    shield = config["shield"] if args.shield is None else args.shield == "on"
    # The task as trained (config/env.yaml then, with the run's --task overrides: e.g. whole-range starts).
    from dataclasses import fields

    from moverl_gym.task import TaskConfig

    known = {f.name for f in fields(TaskConfig)}  # a run of an older version may have recorded keys since removed
    task = {k: v for k, v in (config.get("task") or {}).items() if k in known}
    task.update(options.task_dict(args.task))
    kwargs = dict(shield=shield, graph=args.graph, task=task)
    obstacles = args.obstacles or config.get("obstacles", "objects")
    launch = options.launch_dict(args.launch)
    kwargs["launch_args"] = ({"obstacles": obstacles} if obstacles != "objects" else {}) | launch
    if args.world:
        kwargs["world"] = args.world
    if args.video > 0:
        from moverl_gym.training import recording_env

        env = recording_env(config["env"], kwargs, model_path.parent / "videos", args.video)
    else:
        env = gym.make(config["env"], **kwargs)
    try:
        if config.get("framework") == "rllib":
            from moverl_gym.rllib import CheckpointPolicy

            model = CheckpointPolicy(model_path, env.action_space)
        else:
            from stable_baselines3 import PPO, SAC, TD3

            # With the env: a HerReplayBuffer model needs one to load.
            model = {"ppo": PPO, "sac": SAC, "td3": TD3}[algo].load(str(model_path), env=env, device="cpu")
    except BaseException:
        env.close()
        raise
    episodes = []
    t0 = time.perf_counter()
    try:
        for i in range(args.episodes):
            obs, _ = env.reset(seed=args.seed + i)
            ep, done = Counter(), False
            while not done:
                action, _ = model.predict(obs, deterministic=args.deterministic)
                obs, reward, terminated, truncated, info = env.step(action)
                done = terminated or truncated
                ep["return"] += float(reward)
                ep["length"] += 1
                ep["contacts"] += max(info.get("contacts", 0), 0)
                ep["contacts_moving"] += max(info.get("contacts_moving", 0), 0)  # of them, while the robot moved
                ep["interventions"] += int(bool(info.get("discarded")))
                if info.get("discarded"):
                    ep[info.get("verdict", "discarded")] += 1  # by verdict: discarded_pose, ..., discarded_unseen
                ep["replanned"] += int(info.get("verdict") == "replanned")
                if "tracks_lost" in info:  # obstacle_poses:=tracker
                    ep["steps_with_lost_tracks"] += int(info["tracks_lost"] > 0)
                    ages = info["track_ages"][np.isfinite(info["track_ages"])]
                    ep["track_age_sum"] += float(ages.mean()) if ages.size else 0.0
                ep["truncated"] += int(info.get("verdict") == "truncated")
            ep["success"] = int(bool(info.get("is_success", False)))
            episodes.append(dict(ep))
    finally:
        env.close()
    wall = time.perf_counter() - t0

    def col(k):
        return np.array([e.get(k, 0) for e in episodes], dtype=float)

    result = {
        "model": str(model_path),
        "framework": config.get("framework", "sb3"),
        "env": config["env"],
        "algo": algo,
        "shield": bool(shield),
        "trained_with_shield": bool(config["shield"]),
        "obstacles": obstacles,
        "launch": launch,
        "task_overrides": options.task_dict(args.task),
        "world": args.world,
        "deterministic": args.deterministic,
        "episodes": len(episodes),
        "seed": args.seed,
        "success_rate": float(col("success").mean()),
        "mean_return": float(col("return").mean()),
        "std_return": float(col("return").std()),
        "mean_length": float(col("length").mean()),
        "contacts_total": int(col("contacts").sum()),
        "contacts_per_episode": float(col("contacts").mean()),
        "episodes_with_contacts": int((col("contacts") > 0).sum()),
        "contacts_moving_total": int(col("contacts_moving").sum()),
        "interventions_total": int(col("interventions").sum()),
        "interventions_per_episode": float(col("interventions").mean()),
        "replanned_total": int(col("replanned").sum()),
        "truncated_total": int(col("truncated").sum()),
        "discarded_unseen_total": int(col("discarded_unseen").sum()),
        "steps_with_lost_tracks": int(col("steps_with_lost_tracks").sum()),
        "mean_track_age": float(col("track_age_sum").sum() / col("length").sum())
        if launch.get("obstacle_poses") == "tracker"
        else None,
        "wall_time": wall,
        "steps_per_second": float(col("length").sum() / wall) if wall > 0 else float("nan"),
        "per_episode": episodes,
    }
    if args.out:
        out = args.out
    elif config.get("framework") == "rllib":  # <run>/checkpoint or <run>/checkpoints/iter_<n>
        out = (
            model_path.parent / "eval.json"
            if model_path.name == "checkpoint"
            else model_path.parent.parent / f"eval_{model_path.name}.json"
        )
    else:
        out = model_path.parent / "eval.json"
        if out.parent.name == "checkpoints":
            out = out.parent.parent / f"eval_{model_path.stem}.json"
    out.write_text(json.dumps(result, indent=2))
    rllib = "RLlib " if config.get("framework") == "rllib" else ""
    print(
        f"== {rllib}{algo.upper()} {config['env']} (trained shield {'on' if config['shield'] else 'off'}), evaluated "
        f"shield {'on' if shield else 'off'}, {'deterministic' if args.deterministic else 'stochastic'} policy, "
        f"{len(episodes)} episodes"
    )
    print(
        f"success rate {result['success_rate']:.1%}   mean return {result['mean_return']:.2f} "
        f"± {result['std_return']:.2f}   mean length {result['mean_length']:.1f}"
    )
    print(
        f"ground-truth contacts: {result['contacts_total']} total, {result['contacts_per_episode']:.2f} per "
        f"episode ({result['episodes_with_contacts']} episodes with contacts; {result['contacts_moving_total']} while "
        "the robot moved)"
    )
    print(
        f"shield interventions (discarded): {result['interventions_total']} "
        f"({result['interventions_per_episode']:.2f} per episode), replanned {result['replanned_total']}, "
        f"truncated {result['truncated_total']}"
    )
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
