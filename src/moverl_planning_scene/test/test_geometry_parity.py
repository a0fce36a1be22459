"""Geometry parity (issue #15): the planning scene's collision shape of every link contains PyBullet's. No roscore.

For every way a URDF can describe collision geometry (fixtures/geometry: primitives, binary and ASCII STL, STL with a
"solid" header, OBJ with one and several objects, COLLADA, mesh scale, collision origins, several collision elements
per link, non-identity inertial origins), for every robot config the repo ships, the test robots, and pybullet_data's
xArm6 (V-HACD OBJ files of several convex pieces), moverl_gym.geometry_parity compares at random configurations what
PyBullet built (its hull vertices, boxes, spheres and points inside its pieces) with the scene's shapes through
scene_geometry, the ROS-free command-line view of the scene's core: contained (no PyBullet point outside the scene's
shape of its link), tight (the scene is no larger than PyBullet's shape plus its margin and 1 mm) and equal link frames.

Why this design (src/moverl_planning_scene/README.md, "Geometry parity"): gtest cannot run PyBullet, and exported
point sets would test a copy of PyBullet's rules rather than PyBullet; so the Python tier builds PyBullet's shapes and
asks the C++ core about them.
"""

import filecmp
import importlib.util
from pathlib import Path

import pybullet_data
import pytest
import yaml

from moverl_gym.geometry_parity import compare, format_report
from moverl_sim.robot_config import load_robot_config
from moverl_sim.urdf import resolve_uri

pytestmark = pytest.mark.core

HERE = Path(__file__).resolve().parent
FIXTURES = HERE / "fixtures" / "geometry"
REPO = HERE.parents[2]
ROBOT_CONFIGS = [
    p
    for p in sorted((REPO / "config" / "robots").glob("*.yaml"))
    + sorted((REPO / "src" / "moverl_gym" / "test" / "robots").glob("*.yaml"))
    if isinstance(yaml.safe_load(p.read_text()), dict) and "robot" in yaml.safe_load(p.read_text())
]


def _check(rep):
    text = format_report(rep)
    assert rep["contained"], "PyBullet's shape sticks out of the scene's:\n" + text
    assert rep["tight"], "the scene's shape is larger than PyBullet's plus its margin and 1 mm:\n" + text
    assert rep["fk_error_m"] < 1e-6, text
    assert rep["links"], "no link with collision geometry"
    for name, r in rep["links"].items():
        assert r["scene_shape"], f"{name}: PyBullet has a shape, the scene none"
        assert not r["pybullet_shape"] or r["pybullet_points"] > 0, name


@pytest.mark.parametrize("urdf", sorted(FIXTURES.glob("*.urdf")), ids=lambda p: p.stem)
def test_fixture(urdf):
    rep = compare(urdf, base_link="base", configs=3, seed=1)
    _check(rep)
    if urdf.stem != "stl_ascii":
        assert all(r["pybullet_shape"] for r in rep["links"].values())


def test_ascii_stl_is_no_shape_for_pybullet_but_is_for_the_scene():
    """PyBullet reads binary STL only (an ASCII file gives no collision shape, with a warning): the scene keeps the
    mesh, so the simulator's contacts are a subset of the scene's (false alarms, no misses)."""
    rep = compare(FIXTURES / "stl_ascii.urdf", base_link="base", configs=1)
    assert not rep["links"]["link1"]["pybullet_shape"] and rep["links"]["link1"]["scene_shape"]


@pytest.mark.parametrize("config", ROBOT_CONFIGS, ids=lambda p: p.stem)
def test_robot_config(config):
    rc = load_robot_config(config)
    rep = compare(resolve_uri(rc["urdf"]), rc["joints"], rc["base_link"], rc.get("fixed_joint_positions"), configs=3)
    _check(rep)


def test_vhacd_pieces_of_pybullet_data_xarm6():
    urdf = Path(pybullet_data.getDataPath()) / "xarm" / "xarm6_robot.urdf"
    rep = compare(urdf, [f"joint{i}" for i in range(1, 7)], configs=2)
    _check(rep)


def test_fixtures_are_what_the_generator_writes(tmp_path):
    spec = importlib.util.spec_from_file_location("make_fixtures", FIXTURES / "make_fixtures.py")
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    for f in gen.write_all(tmp_path):
        committed = FIXTURES / f.relative_to(tmp_path)
        assert committed.is_file() and filecmp.cmp(f, committed, shallow=False), (
            f"{committed} is stale: rerun src/moverl_planning_scene/test/fixtures/geometry/make_fixtures.py"
        )
