"""MoveRL on Ray RLlib (new API stack): the env creator, the safety metrics, a local Ray cluster of its own, and a
policy loaded back from a checkpoint. Used by scripts/rllib_train.py, scripts/evaluate.py and tools/scaling.py.

One env per env runner: every RLlib env runner is its own Ray worker process, rospy allows one ROS master per
process, so each runner holds exactly one env (num_envs_per_env_runner=1, "sync" vectorisation: the env lives in the
runner's process, no throw-away copy in a parent) and that env launches its own graph on a free port (never a port
derived from a worker or vector index: indices repeat across runs, restarts and nodes).

Which layer handles which failure:
* A component of a runner's graph fails (the simulator dies, a node stalls past its deadline): the env's own recovery
  (gym.make(id, recover=...), on by default with the launched simulator) ends the episode (verdict "graph_failed")
  and relaunches the graph at the next reset, inside the same runner process: counted in
  env_runners/moverl/graph_failures and graph_restarts.
* The runner's process dies (killed, out of memory, its node lost): Ray restarts the actor and RLlib brings it back
  (fault_tolerance(restart_failed_env_runners=True)); the dead process's graph is stopped by its reaper (the lifeline
  from the dead process closes) and the new process launches a new one: counted in moverl/env_runner_restarts.
* The env gives up (recovery off, as with a real robot, or max_graph_restarts relaunches in a row that each failed
  quickly): the error propagates out of sample(), RLlib takes the runner out of service; once
  num_consecutive_env_runner_failures_tolerance failures follow each other the run stops with the error.
  RLlib's restart_failed_sub_environments is left off: it would re-create the env after every error, an unbounded
  relaunch loop that the env's bounded recovery exists to prevent.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
import uuid
from pathlib import Path

import gymnasium as gym

from .env import DISCARDED_COUNTERS

#: The name the env creator is registered under with Ray Tune's registry.
ENV_NAME = "moverl"
#: Counters summed over every runner and kept over the whole run (and across a resume): result key
#: env_runners/moverl/<name>.
LIFETIME_COUNTERS = (
    "contacts",
    "contacts_moving",
    "contacts_resting",
    "contact_substeps",
    "cost",
    "interventions",
    *DISCARDED_COUNTERS,
    "replanned",
    "truncated",
    "graph_failures",
    "graph_restarts",
    "steps_without_ground_truth",
    "envs_created",
)
_VERDICT_COUNTERS = (*DISCARDED_COUNTERS, "replanned", "truncated")


def env_creator(env_config: dict) -> gym.Env:
    """Build one MoveRL env from RLlib's env_config: {"env_id": ..., plus keyword arguments of gym.make}."""
    import moverl_gym  # noqa: F401  (registers the env ids in this worker process)

    cfg = dict(env_config)
    env_id = cfg.pop("env_id")
    cfg.pop("num_envs", None)  # RLlib adds it for vector entry points; one env per runner here
    return gym.make(env_id, **cfg)


def register() -> None:
    """Register env_creator as ENV_NAME (in the driver; Ray ships it to the workers)."""
    from ray.tune.registry import register_env

    register_env(ENV_NAME, env_creator)


def metrics_callback():
    """The RLlibCallback class that logs MoveRL's safety metrics (imported lazily: ray is only needed here)."""
    from ray.rllib.callbacks.callbacks import RLlibCallback

    class MoveRLMetrics(RLlibCallback):
        """Ground-truth contacts, cost, shield interventions by type, success, graph failures and relaunches (the env's
        recovery) from the env's info, summed over all runners for the whole run; env runner restarts (RLlib's fault
        tolerance) from the algorithm. Steps are counted only when something happened (a contact, an intervention):
        the hot path stays a dictionary lookup."""

        def on_environment_created(self, *, env_runner, metrics_logger, env, env_context, **kwargs):
            for name in LIFETIME_COUNTERS:  # every key present from the start, zero included
                metrics_logger.log_value(("moverl", name), 0, reduce="lifetime_sum")
            metrics_logger.log_value(("moverl", "envs_created"), 1, reduce="lifetime_sum")

        def on_episode_start(self, *, episode, metrics_logger, **kwargs):
            info = episode.get_infos(-1)
            if info.get("graph_restart"):  # this reset relaunched the graph (env recovery)
                metrics_logger.log_value(("moverl", "graph_restarts"), 1, reduce="lifetime_sum")
            if info.get("graph_failure"):  # this reset found the graph failed (between episodes)
                metrics_logger.log_value(("moverl", "graph_failures"), 1, reduce="lifetime_sum")

        def on_episode_step(self, *, episode, metrics_logger, **kwargs):
            info = episode.get_infos(-1)
            log = metrics_logger.log_value
            contacts = info.get("contacts", 0)
            if contacts:
                if contacts < 0:  # the driver has no ground truth (a real robot)
                    log(("moverl", "steps_without_ground_truth"), 1, reduce="lifetime_sum")
                else:
                    log(("moverl", "contacts"), contacts, reduce="lifetime_sum")
                    log(("moverl", "contacts_moving"), max(info.get("contacts_moving", 0), 0), reduce="lifetime_sum")
                    log(("moverl", "contacts_resting"), max(info.get("contacts_resting", 0), 0), reduce="lifetime_sum")
                    log(("moverl", "contact_substeps"), max(info.get("contact_substeps", 0), 0), reduce="lifetime_sum")
            if info.get("cost"):
                log(("moverl", "cost"), info["cost"], reduce="lifetime_sum")
            if info.get("discarded"):
                log(("moverl", "interventions"), 1, reduce="lifetime_sum")
            verdict = info.get("verdict")
            if verdict in _VERDICT_COUNTERS:
                log(("moverl", verdict), 1, reduce="lifetime_sum")
            elif verdict == "graph_failed":
                log(("moverl", "graph_failures"), 1, reduce="lifetime_sum")

        def on_episode_end(self, *, episode, metrics_logger, **kwargs):
            info = episode.get_infos(-1)
            metrics_logger.log_value(
                ("moverl", "success_rate"), float(bool(info.get("is_success", False))), reduce="mean", window=100
            )

        def on_train_result(self, *, algorithm, result, **kwargs):
            group = algorithm.env_runner_group
            result.setdefault("moverl", {}).update(
                env_runner_restarts=int(group.num_remote_worker_restarts()),
                healthy_env_runners=int(group.num_healthy_remote_workers()),
            )

    return MoveRLMetrics


class LocalCluster:
    """A Ray cluster of our own on this machine, and this process connected to it as the driver.

    `nodes` Ray nodes (the first is the head), all on 127.0.0.1 with ports the OS picks free, in a temp dir of their
    own, started by a host process (moverl_gym/raycluster.py, whose docstring says why) under a moverl_gym reaper:
    shutdown() returns when every process of the cluster is gone (GraphError naming any left), and the reaper stops
    them all if this process dies in any way. Several nodes on one host are a real multi-node cluster to Ray (a
    raylet, an object store and a scheduler each; objects move between nodes over TCP), but on loopback: it measures
    no network.

    Args:
        nodes: resources per node, e.g. [{"num_cpus": 0}, {"num_cpus": 1}, {"num_cpus": 1}] (head first).
        object_store_memory: bytes of object store per node.
        timeout: seconds for the cluster to come up.
        grace: seconds Ray gets to shut down cleanly before SIGKILL.
    """

    def __init__(
        self,
        nodes: list[dict],
        object_store_memory: int = 200 * 1024 * 1024,
        timeout: float = 120.0,
        grace: float = 10.0,
    ):
        import sys

        from . import raycluster, reaper
        from .graph import GraphError

        self.cluster_id = uuid.uuid4().hex
        self.root = Path(tempfile.mkdtemp(prefix="moverl_ray_"))
        self.grace = grace
        self.last_shutdown: dict | None = None
        self._log = open(self.root / "cluster.log", "ab")
        address_file = self.root / "address"
        # Ray's session folder goes below temp_dir (its default below $RAY_TMPDIR, where it also writes its address
        # file), with unix sockets whose paths must fit in 107 bytes: keep $TMPDIR short.
        spec = {
            "nodes": nodes,
            "temp_dir": str(self.root / "ray"),
            "address_file": str(address_file),
            "object_store_memory": object_store_memory,
        }
        (self.root / "ray").mkdir()
        env = dict(os.environ)
        env[reaper.MARKER] = self.cluster_id
        env["RAY_TMPDIR"] = str(self.root)
        env[raycluster.LOOPBACK_SWITCH] = "0"
        self._reaper = reaper.Handle(
            {
                "owner": os.getpid(),
                "log": str(self.root / "cluster.log"),
                "grace": grace,
                "kill_timeout": 5.0,
                "master": None,
                "launch": [sys.executable, raycluster.__file__, json.dumps(spec)],
            },
            env,
            self._log,
        )
        deadline = time.monotonic() + timeout
        try:
            while not address_file.exists():
                for event in self._reaper.poll(0.2):
                    if event[0] in ("exit", "error"):
                        raise GraphError(f"the Ray cluster did not start ({' '.join(event)}):\n{self.log_tail()}")
                if self._reaper.ended or time.monotonic() > deadline:
                    raise GraphError(f"the Ray cluster did not start within {timeout:.0f} s:\n{self.log_tail()}")
            self.address = address_file.read_text().strip()
            # This process connects as the driver: it needs the same switch (read by ray at import time, hence set
            # on the imported module too) and the same temp dir.
            os.environ["RAY_TMPDIR"] = str(self.root)
            os.environ[raycluster.LOOPBACK_SWITCH] = "0"
            import ray
            import ray._private.ray_constants as ray_constants

            ray_constants.ENABLE_RAY_CLUSTER = False
            ray.init(address=self.address, _temp_dir=spec["temp_dir"], log_to_driver=True)
        except BaseException:
            self.shutdown()
            raise

    def log_tail(self, lines: int = 40) -> str:
        self._log.flush()
        return "\n".join((self.root / "cluster.log").read_text(errors="replace").splitlines()[-lines:])

    def processes(self):
        """Every running process of the cluster: the reaper's tree (GCS, raylets, agents, workers, their graphs)."""
        from .proctree import tree

        return tree(self._reaper.proc.pid) if self._reaper is not None else []

    def shutdown(self) -> None:
        """Disconnect, stop the cluster (the host shuts Ray down; the reaper stops whatever is left) and return when
        every process of it is gone; remove the temp dir. Raises GraphError naming processes that survived SIGKILL."""
        import ray

        from .graph import GraphError

        t0 = time.monotonic()
        try:
            ray.shutdown()
        finally:
            r, self._reaper = self._reaper, None
            if r is not None:
                r.stop(time.monotonic() + self.grace + 20.0)
                self.last_shutdown = {
                    "seconds": time.monotonic() - t0,
                    "sigkilled": [" ".join(e[1:]) for e in r.events if e[0] == "killed"],
                    "left": [" ".join(e[1:]) for e in r.events if e[0] == "left"],
                }
            self._log.close()
            if not (self.last_shutdown or {}).get("left"):
                shutil.rmtree(self.root, ignore_errors=True)
        if self.last_shutdown and self.last_shutdown["left"]:
            raise GraphError(
                f"processes of the Ray cluster survived SIGKILL: {self.last_shutdown['left']} (log: "
                f"{self.root / 'cluster.log'})"
            )


def node_layout(num_env_runners: int, nodes: int) -> list[dict]:
    """Local nodes for a run: nodes == 1, one node with as many CPUs as the machine has (at least one per runner, so
    that every runner gets scheduled even when they oversubscribe the cores); nodes > 1, a head without CPUs (the
    driver and learner run in this process, outside Ray's accounting) and `nodes` worker nodes sharing the runners
    equally, so runners land on different nodes."""
    if nodes <= 1:
        return [{"num_cpus": max(os.cpu_count() or 1, num_env_runners)}]
    per_node = -(-num_env_runners // nodes)
    return [{"num_cpus": 0}] + [{"num_cpus": per_node} for _ in range(nodes)]


def is_checkpoint(path: Path) -> bool:
    """True for a directory an RLlib Algorithm was saved to (Algorithm.save_to_path)."""
    return path.is_dir() and (path / "algorithm_state.pkl").exists() and (path / "learner_group").is_dir()


class CheckpointPolicy:
    """The policy of an RLlib checkpoint, without Ray running: its RLModule restored from the checkpoint, actions from
    the action distribution (mean when deterministic), clipped to the action space as RLlib's env runner does."""

    def __init__(self, checkpoint: Path, action_space: gym.spaces.Box):
        import numpy as np
        from ray.rllib.core.rl_module.rl_module import RLModule

        module_dir = Path(checkpoint) / "learner_group" / "learner" / "rl_module" / "default_policy"
        if not module_dir.is_dir():
            raise FileNotFoundError(f"no RLModule in checkpoint {checkpoint} (expected {module_dir})")
        self.module = RLModule.from_checkpoint(module_dir)
        self.dist_cls = self.module.get_inference_action_dist_cls()
        self.low, self.high = np.asarray(action_space.low), np.asarray(action_space.high)

    def predict(self, obs, deterministic: bool = False):
        import numpy as np
        import torch

        with torch.no_grad():
            out = self.module.forward_inference({"obs": torch.as_tensor(np.asarray(obs)[None], dtype=torch.float32)})
            dist = self.dist_cls.from_logits(out["action_dist_inputs"])
            if deterministic:
                dist = dist.to_deterministic()
            action = dist.sample()[0].numpy()
        return np.clip(action, self.low, self.high), None
