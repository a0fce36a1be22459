"""The env's ROS backend: the shield of a live ROS graph (moverl_gym.backend's interface), which it launches
(moverl_gym.graph.LaunchedGraph, on a free port) or attaches to.

Per env step exactly one call is made (the shield's ~step); reset makes a handful. Proxies are created
once; a broken connection is re-opened once, and if that fails the error is raised at once (no waiting,
no retries loops): the shield fails closed, the env raises.

Every call has a deadline (ROS 1 service calls have none): a watchdog thread closes the call's persistent
connection when it passes, the blocked call returns, MoveRLError names the node that did not answer, and the next
call opens a new connection, so a stalled node that wakes up can never deliver its late reply as the answer to a
later request. Requests that move the robot also carry their deadline (`not_after`): a node that serves one after
it, refuses it.
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Mapping

import numpy as np

from moverl_sim.robot_config import parse_robot
from moverl_sim.ros_conversions import motion_from_msg

from .backend import Backend, Obstacle, ResetResult, StepResult, WorldInfo
from .errors import MoveRLError
from .graph import GraphError, LaunchedGraph, master_alive, service_exists
from .launch_args import CheckedLaunch, checked

SHIELD_STEP = "/shield/step"
SHIELD_RESET = "/shield/reset"
SCENE_CHECK = "/planning_scene/check_state"
#: s a state check waits for a sensed map fresh enough to answer (check_state's MAP_STALE) before the env raises.
STALE_MAP_WAIT = 10.0
SCENE_FK = "/planning_scene/fk"
SCENE_CENSUS = "/planning_scene/sensed_census"  # only when the scene senses obstacles
SCENE_WORLD = "/planning_scene/get_world"  # the world as its source (simulator or world server) describes it
REQUIRED_SERVICES = (SHIELD_STEP, SHIELD_RESET, SCENE_CHECK, SCENE_FK, SCENE_WORLD)

_NODE_MASTER: str | None = None  # rospy allows one node (one master) per process


class _Watchdog:
    """One daemon thread that runs an action when the armed deadline passes (one call at a time: the env's).

    Arming does not wake the thread unless the new deadline comes before the one it sleeps until: a notify per call
    would wake it on every env step, and the woken thread takes the GIL from the calling thread in the middle of its
    socket write (measured: the request's send went from 0.08 to 0.5 ms). Steps a few ms apart with deadlines seconds
    away find it asleep until an earlier deadline; it wakes then, sees the newer one and sleeps again."""

    def __init__(self):
        self._cv = threading.Condition()
        self._armed = None  # (deadline on time.monotonic(), action, token)
        self._wake_at = math.inf  # when the thread wakes up next (inf: when notified)
        self._fired = set()
        self._next = 0
        self._closed = False
        threading.Thread(target=self._run, name="moverl_deadlines", daemon=True).start()

    def arm(self, timeout: float, action) -> int:
        with self._cv:
            self._next += 1
            deadline = time.monotonic() + timeout
            self._armed = (deadline, action, self._next)
            if deadline < self._wake_at:
                self._cv.notify()
            return self._next

    def disarm(self, token: int) -> bool:
        """Cancel the armed action; True if it already fired (waits until it finished)."""
        with self._cv:
            if self._armed is not None and self._armed[2] == token:
                self._armed = None
                return False
            return token in self._fired

    def close(self):
        with self._cv:
            self._closed = True
            self._cv.notify()

    def _run(self):
        with self._cv:
            while not self._closed:
                now = time.monotonic()
                if self._armed is not None and self._armed[0] <= now:
                    _, action, token = self._armed
                    self._armed = None
                    try:
                        action()  # under the lock: disarm() returns only after it finished
                    finally:
                        self._fired.add(token)
                    continue
                self._wake_at = self._armed[0] if self._armed is not None else math.inf
                self._cv.wait(None if self._wake_at == math.inf else self._wake_at - now)


def _node_of(service: str) -> str:
    return service.rsplit("/", 1)[0] or "/"


class _Proxy:
    def __init__(self, name, srv_type, watchdog: _Watchdog, timeout: float, reuse_response: bool = False):
        """reuse_response: deserialize every answer into one response instance instead of a new one per call (a
        ShieldStep response builds a JointState, a Header, two Times, a Pose, ... in its constructor: a third of the
        env's deserialization cost per step). Only for a caller that copies what it needs out of the answer before
        its next call (RosBackend.step): deserialize() assigns every field, nothing of the previous answer remains."""
        import rospy

        self._rospy = rospy
        self.name = name
        self.type = srv_type
        self.timeout = timeout
        self._watchdog = watchdog
        self._response = srv_type._response_class() if reuse_response else None
        self._errors = (rospy.ServiceException, rospy.ROSException, OSError)
        self._proxy = self._new_proxy()

    def _new_proxy(self):
        proxy = self._rospy.ServiceProxy(self.name, self.type, persistent=True)
        if self._response is not None:
            # rospy makes the answer with protocol.recv_data_class() and then deserializes into it.
            response = self._response
            proxy.protocol.recv_data_class = lambda: response
        return proxy

    def __call__(self, request, timeout: float | None = None):
        timeout = self.timeout if timeout is None else timeout
        if hasattr(request, "not_after"):
            request.not_after = time.time() + timeout
        errors = self._errors
        for attempt in range(2):
            proxy = self._proxy
            token = self._watchdog.arm(timeout, proxy.close)  # closing the socket unblocks the call
            try:
                return proxy.call(request)
            except errors as exc:
                if self._watchdog.disarm(token):
                    self._renew()
                    raise MoveRLError(
                        f"node {_node_of(self.name)} did not answer {self.name} within its deadline of "
                        f"{timeout:.1f} s (stalled?): connection dropped, nothing more is sent to it"
                    ) from exc
                self._renew()
                if attempt == 1:
                    from .graph import master_alive

                    master = os.environ.get("ROS_MASTER_URI", "")
                    if master and not master_alive(master):
                        raise MoveRLError(
                            f"the graph is down: its ROS master {master} does not answer (roslaunch "
                            f"shuts the whole graph down when a required node, the simulator, dies); "
                            f"{self.name}: {exc}"
                        ) from exc
                    raise MoveRLError(
                        f"node {_node_of(self.name)} is unreachable ({self.name}: {exc}); is the MoveRL graph up?"
                    ) from exc
            finally:
                self._watchdog.disarm(token)

    def _renew(self):
        self._proxy.close()
        self._proxy = self._new_proxy()

    def close(self):
        self._proxy.close()


def init_node(master_uri: str) -> None:
    """Start this process's rospy node on master_uri (once; later calls must use the same port)."""
    global _NODE_MASTER
    import rospy

    if _NODE_MASTER is not None:
        if _NODE_MASTER != master_uri:
            raise GraphError(
                f"this process already talks to the ROS master {_NODE_MASTER}; rospy allows one master per "
                "process. Run one env per process (e.g. SubprocVecEnv) to use several graphs."
            )
        return
    if rospy.core.is_initialized():  # the host program (e.g. a rostest) already made this process a node
        import rosgraph

        bound = rosgraph.get_master_uri()
        if bound.rstrip("/") != master_uri.rstrip("/"):
            raise GraphError(f"this process's rospy node uses the master at {bound}, not {master_uri}")
        _NODE_MASTER = master_uri
        return
    os.environ["ROS_MASTER_URI"] = master_uri
    os.environ.setdefault("ROS_HOSTNAME", "127.0.0.1")
    rospy.init_node("moverl_env", anonymous=True, disable_signals=True, disable_rosout=True)
    _NODE_MASTER = master_uri


def shield_step_bound(shield: dict, step_duration: float) -> float:
    """The longest a legit direct step may take in the shield (s): the hops it bounds one by one (config/shield.yaml
    and the scene's planning_time, config/planning_scene.yaml): waiting for a fresh state, the scene's answer, the
    move, the controller's settling and the result's margin.

    Args:
        shield: the shield node's private parameters (/shield), with the scene's under its scene_namespace when the
            scene runs in the shield's process, or given as shield["planning_time"].
        step_duration: s the move lasts.
    """
    planning_time = shield.get("planning_time")
    if planning_time is None:
        import rospy

        planning_time = rospy.get_param(shield["scene_namespace"].rstrip("/") + "/planning_time")
    return (
        shield["max_state_age"]
        + planning_time
        + shield["scene_margin"]
        + step_duration
        + shield["goal_time"]
        + shield["result_margin"]
    )


class RosBackend(Backend):
    """The shield and the planning scene of a live graph, through persistent proxies whose calls have deadlines.

    Args:
        graph: "auto" (attach to $ROS_MASTER_URI if it serves MoveRL, else launch), "attach" or "launch".
        launch_args: roslaunch arguments for a launched graph (shield, driver, ...; not world nor robot): a
            CheckedLaunch (the env's), taken as it is, or a mapping, checked here.
        call_timeout: deadline of every call but resets (config/env.yaml step_timeout). Checked at start-up against
            the shield's own bound for a step of `step_duration` (shield_step_bound): it must be longer, so that a
            stalled component is reported by the shield (naming it) before this deadline reports the shield.
        reset_timeout: deadline of the shield's ~reset (config/env.yaml reset_timeout).
        step_duration: s a direct move lasts (the env's dt).
        wait_timeout: seconds to wait for the services at start-up.
        world: the world (a name or a path) of a graph it launches; attached, it is not used.
        robot: the robot config name of a graph it launches; attached, it is not used. These two are checked, with
            their combinations with launch_args (a world's sensing, a robot's joints), when a graph is launched.
    """

    def __init__(
        self,
        graph: str,
        launch_args: Mapping[str, object] | CheckedLaunch,
        call_timeout: float,
        reset_timeout: float,
        step_duration: float,
        wait_timeout: float = 30.0,
        *,
        world: str = "table",
        robot: str = "panda",
    ):
        if graph not in ("auto", "attach", "launch"):
            raise ValueError(f"graph must be 'auto', 'attach' or 'launch', got {graph!r}")
        self._launch = checked(launch_args)
        self._where = dict(world=world, robot=robot)
        self._launched: CheckedLaunch | None = None  # the launch with its world and robot, once checked
        self._timeouts = (call_timeout, reset_timeout, wait_timeout)
        self._step_duration = step_duration
        self._graph = None
        self._proxies = ()
        self._watchdog = None
        self._tracked = None  # the TrackedPoses that track() feeds
        self._subscribers = []
        try:
            self._connect(graph)
        except BaseException:
            self.close()
            raise

    # -- graph --------------------------------------------------------------------------------------------------
    def _connect(self, graph: str) -> None:
        import rospy

        from moverl_msgs.srv import CheckState, GetFK, GetWorld, ResetRobot, ShieldStep

        uri = os.environ.get("ROS_MASTER_URI", "")
        attachable = bool(uri) and master_alive(uri) and service_exists(uri, SHIELD_STEP)
        if graph == "attach" and uri and not attachable:
            # A graph that is still coming up (rostest starts the test with the nodes): give it the start-up budget.
            deadline = time.monotonic() + self._timeouts[2]
            while not attachable and time.monotonic() < deadline:
                time.sleep(0.1)
                attachable = master_alive(uri) and service_exists(uri, SHIELD_STEP)
        if graph == "attach" and not attachable:
            raise GraphError(
                f"no MoveRL graph (service {SHIELD_STEP}) at ROS_MASTER_URI={uri or '<unset>'} "
                f"after {self._timeouts[2] if uri else 0} s"
            )
        self.attached = not (graph == "launch" or (graph == "auto" and not attachable))
        if not self.attached:
            if self._launched is None:  # the world and robot are checked before anything starts (a restart reuses)
                # moverl.launch's world is a name; world_file takes a path too.
                self._launched = self._launch.adding(self._where, whole=True).with_world_file()
            port = None
            if _NODE_MASTER is not None:  # rospy is bound to one master per process: reuse its port
                port = int(_NODE_MASTER.rsplit(":", 1)[1])
                if master_alive(_NODE_MASTER):
                    raise GraphError(
                        "this process already runs a MoveRL graph; close that env first, or use "
                        "one process per env (SubprocVecEnv)"
                    )
            self._graph = LaunchedGraph(self._launched, port=port, wait_for=REQUIRED_SERVICES)
            uri = self._graph.uri
        init_node(uri)
        call_timeout, reset_timeout, wait_timeout = self._timeouts
        for name in REQUIRED_SERVICES:
            try:
                rospy.wait_for_service(name, timeout=wait_timeout)  # once, at start-up
            except rospy.ROSException as exc:
                raise GraphError(f"service {name} is not available after {wait_timeout} s") from exc
        self._watchdog = _Watchdog()
        self._step = _Proxy(SHIELD_STEP, ShieldStep, self._watchdog, call_timeout, reuse_response=True)
        self._reset = _Proxy(SHIELD_RESET, ResetRobot, self._watchdog, reset_timeout)
        self._check = _Proxy(SCENE_CHECK, CheckState, self._watchdog, call_timeout)
        self._fk = _Proxy(SCENE_FK, GetFK, self._watchdog, call_timeout)
        self._world = _Proxy(SCENE_WORLD, GetWorld, self._watchdog, call_timeout)
        self._proxies = (self._step, self._reset, self._check, self._fk, self._world)
        # One step request, refilled every step (its three fields are all set per call: target, duration here,
        # not_after by _Proxy), rather than a message constructed per step.
        self._step_request = ShieldStep._request_class()
        self._srv = {
            "reset": ResetRobot._request_class,
            "check": CheckState._request_class,
            "fk": GetFK._request_class,
        }
        self.urdf = rospy.get_param("/robot_description")
        # The robot config's robot: section as the graph was launched with it (an attached graph's too), checked.
        self.robot_config = parse_robot(rospy.get_param("/robot"), "the graph's /robot parameter", prefix="/robot/")
        self.joints = list(self.robot_config["joints"])
        self.home = list(self.robot_config["home"])
        self.ee_link = self.robot_config["ee_link"]
        self.shield_enabled = bool(rospy.get_param("/shield/enabled", True))
        bound = shield_step_bound(rospy.get_param("/shield"), self._step_duration)
        if not call_timeout > bound:
            raise GraphError(
                f"step_timeout ({call_timeout} s, config/env.yaml or task=) must exceed the shield's bound for a step "
                f"({bound:.2f} s: its max_state_age + the scene's planning_time + scene_margin + the move + "
                "goal_time + result_margin), so that a stalled component is reported by the shield, naming it"
            )
        self.world = _world_info(self._world(GetWorld._request_class()).world)
        # The arguments the graph was launched with (moverl.launch stores them, checked): an attached graph's too.
        self.obstacle_poses = str(
            (rospy.get_param("/moverl/launch_args", None) or self._launch.values).get("obstacle_poses", "world_file")
        )
        if self._tracked is not None:  # a restart: the new master does not know the old subscribers
            self._subscribe()
        simulated = not self.attached and str(self._launch.values.get("simulator", True)).lower() != "false"
        self.restartable = simulated  # never a real robot's graph, nor one this env did not launch
        launched = rospy.get_param("/moverl/launch_args", None) or self._launch.values
        self.teleports = (
            str(launched.get("simulator", True)).lower() != "false"
            and str(launched.get("driver", "sim_service")) == "sim_service"
        )

    @property
    def graph(self):
        """The LaunchedGraph this backend started (None when attached)."""
        return self._graph

    def restart(self) -> None:
        """Tear the failed graph down and launch it again (same arguments, same master port)."""
        if not self.restartable:
            raise RuntimeError("only a simulated graph this env launched can be relaunched")
        self.close()
        self._connect("launch")

    # -- the interface ------------------------------------------------------------------------------------------
    def step(self, target: np.ndarray, duration: float) -> StepResult:
        request = self._step_request
        request.target = target.tolist()
        request.duration = float(duration)
        # res is the step proxy's one response instance (reuse_response): everything is copied out of it here.
        res = self._step(request)
        c = res.contacts
        known = c.available
        return StepResult(
            verdict=res.verdict,
            message=res.message,
            q=np.array(res.state.position),
            stamp=res.state.header.stamp.to_sec(),
            ee=_pose_array(res.ee_pose),
            contacts=(c.world_contacts + c.self_contacts) if known else -1,
            contact_substeps=c.substeps_in_contact if known else -1,
            contacts_moving=c.moving_contacts if known else -1,
            contacts_resting=c.resting_contacts if known else -1,
            unsafe_cause=res.unsafe_cause,
            strategy=res.strategy,
            planning_time=res.planning_time,
            driver_error_code=res.driver_error_code,
            map_age=res.map_age,
            sensed_margin=res.sensed_margin,
            timing={
                "state_check": res.state_check_time,
                "path_check": res.path_check_time,
                "planning": res.planning_time,
                "execution": res.execution_time,
            },
        )

    def track(self, tracked) -> None:
        if self.obstacle_poses != "tracker":
            raise RuntimeError(f"the graph was launched with obstacle_poses:={self.obstacle_poses}, not tracker")
        self._tracked = tracked
        self._subscribe()

    def _subscribe(self) -> None:
        """One subscriber per tracked object (moverl_sim.tracker.TOPIC); its callback, in rospy's receive thread, only
        stores the pose (TrackedPoses.update): nothing of it runs on the step's path."""
        import rospy
        from geometry_msgs.msg import PoseStamped

        from moverl_sim.tracker import TOPIC

        self._unsubscribe()
        tracked = self._tracked

        def on_pose(msg, oid):
            p, o = msg.pose.position, msg.pose.orientation
            tracked.update(oid, msg.header.stamp.to_sec(), (p.x, p.y, p.z, o.x, o.y, o.z, o.w), msg.header.frame_id)

        self._subscribers = [
            rospy.Subscriber(TOPIC.format(id=oid), PoseStamped, on_pose, callback_args=oid, queue_size=100)
            for oid in tracked.ids
        ]

    def _unsubscribe(self) -> None:
        for sub in self._subscribers:
            sub.unregister()
        self._subscribers = []

    def reset(self, q: "np.ndarray | None") -> ResetResult:
        res = self._reset(self._srv["reset"](positions=[] if q is None else [float(x) for x in q]))
        return ResetResult(
            success=res.success,
            message=res.message,
            q=np.array(res.state.position) if res.state.position else None,
            stamp=res.state.header.stamp.to_sec(),
            motion_epoch=res.motion_epoch.to_sec(),
            unreachable=res.unreachable,
            moves=res.moves,
            path_duration=res.path_duration,
        )

    def check_state(self, q: np.ndarray) -> bool:
        from moverl_msgs.srv import CheckStateResponse

        # A sensed map too old to tell (MAP_STALE: a camera's cloud is late, or a reset made the old ones worthless)
        # says nothing about q: wait for the cameras, up to STALE_MAP_WAIT, rather than count q as in collision.
        deadline = time.monotonic() + STALE_MAP_WAIT
        while True:
            res = self._check(self._srv["check"](positions=[float(x) for x in q]))
            if res.outcome != CheckStateResponse.MAP_STALE:
                return res.outcome == CheckStateResponse.VALID
            if time.monotonic() > deadline:
                raise MoveRLError(
                    f"the planning scene's sensed map stayed too old for {STALE_MAP_WAIT} s: {res.message}"
                )
            time.sleep(0.05)

    def sensed_census(self):
        import rosservice

        from moverl_msgs.srv import SensedCensus

        from .sensed import SensedCensus as Census

        try:
            if SCENE_CENSUS not in rosservice.get_service_list():
                return None  # the scene senses no obstacles
        except rosservice.ROSServiceIOException:
            return None
        proxy = _Proxy(SCENE_CENSUS, SensedCensus, self._watchdog, self._check.timeout)
        try:
            r = proxy(SensedCensus._request_class(radius=0.0))
        except MoveRLError:
            return None
        finally:
            proxy.close()
        if not r.success:
            return None
        return Census(
            radius=r.radius,
            cells=r.cells,
            free=r.free_cells,
            seen_occupied=r.seen_occupied,
            stale=r.stale_cells,
            unseen=r.unseen_cells,
            unknown_occupied=r.unknown_occupied,
            cells_by_octant=tuple(r.cells_by_octant),
            hidden_by_octant=tuple(r.hidden_by_octant),
        )

    def ee_pose(self, q: np.ndarray) -> np.ndarray:
        fk = self._fk(self._srv["fk"](positions=[float(x) for x in q], links=[]))
        if not fk.success:
            raise MoveRLError(f"forward kinematics failed: {fk.message}")
        return _pose_array(fk.poses[0])

    def close(self) -> None:
        """Close the service connections, then stop the graph if this backend launched it: every process of the
        graph is gone when close() returns (see moverl_gym.graph.LaunchedGraph.close)."""
        try:
            self._unsubscribe()
            for p in self._proxies:
                p.close()
            self._proxies = ()
            if self._watchdog is not None:
                self._watchdog.close()
                self._watchdog = None
        finally:
            if self._graph is not None:
                graph, self._graph = self._graph, None
                graph.close()


def _pose_array(pose) -> np.ndarray:
    return np.array(
        [
            pose.position.x,
            pose.position.y,
            pose.position.z,
            pose.orientation.x,
            pose.orientation.y,
            pose.orientation.z,
            pose.orientation.w,
        ]
    )


def _world_info(w) -> WorldInfo:
    """moverl_msgs/World -> WorldInfo (plain data)."""
    obstacles = []
    for o in w.objects:
        m = o.motion
        motion = motion_from_msg(m)
        obstacles.append(Obstacle(id=o.id, pose=_pose_array(o.pose), observed=bool(o.observed), motion=motion))
    return WorldInfo(
        name=w.name,
        goal=tuple(w.goal) if len(w.goal) else None,
        goal_region=(tuple(w.goal_region[:3]), tuple(w.goal_region[3:])) if len(w.goal_region) == 6 else None,
        obstacles=tuple(obstacles),
        motion_epoch=w.motion_epoch.to_sec(),
        frame=w.header.frame_id or "world",
    )
