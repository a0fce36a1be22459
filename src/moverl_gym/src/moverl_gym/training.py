"""Training helpers (RL Zoo style): hyper-parameters from YAML keyed by env id, an episode logger callback."""

from __future__ import annotations

import csv
import time
from collections import Counter
from pathlib import Path

import numpy as np
import yaml
from stable_baselines3.common.callbacks import BaseCallback

from .env import DISCARDED_COUNTERS

HYPERPARAMS_DIR = Path(__file__).resolve().parents[2] / "config" / "hyperparams"
EPISODE_FIELDS = [
    "episode",
    "env",
    "timesteps",
    "return",
    "length",
    "success",
    "interventions",
    *DISCARDED_COUNTERS,
    "replanned",
    "contacts",
    "contacts_moving",
    "contacts_resting",
    "contact_substeps",
    "cost",
    "cost_contact",
    "wall_time",
    "truncated",
    "graph_failure",
    "graph_restarts",
]


def load_hyperparams(algo: str, env_id: str, path: Path | None = None) -> dict:
    """Hyper-parameters for algo on env_id: the env's entry, else "default". Raises ValueError if neither."""
    path = path or HYPERPARAMS_DIR / f"{algo}.yml"
    if not path.exists():
        raise ValueError(f"no hyper-parameter file {path} for algorithm '{algo}'")
    with open(path) as f:
        table = yaml.safe_load(f) or {}
    params = table.get(env_id, table.get("default"))
    if params is None:
        raise ValueError(f"{path} has no entry for {env_id} and no 'default'")
    return dict(params)


class EpisodeLogger(BaseCallback):
    """Per-episode return, length, success, shield interventions by type and ground-truth contacts.

    Written as CSV rows (episodes.csv) and as TensorBoard scalars; totals kept for the final summary. With a vectorised
    env (train.py --n-envs N) every sub-env has its own running counters: a row's `env` column is the index of the
    sub-env (its own process and graph) the episode ran in, `timesteps` the total over all sub-envs when it ended, and
    `graph_restarts` that sub-env's relaunches so far (the summary adds up the last value of every sub-env, and so for
    graph failures, which include those a reset found between episodes).
    """

    def __init__(self, csv_path: Path, verbose: int = 0):
        super().__init__(verbose)
        self.csv_path = Path(csv_path)
        self.rows: list[dict] = []
        self.totals = Counter()
        self.failures: list[str] = []  # what failed, for every episode a graph failure ended
        self.restarts: dict[int, int] = {}  # sub-env index -> its graph relaunches so far
        self.failure_counts: dict[int, int] = {}  # sub-env index -> its graph failures so far (steps and resets)
        self._t0 = time.perf_counter()

    def _on_training_start(self) -> None:
        n = self.training_env.num_envs
        self._ep = [Counter() for _ in range(n)]
        self._file = open(self.csv_path, "w", newline="")
        self._writer = csv.DictWriter(self._file, fieldnames=EPISODE_FIELDS)
        self._writer.writeheader()
        self._t0 = time.perf_counter()

    def _on_step(self) -> bool:
        infos, rewards, dones = self.locals["infos"], self.locals["rewards"], self.locals["dones"]
        for i, info in enumerate(infos):
            ep = self._ep[i]
            ep["return"] += float(rewards[i])
            ep["length"] += 1
            verdict = info.get("verdict", "")
            if verdict.startswith("discarded") or verdict in ("replanned", "truncated"):
                ep[verdict] += 1
            if info.get("discarded"):
                ep["interventions"] += 1
            ep["contacts"] += max(info.get("contacts", 0), 0)
            ep["contacts_moving"] += max(info.get("contacts_moving", 0), 0)  # who moved (ground truth)
            ep["contacts_resting"] += max(info.get("contacts_resting", 0), 0)
            ep["contact_substeps"] += max(info.get("contact_substeps", 0), 0)
            ep["cost"] += info.get("cost", 0.0)
            ep["cost_contact"] += info.get("cost_contact", 0.0)  # steps with contact; NaN if the driver cannot tell
            ep["graph_restarts"] = info.get("graph_restarts", 0)  # relaunches so far (env recovery)
            if verdict == "graph_failed":  # this episode ended because the graph failed
                ep["graph_failure"] = 1
                self.failures.append(info.get("graph_failure", ""))
            self.restarts[i] = int(ep["graph_restarts"])
            self.failure_counts[i] = int(info.get("graph_failures", 0))
            if dones[i]:
                ep["success"] = int(bool(info.get("is_success", False)))
                self._finish(ep, i)
                self._ep[i] = Counter()
        return True

    def _finish(self, ep: Counter, env_index: int) -> None:
        row = {k: ep.get(k, 0) for k in EPISODE_FIELDS}
        row.update(
            episode=len(self.rows) + 1,
            env=env_index,
            timesteps=self.num_timesteps,
            wall_time=round(time.perf_counter() - self._t0, 3),
            **{"return": round(ep["return"], 4)},
        )
        self.rows.append(row)
        self._writer.writerow(row)
        self._file.flush()
        for key in (
            "interventions",
            "replanned",
            "truncated",
            "contacts",
            "contacts_moving",
            "contacts_resting",
            "contact_substeps",
            "cost",
            "cost_contact",
            *DISCARDED_COUNTERS,
        ):
            self.totals[key] += row[key]
        for key in ("return", "length", "success", "interventions", "contacts", "cost", "graph_restarts"):
            self.logger.record(f"episode/{key}", float(row[key]))

    def _on_training_end(self) -> None:
        self._file.close()

    def summary(self, last: int = 200) -> dict:
        rows = self.rows[-last:]
        elapsed = time.perf_counter() - self._t0
        return {
            "episodes": len(self.rows),
            "success_rate_last": float(np.mean([r["success"] for r in rows])) if rows else float("nan"),
            "last_n": len(rows),
            "interventions": int(self.totals["interventions"]),
            "replanned": int(self.totals["replanned"]),
            "truncated": int(self.totals["truncated"]),
            "by_type": {k: int(self.totals[k]) for k in DISCARDED_COUNTERS},
            "contacts": int(self.totals["contacts"]),
            "contacts_moving": int(self.totals["contacts_moving"]),
            "contacts_resting": int(self.totals["contacts_resting"]),
            "contact_substeps": int(self.totals["contact_substeps"]),
            "graph_failures": int(sum(self.failure_counts.values())),  # incl. those a reset found between episodes
            "graph_restarts": int(sum(self.restarts.values())),
            "failures": self.failures,
            "steps_per_second": self.num_timesteps / elapsed if elapsed > 0 else float("nan"),
            "wall_time": elapsed,
        }


def recording_env(env_id: str, kwargs: dict, folder: Path, episodes: int, name_prefix: str = "eval"):
    """gym.make(env_id, render_mode="rgb_array", **kwargs) wrapped in Gymnasium's RecordVideo: the first `episodes`
    episodes are written to folder as mp4 (moviepy); later ones are not recorded."""
    import gymnasium as gym
    from gymnasium.wrappers import RecordVideo

    return RecordVideo(
        gym.make(env_id, render_mode="rgb_array", **kwargs),
        str(folder),
        episode_trigger=lambda episode: episode < episodes,
        name_prefix=name_prefix,
        disable_logger=True,
    )


def record_episodes(model, env_id: str, kwargs: dict, folder: Path, episodes: int, seed: int) -> None:
    """`episodes` episodes of a trained policy (deterministic actions), recorded to folder by Gymnasium's RecordVideo.

    Args:
        model: anything with SB3's predict(obs, deterministic=...) -> (action, state), such as an SB3 model, or a
            function of the env's action space that returns one (moverl_gym.rllib.CheckpointPolicy for an RLlib
            checkpoint).
        env_id, kwargs: the env, as gym.make takes them (a fresh env with render_mode="rgb_array").
        seed: episode i starts from reset(seed=seed + i).
    """
    env = recording_env(env_id, kwargs, folder, episodes)
    try:
        if not hasattr(model, "predict"):
            model = model(env.action_space)
        for episode in range(episodes):
            obs, _ = env.reset(seed=seed + episode)
            done = False
            while not done:
                action, _ = model.predict(obs, deterministic=True)
                obs, _, terminated, truncated, _ = env.step(action)
                done = terminated or truncated
    finally:
        env.close()
