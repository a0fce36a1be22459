"""A robot's shoulder, reach and base radius from its model (moverl_sim.workspace). No roscore."""

import math
import os

import numpy as np
import pytest
from conftest import REPO_DIR

from moverl_sim.core import Simulator
from moverl_sim.robot_config import load_robot_config, parse_robot
from moverl_sim.settings import sim_settings
from moverl_sim.urdf import robot_description
from moverl_sim.workspace import Workspace, _Kinematics

pytestmark = pytest.mark.core

ROBOTS = {
    "panda": os.path.join(REPO_DIR, "config", "robots", "panda.yaml"),
    "xarm6": os.path.join(REPO_DIR, "config", "robots", "xarm6.yaml"),
    "kuka_iiwa": os.path.join(REPO_DIR, "src", "moverl_gym", "test", "robots", "kuka_iiwa.yaml"),
}
# Where joint 2's axis crosses joint 1's, from the URDFs' joint origins: panda_joint1 at z 0.333 and panda_joint2 at
# its origin; xArm6 joint1 at z 0.267 and joint2 at its origin; iiwa joint 1 at z 0.1575 and joint 2 0.2025 above it.
SHOULDERS = {
    "panda": ((0.0, 0.0, 0.333), "panda_link2"),
    "xarm6": ((0.0, 0.0, 0.267), "link2"),
    "kuka_iiwa": ((0.0, 0.0, 0.36), "lbr_iiwa_link_2"),
}


@pytest.fixture(scope="module", params=sorted(ROBOTS))
def robot(request, tmp_path_factory):
    cfg = load_robot_config(ROBOTS[request.param])
    path = tmp_path_factory.mktemp("ws") / "robot.urdf"
    path.write_text(robot_description(cfg["urdf"]))
    sim = Simulator(
        str(path), cfg["joints"], cfg["base_link"], cfg.get("fixed_joint_positions") or {}, **sim_settings()
    )
    yield request.param, cfg, Workspace.of_robot(cfg), _Kinematics(sim, cfg["ee_link"], cfg["home"])
    sim.close()


def test_shoulder_is_where_the_first_two_axes_cross(robot):
    name, _, ws, _ = robot
    xyz, link = SHOULDERS[name]
    assert ws.shoulder == pytest.approx(xyz, abs=1e-6)
    assert ws.shoulder_link == link


def test_reach_bounds_every_configuration_and_is_attained(robot):
    """No random configuration puts any point of the geometry farther from the shoulder than the reach (nor the flange
    farther than the flange reach); the configuration it names gets there; random search comes within 3 cm of it."""
    _, _, ws, kin = robot
    centre = np.array(ws.shoulder)
    rng = np.random.default_rng(1)
    farthest = flange = 0.0
    for _ in range(1500):
        kin.set(rng.uniform(kin.lower, kin.upper))
        pts, pad = kin._points(False)
        farthest = max(farthest, float(np.max(np.linalg.norm(pts - centre, axis=1) + pad)))
        tip, _ = kin._points(True)
        flange = max(flange, float(np.linalg.norm(tip[0] - centre)))
    assert farthest <= ws.reach + 1e-6 and flange <= ws.flange_reach + 1e-6
    assert farthest > ws.reach - 0.03 and flange > ws.flange_reach - 0.03
    kin.set(ws.reach_q)
    pts, pad = kin._points(False)
    assert float(np.max(np.linalg.norm(pts - centre, axis=1) + pad)) == pytest.approx(ws.reach, abs=1e-6)
    assert all(lo - 1e-9 <= q <= hi + 1e-9 for q, lo, hi in zip(ws.reach_q, kin.lower, kin.upper))
    assert ws.flange_reach < ws.reach


def test_panda_figures():
    """The Panda's flange reach is Franka's datasheet figure (855 mm); its hand adds about 12 cm; its base's housing
    reaches 15.5 cm behind the base axis (coverage used 15 cm before the figures were derived)."""
    ws = Workspace.of_robot(load_robot_config(ROBOTS["panda"]))
    assert ws.flange_reach == pytest.approx(0.855, abs=0.005)
    assert 0.10 < ws.reach - ws.flange_reach < 0.14
    assert ws.base_radius == pytest.approx(0.155, abs=0.003)


ARM = """<?xml version="1.0"?>
<robot name="arm">
  <link name="base">
    <inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
    <collision><origin xyz="-0.05 0 0.05"/><geometry><box size="0.2 0.1 0.1"/></geometry></collision>
  </link>
  <link name="l1"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>
    </inertial></link>
  <link name="l2">
    <inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
    <collision><origin xyz="0.2 0 0"/><geometry><box size="0.4 0.04 0.04"/></geometry></collision>
  </link>
  <link name="l3"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>
    </inertial></link>
  <link name="l4">
    <inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
    <collision><geometry><sphere radius="0.05"/></geometry></collision>
  </link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" velocity="1" effort="10"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" velocity="1" effort="10"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0.4 0 0"/>
    <axis xyz="0 1 0"/><limit lower="0.5" upper="1.5" velocity="1" effort="10"/></joint>
  <joint name="j4" type="prismatic"><parent link="l3"/><child link="l4"/><origin xyz="0.3 0 0"/>
    <axis xyz="1 0 0"/><limit lower="0" upper="0.1" velocity="1" effort="10"/></joint>
</robot>
"""


def test_a_model_with_a_known_answer(tmp_path):
    """Joint 2 turns at joint 1's origin (the shoulder, 0.3 m up), a 0.4 m upper arm, a forearm bent 0.5 to 1.5 rad
    at the elbow ending in a 0.3 + (0 to 0.1) m slide that carries a 5 cm sphere: the farthest the sphere gets is with
    the elbow least bent and the slide out."""
    (tmp_path / "arm.urdf").write_text(ARM)
    cfg = parse_robot(
        {
            "name": "arm",
            "urdf": str(tmp_path / "arm.urdf"),
            "joints": ["j1", "j2", "j3", "j4"],
            "base_link": "base",
            "ee_link": "l4",
            "home": [0.0, 0.0, 1.0, 0.05],
        },
        "test",
    )
    ws = Workspace.of_robot(cfg)
    assert ws.shoulder == pytest.approx((0.0, 0.0, 0.3), abs=1e-6) and ws.shoulder_link == "l2"
    tip = math.hypot(0.4 + 0.4 * math.cos(0.5), 0.4 * math.sin(0.5))
    assert ws.flange_reach == pytest.approx(tip, abs=1e-5)
    assert ws.reach == pytest.approx(tip + 0.05, abs=1e-5)
    assert ws.reach_q[2] == pytest.approx(0.5, abs=1e-6) and ws.reach_q[3] == pytest.approx(0.1, abs=1e-6)
    assert ws.base_radius == pytest.approx(math.hypot(0.15, 0.05), abs=1e-6)


def test_wrong_end_effector_link_is_refused(tmp_path):
    (tmp_path / "arm.urdf").write_text(ARM)
    cfg = {"urdf": str(tmp_path / "arm.urdf"), "joints": ["j1"], "base_link": "base", "ee_link": "hand", "home": [0]}
    with pytest.raises(ValueError, match="'hand' is not in the URDF; its links are"):
        Workspace.of_robot(cfg)
