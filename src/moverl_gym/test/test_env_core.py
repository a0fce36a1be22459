"""The env's logic without a roscore: MoveRLReachEnv on its PyBullet backend (the same robot, worlds, action scaling,
reward, starts and episode rules as on the ROS backend; no shield).

Gymnasium's and SB3's check_env, seed determinism, the reward and success rules, episode truncation, and that the
moving obstacles the env observes are where the simulator has them."""

import time
import types

import gymnasium as gym
import numpy as np
import pytest

import moverl_gym  # noqa: F401
import moverl_gym.bullet_backend
from moverl_gym.env import VERDICTS
from moverl_gym.errors import MoveRLError

pytestmark = pytest.mark.core

IDS = ["MoveRL/PandaReachTable-v0", "MoveRL/PandaReachHumanEE-v0", "MoveRL/PandaReachCase-v0"]


def make(env_id, **kwargs):
    return gym.make(env_id, backend="bullet", shield=False, **kwargs)


@pytest.mark.parametrize("env_id", IDS)
def test_check_env(env_id):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = make(env_id)
    try:
        check_env(env.unwrapped, skip_render_check=True)
        sb3_check_env(env.unwrapped, warn=True)
    finally:
        env.close()


def test_seed_determinism():
    env = make("MoveRL/PandaReachHuman-v0")
    try:
        actions = np.random.default_rng(3).uniform(-1, 1, (150, 7)).astype(np.float32)
        runs = []
        for _ in range(2):
            obs, _ = env.reset(seed=11)
            trace = [obs]
            for a in actions:
                obs, r, term, trunc, info = env.step(a)
                trace += [obs, np.array([r, term, trunc, info["contacts"]])]
                if term or trunc:
                    trace.append(env.reset()[0])
            runs.append(trace)
        for a, b in zip(*runs):
            np.testing.assert_array_equal(a, b)
    finally:
        env.close()


def test_a_closed_env_says_so():
    """step() and reset() after close() raise Gymnasium's ClosedEnvironmentError, not an AttributeError of an internal
    object (and close() twice is fine)."""
    env = make("MoveRL/PandaReachTable-v0")
    env.reset(seed=0)
    env.step(env.action_space.sample())
    env.close()
    env.close()
    with pytest.raises(gym.error.ClosedEnvironmentError, match="closed env"):
        env.step(env.action_space.sample())
    with pytest.raises(gym.error.ClosedEnvironmentError, match="closed env"):
        env.reset(seed=1)


def test_reward_success_and_truncation():
    env = make("MoveRL/PandaReachTable-v0", task={"max_episode_steps": 5})
    try:
        u = env.unwrapped
        env.reset(seed=0)
        d0 = u.distance
        _, r, term, trunc, info = env.step(np.zeros(7, dtype=np.float32))  # stand still: only the step penalty
        assert r == pytest.approx(u.config.step_penalty) and not term and not trunc
        assert info["verdict"] == VERDICTS[6] == "unchecked" and info["distance"] == pytest.approx(d0)
        for _ in range(3):
            _, _, _, trunc, _ = env.step(np.zeros(7, dtype=np.float32))
            assert not trunc
        _, _, _, trunc, _ = env.step(np.zeros(7, dtype=np.float32))
        assert trunc  # the 5th step: task={"max_episode_steps": 5} is honoured
        # At the goal: an episode that starts at home with the goal 5 cm from its end effector succeeds at once.
        home = u._backend.home
        goal = u._backend.ee_pose(np.array(home))[:3] + [0.05, 0.0, 0.0]
        env.reset(seed=0, options={"start": home, "goal": goal.tolist()})
        _, r, term, _, info = env.step(np.zeros(7, dtype=np.float32))
        assert term and info["is_success"] and r == pytest.approx(u.config.goal_reward)
    finally:
        env.close()


def test_observed_moving_obstacles_are_where_the_simulator_has_them():
    env = make("MoveRL/PandaReachHuman-v0")
    try:
        u = env.unwrapped
        env.reset(seed=2)
        for _ in range(40):
            obs, _, term, trunc, _ = env.step(env.action_space.sample())
            if term or trunc:
                obs, _ = env.reset()
        sim = u._backend.sim
        positions = sim.obstacle_positions()
        observed = [o for o in u._backend.world.obstacles if o.observed]
        n = u.limits.size
        tail = obs[n + 7 + 3 :].reshape(len(observed), 7)
        for o, pose in zip(observed, tail):
            np.testing.assert_allclose(pose[:3], positions[o.id], atol=1e-6, err_msg=o.id)
    finally:
        env.close()


def test_the_bullet_backend_has_no_shield():
    with pytest.raises(ValueError, match="no shield"):
        gym.make("MoveRL/PandaReachTable-v0", backend="bullet")  # shield=True by default


class _FailsOnce(moverl_gym.bullet_backend.BulletBackend):
    """The PyBullet backend with one failure injected where a graph's can happen: at a step or at a reset."""

    def __init__(self, where: str, world: str = "table"):
        super().__init__(world)
        self.where, self.failed, self.restarts = where, False, 0

    def _maybe_fail(self, where):
        if self.where == where and not self.failed:
            self.failed = True
            raise MoveRLError("simulator (/sim) failed: injected")

    def step(self, target, duration):
        self._maybe_fail("step")
        return super().step(target, duration)

    def reset(self, q):
        self._maybe_fail("reset")
        return super().reset(q)

    def restart(self):
        self.restarts += 1
        super().restart()


@pytest.mark.parametrize("where", ["step", "reset"])
def test_recovery_counts_a_failure_found_at_a_step_or_at_a_reset(where):
    """A failure ends the episode (at a step) or is found by the next reset (between episodes); either way the env
    relaunches, and info counts it once: graph_failures 1, graph_restarts 1; a reset that found it names it."""
    backend = _FailsOnce(where)
    env = gym.make("MoveRL/PandaReachTable-v0", backend=backend, shield=False, recover=True)
    try:
        _, info = env.reset(seed=0)
        if where == "step":
            assert info["graph_failures"] == 0
            _, _, term, trunc, info = env.step(np.zeros(7, dtype=np.float32))
            assert info["verdict"] == "graph_failed" and trunc and not term
            assert info["graph_failures"] == 1 and backend.restarts == 0
            _, info = env.reset()
            assert "graph_failure" not in info  # counted by the step that ended the episode
        else:
            assert "injected" in info["graph_failure"]
        assert info["graph_restart"] and info["graph_failures"] == 1 and info["graph_restarts"] == 1
        assert backend.restarts == 1
        _, _, _, _, info = env.step(np.zeros(7, dtype=np.float32))
        assert info["verdict"] == "unchecked" and info["graph_failures"] == 1
    finally:
        env.close()


class _TrackedFailsOnce(_FailsOnce):
    """_FailsOnce with the observed obstacles' poses from a tracker (obstacle_poses:=tracker) that never delivers one:
    every track is lost, age inf."""

    obstacle_poses = "tracker"

    def track(self, tracked):
        self.tracked = tracked


@pytest.mark.parametrize("tracker", [False, True], ids=["world_file", "tracker"])
def test_a_failed_step_has_every_key_of_a_step(tracker):
    """A step that failed (recover: verdict graph_failed) has the info keys of a step the backend answered, and
    graph_failure besides (tools/benchmark.py reads info["map_age"] of every step); what it did not measure has the
    value of no measurement: map_age -1 and sensed_margin 0 (no sensed map), track ages inf (never seen)."""
    backend = (_TrackedFailsOnce if tracker else _FailsOnce)("step", world="human")
    env = gym.make("MoveRL/PandaReachHuman-v0", backend=backend, shield=False, recover=True)
    try:
        env.reset(seed=0)
        _, _, _, _, failed = env.step(np.zeros(7, dtype=np.float32))
        assert failed["verdict"] == "graph_failed"
        env.reset()
        _, _, _, _, answered = env.step(np.zeros(7, dtype=np.float32))
        assert answered["verdict"] == "unchecked"
        assert sorted(failed) == sorted([*answered, "graph_failure"])
        assert failed["map_age"] == -1.0 and failed["sensed_margin"] == 0.0
        assert ("track_ages" in failed) == tracker
        if tracker:
            assert len(failed["track_ages"]) == len(answered["track_ages"]) == 4
            assert np.all(np.isinf(failed["track_ages"])) and failed["tracks_lost"] == 4
    finally:
        env.close()


class _HomeBlocked(moverl_gym.bullet_backend.BulletBackend):
    """The PyBullet backend with every state within 0.5 rad of home refused (a person standing at a long arm's
    home), or every state refused."""

    def __init__(self, everywhere=False):
        super().__init__("table")
        self.everywhere = everywhere

    def check_state(self, q):
        near_home = np.max(np.abs(np.asarray(q) - np.asarray(self.home))) < 0.5
        return not (self.everywhere or near_home) and super().check_state(q)


def test_starts_are_sampled_over_the_whole_range_when_home_is_blocked():
    env = gym.make("MoveRL/PandaReachTable-v0", backend=_HomeBlocked(), shield=False)
    try:
        env.reset(seed=0)
        u = env.unwrapped
        assert np.max(np.abs(u.q - np.asarray(u._backend.home))) >= 0.5  # not within start_noise of home
    finally:
        env.close()
    env = gym.make(
        "MoveRL/PandaReachTable-v0",
        backend=_HomeBlocked(everywhere=True),
        shield=False,
        task={"start_sampling_attempts": 20},
    )
    try:
        with pytest.raises(MoveRLError, match="20 random samples near home nor as many over the joint range"):
            env.reset(seed=0)
    finally:
        env.close()


class _HomeUnseenUntilLooked(_HomeBlocked):
    """A teleporting backend with a sensed map (as a freshly launched sensed graph): the states near home are refused
    until the robot has been stood at home, where the cameras see around it."""

    teleports = True

    def __init__(self):
        super().__init__()
        self.looked = False

    def sensed_census(self):
        return types.SimpleNamespace(cells=0, unknown_occupied=True, hidden=0)  # a sensed map (it tells nothing)

    def reset(self, q):
        if q is not None and np.allclose(q, self.home):
            self.looked = True
        return super().reset(q)

    def check_state(self, q):
        return (self.looked or np.max(np.abs(np.asarray(q) - np.asarray(self.home))) >= 0.5) and super(
            _HomeBlocked, self
        ).check_state(q)


def test_a_sensed_map_that_has_not_seen_home_yet_looks_again_before_starting_far_from_home():
    """No start near home free in a sensed map that can look again: the robot is stood at home and the start is
    sampled near home, not over the whole joint range (a first episode far from home was held still)."""
    env = gym.make("MoveRL/PandaReachTable-v0", backend=_HomeUnseenUntilLooked(), shield=False)
    try:
        env.reset(seed=0)
        u = env.unwrapped
        assert u._backend.looked
        assert np.max(np.abs(u.q - np.asarray(u._backend.home))) <= u.config.start_noise + 1e-9
    finally:
        env.close()


class _HomeBlockedTeleports(_HomeBlocked):
    """_HomeBlocked on a backend that teleports (a simulator's lockstep link) but senses nothing: no map to look again
    with, and no census to ask for on a reset that finds a start near home."""

    teleports = True

    def __init__(self):
        super().__init__()
        self.censuses = 0

    def sensed_census(self):
        self.censuses += 1
        return None


def test_a_teleporting_backend_without_a_sensed_map_starts_over_the_whole_range_and_asks_no_census_otherwise():
    env = gym.make("MoveRL/PandaReachTable-v0", backend=_HomeBlockedTeleports(), shield=False)
    try:
        env.reset(seed=0)
        u = env.unwrapped
        assert np.max(np.abs(u.q - np.asarray(u._backend.home))) >= 0.5  # not within start_noise of home
        asked = u._backend.censuses
        assert asked >= 1  # (the error's reason asks too)
        u._backend.check_state = super(_HomeBlocked, u._backend).check_state  # home free again
        for _ in range(3):
            env.reset()
        assert u._backend.censuses == asked  # a start near home was found: no census asked
    finally:
        env.close()


def test_a_later_reset_that_finds_nothing_free_starts_where_the_robot_stands():
    """Nothing free at the first reset: the world cannot be used as it is (NoFreeConfiguration, not a graph failure to
    relaunch). Nothing free later (sensed space the arm's own shadow turned possibly occupied): the episode starts
    where the robot stands, info says why, and the goal is the last one."""
    from moverl_gym.errors import NoFreeConfiguration

    backend = _HomeBlocked()
    env = gym.make("MoveRL/PandaReachTable-v0", backend=backend, shield=False, recover=True,
                   task={"start_sampling_attempts": 20})  # fmt: skip
    try:
        _, info = env.reset(seed=0)
        assert "no_free_start" not in info
        env.step(env.action_space.sample())
        u = env.unwrapped
        stood, goal = u.q.copy(), u.task.goal.copy()
        backend.everywhere = True
        # The sensed mode's reason holds percentages (the warning must not read them as a format).
        u._unseen_reason = lambda: ": 65 % of the robot's reach is space no camera sees"
        with pytest.warns(UserWarning, match="65 % of the robot's reach .* starts where the robot stands"):
            _, info = env.reset()
        assert "20 random samples" in info["no_free_start"]
        np.testing.assert_allclose(u.q, stood, atol=1e-6)
        np.testing.assert_allclose(u.task.goal, goal)
        assert info["graph_failures"] == 0 and info["graph_restarts"] == 0
        _, info = env.reset()  # (warned once)
        assert "no_free_start" in info
        backend.everywhere = False
        _, info = env.reset()
        assert "no_free_start" not in info
    finally:
        env.close()
    env = gym.make("MoveRL/PandaReachTable-v0", backend=_HomeBlocked(everywhere=True), shield=False, recover=True,
                   task={"start_sampling_attempts": 20})  # fmt: skip
    try:
        with pytest.raises(NoFreeConfiguration, match="no collision-free"):
            env.reset(seed=0)
        assert env.unwrapped.graph_failures == 0
    finally:
        env.close()


def test_the_env_step_deadline_exceeds_the_shields_own_bound():
    """config/env.yaml's step_timeout against the shield's bound from the shipped config files (the env checks the
    live graph's parameters the same way at start-up)."""
    import yaml

    from moverl_gym.paths import config_file
    from moverl_gym.ros_backend import shield_step_bound
    from moverl_gym.task import TaskConfig

    shield = yaml.safe_load(config_file("shield.yaml").read_text())
    scene = yaml.safe_load(config_file("planning_scene.yaml").read_text())
    task = TaskConfig.from_yaml(config_file("env.yaml"))
    bound = shield_step_bound({**shield, "planning_time": scene["planning_time"]}, task.dt)
    assert bound == pytest.approx(
        shield["max_state_age"]
        + scene["planning_time"]
        + shield["scene_margin"]
        + task.dt
        + shield["goal_time"]
        + shield["result_margin"]
    )
    assert task.step_timeout > bound


def test_a_worlds_goal_region_samples_each_episodes_goal_in_it():
    """shared_bench's goal_region: every reset's goal lies in the box and is where the end effector of
    goal_configuration is (what a scripted policy drives at); reset's options or goal= fix one, as in any world."""
    from moverl_gym.paths import world_file
    from moverl_gym.sampling import in_region
    from moverl_sim.world import load_world

    region = load_world(world_file("shared_bench")).goal_region
    assert region is not None
    env = make("MoveRL/PandaReachSharedBench-v0")
    try:
        u, goals = env.unwrapped, set()
        for seed in range(8):
            env.reset(seed=seed)
            goal, q = u.task.goal.copy(), u.goal_configuration
            assert in_region(goal, region) and q is not None
            goals.add(tuple(np.round(goal, 6)))
            env.reset(options={"start": q, "goal": goal})  # the robot at the configuration: its hand at the goal
            assert u.distance < 1e-6 and u.goal_configuration is None
        assert len(goals) == 8
        env.reset(seed=0)
        first = u.task.goal.copy()
        env.reset(seed=0)
        np.testing.assert_array_equal(u.task.goal, first)  # seeded
    finally:
        env.close()
    env = make("MoveRL/PandaReachSharedBench-v0", goal=[0.3, 0.0, 0.3])
    try:
        env.reset(seed=0)
        np.testing.assert_allclose(env.unwrapped.task.goal, [0.3, 0.0, 0.3])
        assert env.unwrapped.goal_configuration is None
    finally:
        env.close()


class _RegionBusy(moverl_gym.bullet_backend.BulletBackend):
    """The PyBullet backend of shared_bench with every state whose hand lies in the goal region refused until `busy`
    s after it was made (a person standing in the region at the first reset, who then moves on)."""

    def __init__(self, busy):
        super().__init__("shared_bench")
        from moverl_gym.sampling import in_region

        self.until, self._in_region = time.monotonic() + busy, in_region

    def check_state(self, q):
        held = time.monotonic() < self.until and self._in_region(self.ee_pose(q)[:3], self.world.goal_region)
        return not held and super().check_state(q)


def test_the_first_reset_looks_again_while_a_person_stands_in_the_goal_region():
    """No goal in the region free now: the reset samples again until config/env.yaml's goal_wait, and the person who
    moves on within it costs a wait, not an error; one who stays past it gives NoFreeConfiguration."""
    from moverl_gym.errors import NoFreeConfiguration
    from moverl_gym.sampling import in_region

    env = gym.make("MoveRL/PandaReachSharedBench-v0", backend=_RegionBusy(busy=0.6), shield=False)
    try:
        t0 = time.monotonic()
        env.reset(seed=0)
        assert time.monotonic() - t0 >= 0.4  # (the backend was made a little before)
        u = env.unwrapped
        assert in_region(u.task.goal, u._backend.world.goal_region) and u.goal_configuration is not None
    finally:
        env.close()
    env = gym.make("MoveRL/PandaReachSharedBench-v0", backend=_RegionBusy(busy=60.0), shield=False,
                   task={"goal_wait": 0.5})  # fmt: skip
    try:
        t0 = time.monotonic()
        with pytest.raises(NoFreeConfiguration, match="goal_region"):
            env.reset(seed=0)
        assert 0.5 <= time.monotonic() - t0 < 5.0
    finally:
        env.close()
