"""The goal-conditioned ids against the live graph, shield on (each test launches its own graph on a free port).

- SAC + HER from SB3, unmodified (train.py, HerReplayBuffer with copy_info_dict), on the case world's goal id: zero
  ground-truth contacts, and a video of an evaluation episode recorded (--video);
- relabelled rewards, including the steps the shield discarded: HER-style relabelling (goals achieved later in the
  same episode) of live transitions, rewards computed by the env through a vec env's env_method as SB3 does, against
  the formula recomputed from scratch;
- render_mode="rgb_array" with the ROS backend (the picture is drawn in the env's process from the observed state).
"""

import json
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

import moverl_gym  # noqa: F401
from moverl_gym.paths import config_file
from moverl_gym.task import TaskConfig

pytestmark = pytest.mark.live

TRAIN = Path(__file__).resolve().parents[1] / "scripts" / "train.py"
CASE_INTO = np.array([0.0, 1.0, 0.0, 1.0, 0.0, -0.5, 0.0])  # reach down and forward, into the case's walls


def test_sac_her_trains_on_a_goal_id_with_the_shield_on(tmp_path):
    hp = tmp_path / "sac.yml"
    her = {
        "policy": "MultiInputPolicy",
        "learning_starts": 100,
        "batch_size": 64,
        "buffer_size": 2000,
        "replay_buffer_class": "HerReplayBuffer",
        "replay_buffer_kwargs": {"goal_selection_strategy": "future", "n_sampled_goal": 4, "copy_info_dict": True},
        "policy_kwargs": {"net_arch": [64, 64]},
    }
    hp.write_text(yaml.safe_dump({"default": her}))
    cmd = [sys.executable, str(TRAIN), "--env", "MoveRL/PandaReachCaseGoal-v0", "--algo", "sac", "-n", "400"]
    cmd += ["--seed", "2", "--log-folder", str(tmp_path), "--no-progress", "--checkpoint-freq", "0"]
    cmd += ["--hyperparams", str(hp), "--video", "1"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    run = tmp_path / "sac_PandaReachCaseGoal-v0_on_s2"
    summary = json.loads((run / "summary.json").read_text())
    print("\nSAC + HER, case goal id, 400 steps:", {k: summary[k] for k in ("episodes", "interventions", "contacts")})
    assert summary["contacts"] == 0
    config = yaml.safe_load((run / "config.yaml").read_text())
    assert config["hyperparams"]["replay_buffer_class"] == "HerReplayBuffer"
    videos = list((run / "videos").glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 10_000


def test_relabelled_rewards_with_discarded_steps_match_the_formula():
    from stable_baselines3.common.vec_env import DummyVecEnv

    vec = DummyVecEnv([lambda: gym.make("MoveRL/PandaReachCaseGoal-v0", render_mode="rgb_array")])
    try:
        env = vec.envs[0]
        rng = np.random.default_rng(4)
        episodes, episode = [], []
        obs, _ = env.reset(seed=4)
        frame = env.render()
        assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
        for _ in range(300):  # a policy that keeps pushing into the case: the shield discards many steps
            action = np.clip(CASE_INTO * 0.8 + rng.normal(0.0, 0.5, 7), -1, 1).astype(np.float32)
            next_obs, reward, term, trunc, info = env.step(action)
            assert info["contacts"] == 0
            episode.append((next_obs["achieved_goal"], obs["desired_goal"], info, reward))
            obs = next_obs
            if term or trunc:
                episodes.append(episode)
                episode = []
                obs, _ = env.reset()
        episodes.append(episode)
        achieved, desired, infos, rewards = [], [], [], []
        for ep in episodes:  # "future" relabelling: the goal becomes a position achieved later in the episode
            for k, (ach, des, info, reward) in enumerate(ep):
                future = ep[rng.integers(k, len(ep))][0]
                achieved += [ach, ach]
                desired += [des, future]
                infos += [info, info]
                rewards.append(reward)
        achieved, desired = np.array(achieved), np.array(desired)
        infos = np.array(infos, dtype=object)
        got = vec.env_method("compute_reward", achieved, desired, infos, indices=[0])[0]
        # From scratch: sparse -1 / 0 at goal_tolerance, plus safety_penalty for a discarded step.
        c = TaskConfig.from_yaml(config_file("env.yaml"))
        d = np.linalg.norm(achieved.astype(float) - desired.astype(float), axis=1)
        discarded = np.array([float(i["discarded"]) for i in infos])
        expected = np.where(d < c.goal_tolerance, 0.0, -1.0) + c.safety_penalty * discarded
        np.testing.assert_allclose(got, expected, atol=1e-5)
        np.testing.assert_allclose(got[0::2], rewards, atol=1e-5)  # the original goals: what the env returned
        n_discarded = int(discarded[0::2].sum())
        print(f"\n{len(rewards)} live steps, {n_discarded} discarded; {len(got)} rewards recomputed")
        assert n_discarded > 10, "the pushing policy must make the shield discard steps"
        assert (got[1::2] == 0).any() or (got[1::2] == c.safety_penalty).any()  # relabelled successes exist
    finally:
        vec.close()


ZOO_HYPERPARAMS = """
MoveRL/PandaReachTableGoal-v0:
  n_timesteps: 300
  policy: 'MultiInputPolicy'
  buffer_size: 2000
  batch_size: 64
  learning_starts: 100
  replay_buffer_class: HerReplayBuffer
  replay_buffer_kwargs: "dict(goal_selection_strategy='future', n_sampled_goal=4, copy_info_dict=True)"
  policy_kwargs: "dict(net_arch=[64, 64])"
"""


def test_rl_zoo_trains_and_records_a_video(tmp_path):
    (tmp_path / "sac.yml").write_text(ZOO_HYPERPARAMS)
    env_id = "MoveRL/PandaReachTableGoal-v0"
    train = [sys.executable, "-m", "rl_zoo3.train", "--algo", "sac", "--env", env_id, "--gym-packages", "moverl_gym"]
    train += ["--conf-file", "sac.yml", "-f", "logs", "--eval-freq", "-1", "--seed", "0"]
    proc = subprocess.run(train, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    # record_video has no --gym-packages: the ids are registered by importing moverl_gym first.
    record = (
        "import runpy, sys; import moverl_gym; sys.argv = ['record_video', '--algo', 'sac', '--env', "
        f"'{env_id}', '-f', 'logs', '--exp-id', '1', '-n', '60', '--deterministic']; "
        "runpy.run_module('rl_zoo3.record_video', run_name='__main__')"
    )
    proc = subprocess.run([sys.executable, "-c", record], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    videos = list((tmp_path / "logs").rglob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 10_000, videos
