import math
import os
from pathlib import Path

import pytest
from conftest import TABLE_WORLD

from moverl_sim.world import World, WorldFileError, load_world, rpy_to_quaternion, sensing_problems

pytestmark = pytest.mark.core


def test_table_world_is_parsed():
    w = load_world(TABLE_WORLD)
    assert isinstance(w, World)
    assert w.name == "table" and w.frame == "world"
    assert w.goal == (0.4, 0.2, 0.2)
    assert len(w.objects) == 1
    t = w.object("table")
    assert t.shape == "box" and t.size == (1.5, 0.8, 0.03)
    assert t.xyz == (0.35, 0.0, -0.015) and t.rpy == (0.0, 0.0, 0.0)
    assert t.observed is False
    assert t.quaternion == pytest.approx((0.0, 0.0, 0.0, 1.0))
    assert w.source == TABLE_WORLD


def test_all_shapes_and_defaults(tmp_path):
    p = tmp_path / "w.yaml"
    p.write_text(
        "name: w\nobjects:\n"
        "  - {id: s, shape: sphere, size: [0.1], xyz: [0.5, 0, 0.3]}\n"
        "  - {id: c, shape: cylinder, size: [0.4, 0.05], xyz: [0.4, 0.3, 0.2], rpy: [0, 0, 1.5707963267948966]}\n"
    )
    w = load_world(p)
    assert w.frame == "world" and w.goal is None
    s, c = w.objects
    assert s.size == (0.1,) and s.observed is True
    assert c.size == (0.4, 0.05)
    h = math.sqrt(0.5)
    assert c.quaternion == pytest.approx((0.0, 0.0, h, h))


def test_goal_region(tmp_path):
    p = tmp_path / "w.yaml"
    p.write_text("name: w\ngoal_region: {low: [0.2, -0.4, 0.1], high: [0.5, 0.1, 0.4]}\n")
    w = load_world(p)
    assert w.goal is None and w.goal_region == ((0.2, -0.4, 0.1), (0.5, 0.1, 0.4))
    assert load_world(TABLE_WORLD).goal_region is None


def test_rpy_to_quaternion_roll_pitch():
    assert rpy_to_quaternion((math.pi, 0, 0)) == pytest.approx((1, 0, 0, 0), abs=1e-12)
    assert rpy_to_quaternion((0, math.pi / 2, 0)) == pytest.approx((0, math.sqrt(0.5), 0, math.sqrt(0.5)))


OBJ = "  - {id: box1, shape: box, size: [0.1, 0.1, 0.1], xyz: [0.5, 0, 0.2]}\n"
BAD_WORLDS = {
    # case: (file text, substring the error must contain)
    "yaml_syntax": ("name: w\nobjects: [\n  - {id: a\n", "YAML syntax error"),
    "not_mapping": ("- a\n- b\n", "mapping"),
    "missing_name": ("objects: []\n", "'name'"),
    "unknown_top_key": ("name: w\nobstacles: []\n", "'obstacles'"),
    "unknown_shape": (
        "name: w\nobjects:\n  - {id: a, shape: cone, size: [1], xyz: [0, 0, 0]}\n",
        "unknown shape 'cone'",
    ),
    "size_length": ("name: w\nobjects:\n  - {id: a, shape: box, size: [1, 1], xyz: [0, 0, 0]}\n", "(id a).size"),
    "size_length_cyl": (
        "name: w\nobjects:\n  - {id: a, shape: cylinder, size: [1], xyz: [0, 0, 0]}\n",
        "[height, radius]",
    ),
    "size_nonpositive": ("name: w\nobjects:\n  - {id: a, shape: sphere, size: [0], xyz: [0, 0, 0]}\n", "positive"),
    "size_negative": ("name: w\nobjects:\n  - {id: a, shape: box, size: [1, -1, 1], xyz: [0, 0, 0]}\n", "positive"),
    "duplicate_id": ("name: w\nobjects:\n" + OBJ + OBJ, "duplicate id 'box1'"),
    "nan_xyz": ("name: w\nobjects:\n  - {id: a, shape: sphere, size: [1], xyz: [.nan, 0, 0]}\n", "(id a).xyz"),
    "inf_size": ("name: w\nobjects:\n  - {id: a, shape: sphere, size: [.inf], xyz: [0, 0, 0]}\n", "non-finite"),
    "inf_goal": ("name: w\ngoal: [0, .inf, 0]\nobjects: []\n", "'goal'"),
    "xyz_length": ("name: w\nobjects:\n  - {id: a, shape: sphere, size: [1], xyz: [0, 0]}\n", "expected 3 numbers"),
    "string_number": (
        "name: w\nobjects:\n  - {id: a, shape: sphere, size: [big], xyz: [0, 0, 0]}\n",
        "expected numbers",
    ),
    "missing_xyz": ("name: w\nobjects:\n  - {id: a, shape: sphere, size: [1]}\n", "(id a).xyz': missing"),
    "unknown_object_key": (
        "name: w\nobjects:\n  - {id: a, shape: sphere, size: [1], xyz: [0, 0, 0], mass: 1}\n",
        ".mass",
    ),
    "bad_observed": (
        "name: w\nobjects:\n  - {id: a, shape: sphere, size: [1], xyz: [0, 0, 0], observed: maybe}\n",
        ".observed",
    ),
    "numeric_id": ("name: w\nobjects:\n  - {id: 3, shape: sphere, size: [1], xyz: [0, 0, 0]}\n", "objects[0].id"),
    "sensing_not_a_mapping": ("name: w\nsensing: 1.6\n", "'sensing'"),
    "sensing_unknown_key": ("name: w\nsensing: {speed: 1.6}\n", "sensing.speed"),
    "sensing_negative_speed": ("name: w\nsensing: {speed_bound: -1}\n", ">= 0"),
    "sensing_infinite_speed": ("name: w\nsensing: {speed_bound: .inf}\n", "sensing.speed_bound"),
    "sensing_unknown_not_bool": ("name: w\nsensing: {unknown_occupied: 1}\n", "sensing.unknown_occupied"),
    "goal_region_not_a_box": ("name: w\ngoal_region: [0, 0, 0]\n", "keys low and high"),
    "goal_region_extra_key": ("name: w\ngoal_region: {low: [0, 0, 0], high: [1, 1, 1], z: 1}\n", "keys low and high"),
    "goal_region_short": ("name: w\ngoal_region: {low: [0, 0], high: [1, 1, 1]}\n", "goal_region.low"),
    "goal_region_inverted": ("name: w\ngoal_region: {low: [0, 0, 0], high: [1, -1, 1]}\n", "below its high"),
}


@pytest.mark.parametrize("case", sorted(BAD_WORLDS))
def test_malformed_world_files(tmp_path, case):
    text, expected = BAD_WORLDS[case]
    p = tmp_path / ("%s.yaml" % case)
    p.write_text(text)
    with pytest.raises(WorldFileError) as err:
        load_world(p)
    msg = str(err.value)
    assert str(p) in msg, msg
    assert expected in msg, msg


def test_missing_world_file(tmp_path):
    p = os.path.join(str(tmp_path), "nope.yaml")
    with pytest.raises(WorldFileError, match="nope.yaml: world file not found"):
        load_world(p)


def test_world_dataclass_is_extensible():
    # New optional keys become dataclass fields with defaults: constructing without them must work.
    from moverl_sim.world import WorldObject

    o = WorldObject(id="a", shape="sphere", size=(0.1,), xyz=(0, 0, 0))
    assert o.rpy == (0.0, 0.0, 0.0) and o.observed is True


def test_sensing_speed_bound(tmp_path):
    p = tmp_path / "w.yaml"
    p.write_text("name: w\nsensing: {speed_bound: 0.16}\n")
    assert load_world(p).sensed_speed_bound == 0.16
    p.write_text("name: w\n")
    assert load_world(p).sensed_speed_bound is None  # the planning scene's octomap/speed_bound applies


def test_sensing_unknown_occupied(tmp_path):
    p = tmp_path / "w.yaml"
    p.write_text("name: w\nsensing: {unknown_occupied: true}\n")
    assert load_world(p).sensed_unknown_occupied is True
    p.write_text("name: w\nsensing: {unknown_occupied: false}\n")
    assert load_world(p).sensed_unknown_occupied is False  # the file says unknown cells count as free
    p.write_text("name: w\n")
    assert load_world(p).sensed_unknown_occupied is True  # fail closed: unseen space may hold a person (issue 23)


def test_base_world(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "a.yaml").write_text("name: a\ngoal: [0.1, 0.2, 0.3]\nsensing: {speed_bound: 0.16}\n")
    (tmp_path / "sub" / "b.yaml").write_text("base: ../a.yaml\nname: b\nsensing: {unknown_occupied: true}\n")
    w = load_world(tmp_path / "sub" / "b.yaml")
    assert w.name == "b" and w.goal == (0.1, 0.2, 0.3)  # the base's goal
    # sensing: never from the base (issue 23): the file's own, else the fail-closed defaults
    assert w.sensed_speed_bound is None and w.sensed_unknown_occupied
    (tmp_path / "a.yaml").write_text("base: sub/b.yaml\nname: a\n")
    with pytest.raises(WorldFileError, match="cycle"):
        load_world(tmp_path / "sub" / "b.yaml")
    (tmp_path / "c.yaml").write_text("base: missing.yaml\nname: c\n")
    with pytest.raises(WorldFileError, match="missing.yaml: world file not found"):
        load_world(tmp_path / "c.yaml")


PERSON = """
  - {id: torso, shape: cylinder, size: [0.58, 0.165], xyz: [0.8, 0.0, 0.43],
     motion: {type: oscillate, axis: [0, 1, 0], amplitude: 0.15, period: 6.0}}
"""


def test_the_template_cell_does_not_inherit_nothing_moves(tmp_path):
    """Issue 23: a cell written from the documented template (base: table.yaml, a walking person and cameras added,
    no sensing:) used to inherit table.yaml's "speed_bound: 0.0  # nothing moves here" and free unknown space. It now
    gets the scene's default bound (ISO 13855's) and unknown space occupied; its sensing is consistent."""
    table = Path(__file__).resolve().parents[3] / "worlds" / "table.yaml"
    cell = tmp_path / "cell.yaml"
    cell.write_text(
        "base: %s\nname: cell\nobjects:\n  - {id: table, shape: box, size: [1.5, 0.8, 0.03], xyz: [0.35, 0, -0.015]}"
        "%s" % (table, PERSON)
    )
    w = load_world(cell)
    assert load_world(table).sensed_speed_bound == 0.0  # the base says nothing moves
    assert w.sensed_speed_bound is None and w.sensed_unknown_occupied
    assert len(w.cameras) == 2  # the base's cameras
    assert sensing_problems(w, 1.6) == []


def test_sensing_problems_name_the_file_and_key(tmp_path):
    p = tmp_path / "w.yaml"
    cams = (
        "cameras:\n  - {id: c, xyz: [0, 1, 1], target: [0, 0, 0], width: 4, height: 3, fov: 60, near: 0.1, far: 3, "
        "rate: 2}\n"
    )
    p.write_text("name: w\nobjects:%s%ssensing: {speed_bound: 0.0}\n" % (PERSON, cams))
    (problem,) = sensing_problems(load_world(p), 1.6)
    assert str(p) in problem and "'sensing.speed_bound' = 0 m/s" in problem and "torso: 0.1571 m/s" in problem
    p.write_text("name: w\nobjects:%s%ssensing: {speed_bound: 0.16}\n" % (PERSON, cams))
    assert sensing_problems(load_world(p), 1.6) == []
    # No bound in the file: the default applies, and is named when it is too low.
    p.write_text("name: w\nobjects:%s%s" % (PERSON, cams))
    (problem,) = sensing_problems(load_world(p), 0.1)
    assert "no 'sensing.speed_bound'" in problem and "octomap/speed_bound" in problem
    # No cameras: nothing to sense with.
    p.write_text("name: w\n")
    (problem,) = sensing_problems(load_world(p), 1.6)
    assert "'cameras'" in problem
