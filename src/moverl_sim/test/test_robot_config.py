"""Robot configs are as strict as world files (moverl_sim.robot_config): an unknown, missing or malformed key is an
error naming the file, the key and the valid keys; every shipped and test robot config is valid."""

import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from conftest import REPO_DIR

from moverl_sim.robot_config import KEYS, REQUIRED, RobotConfigError, load_robot_config, parse_robot

pytestmark = pytest.mark.core

REPO = Path(REPO_DIR)
SHIPPED = sorted((REPO / "config" / "robots").glob("*.yaml"))
TEST_ROBOTS = [
    p
    for p in sorted((REPO / "src/moverl_gym/test/robots").glob("*.yaml"))
    if isinstance(yaml.safe_load(p.read_text()), dict)
]
PANDA = REPO / "config" / "robots" / "panda.yaml"
SCRIPT = REPO / "src" / "moverl_sim" / "scripts" / "robot_description"


@pytest.mark.parametrize("path", SHIPPED + TEST_ROBOTS, ids=lambda p: p.stem)
def test_every_robot_config_of_the_repo_is_valid(path):
    robot = load_robot_config(path)
    assert set(REQUIRED) <= set(robot) <= set(KEYS)
    if path in SHIPPED:
        assert "id_name" in robot  # it names the robot's env ids


def test_every_key_is_documented_in_panda_yaml():
    """config/robots/panda.yaml documents the format, key by key."""
    assert set(yaml.safe_load(PANDA.read_text())["robot"]) == set(KEYS)


def write(tmp_path, text: str) -> Path:
    path = tmp_path / "my_arm.yaml"
    path.write_text(text)
    return path


def panda_with(tmp_path, old: str, new: str) -> Path:
    text = PANDA.read_text()
    assert old in text
    return write(tmp_path, text.replace(old, new))


@pytest.mark.parametrize(
    "old,new,words",
    [
        ("acceleration_limits:", "acceleration_limit:", ["'robot.acceleration_limit': unknown key", "did you mean"]),
        ("  ee_link: panda_link8\n", "", ["'robot.ee_link': missing required key", "required: name, urdf"]),
        ("robot:\n", "robots:\n", ["'robots': unknown key", "valid keys: robot"]),
        ("home: [0.0, -0.785,", "home: [-0.785,", ["'robot.home': expected 7 numbers (one per joint), got 6"]),
        ("[15.0, 7.5,", "[-15.0, 7.5,", ["'robot.acceleration_limits': must be > 0"]),
        ("joints: [panda_joint1,", "joints: [panda_joint2,", ["'robot.joints': joint(s) listed twice: panda_joint2"]),
        ("{panda_finger_joint1: 0.04,", "{panda_joint1: 0.04,", ["controlled joint(s) cannot be fixed: panda_joint1"]),
        ("panda_finger_joint2: 0.04}", "panda_finger_joint2: open}", ["fixed_joint_positions.panda_finger_joint2"]),
        ("  urdf: pybullet_data", "  urdf: [pybullet_data", ["YAML syntax error"]),
        ("ee_link: panda_link8", "ee_link: ''", ["'robot.ee_link': expected a non-empty string"]),
    ],
)
def test_a_wrong_key_is_named(tmp_path, old, new, words):
    path = panda_with(tmp_path, old, new)
    with pytest.raises(RobotConfigError) as err:
        load_robot_config(path)
    msg = str(err.value)
    assert msg.startswith(str(path)) and all(w in msg for w in words), msg


def test_valid_keys_are_listed(tmp_path):
    with pytest.raises(RobotConfigError, match="valid keys: " + ", ".join(KEYS)):
        load_robot_config(panda_with(tmp_path, "  home:", "  homme: [0]\n  home:"))


def test_missing_file():
    with pytest.raises(RobotConfigError, match="robot config file not found"):
        load_robot_config("/nonexistent/my_arm.yaml")


def test_a_parameter_mapping_is_checked_the_same_way():
    robot = yaml.safe_load(PANDA.read_text())["robot"]
    assert parse_robot(robot, "/robot") == load_robot_config(PANDA)
    with pytest.raises(RobotConfigError, match=r"/robot: '/robot/extra': unknown key"):
        parse_robot({**robot, "extra": 1}, "/robot", prefix="/robot/")


def test_robot_description_refuses_a_wrong_config(tmp_path):
    """robot_description checks the config (launch/robot.launch runs it while roslaunch reads the file)."""
    path = panda_with(tmp_path, "acceleration_limits:", "acceleration_limit:")
    r = subprocess.run([sys.executable, str(SCRIPT), "--robot-config", str(path)], capture_output=True, text=True)
    assert r.returncode == 1 and r.stdout == "" and "'robot.acceleration_limit': unknown key" in r.stderr, r.stderr
