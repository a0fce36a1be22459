"""The simulator node's parameters (moverl_sim.node_config) are read and checked without a roscore: the shipped
config/sim.yaml with sim.launch's values and a robot config gives the expected config, every wrong value is refused
with the node's message, and the optional parameters keep their defaults."""

import dataclasses
import math
from pathlib import Path

import pytest
import yaml
from conftest import REPO_DIR

from moverl_sim.node_config import SimNodeConfig, SimNodeConfigError
from moverl_sim.tracker import TrackerOptions

pytestmark = pytest.mark.core

REPO = Path(REPO_DIR)
SIM_YAML = yaml.safe_load((REPO / "config" / "sim.yaml").read_text())
PANDA = yaml.safe_load((REPO / "config" / "robots" / "panda.yaml").read_text())["robot"]
#: What launch/sim.launch sets besides config/sim.yaml (its defaults; initial_positions only when given).
LAUNCH = {
    "world_file": str(REPO / "worlds" / "table.yaml"),
    "gui": False,
    "mode": "lockstep",
    "interface": "extras",
    "action": "/arm_controller/follow_joint_trajectory",
    "sensed": False,
    "publish_tracker": False,
}


def params(**changes):
    """The parameters of a graph launched with sim.launch's defaults and panda.yaml loaded as /robot (rosparam's
    names), `changes` applied by name (a value of None removes the parameter)."""
    out = {"~" + k: v for k, v in {**SIM_YAML, **LAUNCH}.items()}
    out.update({"/robot/" + k: v for k, v in PANDA.items()})
    for name, value in changes.items():
        name = name.replace("__", "/")
        if value is None:
            out.pop(name, None)
        else:
            out[name] = value
    return out


def config(values):
    return SimNodeConfig.from_params(values.get)


def refused(values):
    with pytest.raises(SimNodeConfigError) as err:
        config(values)
    return str(err.value)


def test_the_shipped_parameters_give_the_expected_config():
    cfg = config(params())
    assert (cfg.world_file, cfg.mode, cfg.interface, cfg.action) == (
        LAUNCH["world_file"],
        "lockstep",
        "extras",
        "/arm_controller/follow_joint_trajectory",
    )
    assert cfg.gui is False and cfg.sensed is False and cfg.publish_tracker is False
    assert cfg.physics_hz == 240.0 and isinstance(cfg.physics_hz, float)
    assert cfg.control == SIM_YAML["control"]
    assert (cfg.tf_rate, cfg.joint_state_rate, cfg.publish_tf, cfg.cameras) == (30.0, 100.0, True, True)
    assert cfg.mute_cameras == () and cfg.motion_time_scale == 1.0 and cfg.camera_rate == 0.0
    assert (cfg.robot_visuals, cfg.simplified_faces, cfg.camera_renderer) == ("simplified", 2000, "raster")
    assert cfg.moving_speed == SIM_YAML["moving_speed"]
    assert cfg.reset_clearance_time == SIM_YAML["reset_clearance_time"]
    assert cfg.constraints == SIM_YAML["constraints"]
    assert cfg.tracker is None  # read only with ~publish_tracker
    assert cfg.restart_motions_on_reset is True
    assert (cfg.joints, cfg.base_link) == (PANDA["joints"], PANDA["base_link"])
    assert cfg.fixed_joint_positions == PANDA["fixed_joint_positions"]
    assert cfg.home == PANDA["home"]
    assert (cfg.robot_description, cfg.urdf) == (None, PANDA["urdf"])


def test_every_tunable_of_sim_yaml_is_read():
    """No key of config/sim.yaml is left unread (a tunable nobody reads would change nothing), and nothing is read
    that neither it nor sim.launch sets."""
    values = params(**{"~publish_tracker": True})
    read = []
    SimNodeConfig.from_params(lambda name, default: read.append(name) or values.get(name, default))
    private = {name[1:] for name in read if name.startswith("~")}
    assert set(SIM_YAML) <= private
    assert private - set(SIM_YAML) == set(LAUNCH) | {"initial_positions"}


def test_the_config_is_frozen():
    cfg = config(params())
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.mode = "realtime"


@pytest.mark.parametrize("name", sorted(set(SIM_YAML) - {"tracker"} | set(LAUNCH)))
def test_a_missing_parameter_is_refused_naming_it(name):
    assert refused(params(**{"~" + name: None})) == (
        "parameter ~%s is not set (config/sim.yaml or launch/sim.launch)" % name
    )


@pytest.mark.parametrize(
    "changes, message",
    [
        (
            {"~camera_rate": -1.0},
            "~camera_rate must be a number >= 0 (0: each camera's rate in the world file), got -1.0",
        ),
        (
            {"~camera_rate": math.nan},
            "~camera_rate must be a number >= 0 (0: each camera's rate in the world file), got nan",
        ),
        ({"~reset_clearance_time": -0.1}, "~reset_clearance_time must be >= 0 s, got -0.1"),
        ({"~reset_clearance_time": math.nan}, "~reset_clearance_time must be >= 0 s, got nan"),
        ({"~interface": "minimal"}, "~interface must be 'extras' or 'standard', got 'minimal'"),
        (
            {"~interface": "standard"},
            "~interface standard needs ~mode realtime (a real robot's time does not stand still)",
        ),
        ({"~mode": "fast"}, "~mode must be 'lockstep' or 'realtime', got 'fast'"),
        ({"~control": "torque"}, "~control must be 'kinematic' or 'dynamic', got 'torque'"),
        ({"~physics_hz": 0}, "~physics_hz must be positive, got 0.0"),
        ({"~physics_hz": math.inf}, "~physics_hz must be positive, got inf"),
        ({"~world_file": ""}, "~world_file is required (path of a worlds/*.yaml file)"),
    ],
)
def test_a_wrong_value_is_refused_with_the_nodes_message(changes, message):
    assert refused(params(**changes)) == message


def test_the_standard_interface_in_real_time_is_accepted():
    cfg = config(params(**{"~interface": "standard", "~mode": "realtime"}))
    assert (cfg.interface, cfg.mode) == ("standard", "realtime")


def test_the_first_mistake_is_the_one_reported():
    """The node's order: a wrong interface is named before a wrong mode, the camera rate before a missing key read
    after it."""
    assert "~interface must be" in refused(params(**{"~interface": "x", "~mode": "x"}))
    assert "~camera_rate must be" in refused(params(**{"~camera_rate": -1.0, "~moving_speed": None}))


ROBOT_MISSING = "/robot/joints and /robot/base_link must be set (rosparam load config/robots/<robot>.yaml)"


@pytest.mark.parametrize(
    "changes", [{"/robot/joints": None}, {"/robot/base_link": None}, {"/robot/joints": []}, {"/robot/base_link": ""}]
)
def test_a_robot_without_joints_or_base_link_is_refused(changes):
    assert refused(params(**changes)) == ROBOT_MISSING


@pytest.mark.parametrize("value", ["unset", None, {}])
def test_fixed_joint_positions_default_to_none(value):
    """Not set, set to null (a YAML `fixed_joint_positions:` with no value) or empty: no fixed joints."""
    values = params(**{"/robot/fixed_joint_positions": None})
    if value != "unset":
        values["/robot/fixed_joint_positions"] = value
    assert config(values).fixed_joint_positions == {}


def test_the_robot_starts_at_initial_positions_else_home_else_where_it_loads():
    start = [0.1] * len(PANDA["joints"])
    assert config(params(**{"~initial_positions": start})).home == start
    assert config(params()).home == PANDA["home"]
    assert config(params(**{"/robot/home": None})).home is None


def test_robot_description_is_used_before_the_robot_configs_urdf():
    cfg = config(params(**{"/robot_description": "<robot name='r'/>"}))
    assert (cfg.robot_description, cfg.urdf) == ("<robot name='r'/>", PANDA["urdf"])
    cfg = config(params(**{"/robot_description": "<robot name='r'/>", "/robot/urdf": None}))
    assert (cfg.robot_description, cfg.urdf) == ("<robot name='r'/>", None)
    assert refused(params(**{"/robot/urdf": None})) == "neither /robot_description nor /robot/urdf is set"


def test_the_tracker_is_read_only_when_published():
    cfg = config(params(**{"~publish_tracker": True}))
    assert cfg.tracker == TrackerOptions.from_dict(SIM_YAML["tracker"])
    assert config(params(**{"~tracker": None})).tracker is None
    assert refused(params(**{"~publish_tracker": True, "~tracker": None})) == (
        "parameter ~tracker is not set (config/sim.yaml or launch/sim.launch)"
    )


def test_a_wrong_tracker_option_is_refused_by_the_trackers_check():
    message = refused(params(**{"~publish_tracker": True, "~tracker": {**SIM_YAML["tracker"], "rat": 30.0}}))
    assert message.startswith("~tracker (config/sim.yaml): unknown key(s) rat"), message


def test_sensed_obstacles_keep_their_motions_on_reset():
    assert config(params(**{"~sensed": True})).restart_motions_on_reset is False


def test_muted_cameras_must_be_cameras_of_the_world():
    cfg = config(params(**{"~mute_cameras": ["cam_b", "cam_x", "cam_a"]}))
    assert cfg.mute_cameras == ("cam_b", "cam_x", "cam_a")
    cfg.check_cameras(["cam_a", "cam_b", "cam_x"])
    with pytest.raises(SimNodeConfigError) as err:
        cfg.check_cameras(c for c in ["cam_a", "cam_b"])
    assert str(err.value) == "~mute_cameras: no camera cam_x in %s (its cameras: cam_a, cam_b)" % LAUNCH["world_file"]
    with pytest.raises(SimNodeConfigError) as err:
        cfg.check_cameras([])
    assert str(err.value).endswith("(its cameras: none)")
    config(params()).check_cameras([])  # nothing muted: any world
