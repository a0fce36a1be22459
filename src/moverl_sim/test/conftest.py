"""Shared fixtures. No roscore needed; works with or without devel/setup.bash sourced."""

import os
import sys

import pytest

PKG_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REPO_DIR = os.path.dirname(os.path.dirname(PKG_DIR))
SRC = os.path.join(PKG_DIR, "src")
if SRC not in sys.path:
    sys.path.insert(0, SRC)

TABLE_WORLD = os.path.join(REPO_DIR, "worlds", "table.yaml")
PANDA_URI = "pybullet_data://franka_panda/panda.urdf"
JOINTS = ["panda_joint%d" % i for i in range(1, 8)]
FIXED = {"panda_finger_joint1": 0.04, "panda_finger_joint2": 0.04}
HOME = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]


@pytest.fixture(scope="session")
def panda_urdf(tmp_path_factory):
    from moverl_sim.urdf import robot_description

    path = tmp_path_factory.mktemp("urdf") / "panda.urdf"
    path.write_text(robot_description(PANDA_URI))
    return str(path)


@pytest.fixture(scope="session")
def table_world():
    from moverl_sim.world import load_world

    return load_world(TABLE_WORLD)


def make_sim(panda_urdf, world, **kwargs):
    from moverl_sim.core import Simulator
    from moverl_sim.settings import sim_settings

    return Simulator(panda_urdf, JOINTS, "panda_link0", FIXED, world, **{**sim_settings(), **kwargs})


@pytest.fixture(scope="module")
def sim(panda_urdf, table_world):
    s = make_sim(panda_urdf, table_world)
    yield s
    s.close()


@pytest.fixture
def home_sim(sim):
    sim.reset_robot(HOME)
    return sim
