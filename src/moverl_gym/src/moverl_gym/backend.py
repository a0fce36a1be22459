"""The env's connection to the ROS graph: persistent service proxies, nothing else.

Per env step exactly one call is made (the shield's ~step); reset makes a handful. Proxies are created
once; a broken connection is re-opened once, and if that fails the error is raised at once (no waiting,
no retries loops): the shield fails closed, the env raises.
"""

from __future__ import annotations

import os

import numpy as np

from .graph import GraphError

SHIELD_STEP = "/shield/step"
SHIELD_RESET = "/shield/reset"
SCENE_CHECK = "/planning_scene/check_state"
SCENE_FK = "/planning_scene/fk"
SIM_WORLD = "/sim/get_world"
REQUIRED_SERVICES = (SHIELD_STEP, SHIELD_RESET, SCENE_CHECK, SCENE_FK, SIM_WORLD)

_NODE_MASTER: str | None = None  # rospy allows one node (one master) per process


class _Proxy:
    def __init__(self, name, srv_type):
        import rospy

        self._rospy = rospy
        self.name = name
        self.type = srv_type
        self._proxy = rospy.ServiceProxy(name, srv_type, persistent=True)

    def __call__(self, request):
        try:
            return self._proxy.call(request)
        except (self._rospy.ServiceException, self._rospy.ROSException, OSError):
            self._proxy.close()
            self._proxy = self._rospy.ServiceProxy(self.name, self.type, persistent=True)
            try:
                return self._proxy.call(request)
            except (self._rospy.ServiceException, self._rospy.ROSException, OSError) as exc:
                raise GraphError(f"service {self.name} is unreachable ({exc}); is the MoveRL graph up?") from exc

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


class RosBackend:
    """Persistent proxies to the shield, the planning scene and the simulator."""

    def __init__(self, wait_timeout: float = 30.0):
        import rospy
        from moverl_msgs import srv
        from moverl_msgs.srv import CheckState, GetFK, GetWorld, ResetRobot, ShieldStep

        self._srv = srv

        for name in REQUIRED_SERVICES:
            try:
                rospy.wait_for_service(name, timeout=wait_timeout)  # once, at construction
            except rospy.ROSException as exc:
                raise GraphError(f"service {name} is not available after {wait_timeout} s") from exc
        self._step = _Proxy(SHIELD_STEP, ShieldStep)
        self._reset = _Proxy(SHIELD_RESET, ResetRobot)
        self._check = _Proxy(SCENE_CHECK, CheckState)
        self._fk = _Proxy(SCENE_FK, GetFK)
        self._world = _Proxy(SIM_WORLD, GetWorld)
        self.robot_description = rospy.get_param("/robot_description")
        self.joints = list(rospy.get_param("/robot/joints"))
        self.home = list(rospy.get_param("/robot/home"))
        self.shield_enabled = bool(rospy.get_param("/shield/enabled", True))

    def step(self, target: np.ndarray, duration: float):
        return self._step(self._srv.ShieldStepRequest(target=list(map(float, target)), duration=float(duration)))

    def reset_robot(self, q: np.ndarray):
        return self._reset(self._srv.ResetRobotRequest(positions=list(map(float, q))))

    def check_state(self, q: np.ndarray):
        return self._check(self._srv.CheckStateRequest(positions=list(map(float, q))))

    def fk(self, q: np.ndarray):
        return self._fk(self._srv.GetFKRequest(positions=list(map(float, q)), links=[]))

    def world(self):
        return self._world(self._srv.GetWorldRequest()).world

    def close(self):
        for p in (self._step, self._reset, self._check, self._fk, self._world):
            p.close()
