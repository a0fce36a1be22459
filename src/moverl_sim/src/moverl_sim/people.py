"""The world's people as a REP 155 (ROS4HRI) skeleton tracker reports them, ROS-free.

A world file's optional ``people:`` list names each tracked person's body id and, per REP 155 frame of the human
kinematic model (human_description's names: ``head``, ``torso``, ``r_wrist``, ...), the world object the frame rides
on and the point on it (``at``, object frame, m)::

    people:
      - body: b1                      # frames body_b1, head_b1, r_wrist_b1, ...; listed on /humans/bodies/tracked
        parts:
          head: {object: human_head}
          r_wrist: {object: human_right_arm, at: [0.0, 0.0, -0.25]}   # the hand's end of the forearm

The simulator's tracker (moverl_sim.tracker, launch argument ``obstacle_poses:=tracker``) measures the observed
objects; each frame is its object's measured pose moved by ``at``, stamped when it was measured, delivered after the
tracker's latency and lost with its object's measurement. REP 155 parents the frames to ``body_<id>`` and that to the
sensor; here every frame hangs from the world's frame (as openni_tracker's do from the camera's): a listener looks
frames up in its own frame either way. A body is listed as tracked while any of its frames is delivered.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Tuple

from .world import _fail

__all__ = ["FRAMES", "Person", "PersonPart", "parse_people", "part_frames", "tracked_bodies"]

#: REP 155's frames of a body (human_description's main links), without the ``_<body id>`` suffix.
FRAMES = (
    "body",
    "waist",
    "torso",
    "head",
    "l_shoulder",
    "l_elbow",
    "l_wrist",
    "r_shoulder",
    "r_elbow",
    "r_wrist",
    "l_hip",
    "l_knee",
    "l_ankle",
    "r_hip",
    "r_knee",
    "r_ankle",
)
#: The topic of the tracked bodies' ids (hri_msgs/IdsList), REP 155's.
TRACKED_TOPIC = "/humans/bodies/tracked"
_BODY_ID = re.compile(r"^[A-Za-z][A-Za-z0-9]*$")  # REP 155: short, starting with a letter (a frame name's suffix)


@dataclass(frozen=True)
class PersonPart:
    frame: str  # REP 155's name (FRAMES)
    object: str  # the world object it rides on (observed)
    at: Tuple[float, float, float] = (0.0, 0.0, 0.0)  # m, the object's frame

    def tf_frame(self, body):
        return "%s_%s" % (self.frame, body)


@dataclass(frozen=True)
class Person:
    body: str
    parts: Tuple[PersonPart, ...]


def parse_people(raw, objects, source):
    """The ``people:`` list (None: none) of a world whose objects are `objects` (WorldObject); WorldFileError naming the
    file and the key for a bad entry: an unknown key or frame (naming the valid ones), a duplicate body id, an object
    the world does not list or does not observe (the tracker measures only observed objects)."""
    if raw is None:
        return ()
    if not isinstance(raw, list):
        _fail(
            source,
            "people",
            "expected a list of people ({body: <id>, parts: {<frame>: {object: <id>}}}), got %r" % (raw,),
        )
    by_id = {o.id: o for o in objects}
    people, bodies = [], set()
    for i, entry in enumerate(raw):
        where = "people[%d]" % i
        if not isinstance(entry, dict) or set(map(str, entry)) != {"body", "parts"}:
            _fail(source, where, "expected a mapping with keys body and parts, got %r" % (entry,))
        body = entry["body"]
        if not isinstance(body, str) or not _BODY_ID.match(body):
            _fail(
                source,
                where + ".body",
                "expected a short id of letters and digits starting with a letter, got %r" % (body,),
            )
        if body in bodies:
            _fail(source, where + ".body", "duplicate body id %r" % body)
        bodies.add(body)
        raw_parts = entry["parts"]
        if not isinstance(raw_parts, dict) or not raw_parts:
            _fail(
                source, where + ".parts", "expected a mapping of REP 155 frames to {object, at}, got %r" % (raw_parts,)
            )
        parts = []
        for frame, spec in raw_parts.items():
            key = "%s.parts.%s" % (where, frame)
            if frame not in FRAMES:
                _fail(source, key, "unknown REP 155 frame (allowed: %s)" % ", ".join(FRAMES))
            if not isinstance(spec, dict) or not set(map(str, spec)) <= {"object", "at"} or "object" not in spec:
                _fail(source, key, "expected {object: <id>, at: [x, y, z]} (at optional), got %r" % (spec,))
            obj = by_id.get(spec["object"])
            if obj is None:
                _fail(source, key + ".object", "no object %r in this world" % (spec["object"],))
            if not obj.observed:
                _fail(
                    source, key + ".object", "%r is not observed: the tracker measures observed objects only" % obj.id
                )
            at = spec.get("at", [0.0, 0.0, 0.0])
            numbers = isinstance(at, (list, tuple)) and len(at) == 3
            numbers = numbers and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in at)
            if not (numbers and all(math.isfinite(v) for v in at)):
                _fail(source, key + ".at", "expected 3 finite numbers (m, the object's frame), got %r" % (at,))
            parts.append(PersonPart(frame=frame, object=obj.id, at=tuple(float(v) for v in at)))
        people.append(Person(body=body, parts=tuple(parts)))
    return tuple(people)


def _rotate(q, v):
    """Quaternion (x, y, z, w) applied to v."""
    x, y, z, w = q
    # v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z)
    cx, cy, cz = y * v[2] - z * v[1], z * v[0] - x * v[2], x * v[1] - y * v[0]
    return (
        v[0] + 2.0 * (w * cx + y * cz - z * cy),
        v[1] + 2.0 * (w * cy + z * cx - x * cz),
        v[2] + 2.0 * (w * cz + x * cy - y * cx),
    )


def part_frames(people, measurements):
    """The REP 155 frames the tracker's `measurements` (moverl_sim.tracker.Measurement, of the objects) give: a list
    of (frame, stamp, (x, y, z, qx, qy, qz, qw)), each frame's point `at` on its object's measured pose."""
    by_object = {}
    for m in measurements:
        by_object.setdefault(m.id, []).append(m)
    out = []
    for person in people:
        for part in person.parts:
            for m in by_object.get(part.object, ()):
                quat = tuple(m.pose[3:7])
                off = _rotate(quat, part.at)
                out.append(
                    (
                        part.tf_frame(person.body),
                        m.stamp,
                        (m.pose[0] + off[0], m.pose[1] + off[1], m.pose[2] + off[2], *quat),
                    )
                )
    return out


def tracked_bodies(people, measurements):
    """The bodies any of whose frames `measurements` deliver, in the world file's order."""
    measured = {m.id for m in measurements}
    return [p.body for p in people if any(part.object in measured for part in p.parts)]
