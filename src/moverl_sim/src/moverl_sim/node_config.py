"""The simulator node's parameters (scripts/sim_node), read once and checked: the Python twin of the planning scene's
Tunables (moverl_planning_scene/src/tunables.cpp).

ROS-free: SimNodeConfig.from_params takes a parameter getter, ``get(name, default)``, with the node's names (``~mode``
for a private parameter, ``/robot/joints`` for the robot's). The node passes ``rospy.get_param``, the tests a dict's
``get``. Nothing here holds a default: the private parameters are the tunables of config/sim.yaml (each commented
there) and the values launch/sim.launch sets from its arguments (each documented there), and a missing one is an
error; the few optional parameters keep the defaults the node has always given them (each named below). A wrong value
is refused here, before the node builds anything, with the message the node has always given; checks that another
module owns are called, not copied (the tracker's options: moverl_sim.tracker; the robot's joints and URDF, and the
values Simulator rechecks: moverl_sim.core).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from .core import CONTROLS
from .tracker import TrackerOptions, TrackerOptionsError

__all__ = ["CONTROLS", "INTERFACES", "MODES", "SimNodeConfig", "SimNodeConfigError"]

#: The values ~mode and ~interface accept, and (moverl_sim.core's) ~control: moverl_gym/test/test_launch_args.py
#: compares MODES and CONTROLS with moverl_gym.launch_args.CHOICES.
MODES = ("lockstep", "realtime")
INTERFACES = ("extras", "standard")

#: What a parameter getter returns for a parameter that is not set: the default it is given.
_UNSET = object()


def _one_of(values: tuple) -> str:
    """A check's choices as its message names them: 'a' or 'b'."""
    return " or ".join(repr(v) for v in values)


class SimNodeConfigError(ValueError):
    """A parameter of the simulator node is missing or has a wrong value; the message names it (and its choices)."""


@dataclass(frozen=True)
class SimNodeConfig:
    """Every parameter the simulator node reads, checked (no field is changed after from_params)."""

    # ---- launch/sim.launch's arguments (each documented there)
    world_file: str  # world YAML file
    mode: str  # lockstep | realtime
    gui: bool  # PyBullet GUI window
    interface: str  # extras | standard (needs mode realtime)
    action: str  # the FollowJointTrajectory action served in real time
    sensed: bool  # the planning scene senses moving obstacles (obstacles:=octomap|both|sensed)
    publish_tracker: bool  # publish the observed objects as a person tracker would
    # ---- config/sim.yaml's tunables (each commented there; sim.launch's arguments override some)
    physics_hz: float
    control: str  # kinematic | dynamic
    tf_rate: float
    joint_state_rate: float
    publish_tf: bool
    cameras: bool
    mute_cameras: tuple  # fault injection: cameras never rendered
    motion_time_scale: float  # experiments: obstacles faster than declared
    camera_rate: float  # renders per simulated second of every camera (0: the world's)
    robot_visuals: str  # what the cameras (and the GUI) see of the robot
    simplified_faces: int  # robot_visuals simplified: triangles per visual mesh
    camera_renderer: str  # what draws the cameras' images
    moving_speed: float  # who moved: below it the robot rests
    reset_clearance_time: float  # teleports refused where a moving obstacle can reach the robot within this time (s)
    constraints: dict  # the FollowJointTrajectory action's default tolerances
    tracker: TrackerOptions | None  # ~tracker, read only with ~publish_tracker
    # ---- the robot (/robot, config/robots/<robot>.yaml), as the parameters hold them (moverl_sim.core checks them)
    joints: list
    base_link: str
    fixed_joint_positions: dict  # {} when not set
    home: list | None  # where the robot stands at start-up: ~initial_positions, else /robot/home, else None
    robot_description: str | None  # /robot_description, None when not set (then urdf is read)
    urdf: str | None  # /robot/urdf, None when not set

    @property
    def restart_motions_on_reset(self) -> bool:
        """Whether a reset restarts the obstacles' motions: not when the planning scene senses them. A person does
        not teleport back to the start of its walk under the cameras' eyes (the map would keep the space it walked
        away from as seen free, where it now stands hidden by the robot)."""
        return not self.sensed

    @classmethod
    def from_params(cls, get: Callable[[str, Any], Any]) -> SimNodeConfig:
        """The node's parameters, read with `get` and checked.

        Args:
            get: ``get(name, default)``, the value of the parameter `name` (``~x`` private, ``/robot/x``), `default`
                when it is not set (``rospy.get_param``; a dict's ``get`` in tests).

        Returns:
            The checked configuration.

        Raises:
            SimNodeConfigError: a parameter is missing or its value is wrong (the message names it).
        """

        def param(name, kind=str):
            value = get("~" + name, _UNSET)
            if value is _UNSET:
                raise SimNodeConfigError("parameter ~%s is not set (config/sim.yaml or launch/sim.launch)" % name)
            return kind(value)

        # The order of the reads and checks is the node's: a graph with several mistakes is told the same first one.
        world_file = param("world_file")
        mode = param("mode")
        gui = param("gui", bool)
        interface = param("interface")
        action = param("action")
        physics_hz = param("physics_hz", float)
        control = param("control")
        tf_rate = param("tf_rate", float)
        joint_state_rate = param("joint_state_rate", float)
        publish_tf = param("publish_tf", bool)
        cameras = param("cameras", bool)
        mute_cameras = param("mute_cameras", tuple)
        motion_time_scale = param("motion_time_scale", float)
        camera_rate = param("camera_rate", float)
        robot_visuals = param("robot_visuals")
        simplified_faces = param("simplified_faces", int)
        camera_renderer = param("camera_renderer")
        if not (math.isfinite(camera_rate) and camera_rate >= 0.0):
            raise SimNodeConfigError(
                "~camera_rate must be a number >= 0 (0: each camera's rate in the world file), got %r" % camera_rate
            )
        moving_speed = param("moving_speed", float)
        reset_clearance_time = param("reset_clearance_time", float)
        sensed = param("sensed", bool)
        if not reset_clearance_time >= 0.0:
            raise SimNodeConfigError("~reset_clearance_time must be >= 0 s, got %r" % reset_clearance_time)
        constraints = param("constraints", dict)
        if interface not in INTERFACES:
            raise SimNodeConfigError("~interface must be %s, got %r" % (_one_of(INTERFACES), interface))
        if interface == "standard" and mode != "realtime":
            raise SimNodeConfigError(
                "~interface standard needs ~mode realtime (a real robot's time does not stand still)"
            )
        if mode not in MODES:
            raise SimNodeConfigError("~mode must be %s, got %r" % (_one_of(MODES), mode))
        if control not in CONTROLS:
            raise SimNodeConfigError("~control must be %s, got %r" % (_one_of(CONTROLS), control))
        if not math.isfinite(physics_hz) or physics_hz <= 0:
            raise SimNodeConfigError("~physics_hz must be positive, got %r" % (physics_hz,))
        if not world_file:
            raise SimNodeConfigError("~world_file is required (path of a worlds/*.yaml file)")

        joints = get("/robot/joints", None)
        base_link = get("/robot/base_link", None)
        if not joints or not base_link:
            raise SimNodeConfigError(
                "/robot/joints and /robot/base_link must be set (rosparam load config/robots/<robot>.yaml)"
            )
        fixed_joint_positions = get("/robot/fixed_joint_positions", {}) or {}
        home = get("~initial_positions", get("/robot/home", None))
        robot_description = get("/robot_description", _UNSET)
        urdf = get("/robot/urdf", _UNSET)
        if robot_description is _UNSET and urdf is _UNSET:
            raise SimNodeConfigError("neither /robot_description nor /robot/urdf is set")

        publish_tracker = param("publish_tracker", bool)
        tracker = None
        if publish_tracker:
            try:
                tracker = TrackerOptions.from_dict(param("tracker", dict), "~tracker (config/sim.yaml)")
            except TrackerOptionsError as exc:
                raise SimNodeConfigError(str(exc)) from None

        return cls(
            world_file=world_file,
            mode=mode,
            gui=gui,
            interface=interface,
            action=action,
            sensed=sensed,
            publish_tracker=publish_tracker,
            physics_hz=physics_hz,
            control=control,
            tf_rate=tf_rate,
            joint_state_rate=joint_state_rate,
            publish_tf=publish_tf,
            cameras=cameras,
            mute_cameras=mute_cameras,
            motion_time_scale=motion_time_scale,
            camera_rate=camera_rate,
            robot_visuals=robot_visuals,
            simplified_faces=simplified_faces,
            camera_renderer=camera_renderer,
            moving_speed=moving_speed,
            reset_clearance_time=reset_clearance_time,
            constraints=constraints,
            tracker=tracker,
            joints=joints,
            base_link=base_link,
            fixed_joint_positions=fixed_joint_positions,
            home=home,
            robot_description=None if robot_description is _UNSET else robot_description,
            urdf=None if urdf is _UNSET else urdf,
        )

    def check_cameras(self, camera_ids: Iterable[str]) -> None:
        """Refuse a ~mute_cameras entry that names no camera of the world file (its cameras: `camera_ids`).

        Raises:
            SimNodeConfigError: naming the unknown ids, the world file and its cameras.
        """
        camera_ids = list(camera_ids)
        unknown = sorted(set(self.mute_cameras) - set(camera_ids))
        if unknown:
            raise SimNodeConfigError(
                "~mute_cameras: no camera %s in %s (its cameras: %s)"
                % (", ".join(unknown), self.world_file, ", ".join(camera_ids) or "none")
            )
