"""Gymnasium conveniences without a roscore (the env on its PyBullet backend): bounded observation spaces, the
goal-conditioned ids (Dict observation, vectorised compute_reward, HER's relabelling), and rendering (rgb_array,
Gymnasium's HumanRendering and RecordVideo)."""

import os

import gymnasium as gym
import numpy as np
import pytest

import moverl_gym
from moverl_gym.paths import config_file
from moverl_gym.task import TaskConfig
from moverl_sim.scene_view import ViewSettings

pytestmark = pytest.mark.core


def make(env_id, **kwargs):
    return gym.make(env_id, backend="bullet", shield=False, **kwargs)


@pytest.mark.parametrize("env_id", moverl_gym.ENV_IDS)
def test_every_observation_of_1000_random_steps_is_in_the_space(env_id):
    env = make(env_id)
    try:
        space = env.observation_space
        if isinstance(space, gym.spaces.Box):
            assert np.isfinite(space.low).all() and np.isfinite(space.high).all()  # bounded
        obs, _ = env.reset(seed=0)
        env.action_space.seed(0)
        for k in range(1000):
            assert space.contains(obs), (k, obs)
            obs, _, term, trunc, _ = env.step(env.action_space.sample())
            if term or trunc:
                obs, _ = env.reset()
    finally:
        env.close()


@pytest.mark.parametrize("env_id", moverl_gym.ENV_IDS)
def test_both_env_checkers_pass_on_every_id_without_a_warning(env_id):
    import warnings

    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = make(env_id)
    try:
        if env_id in moverl_gym.GOAL_ENV_IDS:
            assert set(env.observation_space.spaces) == {"observation", "achieved_goal", "desired_goal"}
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env.unwrapped, skip_render_check=True)
            sb3_check_env(env.unwrapped, warn=True)
        messages = [str(w.message) for w in caught]
        # The one message allowed: SB3 telling that it recognised a goal env by its compute_reward.
        assert not [m for m in messages if "GoalEnv" not in m], messages
    finally:
        env.close()


def test_a_goal_out_of_reach_is_refused():
    env = make("MoveRL/PandaReachTable-v0")
    try:
        with pytest.raises(ValueError, match="out of the robot's reach"):
            env.reset(seed=0, options={"goal": [5.0, 0.0, 0.3]})
    finally:
        env.close()


def _reward_from_scratch(achieved, desired, discarded, sparse):
    """The goal ids' reward written out again from config/env.yaml, independently of moverl_gym.task."""
    c = TaskConfig.from_yaml(config_file("env.yaml"))
    d = np.sqrt(((np.asarray(achieved, float) - np.asarray(desired, float)) ** 2).sum(axis=-1))
    base = np.where(d < c.goal_tolerance, 0.0, -1.0) if sparse else -d
    return base + c.safety_penalty * np.asarray(discarded, float)


@pytest.mark.parametrize("env_id", ["MoveRL/PandaReachTableGoal-v0", "MoveRL/PandaReachCaseGoalDense-v0"])
def test_step_rewards_and_batched_compute_reward_agree_with_the_formula(env_id):
    env = make(env_id)
    try:
        u = env.unwrapped
        sparse = u.reward_type == "sparse"
        obs, _ = env.reset(seed=1)
        ach, des, infos, rewards = [], [], [], []
        for _ in range(200):
            obs, r, term, trunc, info = env.step(env.action_space.sample())
            ach.append(obs["achieved_goal"])
            des.append(obs["desired_goal"])
            infos.append(info)
            rewards.append(r)
            if term or trunc:
                obs, _ = env.reset()
        ach, des = np.array(ach), np.array(des)
        # The env's own rewards (float64 positions) against the formula on the float32 observations.
        np.testing.assert_allclose(rewards, _reward_from_scratch(ach, des, [0] * len(ach), sparse), atol=1e-4)
        # A batch as SB3's HER passes it: relabelled goals, an array of info dicts, some of them discarded steps
        # (the shield's penalty; the PyBullet backend has no shield, so the flag is set here), some empty (SB3
        # without copy_info_dict).
        rng = np.random.default_rng(0)
        relabelled = ach[rng.permutation(len(ach))]
        batch_infos = np.array([{**i, "discarded": bool(k % 3 == 0)} for k, i in enumerate(infos)], dtype=object)
        batch_infos[1::7] = [{} for _ in batch_infos[1::7]]
        discarded = [bool(i.get("discarded", False)) for i in batch_infos]
        got = u.compute_reward(ach, relabelled, batch_infos)
        assert got.shape == (len(ach),) and got.dtype == np.float32
        np.testing.assert_allclose(got, _reward_from_scratch(ach, relabelled, discarded, sparse), atol=1e-5)
        # One sample (a dict info) gives the same as its row of the batch.
        assert u.compute_reward(ach[0], relabelled[0], batch_infos[0]) == pytest.approx(got[0])
    finally:
        env.close()


def test_her_relabels_with_compute_reward_through_sb3():
    """SB3's HerReplayBuffer, unmodified, on a goal id: every sampled (relabelled) reward equals the formula."""
    from stable_baselines3 import SAC, HerReplayBuffer

    env = make("MoveRL/PandaReachTableGoal-v0")
    try:
        model = SAC(
            "MultiInputPolicy",
            env,
            learning_starts=150,
            batch_size=64,
            replay_buffer_class=HerReplayBuffer,
            replay_buffer_kwargs=dict(n_sampled_goal=4, goal_selection_strategy="future", copy_info_dict=True),
            policy_kwargs=dict(net_arch=[32, 32]),
            seed=0,
            verbose=0,
        )
        model.learn(300)
        batch = model.replay_buffer.sample(256)
        discarded = [0.0] * 256  # the PyBullet backend never discards
        expected = _reward_from_scratch(
            batch.next_observations["achieved_goal"].cpu().numpy(),
            batch.observations["desired_goal"].cpu().numpy(),
            discarded,
            True,
        )
        np.testing.assert_allclose(batch.rewards.cpu().numpy().ravel(), expected, atol=1e-5)
        assert (expected == 0).any() and (expected == -1).any()  # relabelled successes and failures both present
    finally:
        env.close()


def test_rgb_array_shows_the_current_state():
    env = make("MoveRL/PandaReachHuman-v0", render_mode="rgb_array")
    try:
        s = ViewSettings.from_yaml()
        assert env.metadata["render_fps"] == pytest.approx(1.0 / env.unwrapped.config.dt)
        env.reset(seed=0)
        first = env.render()
        assert first.shape == (s.height, s.width, 3) and first.dtype == np.uint8
        assert len(np.unique(first.reshape(-1, 3), axis=0)) > 50  # a picture, not a blank
        for _ in range(30):
            env.step(np.ones(7, dtype=np.float32))
        later = env.render()
        assert (np.abs(later.astype(int) - first).sum(axis=2) > 30).mean() > 0.005  # the robot moved in the picture
    finally:
        env.close()


def test_no_renderer_without_a_render_mode():
    env = make("MoveRL/PandaReachTable-v0")
    try:
        env.reset(seed=0)
        env.step(env.action_space.sample())
        assert env.unwrapped._view is None  # nothing built, nothing rendered
        with pytest.raises(ValueError, match="render_mode"):
            make("MoveRL/PandaReachTable-v0", render_mode="ansi")
    finally:
        env.close()


def test_human_mode_through_gymnasiums_wrapper(monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")  # no display here: pygame draws into a dummy window
    env = make("MoveRL/PandaReachTable-v0", render_mode="human")
    try:
        assert isinstance(env, gym.wrappers.HumanRendering) or any(
            isinstance(w, gym.wrappers.HumanRendering) for w in _wrappers(env)
        )
        env.reset(seed=0)
        env.step(env.action_space.sample())
    finally:
        env.close()


def _wrappers(env):
    while isinstance(env, gym.Wrapper):
        yield env
        env = env.env


def test_record_video_writes_an_episode(tmp_path):
    import imageio.v3 as iio
    from gymnasium.wrappers import RecordVideo

    env = RecordVideo(
        make("MoveRL/PandaReachTableGoal-v0", render_mode="rgb_array", task={"max_episode_steps": 20}),
        str(tmp_path),
        episode_trigger=lambda _: True,
        disable_logger=True,
    )
    try:
        env.reset(seed=0)
        done = False
        while not done:
            _, _, term, trunc, _ = env.step(env.action_space.sample())
            done = term or trunc
    finally:
        env.close()
    videos = sorted(os.listdir(tmp_path))
    assert videos and videos[0].endswith(".mp4")
    frames = iio.imread(tmp_path / videos[0])
    s = ViewSettings.from_yaml()
    assert frames.shape[1:] == (s.height, s.width, 3) and frames.shape[0] >= 2
