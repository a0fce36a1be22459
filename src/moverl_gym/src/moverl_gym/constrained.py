"""PPO-Lagrangian on stable-baselines3's PPO, ROS-free: the smallest correct constrained agent for MoveRL.

The constrained MDP: maximise the expected return subject to J_c = E[sum of an episode's costs] <= cost_limit, with the
cost read from each step's info (MoveRL: info["cost_contact"], 1.0 for a step whose motion made contact). As in
OmniSafe's PPOLag (and Ray et al. 2019, Stooke et al. 2020), a Lagrange multiplier lambda >= 0 turns it into
max_pi min_lambda J_r - lambda (J_c - d):

* a separate cost critic V_c (an MLP like PPO's value net, its own Adam) is fitted to the discounted cost returns;
  cost advantages A_c come from GAE on the costs, with the reward's gamma and lambda, and the same bootstrapping of
  time-limit truncations from the terminal observation that SB3 applies to rewards;
* before each policy update, lambda <- max(0, lambda + lagrange_lr * (J_c - d)), J_c the mean cost of the episodes
  that ended since the previous update (no episode ended: lambda is kept);
* PPO's clipped objective then runs on the advantage (A_r - lambda A_c) / (1 + lambda), A_r standardised and A_c
  centred over the rollout as OmniSafe does (SB3's per-batch normalisation follows; it keeps the ratio of the two).

Everything else is SB3's PPO, unchanged (OmniSafe 0.5 itself cannot be installed next to MoveRL: docs/constrained.md).
A test on a small constrained problem (test_constrained.py) checks that the multiplier ends above 0 and the cost at
the limit when the constraint is active, and at 0 with plain PPO's behaviour when it is not.
"""

from __future__ import annotations

import math

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3 import PPO


def gae(
    rewards: np.ndarray,
    values: np.ndarray,
    episode_starts: np.ndarray,
    last_values: np.ndarray,
    dones: np.ndarray,
    gamma: float,
    gae_lambda: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Generalised advantage estimation over a rollout, as SB3's RolloutBuffer.compute_returns_and_advantage does it.

    Args:
        rewards: (steps, envs) rewards (here: costs), time-limit bootstraps already added.
        values: (steps, envs) value estimates of the observations the steps started from.
        episode_starts: (steps, envs) 1 where a step's observation was the first of an episode.
        last_values: (envs,) value of the observation after the last step.
        dones: (envs,) 1 where the last step ended its episode.
        gamma: discount.
        gae_lambda: GAE's lambda.

    Returns:
        (advantages, returns), each (steps, envs); returns = advantages + values.
    """
    steps = rewards.shape[0]
    adv = np.zeros_like(rewards, dtype=np.float32)
    last = np.zeros(rewards.shape[1:], dtype=np.float32)
    for t in reversed(range(steps)):
        if t == steps - 1:
            non_terminal, next_values = 1.0 - dones.astype(np.float32), last_values
        else:
            non_terminal, next_values = 1.0 - episode_starts[t + 1], values[t + 1]
        delta = rewards[t] + gamma * next_values * non_terminal - values[t]
        last = delta + gamma * gae_lambda * non_terminal * last
        adv[t] = last
    return adv, adv + values


def lagrange_update(multiplier: float, episode_cost: float, cost_limit: float, lr: float) -> float:
    """One projected gradient-ascent step of the multiplier on lambda (J_c - d): max(0, lambda + lr (J_c - d))."""
    return max(0.0, multiplier + lr * (episode_cost - cost_limit))


class PPOLagrangian(PPO):
    """SB3's PPO with a cost critic and a Lagrange multiplier (see the module).

    Args:
        policy: as PPO ("MlpPolicy"); Box observations only (the cost critic is an MLP on them, flattened).
        env: as PPO.
        cost_limit: d, the allowed expected cost per episode (sum over its steps); 0 asks for none.
        lagrange_lr: step size of the multiplier's update.
        lagrange_init: the multiplier's initial value (>= 0).
        cost_key: the info key each step's cost is read from. Missing or NaN (MoveRL: contacts unknown, as with a real
            robot's driver) raises: a constrained agent cannot learn from a cost it does not have.
        cost_net_arch: hidden layer sizes of the cost critic (PPO's default value net: 64, 64, tanh).
        **kwargs: PPO's arguments (learning_rate, n_steps, batch_size, n_epochs, gamma, gae_lambda, ...). The cost
            critic uses the same learning rate, epochs and batch size as the policy.

    Attributes:
        multiplier: the current lambda.
        lagrange_log: one dict per update: timesteps, multiplier (used in that update), episode_cost (J_c estimate,
            NaN if no episode ended), episodes (how many it is the mean of), cost_critic_loss.
    """

    def __init__(
        self,
        policy,
        env,
        cost_limit: float = 0.0,
        lagrange_lr: float = 0.035,
        lagrange_init: float = 0.0,
        cost_key: str = "cost_contact",
        cost_net_arch: tuple[int, ...] = (64, 64),
        **kwargs,
    ):
        if cost_limit < 0 or lagrange_lr <= 0 or lagrange_init < 0:
            raise ValueError(
                f"need cost_limit >= 0, lagrange_lr > 0, lagrange_init >= 0; got {cost_limit}, {lagrange_lr}, "
                f"{lagrange_init}"
            )
        self.cost_limit = float(cost_limit)
        self.lagrange_lr = float(lagrange_lr)
        self.multiplier = float(lagrange_init)
        self.cost_key = cost_key
        self.cost_net_arch = tuple(int(n) for n in cost_net_arch)
        self.lagrange_log: list[dict] = []
        super().__init__(policy, env, **kwargs)

    # -- set-up and saving -------------------------------------------------------------------------------------
    def _setup_model(self) -> None:
        super()._setup_model()
        if not isinstance(self.observation_space, spaces.Box):
            raise ValueError(f"PPOLagrangian takes Box observations, got {self.observation_space}")
        layers, size = [], int(np.prod(self.observation_space.shape))
        for width in self.cost_net_arch:
            layers += [th.nn.Linear(size, width), th.nn.Tanh()]
            size = width
        self.cost_critic = th.nn.Sequential(*layers, th.nn.Linear(size, 1)).to(self.device)
        self.cost_critic_optimizer = th.optim.Adam(self.cost_critic.parameters(), lr=self.lr_schedule(1.0))
        self._costs = np.zeros((self.n_steps, self.n_envs), dtype=np.float32)
        self._episode_costs = np.zeros(self.n_envs)  # running sum of each env's current episode
        self._finished_costs: list[float] = []  # costs of the episodes that ended since the last update

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        state_dicts, other = super()._get_torch_save_params()
        return [*state_dicts, "cost_critic", "cost_critic_optimizer"], other

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "cost_critic", "cost_critic_optimizer", "_costs"]

    # -- rollouts --------------------------------------------------------------------------------------------------
    def _cost_values(self, obs: np.ndarray) -> np.ndarray:
        with th.no_grad():
            x = th.as_tensor(np.asarray(obs, dtype=np.float32), device=self.device).reshape(len(obs), -1)
            return self.cost_critic(x).squeeze(-1).cpu().numpy()

    def _update_info_buffer(self, infos: list[dict], dones: np.ndarray | None = None) -> None:
        """Called by collect_rollouts once per vector step, before the step is added to the rollout buffer (at
        rollout_buffer.pos): the step's costs are recorded there."""
        super()._update_info_buffer(infos, dones)
        pos = self.rollout_buffer.pos
        for i, info in enumerate(infos):
            if self.cost_key not in info:
                raise KeyError(
                    f"PPOLagrangian: the env's info has no {self.cost_key!r} (MoveRL: a driver without contact ground "
                    f"truth; its keys: {sorted(info)})"
                )
            cost = float(info[self.cost_key])
            if not math.isfinite(cost):
                raise ValueError(
                    f"PPOLagrangian: info[{self.cost_key!r}] is {cost}: the cost is unknown (MoveRL: a driver without "
                    "contact ground truth); a constrained agent needs it"
                )
            self._episode_costs[i] += cost
            done = dones is not None and dones[i]
            if done:
                self._finished_costs.append(float(self._episode_costs[i]))
                self._episode_costs[i] = 0.0
                if info.get("TimeLimit.truncated", False) and info.get("terminal_observation") is not None:
                    cost += self.gamma * float(self._cost_values(info["terminal_observation"][None])[0])
            self._costs[pos, i] = cost

    # -- updates -------------------------------------------------------------------------------------------------
    def train(self) -> None:
        buf = self.rollout_buffer
        obs = buf.observations.reshape(self.n_steps * self.n_envs, -1)
        values_c = self._cost_values(obs).reshape(self.n_steps, self.n_envs)
        last_c = self._cost_values(self._last_obs)
        adv_c, ret_c = gae(
            self._costs,
            values_c,
            buf.episode_starts,
            last_c,
            np.asarray(self._last_episode_starts, dtype=np.float32),
            self.gamma,
            self.gae_lambda,
        )
        # The multiplier first (OmniSafe's order), from the episodes that ended since the last update.
        episodes = len(self._finished_costs)
        episode_cost = float(np.mean(self._finished_costs)) if episodes else math.nan
        if episodes:
            self.multiplier = lagrange_update(self.multiplier, episode_cost, self.cost_limit, self.lagrange_lr)
        self._finished_costs = []
        adv_r = buf.advantages
        adv_r = (adv_r - adv_r.mean()) / (adv_r.std() + 1e-8)
        adv_c = adv_c - adv_c.mean()
        buf.advantages = ((adv_r - self.multiplier * adv_c) / (1.0 + self.multiplier)).astype(np.float32)
        critic_loss = self._fit_cost_critic(obs, ret_c.reshape(-1))
        self.lagrange_log.append(
            dict(
                timesteps=self.num_timesteps,
                multiplier=self.multiplier,
                episode_cost=episode_cost,
                episodes=episodes,
                cost_critic_loss=critic_loss,
            )
        )
        self.logger.record("lagrange/multiplier", self.multiplier)
        self.logger.record("lagrange/episode_cost", episode_cost)
        self.logger.record("lagrange/cost_critic_loss", critic_loss)
        super().train()

    def _fit_cost_critic(self, obs: np.ndarray, returns: np.ndarray) -> float:
        """n_epochs passes of minibatch regression of V_c on the cost returns; the last minibatch's loss."""
        for group in self.cost_critic_optimizer.param_groups:
            group["lr"] = self.lr_schedule(self._current_progress_remaining)
        x = th.as_tensor(obs, dtype=th.float32, device=self.device)
        y = th.as_tensor(returns, dtype=th.float32, device=self.device)
        n = len(x)
        loss = th.zeros(())
        for _ in range(self.n_epochs):
            order = th.randperm(n, device=self.device)
            for start in range(0, n, self.batch_size):
                idx = order[start : start + self.batch_size]
                loss = th.nn.functional.mse_loss(self.cost_critic(x[idx]).squeeze(-1), y[idx])
                self.cost_critic_optimizer.zero_grad()
                loss.backward()
                th.nn.utils.clip_grad_norm_(self.cost_critic.parameters(), self.max_grad_norm)
                self.cost_critic_optimizer.step()
        return float(loss.detach())
