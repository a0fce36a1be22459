"""MoveRL reach env: a Gymnasium env whose every action passes the safety shield of a live ROS graph.

The env's logic works on plain data (moverl_gym.backend): the ROS backend (the default) talks to the shield of a
graph the env launches or attaches to; the PyBullet backend (backend="bullet", no shield) steps the same robot and
world in-process, without a roscore. Paper sections 4.2-4.6. Action: Box[-1, 1]^n, scaled to delta q within
+-dt * qdot_limit, clipped to the joint limits (ActionScaler). Observation: joint angles (obs_type="joints") and/or
the end-effector pose, the goal, and the pose of every observed obstacle (7 numbers each: from the world file's
motion, or with launch argument obstacle_poses:=tracker the last pose a tracker delivered, moverl_gym.tracking).
Reward: ReachTask. Each
episode starts at a random collision-free configuration; it terminates at the goal and is truncated after
config.max_episode_steps (config/env.yaml, or task={"max_episode_steps": n}): the env counts them itself.
"""

from __future__ import annotations

import os
import time

import gymnasium as gym
import numpy as np

from control_msgs.msg import FollowJointTrajectoryResult as _Fjt
from moverl_msgs.srv import ShieldStepResponse as _Step
from moverl_msgs.srv import ValidateMotionResponse as _Motion

from .backend import Backend, StepResult
from .errors import MoveRLError, NoFreeConfiguration
from .graph import GraphError
from .launch_args import LaunchArgError
from .launch_args import checked as checked_launch
from .paths import config_file
from .robot import ActionScaler, JointLimits, chain_reach
from .sampling import sample_goal, sample_start
from .task import ReachTask, TaskConfig
from .tracking import TrackedPoses

#: Shield verdicts by code, named as in moverl_msgs/ShieldStep (the generated class is the one source of the codes).
VERDICTS = {
    getattr(_Step, name): name.lower()
    for name in dir(_Step)
    if name.isupper() and isinstance(getattr(_Step, name), int)
}
#: The collision the shield found (and prevented or avoided) for each verdict.
#: For TRUNCATED (strategy last_safe) and RETREATED (retreat) it depends on the step: see _collision_type
#: (unsafe_cause).
COLLISION_TYPES = {
    _Step.REPLANNED: "path",
    _Step.DISCARDED_SELF: "self",
    _Step.DISCARDED_POSE: "pose",
    _Step.DISCARDED_PATH: "path",
    _Step.DISCARDED_START: "start",
    _Step.DISCARDED_UNSEEN: "unseen",  # not a collision: the sensed map was too old to know anything free
    _Step.TRUNCATED: "path",
}
#: ShieldStep.unsafe_cause codes (moverl_msgs/ValidateMotion outcomes) -> collision type.
UNSAFE_CAUSES = {
    _Motion.SELF_COLLISION: "self",
    _Motion.POSE_COLLISION: "pose",
    _Motion.PATH_COLLISION: "path",
    _Motion.START_IN_COLLISION: "start",
}
#: Verdicts that count as discarded (the action was unsafe: the agent gets safety_penalty). A truncated step
#: (strategy last_safe) moved only along the safe part of the unsafe action, a retreated one (retreat) backed away
#: from a person instead: they count too.
DISCARDED = frozenset(
    {
        _Step.DISCARDED_SELF,
        _Step.DISCARDED_POSE,
        _Step.DISCARDED_PATH,
        _Step.DISCARDED_START,
        _Step.DISCARDED_UNSEEN,
        _Step.TRUNCATED,
        _Step.RETREATED,
    }
)
#: Counters of discarded steps per verdict for training logs and metrics ("discarded_self", ... in code order).
DISCARDED_COUNTERS = tuple(VERDICTS[v] for v in sorted(DISCARDED) if VERDICTS[v].startswith("discarded_"))
#: s a component failure waits for a launched graph's roslaunch to report a required node's death (the failure may be
#: the graph going down; the error then says so)
GRAPH_DOWN_WAIT = 2.0
#: Verdicts after which the env cannot go on (MoveRLError), with the component that failed.
FAILURES = {
    _Step.INVALID_REQUEST: "shield (invalid request)",
    _Step.SCENE_UNAVAILABLE: "planning scene",
    _Step.EXECUTION_FAILED: "robot driver (refused the move)",
    _Step.DRIVER_UNAVAILABLE: "robot driver",
    _Step.STATE_UNAVAILABLE: "robot joint states",
}
#: The verdict of a step that has none (it failed before the shield answered, or with a FAILURES verdict, and the env
#: recovers: info["verdict"] is "graph_failed"); no ShieldStep code.
_NO_VERDICT = -1
#: The driver stopped the move on the way (e.g. the arm was blocked): the episode ends (truncated).
ABORTED = _Step.ABORTED
#: control_msgs/FollowJointTrajectoryResult error codes by value (info["driver_error"]).
DRIVER_ERRORS = {
    getattr(_Fjt, name): name
    for name in dir(_Fjt)
    if name.isupper() and isinstance(getattr(_Fjt, name), int) and getattr(_Fjt, name) != _Fjt.SUCCESSFUL
}
OBS_TYPES = ("joints", "ee")
#: moverl.launch's arguments that the env takes as its own arguments, not in launch_args.
ENV_LAUNCH_ARGS = {
    "world": "world=<name or path>",
    "world_file": "world=<path>",
    "robot": "robot=<name> (or launch_args robot_config=<path>)",
    "shield": "shield=True/False",
}


def _collision_type(verdict: int, unsafe_cause: int) -> "str | None":
    """The collision the shield found for this step (None when none): from the verdict, and for a truncated or
    retreated step from the step's unsafe_cause (self, pose, path or start), else "path"."""
    if verdict in (_Step.TRUNCATED, _Step.RETREATED):
        return UNSAFE_CAUSES.get(unsafe_cause, "path")
    return COLLISION_TYPES.get(verdict)


class MoveRLReachEnv(gym.Env):
    """Reach a goal with the end effector, every action checked by the shield.

    Args:
        world: world name (worlds/<world>.yaml) or path, when the env launches its own graph.
        obs_type: "joints" (joint angles + ee pose + goal + obstacles) or "ee" (ee pose + goal + obstacles).
        shield: shield on (True) or the unchecked baseline (False).
        graph: "auto" (attach to $ROS_MASTER_URI if it serves MoveRL, else launch), "attach" or "launch".
        backend: "ros" (the shield of a live graph) or "bullet" (the same robot and world in PyBullet, in this process:
            no ROS, no shield; shield must be False), or a moverl_gym.backend.Backend instance.
        robot: robot config name (config/robots/<robot>.yaml) for a launched graph.
        goal: override the world's goal [x, y, z].
        launch_args: extra roslaunch arguments (gui, mode, ...): launch/moverl.launch's, world, world_file, robot and
            shield excepted (the arguments above). Checked, with world and robot when a graph is launched, before
            anything starts (moverl_gym.launch_args): a wrong name or value raises LaunchArgError (a ValueError) naming
            the valid ones.
        task: overrides of config/env.yaml (dt, kappa, ...).
        recover: when a component of the graph fails (MoveRLError), end the episode (truncated, info["graph_failure"]
            says what failed) instead of raising, and tear the graph down and relaunch it at the next reset()
            (info["graph_restarts"] counts them; info["graph_failures"] counts failures, including those a reset()
            finds between episodes, which relaunches at once and names the failure in its info). Only for a graph this
            env launched with the simulator: never with a real robot, where a failure stops the run. Bounded:
            max_graph_restarts relaunches in a row, each failing within restart_min_steps steps (config/env.yaml), end
            the run with MoveRLError. "auto": on exactly when
            this env launched the graph with the simulator.
    """

    # render_fps (1 / dt) is set per instance from config/env.yaml; render_mode="human" is Gymnasium's HumanRendering
    # wrapper around rgb_array (gym.make applies it).
    metadata = {"render_modes": ["rgb_array"]}

    def __init__(
        self,
        world: str = "table",
        obs_type: str = "joints",
        shield: bool = True,
        graph: str = "auto",
        robot: str = "panda",
        goal=None,
        launch_args: dict | None = None,
        task: dict | None = None,
        render_mode=None,
        recover: "bool | str" = False,
        backend: "str | Backend" = "ros",
    ):
        if obs_type not in OBS_TYPES:
            raise ValueError(f"obs_type must be one of {OBS_TYPES}, got {obs_type!r}")
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(
                f"render_mode must be None or one of {self.metadata['render_modes']} (\"human\": gym.make wraps "
                f"rgb_array in Gymnasium's HumanRendering), got {render_mode!r}"
            )
        self.render_mode = render_mode
        self._view = None  # the renderer, made at the first render() (no cost when not rendering)
        self._world_arg = world
        if recover not in (True, False, "auto"):
            raise ValueError(f"recover must be True, False or 'auto', got {recover!r}")
        self.obs_type = obs_type
        self.config = TaskConfig.from_yaml(config_file("env.yaml"), **(task or {}))
        self.metadata = {**type(self).metadata, "render_fps": 1.0 / self.config.dt}
        self.graph_restarts = 0  # relaunches so far (reported in every info)
        self.graph_failures = 0  # failures found so far, at a step or a reset (reported in every info)
        self._failure = None  # what failed, until the next reset relaunches the graph
        self._restarts_in_a_row = 0
        self._steps_since_restart = 0
        self._resets_done = 0  # successful resets (the first one raises NoFreeConfiguration; later ones stay put)
        self._no_free_start = ""
        self._warned_no_free_start = False
        self._backend = None
        # Every launch argument checked once, before anything starts (moverl_gym.launch_args): the backends take the
        # result as it is. world and robot are checked by the backend that uses them as files (the PyBullet one; the
        # ROS one when it launches a graph, with their combinations with these): attached to a graph, world is only
        # the name of the graph's world, and robot is not used.
        launch_args = dict(launch_args or {})
        for name, instead in ENV_LAUNCH_ARGS.items():
            if name in launch_args:
                raise LaunchArgError(f"launch_args[{name!r}]: give it as the env's argument {instead}")
        launch = checked_launch(dict(shield=shield, **launch_args))
        try:
            if isinstance(backend, Backend):
                self._backend = backend
            elif backend == "bullet":
                from .bullet_backend import BulletBackend

                if launch_args.get("obstacle_poses", "world_file") != "world_file":
                    raise LaunchArgError(
                        "obstacle_poses:=tracker needs a ROS graph (backend='ros'): the PyBullet backend has no tracker"
                    )

                self._backend = BulletBackend(world, robot, launch_args.get("robot_config"), shield=shield)
            elif backend == "ros":
                from .ros_backend import RosBackend

                self._backend = RosBackend(
                    graph,
                    launch,
                    call_timeout=self.config.step_timeout,
                    reset_timeout=self.config.reset_timeout,
                    step_duration=self.config.dt,
                    world=world,
                    robot=robot,
                )
            else:
                raise ValueError(f"backend must be 'ros', 'bullet' or a Backend, got {backend!r}")
            b = self._backend
            self.attached = bool(getattr(b, "attached", False))
            if recover is True and not b.restartable:
                raise ValueError(
                    "recover=True relaunches the graph the env launched with the simulator; it is never "
                    "used with an attached graph or a real robot (there a failure stops the run)"
                )
            self.recover = b.restartable if recover == "auto" else bool(recover)
            self._setup(world, shield, goal)
        except BaseException:
            self.close()
            raise

    @property
    def _graph(self):
        """The LaunchedGraph of the ROS backend (None when attached or not ROS)."""
        return getattr(self._backend, "graph", None)

    def _setup(self, world: str, shield: bool, goal) -> None:
        b = self._backend
        if self.attached and b.shield_enabled != bool(shield):
            raise GraphError(
                f"the attached graph has the shield {'on' if b.shield_enabled else 'off'}, "
                f"but the env was asked for shield={shield}"
            )
        self.shield_enabled = b.shield_enabled
        self.limits = JointLimits.from_urdf(b.urdf, b.joints)
        self._home = np.clip(np.asarray(b.home, dtype=np.float64), self.limits.lower, self.limits.upper)
        self.scaler = ActionScaler(self.limits, self.config.dt)
        w = b.world
        self.world_name = w.name
        if self.attached and world and os.sep not in str(world) and world != w.name:
            raise GraphError(f"the attached graph runs world '{w.name}', the env was asked for '{world}'")
        # A world's goal_region: each reset samples the goal in it (unless goal= fixes one, or reset's options do).
        self._goal_region = w.goal_region if goal is None else None
        self.goal_configuration = None  # the configuration a sampled goal came from (None: a given goal)
        if goal is None and w.goal is None and self._goal_region is None:
            raise ValueError(f"world '{w.name}' has no goal: give one (goal=[x, y, z])")
        self.reach = chain_reach(b.urdf, b.ee_link)  # positions the end effector can reach: within +-reach of the base
        if goal is None and w.goal is None:
            goal = list(np.mean(self._goal_region, axis=0))  # until the first reset samples one
        for corner in self._goal_region or ():
            self._make_task(corner)  # a region beyond the robot's reach is refused here, naming it
        self.task = self._make_task(goal if goal is not None else list(w.goal))
        observed = [o for o in w.obstacles if o.observed]
        self._obstacles0 = np.concatenate([o.pose for o in observed]) if observed else np.zeros(0)  # at motion time 0
        self._obstacles = self._obstacles0
        # Observed moving obstacles, grouped by motion: (offsets of their x in the obstacle vector, the motion's axis,
        # the motion). Obstacles that share a motion (the parts of a walking person) move by the same displacement:
        # it is computed once per motion and step.
        groups = []  # [(motion, [offset, ...])], by equality (a motion need not be hashable)
        for k, o in enumerate(observed):
            if o.motion is not None:
                group = next((g for g in groups if g[0] == o.motion), None)
                if group is None:
                    groups.append((o.motion, [7 * k]))
                else:
                    group[1].append(7 * k)
        self._movers = [(offsets, np.asarray(m.axis), m) for m, offsets in groups]
        self._motion_epoch = w.motion_epoch
        # obstacle_poses:=tracker: the observed obstacles' poses are the last ones a tracker delivered (the backend's
        # subscribers feed self._tracked), not the motion's (moverl_gym.tracking).
        self._tracked = None
        if b.obstacle_poses == "tracker":
            self._tracked = TrackedPoses(
                [o.id for o in observed], self._obstacles0, self.config.track_timeout, frame=w.frame
            )
            b.track(self._tracked)
        n = self.limits.size
        # Bounded spaces: joint angles within the URDF limits (a reported state a hair beyond one is clipped onto it
        # in the observation), positions within the robot's reach of its base (end effector, goal), observed obstacles
        # within their motion's envelope, quaternions in [-1, 1].
        self._goal_low, self._goal_high = np.full(3, -self.reach), np.full(3, self.reach)
        ee_low = np.concatenate([self._goal_low, -np.ones(4)])
        ee_high = np.concatenate([self._goal_high, np.ones(4)])
        ob_low, ob_high = _obstacle_bounds(observed, self.config.observation_margin)
        low = ([self.limits.lower] if obs_type_has_joints(self.obs_type) else []) + [ee_low, self._goal_low, ob_low]
        high = ([self.limits.upper] if obs_type_has_joints(self.obs_type) else []) + [ee_high, self._goal_high, ob_high]
        self._obs_low, self._obs_high = np.concatenate(low), np.concatenate(high)
        # _observation fills this buffer in place: [joints] ee (7) goal (3) obstacles, the joints from offset 0.
        self._obs_buf = np.empty(self._obs_low.size)
        self._obs_ee = n if obs_type_has_joints(self.obs_type) else 0  # where the ee pose starts
        self.observation_space = gym.spaces.Box(
            self._obs_low.astype(np.float32), self._obs_high.astype(np.float32), dtype=np.float32
        )
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32)
        self.q = None
        self.last_timing = {}

    def _make_task(self, goal) -> ReachTask:
        task = ReachTask(self.config, goal)
        if np.any(np.abs(task.goal) > self.reach):
            raise ValueError(
                f"goal {task.goal.tolist()} is out of the robot's reach: each coordinate must lie within "
                f"{self.reach:.3f} m of its base"
            )
        return task

    def _observe_obstacles(self, stamp: float, info: dict) -> np.ndarray:
        """The observed obstacles' poses for a state stamped `stamp`: the tracker's last ones (info gets
        track_ages and tracks_lost) or the world file's motion."""
        if self._tracked is None:
            return self._obstacles_at(stamp)
        poses, ages = self._tracked.read(stamp)
        info["track_ages"] = ages
        info["tracks_lost"] = self._tracked.lost(ages)
        return poses

    def _obstacles_at(self, stamp: float) -> np.ndarray:
        """Observed obstacle poses at the state stamp `stamp` (motion time = stamp - the motion epoch)."""
        if not self._movers:
            return self._obstacles0
        t = stamp - self._motion_epoch
        out = self._obstacles0.copy()
        for offsets, axis, motion in self._movers:
            delta = axis * motion.displacement(t)
            for i in offsets:
                out[i : i + 3] += delta
        return out

    # -- gym API -------------------------------------------------------------------------------------------
    def reset(self, *, seed=None, options=None):
        if self._backend is None:
            raise gym.error.ClosedEnvironmentError("reset() on a closed env: make a new one")
        super().reset(seed=seed)
        options = options or {}
        restarted = None
        if self._failure is not None:
            restarted = self._relaunch()
        try:
            obs, info = self._reset(options)
        except NoFreeConfiguration:
            raise  # the graph works: a relaunch would find the same world
        except MoveRLError as exc:
            if not self.recover:
                raise
            # The graph failed before the episode started (found by this reset, or the relaunched graph failed
            # again): relaunch now; the reset's info names the failure (info["graph_failure"]) so that it is counted
            # like a failure that ends an episode.
            self._fail(exc)
            obs, info = self.reset(seed=None, options=options)
            info.setdefault("graph_failure", str(exc))
            return obs, info
        info["graph_restarts"] = self.graph_restarts
        info["graph_failures"] = self.graph_failures
        if restarted is not None:
            info["graph_restart"] = restarted
        return obs, info

    def _fail(self, exc: Exception) -> None:
        """Recovery: remember what failed; the next reset() relaunches, unless this keeps happening."""
        self._failure = str(exc)
        self.graph_failures += 1
        quick = self._steps_since_restart < self.config.restart_min_steps
        self._restarts_in_a_row = self._restarts_in_a_row + 1 if quick else 1
        if self._restarts_in_a_row > self.config.max_graph_restarts:
            raise MoveRLError(
                f"the graph failed {self._restarts_in_a_row} times in a row, each within "
                f"{self.config.restart_min_steps} steps of a relaunch; giving up. Last failure: "
                f"{exc}"
            ) from exc

    def _relaunch(self) -> str:
        """Tear the failed graph down and launch it again (same arguments, same master port). Returns what failed."""
        failure, self._failure = self._failure, None
        self._backend.restart()
        self.graph_restarts += 1
        self._steps_since_restart = 0
        self.q = None
        return failure

    def _reset(self, options):
        if "goal" in options:
            self.task = self._make_task(options["goal"])
            self.goal_configuration = None
        elif self.config.goal_noise > 0 or self._goal_region is not None:
            try:
                self.task = self._make_task(self._sample_goal())
            except NoFreeConfiguration:
                if self._resets_done == 0:
                    raise
                # (later: the episode keeps the last goal; the start below says whether anything is free)
        self._no_free_start = ""
        res = self._reset_robot(options.get("start"))
        self._episode_steps = 0
        self.q = res.q
        self._motion_epoch = res.motion_epoch  # a simulator reset restarts the obstacles' motions; a move does not
        self._stamp = res.stamp
        info = {}
        self._obstacles = self._observe_obstacles(res.stamp, info)
        self.ee = self._backend.ee_pose(self.q)
        self.distance = self.task.distance(self.ee[:3])
        info.update(distance=self.distance, is_success=self.task.is_success(self.distance))
        if res.moves:  # a planned reset (a driver that cannot teleport): what it ran
            info["reset_moves"], info["reset_path_duration"] = res.moves, res.path_duration
        if self._no_free_start:
            info["no_free_start"] = self._no_free_start
        self._resets_done += 1
        return self._observation(), info

    def _reset_robot(self, start):
        """Bring the robot to the episode's start through the shield: `start` (a configuration), "current" (stay where
        the robot is) or None (a random collision-free start; with a driver that moves the robot there, a start it
        finds no path to is replaced by another sample)."""
        if isinstance(start, str):
            if start != "current":
                raise ValueError(f'options["start"] must be a configuration or "current", got {start!r}')
            res = self._backend.reset(None)  # the robot stays; the backend reports its state
            if not res.success:
                raise MoveRLError(f"could not read the robot's state: {res.message}")
            return res
        attempts = 1 if start is not None else self.config.start_sampling_attempts
        # Samples the driver refuses (the simulator does not teleport the robot into or next to an obstacle where its
        # motion restarts, where the map does not show it yet): after a tenth of the attempts, from the whole range
        # (the KUKA iiwa's home lies inside the human world's walking person).
        refused = 0
        for _ in range(attempts):
            if start is not None:
                q = np.asarray(start, dtype=np.float64)
            else:
                try:
                    q = self._sample_start_or_look_again(near_home=refused < max(1, attempts // 10))
                except NoFreeConfiguration as exc:
                    if self._resets_done == 0:
                        raise  # the world as the env first sees it leaves nothing free: say so
                    # Later (the arm's own shadow, a person standing close): the episode starts where the robot
                    # stands, which the shield keeps safe (it moves only into space known free), rather than end a
                    # training run whose graph works.
                    if not self._warned_no_free_start:
                        # (warn formats its message with %: the reason holds percentages)
                        gym.logger.warn("%s; the episode starts where the robot stands (info['no_free_start'])", exc)
                        self._warned_no_free_start = True
                    self._no_free_start = str(exc)
                    return self._reset_robot("current")
            res = self._backend.reset(q)
            if res.success:
                return res
            if not res.unreachable:
                break
            refused += 1
        raise MoveRLError(f"could not bring the robot to the start configuration: {res.message}")

    def _sample_start_or_look_again(self, near_home: bool) -> np.ndarray:
        """_sample_start; when no start is free and the robot can be teleported, first let the cameras look again.

        With sensed obstacles, the robot's own links hide space from the cameras, and hidden space near what may move
        turns possibly occupied (docs/sensing.md, "Space no camera sees"): the arm where an episode ended can hide the
        space next to every start. A simulator may stand the robot elsewhere (it refuses poses that touch or will be
        walked into by an obstacle, from its ground truth); its cameras then see what the arm hid, and the starts are
        sampled again from those views. There, when no start near home is free, the cameras look again before any
        start over the whole joint range is tried (a freshly launched graph's map has seen little around the robot's
        first pose, and a start far from home held the first episode still: 1 of 300 in docs/sensed_person).
        """
        teleports = getattr(self._backend, "teleports", False)
        look_first = teleports and near_home  # look again before a start over the whole range
        try:
            return self._sample_start(near_home=near_home, over_range=not look_first)
        except MoveRLError as exc:
            if not teleports:
                raise
            failed = exc
        # The census only now: a service call and a count over the robot's reach, not for every reset.
        if self._backend.sensed_census() is None:  # no map to look again with
            if not look_first:
                raise failed
            return self._sample_start(near_home=False)  # the whole range, as without a map
        lo, hi = self.limits.lower, self.limits.upper
        for k in range(self.config.start_sampling_attempts):
            look = self._home if k == 0 else self.np_random.uniform(lo, hi)
            if self._backend.reset(look).success:
                break
        return self._sample_start(near_home=near_home)

    def _sample_goal(self) -> np.ndarray:
        """A goal that can be reached (moverl_gym.sampling): the end-effector position of a random collision-free
        configuration within +-goal_noise rad of home (config/env.yaml), and in the world's goal_region when it has
        one. The configuration is kept in goal_configuration."""
        n, deadline = self.config.start_sampling_attempts, time.monotonic() + self.config.goal_wait
        while True:  # (a person in the region now moves on: look again until config/env.yaml's goal_wait)
            found = sample_goal(
                self.np_random, self._backend, self.limits.lower, self.limits.upper, self._home,
                self.config.goal_noise, n, self._goal_region,
            )  # fmt: skip
            if found is not None or time.monotonic() >= deadline:
                break
            time.sleep(0.2)
        if found is None:
            where = f" with its end effector in goal_region {self._goal_region}" if self._goal_region else ""
            raise NoFreeConfiguration(
                f"no collision-free goal configuration{where} found in {n} random samples of world "
                f"'{self.world_name}'{self._unseen_reason()}"
            )
        goal, self.goal_configuration = found
        return goal

    def _sample_start(self, near_home: bool = True, over_range: bool = True) -> np.ndarray:
        """A random collision-free start not at the goal (moverl_gym.sampling; config/env.yaml: start_noise around
        the robot's home, then (unless over_range is false), or when near_home is false, uniform)."""
        noise = self.config.start_noise if near_home else 0.0
        n = self.config.start_sampling_attempts
        q = sample_start(self.np_random, self._backend, self.limits.lower, self.limits.upper, self._home, noise, n,
                         lambda ee: self.task.is_success(self.task.distance(ee)), over_range)  # fmt: skip
        if q is None:
            raise NoFreeConfiguration(
                f"no collision-free start configuration found in {n} random samples "
                + (
                    "over the joint range "
                    if noise <= 0
                    else "near home nor as many over the joint range "
                    if over_range
                    else "near home "
                )
                + f"of world '{self.world_name}'"
                f"{self._unseen_reason()}"
            )
        return q

    def _unseen_reason(self) -> str:
        """': <how much of the reach no camera sees, where, and the tool that shows it>' when the sensed map's
        unseen space may be why nothing is free ('' otherwise)."""
        from .sensed import describe_unseen

        text = describe_unseen(self._backend.sensed_census(), self.world_name)
        return f": {text}" if text else ""

    def step(self, action):
        if self.q is None or self._failure is not None:
            if self._backend is None:
                raise gym.error.ClosedEnvironmentError("step() on a closed env: make a new one")
            raise gym.error.ResetNeeded("call reset() before step()")
        target = self.scaler.command(self.q, action)  # raises ValueError on bad shape / NaN / inf
        t0 = time.perf_counter()
        try:
            res = self._backend.step(target, self.config.dt)
            verdict = res.verdict
            if verdict in FAILURES:
                message = f"{FAILURES[verdict]} failed ({VERDICTS[verdict]}): {res.message}"
                down = self._graph.down(GRAPH_DOWN_WAIT) if self._graph is not None else ""
                raise MoveRLError(f"the graph is down ({down}): {message}" if down else message)
        except MoveRLError as exc:
            if not self.recover:
                raise
            self._fail(exc)
            # The episode ends here; the next reset() relaunches the graph. The robot did not move, and nothing of the
            # step was measured: no answer, the facts of a step where nothing happened.
            nothing = StepResult(
                _NO_VERDICT,
                str(exc),
                self.q,
                self._stamp,
                self.ee,
                contacts=0,
                contact_substeps=0,
                contacts_moving=0,
                contacts_resting=0,
            )
            info = self._step_info(nothing, self.distance, False, None, failure=str(exc))
            return self._observation(), 0.0, False, True, info
        round_trip = time.perf_counter() - t0
        self._steps_since_restart += 1
        self.q = res.q
        self.ee = res.ee
        self._stamp = res.stamp
        tracks = {}
        if self._tracked is not None:
            self._obstacles = self._observe_obstacles(res.stamp, tracks)
        elif self._movers:
            self._obstacles = self._obstacles_at(res.stamp)
        d = self.task.distance(self.ee[:3])
        discarded = verdict in DISCARDED
        reward = self.task.reward(self.distance, d, discarded, res.contacts)
        self.distance = d
        success = self.task.is_success(d)
        self.last_timing = dict(round_trip=round_trip, **res.timing)
        info = self._step_info(res, d, success, tracks)
        # The driver stopped the move on the way (a path or goal tolerance, e.g. the arm was blocked): the robot
        # stands where it stopped, and the episode ends here (truncated; info["driver_error"] says why).
        aborted = verdict == ABORTED
        self._episode_steps += 1
        truncated = aborted or (not success and self._episode_steps >= self.config.max_episode_steps)
        return self._observation(), reward, success, truncated, info

    def _step_info(
        self, res: StepResult, distance: float, success: bool, tracks: "dict | None", failure: "str | None" = None
    ) -> dict:
        """A step's info (docs/env.md, "info"), from the step's facts: the backend's answer `res`, the goal distance
        and success after the step, the tracker's ages (track_ages and tracks_lost; {} without a tracker, None when
        they were not read) and, for a step that failed (recover), what failed.

        Every step has every key, whatever its path; only graph_failure (a failed step), driver_message (an aborted
        step) and cost_contact (absent when contacts are unknown) come and go. A failed step's answer is the facts of
        a step where nothing happened (no verdict, no contact, map_age -1 and sensed_margin 0: no map measured) and
        its tracks are unread (age inf, lost).
        """
        verdict, contacts = res.verdict, res.contacts
        discarded = verdict in DISCARDED
        if tracks is None:
            tracks = {}
            if self._tracked is not None:
                ages = np.full(len(self._tracked.ids), np.inf)
                tracks = {"track_ages": ages, "tracks_lost": self._tracked.lost(ages)}
        info = {
            "verdict": "graph_failed" if failure is not None else VERDICTS.get(verdict, str(verdict)),
            "collision_type": _collision_type(verdict, res.unsafe_cause),
            "discarded": discarded,
            "replanned": verdict == _Step.REPLANNED,
            "strategy": res.strategy,
            "planning_time": float(res.planning_time),
            "contacts": int(contacts),
            "contact_substeps": int(res.contact_substeps),
            # Who moved: the contact pairs that touched while the robot moved, and while it rested (-1: unknown).
            "contacts_moving": int(res.contacts_moving),
            "contacts_resting": int(res.contacts_resting),
            "cost": float(discarded or contacts > 0),
            "distance": distance,
            "is_success": success,
            "driver_error": DRIVER_ERRORS.get(res.driver_error_code) if res.driver_error_code else None,
            "message": res.message,  # the shield's words on the step (why an action was discarded, ...)
            # Sensed obstacles: how old the map the step was checked against was, and the margin that covered it
            # (-1 and 0 without a sensed map).
            "map_age": float(res.map_age),
            "sensed_margin": float(res.sensed_margin),
            "graph_restarts": self.graph_restarts,
            "graph_failures": self.graph_failures,
            **tracks,
        }
        if failure is not None:
            info["graph_failure"] = failure
        # Ground truth for constrained RL: 1.0 if the step's motion made contact. Absent when contacts are unknown (a
        # driver without ground truth: a constrained agent cannot learn there, and NaN would make equal steps unequal).
        if contacts >= 0:
            info["cost_contact"] = float(contacts > 0)
        # The driver stopped the move on the way (info["driver_error"] says why): its message under this key too.
        if verdict == ABORTED:
            info["driver_message"] = res.message
        return info

    def _observation(self) -> np.ndarray:
        # [joints] ee goal obstacles, written into the preallocated float64 buffer (no list, no concatenate).
        buf, e = self._obs_buf, self._obs_ee
        if e:
            buf[:e] = self.q
        buf[e : e + 7] = self.ee
        buf[e + 7 : e + 10] = self.task.goal
        buf[e + 10 :] = self._obstacles
        # Within the space: joints a hair beyond a limit (PyBullet, encoders) and float rounding of unit quaternions.
        # = np.clip(buf, low, high).astype(np.float32): clipped in float64, then rounded into a new float32 array.
        np.maximum(buf, self._obs_low, out=buf)
        return np.minimum(buf, self._obs_high, out=np.empty(buf.size, dtype=np.float32))

    def render(self):
        """render_mode "rgb_array": an (H, W, 3) uint8 picture of the current state (the robot as observed, every
        world object where its motion has it now, the goal as a red sphere), drawn in this process from the state and
        the world file (moverl_sim.scene_view; camera and size in config/render.yaml), so it works with a real robot
        too. None when the env was made without a render_mode."""
        if self.render_mode is None:
            gym.logger.warn('render() without a render_mode: make the env with render_mode="rgb_array"')
            return None
        if self.q is None:
            raise gym.error.ResetNeeded("call reset() before render()")
        if self._view is None:
            self._view = self._make_view()
        self._view.pose(self.q, self._stamp - self._motion_epoch, self.task.goal)
        return self._view.image()

    def _make_view(self):
        from moverl_sim.scene_view import SceneView
        from moverl_sim.world import load_world

        from .paths import world_file

        path = world_file(self._world_arg or self.world_name)
        if not path.exists():
            path = world_file(self.world_name)
        if not path.exists():
            raise FileNotFoundError(f"render(): the world file of world '{self.world_name}' is not at {path}")
        return SceneView(self._backend.robot_config, load_world(str(path)))

    def close(self):
        """Close the backend: a graph this env launched is gone, every process of it, when close() returns (see
        moverl_gym.graph.LaunchedGraph.close)."""
        view, self._view = getattr(self, "_view", None), None
        if view is not None:
            view.close()
        self.q = None  # step() and reset() refuse a closed env
        if self._backend is not None:
            backend, self._backend = self._backend, None
            backend.close()


def obs_type_has_joints(obs_type: str) -> bool:
    return obs_type == "joints"


def _obstacle_bounds(observed, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of the observed obstacles' poses (7 numbers each): the positions over their whole motion (its envelope()
    along the axis from the pose at motion time 0), `margin`
    (config/env.yaml observation_margin: what a tracker may report beyond) and 1 mm (float32 rounding) wider;
    quaternions in [-1, 1]."""
    if not (np.isfinite(margin) and margin >= 0.0):
        raise ValueError(f"observation_margin must be a number of metres >= 0, got {margin!r}")
    low, high = [], []
    for o in observed:
        p = np.asarray(o.pose[:3], dtype=np.float64)
        lo = hi = p
        if o.motion is not None:
            m, axis = o.motion, np.asarray(o.motion.axis, dtype=np.float64)
            ends = [p + axis * s for s in m.envelope()]
            lo, hi = np.minimum(*ends), np.maximum(*ends)
        low += [lo - margin - 1e-3, -np.ones(4)]
        high += [hi + margin + 1e-3, np.ones(4)]
    return (np.concatenate(low), np.concatenate(high)) if low else (np.zeros(0), np.zeros(0))
