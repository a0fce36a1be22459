"""Start-up errors of the live graph are clear and quick (roslaunch on a free port; no roscore of our own).

A malformed or missing world file, a URDF that does not parse and an unknown world name each give an error
that names the problem within seconds, and nothing is left running.
"""

import time

import gymnasium as gym
import pytest

import moverl_gym  # noqa: F401
from moverl_gym import ros_backend as ros
from moverl_gym.graph import GraphError, LaunchedGraph
from moverl_gym.launch_args import LaunchArgError
from moverl_gym.paths import config_file

pytestmark = pytest.mark.quick


def start(tmp_path, **args):
    t0 = time.monotonic()
    with pytest.raises(GraphError) as err:
        LaunchedGraph(args, wait_for=ros.REQUIRED_SERVICES, timeout=60).close()
    assert time.monotonic() - t0 < 30, "a failed start-up is reported within seconds"
    return str(err.value)


def test_malformed_world_file(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\nobjects:\n  - id: x\n    shape: blob\n    size: [1]\n    xyz: [0, 0, 0]\n")
    msg = start(tmp_path, world_file=str(bad))
    assert "blob" in msg and str(bad) in msg


def test_missing_world_file_is_refused_before_launching(tmp_path):
    t0 = time.monotonic()
    with pytest.raises(LaunchArgError, match="nope.yaml"):
        LaunchedGraph(dict(world_file=str(tmp_path / "nope.yaml")))
    assert time.monotonic() - t0 < 1.0


def test_urdf_that_does_not_parse(tmp_path):
    urdf = tmp_path / "broken.urdf"
    urdf.write_text('<robot name="x"><link name="a"/><joint name="j" type="revolute"><parent link="a"/></robot')
    robot = tmp_path / "robot.yaml"
    robot.write_text(
        config_file("robots/panda.yaml").read_text().replace("pybullet_data://franka_panda/panda.urdf", str(urdf))
    )
    msg = start(tmp_path, robot_config=str(robot))
    assert "broken.urdf" in msg and "not valid" in msg


def test_unknown_world_name_is_refused_before_launching():
    with pytest.raises(ValueError, match="worlds available"):
        gym.make("MoveRL/PandaReachTable-v0", world="atlantis", graph="launch")
