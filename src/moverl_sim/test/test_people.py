"""The world's people as a REP 155 tracker reports them (moverl_sim.people): the world file's ``people:`` refused at
once when wrong, and the frames the tracker's measurements give."""

import math
import re
from pathlib import Path

import pytest

from moverl_sim.people import FRAMES, part_frames, tracked_bodies
from moverl_sim.tracker import Measurement
from moverl_sim.world import WorldFileError, load_world, parse_world, rpy_to_quaternion

pytestmark = pytest.mark.core

REPO = Path(__file__).resolve().parents[3]

ARM = {"id": "arm", "shape": "cylinder", "size": [0.5, 0.045], "xyz": [0.87, -0.15, 0.05], "rpy": [0, math.pi / 2, 0]}
HIDDEN = {"id": "legs", "shape": "box", "size": [0.2, 0.3, 0.8], "xyz": [1, 0, -0.35], "observed": False}


def _world(people):
    return parse_world({"name": "p", "objects": [ARM, HIDDEN], "people": people}, source="p.yaml")


def test_a_part_rides_on_its_object_at_its_point():
    w = _world(
        [{"body": "b1", "parts": {"r_wrist": {"object": "arm", "at": [0, 0, -0.25]}, "r_elbow": {"object": "arm"}}}]
    )
    quat = rpy_to_quaternion(ARM["rpy"])
    m = Measurement("arm", 2.5, (0.9, -0.1, 0.05, *quat))
    frames = {f: (stamp, pose) for f, stamp, pose in part_frames(w.people, [m])}
    assert set(frames) == {"r_wrist_b1", "r_elbow_b1"}
    stamp, pose = frames["r_wrist_b1"]
    assert stamp == 2.5
    # The cylinder's axis (its z) lies along the world's x: its -z end is 0.25 m towards -x.
    assert pose[:3] == pytest.approx((0.65, -0.1, 0.05), abs=1e-9)
    assert frames["r_elbow_b1"][1][:3] == pytest.approx((0.9, -0.1, 0.05))
    assert tracked_bodies(w.people, [m]) == ["b1"]
    assert tracked_bodies(w.people, []) == [] and part_frames(w.people, []) == []


@pytest.mark.parametrize(
    "people, key, says",
    [
        ({"body": "b1"}, "people", "expected a list"),
        ([{"body": "b1", "parts": {"hand": {"object": "arm"}}}], "people[0].parts.hand", "unknown REP 155 frame"),
        ([{"body": "b1", "parts": {"head": {"object": "ball"}}}], "people[0].parts.head.object", "no object"),
        ([{"body": "b1", "parts": {"head": {"object": "legs"}}}], "people[0].parts.head.object", "not observed"),
        ([{"body": "1b", "parts": {"head": {"object": "arm"}}}], "people[0].body", "starting with a letter"),
        ([{"body": "b1", "parts": {"head": {"object": "arm", "at": [0, 0]}}}], "people[0].parts.head.at", "3 finite"),
        ([{"body": "b1", "parts": {"head": {"object": "arm", "size": 1}}}], "people[0].parts.head", "expected"),
        ([{"body": "b1", "parts": {"head": {"object": "arm"}}}] * 2, "people[1].body", "duplicate"),
    ],
)
def test_a_wrong_person_is_refused_naming_the_key(people, key, says):
    with pytest.raises(WorldFileError, match=f"'{re.escape(key)}'.*{says}"):
        _world(people)


def test_an_unknown_frame_names_the_valid_ones():
    with pytest.raises(WorldFileError) as e:
        _world([{"body": "b1", "parts": {"hand": {"object": "arm"}}}])
    assert all(f in str(e.value) for f in FRAMES)


def test_shared_bench_lists_its_person():
    (person,) = load_world(REPO / "worlds" / "shared_bench.yaml").people
    assert person.body == "b1"
    assert {p.frame for p in person.parts} == {"head", "torso", "r_wrist", "l_wrist"}
