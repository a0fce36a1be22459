"""World files (worlds/*.yaml): parsing with strict validation into plain dataclasses.

ROS-free. The format is documented in the header of worlds/table.yaml. Unknown keys are rejected so
that a typo never goes unnoticed; new optional keys (e.g. ``motion:`` for moving obstacles) can be
added later as dataclass fields with a default, which keeps every existing world file valid.
"""
import math
import os
from dataclasses import dataclass, field
from typing import Optional, Tuple

import yaml

__all__ = ["WorldFileError", "WorldObject", "World", "load_world", "parse_world", "rpy_to_quaternion",
           "SHAPE_SIZES"]

# Number of size values per shape (shape_msgs/SolidPrimitive conventions).
SHAPE_SIZES = {"box": 3, "sphere": 1, "cylinder": 2}
_SIZE_DOC = {"box": "[x, y, z]", "sphere": "[radius]", "cylinder": "[height, radius]"}
_TOP_KEYS = {"name", "frame", "goal", "objects"}
_OBJECT_KEYS = {"id", "shape", "size", "xyz", "rpy", "observed"}


class WorldFileError(Exception):
    """A world file is missing or malformed. The message names the file and the offending key."""


def rpy_to_quaternion(rpy):
    """Fixed-axis roll, pitch, yaw (URDF/ROS convention) -> quaternion (x, y, z, w)."""
    r, p, y = (0.5 * float(a) for a in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return (sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)


@dataclass(frozen=True)
class WorldObject:
    id: str
    shape: str                        # "box" | "sphere" | "cylinder"
    size: Tuple[float, ...]           # box (x, y, z); sphere (radius,); cylinder (height, radius)
    xyz: Tuple[float, float, float]   # centre, world frame
    rpy: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    observed: bool = True

    @property
    def quaternion(self):
        """Orientation as (x, y, z, w)."""
        return rpy_to_quaternion(self.rpy)


@dataclass(frozen=True)
class World:
    name: str
    frame: str = "world"
    goal: Optional[Tuple[float, float, float]] = None
    objects: Tuple[WorldObject, ...] = ()
    source: str = field(default="<memory>", compare=False)   # file it was read from

    def object(self, object_id):
        for obj in self.objects:
            if obj.id == object_id:
                return obj
        raise KeyError(object_id)


def load_world(path):
    """Read and validate a world file. Raises WorldFileError naming the file and the bad key."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise WorldFileError("%s: world file not found" % path)
    try:
        with open(path, "r", encoding="utf-8") as fh:
            data = yaml.safe_load(fh)
    except yaml.YAMLError as exc:
        raise WorldFileError("%s: YAML syntax error: %s" % (path, exc)) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise WorldFileError("%s: cannot read: %s" % (path, exc)) from None
    return parse_world(data, source=path)


def _fail(source, key, msg):
    raise WorldFileError("%s: '%s': %s" % (source, key, msg))


def _numbers(value, source, key, count=None):
    if not isinstance(value, (list, tuple)):
        _fail(source, key, "expected a list of numbers, got %r" % (value,))
    if count is not None and len(value) != count:
        _fail(source, key, "expected %d numbers, got %d (%r)" % (count, len(value), list(value)))
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            _fail(source, key, "expected numbers, got %r" % (v,))
        if not math.isfinite(v):
            _fail(source, key, "non-finite number %r" % (v,))
        out.append(float(v))
    return tuple(out)


def _string(value, source, key):
    if not isinstance(value, str) or not value.strip():
        _fail(source, key, "expected a non-empty string, got %r" % (value,))
    return value


def parse_world(data, source="<memory>"):
    """Validate an already-loaded YAML document (a dict) and build a World."""
    if not isinstance(data, dict):
        raise WorldFileError("%s: expected a mapping with keys %s at the top level, got %s"
                             % (source, sorted(_TOP_KEYS), type(data).__name__))
    unknown = set(map(str, data)) - _TOP_KEYS
    if unknown:
        _fail(source, sorted(unknown)[0], "unknown key (allowed: %s)" % ", ".join(sorted(_TOP_KEYS)))
    if "name" not in data:
        _fail(source, "name", "missing required key")
    name = _string(data["name"], source, "name")
    frame = _string(data.get("frame", "world"), source, "frame")
    goal = None
    if data.get("goal") is not None:
        goal = _numbers(data["goal"], source, "goal", 3)
    raw_objects = data.get("objects", [])
    if raw_objects is None:
        raw_objects = []
    if not isinstance(raw_objects, list):
        _fail(source, "objects", "expected a list of objects, got %r" % (raw_objects,))
    objects, seen = [], set()
    for i, raw in enumerate(raw_objects):
        where = "objects[%d]" % i
        if not isinstance(raw, dict):
            _fail(source, where, "expected a mapping, got %r" % (raw,))
        if isinstance(raw.get("id"), str):
            where = "objects[%d] (id %s)" % (i, raw["id"])
        unknown = set(map(str, raw)) - _OBJECT_KEYS
        if unknown:
            _fail(source, "%s.%s" % (where, sorted(unknown)[0]),
                  "unknown key (allowed: %s)" % ", ".join(sorted(_OBJECT_KEYS)))
        for key in ("id", "shape", "size", "xyz"):
            if key not in raw:
                _fail(source, "%s.%s" % (where, key), "missing required key")
        oid = _string(raw["id"], source, where + ".id")
        if oid in seen:
            _fail(source, where + ".id", "duplicate id %r" % oid)
        seen.add(oid)
        shape = raw["shape"]
        if shape not in SHAPE_SIZES:
            _fail(source, where + ".shape", "unknown shape %r (allowed: %s)" % (shape, ", ".join(sorted(SHAPE_SIZES))))
        n = SHAPE_SIZES[shape]
        key = where + ".size"
        if not isinstance(raw["size"], (list, tuple)) or len(raw["size"]) != n:
            _fail(source, key, "a %s needs %d size values %s, got %r" % (shape, n, _SIZE_DOC[shape], raw["size"]))
        size = _numbers(raw["size"], source, key, n)
        if any(s <= 0.0 for s in size):
            _fail(source, key, "sizes must be positive, got %r" % (list(size),))
        xyz = _numbers(raw["xyz"], source, where + ".xyz", 3)
        rpy = _numbers(raw.get("rpy", [0.0, 0.0, 0.0]), source, where + ".rpy", 3)
        observed = raw.get("observed", True)
        if not isinstance(observed, bool):
            _fail(source, where + ".observed", "expected true or false, got %r" % (observed,))
        objects.append(WorldObject(id=oid, shape=shape, size=size, xyz=xyz, rpy=rpy, observed=observed))
    return World(name=name, frame=frame, goal=goal, objects=tuple(objects), source=source)
