"""Constrained RL without a roscore: the env's ground-truth cost (info["cost_contact"]) and contact penalty on the
PyBullet backend, and PPO-Lagrangian (moverl_gym.constrained) on a small constrained problem whose constraint is active
(the multiplier ends above 0, the episode cost at the limit) and on one whose constraint is not (the multiplier stays 0
and PPO takes all the reward). The study's pure functions are tested on synthetic run folders."""

import csv
import dataclasses
import json
import math

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces

import moverl_gym  # noqa: F401  (registers the ids)
from moverl_gym import constrained_study as cs
from moverl_gym.bullet_backend import BulletBackend
from moverl_gym.constrained import PPOLagrangian, gae, lagrange_update
from moverl_gym.env import MoveRLReachEnv
from moverl_gym.paths import config_file
from moverl_gym.task import ReachTask, TaskConfig

pytestmark = pytest.mark.core


# -- the env's cost signal and contact penalty ----------------------------------------------------------------------
def test_contact_penalty_in_the_reward():
    cfg = TaskConfig.from_yaml(config_file("env.yaml"), contact_penalty=-5.0)
    assert TaskConfig.from_yaml(config_file("env.yaml")).contact_penalty == 0.0  # the paper's reward by default
    task = ReachTask(cfg, [0.4, 0.2, 0.2])
    base = task.reward(0.5, 0.4, discarded=False)
    assert task.reward(0.5, 0.4, discarded=False, contacts=3) == pytest.approx(base - 5.0)
    assert task.reward(0.5, 0.4, discarded=False, contacts=0) == base
    assert task.reward(0.5, 0.4, discarded=False, contacts=-1) == base  # unknown: no penalty
    assert task.reward(0.5, 0.4, discarded=True, contacts=1) == pytest.approx(base - 1.0 - 5.0)


def _rollout(env, actions, seed):
    env.reset(seed=seed)
    out = []
    for a in actions:
        _, reward, terminated, truncated, info = env.step(a)
        out.append((reward, info))
        if terminated or truncated:
            env.reset()
    return out


def test_cost_contact_is_the_ground_truth_and_the_penalty_is_applied_at_contact():
    actions = np.random.default_rng(5).uniform(-1, 1, (300, 7)).astype(np.float32)
    runs = []
    for penalty in (0.0, -5.0):
        env = gym.make("MoveRL/PandaReachCase-v0", backend="bullet", shield=False, task={"contact_penalty": penalty})
        try:
            runs.append(_rollout(env, actions, seed=2))
        finally:
            env.close()
    touched = 0
    for (r0, i0), (r1, i1) in zip(*runs):
        assert i0["contacts"] == i1["contacts"]  # the same motion: the penalty changes only the reward
        assert i0["cost_contact"] == (1.0 if i0["contacts"] > 0 else 0.0)
        assert i0["cost"] == i0["cost_contact"]  # no shield: nothing is discarded
        assert r1 == pytest.approx(r0 - 5.0 * (i0["contacts"] > 0))
        touched += i0["contacts"] > 0
    assert 0 < touched < len(actions)


class _NoGroundTruth(BulletBackend):
    """The PyBullet backend reporting contacts as a real robot's driver does: unknown (-1). It keeps the truth."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.truth = []

    def step(self, target, duration):
        res = super().step(target, duration)
        self.truth.append(res.contacts)
        return dataclasses.replace(res, contacts=-1, contact_substeps=-1)


def test_unknown_contacts_give_no_cost_contact_and_no_penalty():
    actions = np.random.default_rng(5).uniform(-1, 1, (300, 7)).astype(np.float32)
    rewards, backends = [], []
    for penalty in (0.0, -5.0):
        backends.append(_NoGroundTruth("case"))
        env = MoveRLReachEnv("case", shield=False, backend=backends[-1], task={"contact_penalty": penalty})
        try:
            steps = _rollout(env, actions, seed=2)
        finally:
            env.close()
        for _, info in steps:
            assert info["contacts"] == -1 and "cost_contact" not in info and info["cost"] == 0.0
        rewards.append([r for r, _ in steps])
    assert any(c > 0 for c in backends[0].truth)  # the arm did touch: the penalty would have applied
    assert rewards[0] == rewards[1]


def test_goal_ids_refuse_a_contact_penalty():
    with pytest.raises(ValueError, match="contact_penalty"):
        gym.make("MoveRL/PandaReachTableGoal-v0", backend="bullet", shield=False, task={"contact_penalty": -1.0})


# -- PPO-Lagrangian -------------------------------------------------------------------------------------------------
class Toy(gym.Env):
    """A constrained problem with an active constraint: 10-step episodes (time-limit truncation), reward a, cost 1
    when a > 0. Unconstrained, the best policy pushes a to 1 (cost 10 per episode); with cost limit d it keeps a > 0 on
    d of the 10 steps on average."""

    observation_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
    action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.zeros(1, np.float32), {}

    def step(self, action):
        a = float(np.clip(action[0], -1.0, 1.0))
        self.t += 1
        return np.zeros(1, np.float32), a, False, self.t >= 10, {"cost_contact": float(a > 0)}


def _train(cost_limit, steps=8000, **kwargs):
    model = PPOLagrangian(
        "MlpPolicy",
        Toy(),
        cost_limit=cost_limit,
        lagrange_lr=0.1,
        n_steps=200,
        batch_size=100,
        learning_rate=3e-3,
        seed=0,
        device="cpu",
        **kwargs,
    )
    model.learn(steps)
    costs = np.array([x["episode_cost"] for x in model.lagrange_log])
    return model, costs


def test_ppo_lagrangian_holds_an_active_constraint_at_its_limit():
    th.set_num_threads(1)
    model, costs = _train(cost_limit=2.0)
    last = costs[-len(costs) // 3 :]
    assert costs[:3].mean() > 4  # it starts well above the limit (random policy: 5 per episode)
    assert model.multiplier > 0.1  # the constraint is active: the multiplier is still pushing at the end
    assert abs(np.nanmean(last) - 2.0) < 0.75, f"episode cost over the last third {np.nanmean(last):.2f}, limit 2"
    assert all(x["multiplier"] >= 0 for x in model.lagrange_log)


def test_ppo_lagrangian_with_an_inactive_constraint_is_ppo():
    th.set_num_threads(1)
    model, costs = _train(cost_limit=10.0)  # 10 per episode can never be exceeded
    assert model.multiplier == 0.0 and all(x["multiplier"] == 0.0 for x in model.lagrange_log)
    assert np.nanmean(costs[-len(costs) // 3 :]) > 9.0  # all the reward, whatever the cost


def test_gae_is_sb3s():
    from stable_baselines3.common.buffers import RolloutBuffer

    rng = np.random.default_rng(0)
    steps, envs = 7, 3
    buf = RolloutBuffer(steps, spaces.Box(-1, 1, (2,)), spaces.Box(-1, 1, (1,)), gamma=0.9, gae_lambda=0.8, n_envs=envs)
    rewards, values = rng.normal(size=(steps, envs)), rng.normal(size=(steps, envs))
    starts = (rng.random((steps, envs)) < 0.3).astype(np.float32)
    for t in range(steps):
        buf.add(
            np.zeros((envs, 2)),
            np.zeros((envs, 1)),
            rewards[t],
            starts[t],
            th.as_tensor(values[t]),
            th.zeros(envs),
        )
    last, dones = rng.normal(size=envs), np.array([True, False, True])
    buf.compute_returns_and_advantage(th.as_tensor(last), dones)
    adv, ret = gae(rewards.astype(np.float32), values.astype(np.float32), starts, last, dones, 0.9, 0.8)
    np.testing.assert_allclose(adv, buf.advantages, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(ret, buf.returns, rtol=1e-5, atol=1e-6)


def test_lagrange_update_is_projected_ascent():
    assert lagrange_update(0.0, 3.0, 1.0, 0.1) == pytest.approx(0.2)
    assert lagrange_update(0.5, 0.0, 1.0, 0.1) == pytest.approx(0.4)
    assert lagrange_update(0.05, 0.0, 1.0, 0.1) == 0.0  # never below 0


def test_ppo_lagrangian_refuses_an_unknown_cost_and_saves_its_state(tmp_path):
    class Unknown(Toy):
        def step(self, action):
            obs, r, term, trunc, info = super().step(action)
            return obs, r, term, trunc, {"cost_contact": float("nan")}

    with pytest.raises(ValueError, match="unknown"):
        PPOLagrangian("MlpPolicy", Unknown(), n_steps=20, batch_size=20, device="cpu").learn(20)
    with pytest.raises(ValueError):
        PPOLagrangian("MlpPolicy", Toy(), cost_limit=-1.0, device="cpu")
    model, _ = _train(cost_limit=2.0, steps=400)
    model.save(tmp_path / "m")
    back = PPOLagrangian.load(tmp_path / "m.zip", device="cpu")
    assert back.multiplier == model.multiplier and back.cost_limit == 2.0 and len(back.lagrange_log) == 2
    x = np.zeros((1, 1), np.float32)
    np.testing.assert_allclose(back._cost_values(x), model._cost_values(x))


# -- the study's pure functions -------------------------------------------------------------------------------------
def _make_run(root, method, world, seed, success, contacts, value=None, evals=None, wall=100.0, length=20):
    folder = root / cs.run_name(method, world, seed, value)
    folder.mkdir(parents=True)
    with open(folder / "episodes.csv", "w", newline="") as f:
        w = csv.DictWriter(
            f, fieldnames=["episode", "timesteps", "success", "contacts", "cost_contact", "interventions"]
        )
        w.writeheader()
        for i, (s, c) in enumerate(zip(success, contacts)):
            w.writerow(dict(episode=i + 1, timesteps=(i + 1) * length, success=s, contacts=c, cost_contact=min(c, 1)))
    for mode, (succ, cont) in (evals or {}).items():
        with open(folder / f"eval_{mode}.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=cs.EVAL_FIELDS)
            w.writeheader()
            for i, (s, c) in enumerate(zip(succ, cont)):
                w.writerow(dict(episode=i, seed=i, success=s, length=10, contacts=c, contact_steps=min(c, 1)))
    (folder / "summary.json").write_text(json.dumps({"wall_time": wall, "steps_per_second": 1000 / wall}))
    return folder


def test_names_and_the_tuning_rule():
    assert cs.run_name("ppolag_d1", "case", 3) == "ppolag_d1_case_s3"
    assert cs.parse_run_name("ppolag_d1_case_s3") == dict(method="ppolag_d1", world="case", seed=3, value=None)
    assert cs.parse_run_name(cs.run_name("ppo_shield", "table", 100, -0.5))["value"] == -0.5
    assert cs.parse_run_name(cs.run_name("ppolag_d0", "table", 100, 0.01))["value"] == 0.01
    assert cs.parse_run_name("ppo_PandaReachTable-v0_on_s0") is None
    with pytest.raises(ValueError):
        cs.run_name("sac", "table", 0)
    # best success wins; within 5 points of it, the fewest contacts
    assert cs.select_value({1: dict(success=0.9, contacts=10), 2: dict(success=0.7, contacts=0)}) == 1
    assert cs.select_value({1: dict(success=0.9, contacts=10), 2: dict(success=0.88, contacts=3)}) == 2
    assert cs.select_value({1: dict(success=0.9, contacts=3), 2: dict(success=0.9, contacts=3)}) == 1


def test_statistics():
    m, h, n = cs.mean_ci([1.0, 2.0, 3.0])
    assert (m, n) == (2.0, 3) and h == pytest.approx(4.303 * 1.0 / math.sqrt(3), rel=1e-3)  # t(0.975, 2) = 4.303
    m, h, n = cs.mean_ci([5.0, math.nan])
    assert (m, n) == (5.0, 1) and math.isnan(h)
    assert cs.mean_ci([math.nan])[2] == 0
    c = cs.cumulative_on_grid([10, 20, 30], [1, 0, 2], [0, 10, 15, 30, 31])
    np.testing.assert_allclose(c[:4], [0, 1, 1, 3])
    assert math.isnan(c[4])


def test_summaries_tables_and_figures(tmp_path):
    for seed in (0, 1):
        _make_run(tmp_path, "ppo_shield", "table", seed, [0, 1, 1, 1], [0] * 4, evals={"on": ([1, 1], [0, 0])})
        _make_run(
            tmp_path,
            "ppolag_d0",
            "table",
            seed,
            [0, 0, 1, 1],
            [5, 3, 0, 0],
            evals={"on": ([1, 0], [0, 0]), "off": ([1, 1], [2, 0])},
        )
    _make_run(tmp_path, "ppo_penalty", "table", 100, [1], [1], value=-5.0)  # a tuning run: not in the tables
    (tmp_path / "logs").mkdir()
    runs = cs.load_runs(tmp_path)
    assert [r.method for r in runs] == ["ppo_shield", "ppo_shield", "ppo_penalty", "ppolag_d0", "ppolag_d0"]
    rows = cs.summarize(runs, last=2)
    assert [(r["method"], r["n_runs"]) for r in rows] == [("ppo_shield", 2), ("ppolag_d0", 2)]
    lag = rows[1]
    assert lag["success_mean"] == 1.0 and lag["train_contacts_mean"] == 8 and lag["train_contact_steps_mean"] == 2
    assert lag["eval_mode"] == "off" and lag["eval_contacts_mean"] == 2 and lag["eval_success_mean"] == 1.0
    two = cs.summarize_2x2(runs)
    assert [(r["method"], r["deployed_with_shield"]) for r in two] == [
        ("ppo_shield", True),
        ("ppolag_d0", True),
        ("ppolag_d0", False),
    ]
    assert two[2]["contacts_per_episode_mean"] == 1.0 and two[2]["runs_with_contacts"] == 2
    assert two[1]["success_mean"] == 0.5
    assert "| table | PPO + shield (ours) | 2 | 100.0 ± 0.0 % | 0 ± 0 |" in cs.markdown_table(rows, last=2)
    assert cs.markdown_2x2(two).count("\n") == 5
    cs.write_csv(rows, tmp_path / "docs" / "results.csv")
    assert list(csv.DictReader(open(tmp_path / "docs" / "results.csv")))[1]["train_contacts_mean"] == "8"
    cs.curves_csv(runs, tmp_path / "docs" / "curves.csv", points=5)
    curves = list(csv.DictReader(open(tmp_path / "docs" / "curves.csv")))
    assert len(curves) == 4 * 5 and curves[-1]["cumulative_contacts"] == "8"
    p = cs.plot_world(runs, "table", tmp_path / "docs" / "fig_table.png", window=2)
    assert p.stat().st_size > 10000
    assert cs.lagrange_curves(runs, tmp_path / "docs" / "lagrange.png").exists()
    assert "ppolag_d0_table_s1" in cs.markdown_runs(cs.per_run_rows(runs))
