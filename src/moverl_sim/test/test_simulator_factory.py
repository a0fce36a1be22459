"""Simulator.from_robot builds the simulator the node runs: the URDF resolved as the node resolves it (package:// meshes
through the ROS packages), a scratch file it removes, the node's errors.

No roscore. The repository's robot configs (their URDFs name their meshes package://...) and a robot whose mesh is in a
ROS package (a fake one on ROS_PACKAGE_PATH) that PyBullet cannot find from the URDF's folder.
"""

import os
import tempfile
import xml.etree.ElementTree as ET

import pytest
from conftest import REPO_DIR

from moverl_sim.core import Simulator
from moverl_sim.robot_config import load_robot_config
from moverl_sim.settings import sim_settings, simulator_for
from moverl_sim.urdf import UrdfError, resolve_uri, rewrite_mesh_paths, robot_description

pytestmark = pytest.mark.core

PKG = "fake_moverl_mesh_pkg"
BOX_OBJ = "".join("v %g %g %g\n" % (x, y, z) for z in (0.0, 0.1) for x, y in ((-1, -1), (1, -1), (1, 1), (-1, 1))) + (
    "f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n"
)
URDF = (
    """<robot name="r">
  <link name="base"><collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link>
  <link name="arm"><collision><geometry><mesh filename="package://%s/meshes/box.obj"/></geometry></collision></link>
  <joint name="j" type="revolute"><parent link="base"/><child link="arm"/><origin xyz="0 0 0.2"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" velocity="1" effort="1"/></joint>
</robot>
"""
    % PKG
)


def shapes(sim):
    """Link name -> PyBullet's collision shape data of the link (mesh file names included)."""
    return {name: sim.client.getCollisionShapeData(sim.robot, i) for i, name in sim.link_names.items()}


def as_the_node_did(rc, **settings):
    """The simulator node's construction before Simulator.from_robot: robot_description, rewrite_mesh_paths, a file."""
    text = rewrite_mesh_paths(robot_description(rc["urdf"]), source=rc["urdf"])
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "robot.urdf")
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(text)
        return Simulator(path, rc["joints"], rc["base_link"], rc.get("fixed_joint_positions"), None, **settings)


@pytest.fixture
def scratch(tmp_path, monkeypatch):
    """The folder tempfile makes its folders in, for this test only: what a build leaves there is seen."""
    folder = tmp_path / "scratch"
    folder.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    return folder


@pytest.mark.parametrize("robot", ["panda", "xarm6"])
def test_repo_robot_builds_as_the_node_builds_it(robot, scratch):
    rc = load_robot_config(os.path.join(REPO_DIR, "config", "robots", robot + ".yaml"))
    with open(resolve_uri(rc["urdf"]), encoding="utf-8") as fh:
        raw = ET.fromstring(fh.read())
    assert any(m.get("filename").startswith("package://") for m in raw.iter("mesh")), "the fixture needs package://"
    sim = simulator_for(rc, None)
    node = as_the_node_did(rc, **sim_settings())
    try:
        assert sim.link_names == node.link_names
        assert shapes(sim) == shapes(node)
        assert any(data for data in shapes(sim).values())
        assert list(scratch.iterdir()) == []  # the scratch file is gone once the simulator is built
    finally:
        sim.close()
        node.close()


@pytest.fixture
def ros_package_robot(tmp_path, monkeypatch):
    """A robot URDF (in a folder of its own) whose arm link's collision mesh is package://fake_moverl_mesh_pkg/..., a
    ROS package on ROS_PACKAGE_PATH: (robot config mapping, the mesh's path)."""
    pytest.importorskip("rospkg", reason="rospkg (python3-rospkg) is needed for package:// lookups")
    pkg = tmp_path / "ros" / PKG
    (pkg / "meshes").mkdir(parents=True)
    (pkg / "package.xml").write_text(
        '<?xml version="1.0"?><package format="2"><name>%s</name>'
        "<version>0.0.0</version><description>x</description>"
        '<maintainer email="a@b.c">a</maintainer><license>BSD</license></package>' % PKG
    )
    (pkg / "meshes" / "box.obj").write_text(BOX_OBJ)
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "ros"))
    (tmp_path / "robot").mkdir()
    urdf = tmp_path / "robot" / "robot.urdf"
    urdf.write_text(URDF)
    return {"urdf": str(urdf), "joints": ["j"], "base_link": "base"}, str(pkg / "meshes" / "box.obj")


def test_ros_package_mesh_is_found_from_a_file_and_from_a_description(ros_package_robot, scratch):
    rc, mesh = ros_package_robot
    settings = {**sim_settings(), "robot_visuals": "visual"}  # PyBullet reads the URDF as it is (no visuals rewritten)
    # Why the factory: PyBullet alone looks for the mesh under the URDF's folder, and refuses the URDF.
    with pytest.raises(ValueError, match="PyBullet cannot load the URDF"):
        Simulator(rc["urdf"], rc["joints"], rc["base_link"], None, None, **settings)
    built = [
        Simulator.from_robot(rc, None, **settings),  # /robot/urdf
        Simulator.from_robot(  # /robot_description (the file is not read)
            {**rc, "urdf": None}, None, description=URDF, description_name="/robot_description", **settings
        ),
    ]
    try:
        for sim in built:
            (arm,) = shapes(sim)["arm"]
            assert arm[4].decode() == mesh
        assert list(scratch.iterdir()) == []
    finally:
        for sim in built:
            sim.close()


def test_errors_leave_no_scratch(ros_package_robot, scratch, monkeypatch):
    rc, _ = ros_package_robot
    with pytest.raises(UrdfError, match="/robot_description: mesh .* does not exist"):
        Simulator.from_robot(
            rc, None, description=URDF.replace("box.obj", "gone.obj"), description_name="/robot_description"
        )
    with pytest.raises(UrdfError, match="URDF file not found"):
        Simulator.from_robot({**rc, "urdf": rc["urdf"] + ".gone"}, None, **sim_settings())
    with pytest.raises(ValueError, match="joint 'nope' is not in the URDF"):
        Simulator.from_robot({**rc, "joints": ["nope"]}, None, **sim_settings())
    assert list(scratch.iterdir()) == []
