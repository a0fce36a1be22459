"""MoveRL reach env: a Gymnasium env whose every action passes the safety shield of a live ROS graph.

Paper sections 4.2-4.6. Action: Box[-1, 1]^n, scaled to delta q within +-dt * qdot_limit, clipped to the
joint limits (ActionScaler). Observation: joint angles (obs_type="joints") and/or the end-effector pose,
the goal, and the pose of every observed obstacle (7 numbers each). Reward: ReachTask. Each episode starts
at a random collision-free configuration; it terminates at the goal and is truncated after
max_episode_steps (by the TimeLimit wrapper that gym.make adds).
"""

from __future__ import annotations

import math
import os
import time

import gymnasium as gym
import numpy as np

from . import backend as ros
from .graph import GraphError, LaunchedGraph, master_alive, service_exists
from .paths import config_file, world_file
from .robot import ActionScaler, JointLimits
from .task import ReachTask, TaskConfig

#: Shield verdicts (moverl_msgs/ShieldStep) by code.
VERDICTS = {0: "safe", 1: "replanned", 2: "discarded_self", 3: "discarded_pose", 4: "discarded_path",
            5: "discarded_start", 6: "unchecked", 7: "truncated", 10: "invalid_request",
            11: "scene_unavailable", 12: "execution_failed"}
#: The collision the shield found (and prevented or avoided) for each verdict.
#: For 7 (truncated, strategy last_safe) it depends on the step: see _collision_type (unsafe_cause).
COLLISION_TYPES = {1: "path", 2: "self", 3: "pose", 4: "path", 5: "start", 7: "path"}
#: ShieldStep.unsafe_cause codes (ValidateMotion outcomes) -> collision type.
UNSAFE_CAUSES = {1: "self", 2: "pose", 3: "path", 4: "start"}
#: Verdicts that count as discarded (the action was unsafe: the agent gets safety_penalty). A truncated step
#: (strategy last_safe) moved only along the safe part of the unsafe action: it counts too.
DISCARDED = frozenset({2, 3, 4, 5, 7})
FAILURES = frozenset({10, 11, 12})
OBS_TYPES = ("joints", "ee")


class MoveRLError(RuntimeError):
    """The shield or the driver failed: the robot did not move and the env cannot go on."""


def _collision_type(verdict: int, res) -> "str | None":
    """The collision the shield found for this step (None when none): from the verdict, and for a truncated
    step from the response's unsafe_cause (self, pose or path), else "path"."""
    if verdict == 7:
        return UNSAFE_CAUSES.get(getattr(res, "unsafe_cause", 0), "path")
    return COLLISION_TYPES.get(verdict)


class MoveRLReachEnv(gym.Env):
    """Reach a goal with the end effector, every action checked by the shield.

    Args:
        world: world name (worlds/<world>.yaml) or path, when the env launches its own graph.
        obs_type: "joints" (joint angles + ee pose + goal + obstacles) or "ee" (ee pose + goal + obstacles).
        shield: shield on (True) or the unchecked baseline (False).
        graph: "auto" (attach to $ROS_MASTER_URI if it serves MoveRL, else launch), "attach" or "launch".
        robot: robot config name (config/robots/<robot>.yaml) for a launched graph.
        goal: override the world's goal [x, y, z].
        launch_args: extra roslaunch arguments (gui, mode, ...).
        task: overrides of config/env.yaml (dt, kappa, ...).
    """

    metadata = {"render_modes": []}

    def __init__(self, world: str = "table", obs_type: str = "joints", shield: bool = True, graph: str = "auto",
                 robot: str = "panda", goal=None, launch_args: dict | None = None, task: dict | None = None,
                 render_mode=None):
        if obs_type not in OBS_TYPES:
            raise ValueError(f"obs_type must be one of {OBS_TYPES}, got {obs_type!r}")
        if graph not in ("auto", "attach", "launch"):
            raise ValueError(f"graph must be 'auto', 'attach' or 'launch', got {graph!r}")
        if render_mode is not None:
            raise ValueError("rendering is done by the simulator (launch with gui:=true), not by the env")
        self.obs_type = obs_type
        self.config = TaskConfig.from_yaml(config_file("env.yaml"), **(task or {}))
        self._graph = None
        self._backend = None
        try:
            self._connect(graph, dict(world=world, robot=robot, shield=shield, **(launch_args or {})))
            self._setup(world, shield, goal)
        except BaseException:
            self.close()
            raise

    # -- graph ---------------------------------------------------------------------------------------------
    def _connect(self, graph: str, launch_args: dict) -> None:
        uri = os.environ.get("ROS_MASTER_URI", "")
        attachable = bool(uri) and master_alive(uri) and service_exists(uri, ros.SHIELD_STEP)
        if graph == "attach" and not attachable:
            raise GraphError(f"no MoveRL graph (service {ros.SHIELD_STEP}) at ROS_MASTER_URI={uri or '<unset>'}")
        if graph == "launch" or (graph == "auto" and not attachable):
            wf = world_file(launch_args["world"])
            if not wf.exists():
                known = sorted(p.stem for p in wf.parent.glob("*.yaml"))
                raise ValueError(f"no world file {wf} (worlds available: {known})")
            launch_args = {k: v for k, v in launch_args.items() if k != "world"}
            launch_args["world_file"] = str(wf)
            port = None
            if ros._NODE_MASTER is not None:  # rospy is bound to one master per process: reuse its port
                port = int(ros._NODE_MASTER.rsplit(":", 1)[1])
                if master_alive(ros._NODE_MASTER):
                    raise GraphError("this process already runs a MoveRL graph; close that env first, or use "
                                     "one process per env (SubprocVecEnv)")
            self._graph = LaunchedGraph(launch_args, port=port, wait_for=ros.REQUIRED_SERVICES)
            uri = self._graph.uri
            self.attached = False
        else:
            self.attached = True
        ros.init_node(uri)
        self._backend = ros.RosBackend()

    def _setup(self, world: str, shield: bool, goal) -> None:
        b = self._backend
        if self.attached and b.shield_enabled != bool(shield):
            raise GraphError(f"the attached graph has the shield {'on' if b.shield_enabled else 'off'}, "
                             f"but the env was asked for shield={shield}")
        self.shield_enabled = b.shield_enabled
        self.limits = JointLimits.from_urdf(b.robot_description, b.joints)
        self._home = np.clip(np.asarray(b.home, dtype=np.float64), self.limits.lower, self.limits.upper)
        self.scaler = ActionScaler(self.limits, self.config.dt)
        w = b.world()
        self.world_name = w.name
        if self.attached and world and os.sep not in str(world) and world != w.name:
            raise GraphError(f"the attached graph runs world '{w.name}', the env was asked for '{world}'")
        self.task = ReachTask(self.config, goal if goal is not None else list(w.goal))
        self._observed = [o.id for o in w.objects if o.observed]
        self._obstacles0 = self._obstacle_vector(w)          # observed poses at motion time 0
        self._obstacles = self._obstacles0
        # Observed moving obstacles: (offset of x in the obstacle vector, axis, amplitude, period, phase).
        self._movers = []
        for k, oid in enumerate(self._observed):
            m = getattr(next(o for o in w.objects if o.id == oid), "motion", None)
            if m is not None and m.type != 0 and m.amplitude > 0.0:
                self._movers.append((7 * k, np.array(m.axis, dtype=np.float64), m.amplitude, m.period, m.phase))
        self._motion_epoch = None   # stamp (s) of the last reset: motion time 0
        n = self.limits.size
        size = (n if obs_type_has_joints(self.obs_type) else 0) + 7 + 3 + 7 * len(self._observed)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(size,), dtype=np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32)
        self.q = None
        self.last_timing = {}

    def _obstacles_at(self, stamp) -> np.ndarray:
        """Observed obstacle poses at the state stamp `stamp` (motion time = stamp - stamp of the last reset)."""
        if not self._movers:
            return self._obstacles0
        t = (stamp - self._motion_epoch).to_sec()
        out = self._obstacles0.copy()
        for i, axis, amplitude, period, phase in self._movers:
            out[i:i + 3] += axis * (amplitude * (math.sin(2.0 * math.pi * t / period + phase) - math.sin(phase)))
        return out

    def _obstacle_vector(self, w) -> np.ndarray:
        poses = {o.id: o.pose for o in w.objects}
        out = []
        for oid in self._observed:
            p = poses[oid]
            out += [p.position.x, p.position.y, p.position.z,
                    p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w]
        return np.array(out, dtype=np.float64)

    # -- gym API -------------------------------------------------------------------------------------------
    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        options = options or {}
        if "goal" in options:
            self.task = ReachTask(self.config, options["goal"])
        elif self.config.goal_noise > 0:
            self.task = ReachTask(self.config, self._sample_goal())
        q = np.asarray(options["start"], dtype=np.float64) if "start" in options else self._sample_start()
        res = self._backend.reset_robot(q)
        if not res.success:
            raise MoveRLError(f"could not place the robot at the start configuration: {res.message}")
        self.q = np.array(res.state.position, dtype=np.float64)
        self._motion_epoch = res.state.header.stamp   # the reset restarted the obstacles' motions
        self._obstacles = self._obstacles_at(res.state.header.stamp)
        fk = self._backend.fk(self.q)
        if not fk.success:
            raise MoveRLError(f"forward kinematics failed: {fk.message}")
        self.ee = _pose_array(fk.poses[0])
        self.distance = self.task.distance(self.ee[:3])
        return self._observation(), {"distance": self.distance, "is_success": self.task.is_success(self.distance)}

    def _sample_goal(self) -> np.ndarray:
        """A goal in the reachable region: the end-effector position of a random collision-free configuration
        within +-goal_noise rad of home (config/env.yaml), so that every sampled goal can be reached."""
        lo = np.maximum(self.limits.lower, self._home - self.config.goal_noise)
        hi = np.minimum(self.limits.upper, self._home + self.config.goal_noise)
        for _ in range(self.config.start_sampling_attempts):
            q = self.np_random.uniform(lo, hi)
            if self._backend.check_state(q).outcome != 0:
                continue
            fk = self._backend.fk(q)
            if fk.success:
                return _pose_array(fk.poses[0])[:3]
        raise MoveRLError(f"no collision-free goal configuration found in {self.config.start_sampling_attempts} "
                          f"random samples of world '{self.world_name}'")

    def _sample_start(self) -> np.ndarray:
        """A random collision-free start (config/env.yaml: start_noise around the robot's home, or uniform)."""
        lo, hi = self.limits.lower, self.limits.upper
        noise = self.config.start_noise
        if noise > 0:
            lo = np.maximum(lo, self._home - noise)
            hi = np.minimum(hi, self._home + noise)
        for _ in range(self.config.start_sampling_attempts):
            q = self.np_random.uniform(lo, hi)
            if self._backend.check_state(q).outcome != 0:
                continue
            fk = self._backend.fk(q)
            if fk.success and not self.task.is_success(self.task.distance(_pose_array(fk.poses[0])[:3])):
                return q
        raise MoveRLError(f"no collision-free start configuration found in {self.config.start_sampling_attempts} "
                          f"random samples of world '{self.world_name}'")

    def step(self, action):
        if self.q is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        target = self.scaler.command(self.q, action)  # raises ValueError on bad shape / NaN / inf
        t0 = time.perf_counter()
        res = self._backend.step(target, self.config.dt)
        round_trip = time.perf_counter() - t0
        verdict = res.verdict
        if verdict in FAILURES:
            raise MoveRLError(f"shield verdict {VERDICTS[verdict]}: {res.message}")
        self.q = np.array(res.state.position, dtype=np.float64)
        self.ee = _pose_array(res.ee_pose)
        if self._movers:
            self._obstacles = self._obstacles_at(res.state.header.stamp)
        d = self.task.distance(self.ee[:3])
        discarded = verdict in DISCARDED
        reward = self.task.reward(self.distance, d, discarded)
        self.distance = d
        success = self.task.is_success(d)
        c = res.contacts
        contacts = (c.world_contacts + c.self_contacts) if c.available else -1
        self.last_timing = dict(round_trip=round_trip, state_check=res.state_check_time,
                                path_check=res.path_check_time, planning=res.planning_time,
                                execution=res.execution_time)
        info = {
            "verdict": VERDICTS.get(verdict, str(verdict)),
            "collision_type": _collision_type(verdict, res),
            "discarded": discarded,
            "replanned": verdict == 1,
            "strategy": res.strategy,
            "planning_time": float(res.planning_time),
            "contacts": int(contacts),
            "contact_substeps": int(c.substeps_in_contact) if c.available else -1,
            "cost": float(discarded or contacts > 0),
            "distance": d,
            "is_success": success,
        }
        return self._observation(), reward, success, False, info

    def _observation(self) -> np.ndarray:
        parts = [self.q] if obs_type_has_joints(self.obs_type) else []
        parts += [self.ee, self.task.goal, self._obstacles]
        return np.concatenate(parts).astype(np.float32)

    def close(self):
        if self._backend is not None:
            self._backend.close()
            self._backend = None
        if self._graph is not None:
            self._graph.close()
            self._graph = None


def obs_type_has_joints(obs_type: str) -> bool:
    return obs_type == "joints"


def _pose_array(pose) -> np.ndarray:
    return np.array([pose.position.x, pose.position.y, pose.position.z,
                     pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w])
