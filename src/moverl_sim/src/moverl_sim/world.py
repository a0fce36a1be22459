"""World files (worlds/*.yaml): parsing with strict validation into plain dataclasses.

ROS-free. The format is documented in the header of worlds/table.yaml. Unknown keys are rejected so
that a typo never goes unnoticed; new optional keys are dataclass fields with a default, which keeps every
existing world file valid. An object's optional ``motion:`` makes it a moving obstacle (ObjectMotion); the
optional top-level ``cameras:`` list declares simulated depth cameras (WorldCamera, rendered by moverl_sim.camera).
"""

import math
import os
import re
from dataclasses import dataclass, field
from typing import Optional, Tuple

import yaml

__all__ = [
    "WorldFileError",
    "WorldObject",
    "World",
    "ObjectMotion",
    "WorldCamera",
    "load_world",
    "parse_world",
    "rpy_to_quaternion",
    "SHAPE_SIZES",
    "MOTION_TYPES",
    "OPTICAL_FRAME_SUFFIX",
    "sensing_problems",
]

# Number of size values per shape (shape_msgs/SolidPrimitive conventions).
SHAPE_SIZES = {"box": 3, "sphere": 1, "cylinder": 2}
_SIZE_DOC = {"box": "[x, y, z]", "sphere": "[radius]", "cylinder": "[height, radius]"}
_TOP_KEYS = {"name", "frame", "goal", "goal_region", "objects", "cameras", "sensing", "people"}
_SENSING_KEYS = {"speed_bound", "unknown_occupied"}
_OBJECT_KEYS = {"id", "shape", "size", "xyz", "rpy", "observed", "motion"}
MOTION_TYPES = ("oscillate", "reach")
_MOTION_KEYS = {
    "oscillate": {"type", "axis", "amplitude", "period", "phase"},
    "reach": {"type", "axis", "amplitude", "period", "phase", "move", "hold", "chance", "seed"},
}
_CAMERA_KEYS = {"id", "xyz", "target", "up", "width", "height", "fov", "near", "far", "rate"}
_CAMERA_REQUIRED = ("id", "xyz", "target", "width", "height", "fov", "near", "far", "rate")
_CAMERA_ID = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")  # becomes part of a TF frame name
OPTICAL_FRAME_SUFFIX = "_optical_frame"
MIN_UP_ANGLE_SIN = 1e-3  # up must be at least ~0.06 deg away from the view direction


class WorldFileError(Exception):
    """A world file is missing or malformed. The message names the file and the offending key."""


def rpy_to_quaternion(rpy):
    """Fixed-axis roll, pitch, yaw (URDF/ROS convention) -> quaternion (x, y, z, w)."""
    r, p, y = (0.5 * float(a) for a in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


_MASK64 = (1 << 64) - 1


def reach_cycle_draw(seed, k):
    """Uniform number in [0, 1) of a reach motion's cycle k >= 0 (splitmix64 of (seed << 32) ^ k): whether that cycle
    reaches. The planning scene's twin is ObstacleMotion::cycleDraw (collision_checker.h)."""
    z = ((((int(seed) & 0xFFFFFFFF) << 32) ^ (int(k) & _MASK64)) + 0x9E3779B97F4A7C15) & _MASK64
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
    z ^= z >> 31
    return (z >> 11) * (1.0 / (1 << 53))


@dataclass(frozen=True)
class ObjectMotion:
    """A translation of an obstacle over motion time t (s since the motions (re)started); its orientation does not
    change. The object is at xyz + axis * offset(t) (the world file's ``xyz``):

    * oscillate: offset(t) = amplitude * sin(2 pi t / period + phase), a swing about xyz.
    * reach: cycles of `period` s, cycle k = floor(t / period + phase / (2 pi)); a cycle whose draw
      (reach_cycle_draw(seed, k)) is below `chance` first rests at xyz for period - 2 move - hold s, moves out to
      amplitude along the axis in `move` s (offset amplitude (1 - cos(pi u)) / 2 over u in [0, 1]: top speed
      pi amplitude / (2 move)), holds there for `hold` s and comes back the same way; any other cycle rests at xyz.
      A person at a bench who reaches into the shared space from time to time, seeded.

    displacement() (offset(t) - offset(0)) is THE motion formula of the Python code (the simulator, the messages, the
    env); the planning scene's C++ twin is ObstacleMotion::displacement (collision_checker.h), and both are checked on
    the same cases (moverl_sim/test/fixtures/obstacle_motion_cases.txt, reach_motion_cases.txt).
    """

    type: str = "oscillate"
    axis: Tuple[float, float, float] = (1.0, 0.0, 0.0)  # unit vector (normalised by the parser)
    amplitude: float = 0.0  # m
    period: float = 1.0  # s
    phase: float = 0.0  # rad (reach: the fraction phase / (2 pi) of a cycle gone at t = 0)
    move: float = 0.0  # s (reach): each way out and back
    hold: float = 0.0  # s (reach): at the far end
    chance: float = 0.0  # (reach): the fraction of cycles that reach, in [0, 1]
    seed: int = 0  # (reach): of the cycles that reach

    def offset(self, t):
        """Scalar offset along the axis from the world file's xyz at motion time t."""
        if self.type == "reach":
            return self._reach_offset(t)
        return self.amplitude * math.sin(2.0 * math.pi * t / self.period + self.phase)

    def _reach_offset(self, t):
        c = t / self.period + self.phase / (2.0 * math.pi)
        k = math.floor(c)
        if k < 0 or reach_cycle_draw(self.seed, k) >= self.chance:
            return 0.0
        tau = (c - k) * self.period - (self.period - 2.0 * self.move - self.hold)  # time since the reach began
        if tau <= 0.0:
            return 0.0
        if tau < self.move:
            return 0.5 * self.amplitude * (1.0 - math.cos(math.pi * tau / self.move))
        if tau <= self.move + self.hold:
            return self.amplitude
        back = min(1.0, (tau - self.move - self.hold) / self.move)
        return 0.5 * self.amplitude * (1.0 + math.cos(math.pi * back))

    def displacement(self, t):
        """Scalar displacement along the axis at motion time t from the pose at t = 0 (moverl_msgs/ObstacleMotion
        convention): offset(t) - offset(0)."""
        return self.offset(t) - self.offset(0.0)

    def start_offset(self):
        """The pose at t = 0 minus xyz: axis * offset(0)."""
        s = self.offset(0.0)
        return (self.axis[0] * s, self.axis[1] * s, self.axis[2] * s)

    def envelope(self):
        """(lo, hi): the range of displacement(t) over all t."""
        lo, hi = (-self.amplitude, self.amplitude) if self.type == "oscillate" else (0.0, self.amplitude)
        return lo - self.offset(0.0), hi - self.offset(0.0)

    @property
    def max_speed(self):
        """Largest speed (m/s) of any point of the object."""
        if self.type == "reach":
            return math.pi * self.amplitude / (2.0 * self.move)
        return 2.0 * math.pi * self.amplitude / self.period


@dataclass(frozen=True)
class WorldObject:
    id: str
    shape: str  # "box" | "sphere" | "cylinder"
    size: Tuple[float, ...]  # box (x, y, z); sphere (radius,); cylinder (height, radius)
    xyz: Tuple[float, float, float]  # centre, world frame
    rpy: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    observed: bool = True
    motion: Optional[ObjectMotion] = None  # None: static

    @property
    def quaternion(self):
        """Orientation as (x, y, z, w)."""
        return rpy_to_quaternion(self.rpy)

    @property
    def start(self):
        """Position at motion time 0 (xyz for a static object; for a moving one, where its swing starts)."""
        if self.motion is None:
            return self.xyz
        o = self.motion.start_offset()
        return (self.xyz[0] + o[0], self.xyz[1] + o[1], self.xyz[2] + o[2])

    def position_at(self, t):
        """Position at motion time t (xyz for a static object)."""
        if self.motion is None:
            return self.xyz
        x, y, z = self.start
        s = self.motion.displacement(t)
        a = self.motion.axis
        return (x + a[0] * s, y + a[1] * s, z + a[2] * s)


@dataclass(frozen=True)
class WorldCamera:
    """A static simulated depth camera (pinhole), looking from xyz at target, image "up" roughly along up.

    Its TF frame is ``optical_frame`` (REP 103 optical: z forward, x right, y down); moverl_sim.camera
    computes the pose and renders it.
    """

    id: str
    xyz: Tuple[float, float, float]  # optical centre, world frame (m)
    target: Tuple[float, float, float]  # look-at point, world frame (m); the optical axis passes through it
    width: int  # pixels
    height: int  # pixels
    fov: float  # vertical field of view (degrees), 0 < fov < 180
    near: float  # clip distances (m, along the optical axis), 0 < near < far
    far: float
    rate: float  # renders per simulated second
    up: Tuple[float, float, float] = (0.0, 0.0, 1.0)  # world direction that appears "up" in the image

    @property
    def optical_frame(self):
        """TF frame of the camera: ``<id>_optical_frame``."""
        return self.id + OPTICAL_FRAME_SUFFIX


@dataclass(frozen=True)
class World:
    name: str
    frame: str = "world"
    goal: Optional[Tuple[float, float, float]] = None
    #: ``goal_region: {low: [x, y, z], high: [x, y, z]}``: the box (world frame) each episode's goal is sampled in
    #: (moverl_gym.sampling); None: every episode's goal is ``goal``.
    goal_region: Optional[Tuple[Tuple[float, float, float], Tuple[float, float, float]]] = None
    objects: Tuple[WorldObject, ...] = ()
    source: str = field(default="<memory>", compare=False)  # file it was read from
    cameras: Tuple[WorldCamera, ...] = ()
    #: ``sensing: speed_bound:`` (m/s): how fast what the cameras see may move, for the planning scene's predictive
    #: margin in the sensed mode; None: not given (the scene's octomap/speed_bound applies).
    sensed_speed_bound: Optional[float] = None
    #: ``sensing: unknown_occupied:``: in the sensed mode, map cells no camera has seen count as occupied (except
    #: inside the robot and the static objects), the default; False (the file says so): they count as free.
    sensed_unknown_occupied: bool = True
    #: ``people:`` the tracked people as a REP 155 tracker reports them (moverl_sim.people.Person)
    people: tuple = ()

    @property
    def moving_objects(self):
        """The objects that have a motion."""
        return tuple(o for o in self.objects if o.motion is not None)

    @property
    def fastest_object(self):
        """The moving object of the largest speed (None when nothing moves)."""
        return max(self.moving_objects, key=lambda o: o.motion.max_speed, default=None)

    def object(self, object_id):
        for obj in self.objects:
            if obj.id == object_id:
                return obj
        raise KeyError(object_id)

    def camera(self, camera_id):
        for cam in self.cameras:
            if cam.id == camera_id:
                return cam
        raise KeyError(camera_id)


def load_world(path):
    """Read and validate a world file. Raises WorldFileError naming the file and the bad key."""
    return parse_world(_read_world(os.fspath(path), ()), source=os.fspath(path))


def _read_world(path, chain):
    """The top-level mapping of a world file, with its ``base:`` chain merged in: keys given replace the base's, except
    ``sensing:``, which is never taken from a base. What a cell's cameras may see move, and how fast, is a fact of that
    cell: a file says it itself or gets the fail-closed defaults (the scene's speed bound, ISO 13855's; unknown space
    occupied). A base's "nothing moves here" must not reach a cell that lists a walking person."""
    if not os.path.isfile(path):
        raise WorldFileError("%s: world file not found" % path)
    try:
        with open(path, "r", encoding="utf-8") as fh:
            data = yaml.safe_load(fh)
    except yaml.YAMLError as exc:
        raise WorldFileError("%s: YAML syntax error: %s" % (path, exc)) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise WorldFileError("%s: cannot read: %s" % (path, exc)) from None
    if not isinstance(data, dict) or "base" not in data:
        return data
    base = _string(data["base"], path, "base")
    base_path = os.path.normpath(os.path.join(os.path.dirname(path), base))
    if os.path.realpath(base_path) in chain + (os.path.realpath(path),):
        _fail(path, "base", "%s is this file or one it is based on (a cycle)" % base)
    merged = _read_world(base_path, chain + (os.path.realpath(path),))
    if not isinstance(merged, dict):
        _fail(path, "base", "%s is not a world file (a mapping)" % base)
    merged = {k: v for k, v in merged.items() if k != "sensing"}
    for key, value in data.items():
        if key != "base":
            merged[key] = value
    return merged


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


def _number(value, source, key):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        _fail(source, key, "expected a finite number, got %r" % (value,))
    return float(value)


def _parse_motion(raw, source, where):
    """Validate an object's ``motion:`` mapping -> ObjectMotion."""
    if not isinstance(raw, dict):
        _fail(
            source,
            where,
            "expected a mapping like {type: oscillate, axis: [0, 1, 0], amplitude: 0.1, period: 4.0}, got %r" % (raw,),
        )
    mtype = raw.get("type")
    if mtype is None:
        _fail(source, where + ".type", "missing required key (allowed: %s)" % ", ".join(MOTION_TYPES))
    if mtype not in MOTION_TYPES:
        _fail(source, where + ".type", "unknown motion type %r (allowed: %s)" % (mtype, ", ".join(MOTION_TYPES)))
    allowed = _MOTION_KEYS[mtype]
    unknown = set(map(str, raw)) - allowed
    if unknown:
        _fail(
            source,
            "%s.%s" % (where, sorted(unknown)[0]),
            "unknown key for a %s motion (allowed: %s)" % (mtype, ", ".join(sorted(allowed))),
        )
    for key in ("axis", "amplitude", "period"):
        if key not in raw:
            _fail(source, "%s.%s" % (where, key), "missing required key")
    axis = _numbers(raw["axis"], source, where + ".axis", 3)
    norm = math.sqrt(sum(a * a for a in axis))
    if norm < 1e-9:
        _fail(source, where + ".axis", "must be a non-zero vector, got %r" % (list(axis),))
    axis = tuple(a / norm for a in axis)
    amplitude = _number(raw["amplitude"], source, where + ".amplitude")
    if amplitude < 0.0:
        _fail(source, where + ".amplitude", "must be >= 0 (metres), got %r" % (amplitude,))
    period = _number(raw["period"], source, where + ".period")
    if period <= 0.0:
        _fail(source, where + ".period", "must be > 0 (seconds), got %r" % (period,))
    phase = _number(raw.get("phase", 0.0), source, where + ".phase")
    if mtype == "oscillate":
        return ObjectMotion(type=mtype, axis=axis, amplitude=amplitude, period=period, phase=phase)
    for key in ("move", "chance"):
        if key not in raw:
            _fail(source, "%s.%s" % (where, key), "missing required key (a reach motion)")
    move = _number(raw["move"], source, where + ".move")
    if move <= 0.0:
        _fail(source, where + ".move", "must be > 0 (seconds each way), got %r" % (move,))
    hold = _number(raw.get("hold", 0.0), source, where + ".hold")
    if hold < 0.0:
        _fail(source, where + ".hold", "must be >= 0 (seconds), got %r" % (hold,))
    if 2.0 * move + hold > period:
        _fail(
            source,
            where + ".period",
            "must be at least 2 move + hold = %g s (a reach out, its hold and back fit in a cycle), got %r"
            % (2.0 * move + hold, period),
        )
    chance = _number(raw["chance"], source, where + ".chance")
    if not 0.0 <= chance <= 1.0:
        _fail(source, where + ".chance", "must be in [0, 1] (the fraction of cycles that reach), got %r" % (chance,))
    seed = raw.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**32:
        _fail(source, where + ".seed", "must be an integer in [0, 2^32), got %r" % (seed,))
    return ObjectMotion(
        type=mtype,
        axis=axis,
        amplitude=amplitude,
        period=period,
        phase=phase,
        move=move,
        hold=hold,
        chance=chance,
        seed=int(seed),
    )


def _positive_int(value, source, key):
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        _fail(source, key, "expected a positive integer (pixels), got %r" % (value,))
    return int(value)


def _parse_cameras(raw_cameras, source):
    """Validate the top-level ``cameras:`` list -> tuple of WorldCamera."""
    if raw_cameras is None:
        return ()
    if not isinstance(raw_cameras, list):
        _fail(source, "cameras", "expected a list of cameras, got %r" % (raw_cameras,))
    cameras, seen = [], set()
    for i, raw in enumerate(raw_cameras):
        where = "cameras[%d]" % i
        if not isinstance(raw, dict):
            _fail(source, where, "expected a mapping, got %r" % (raw,))
        if isinstance(raw.get("id"), str):
            where = "cameras[%d] (id %s)" % (i, raw["id"])
        unknown = set(map(str, raw)) - _CAMERA_KEYS
        if unknown:
            _fail(
                source,
                "%s.%s" % (where, sorted(unknown)[0]),
                "unknown key (allowed: %s)" % ", ".join(sorted(_CAMERA_KEYS)),
            )
        for key in _CAMERA_REQUIRED:
            if key not in raw:
                _fail(source, "%s.%s" % (where, key), "missing required key")
        cid = _string(raw["id"], source, where + ".id")
        if not _CAMERA_ID.match(cid):
            _fail(
                source,
                where + ".id",
                "must start with a letter and contain only letters, digits and '_' "
                "(it names the TF frame <id>%s), got %r" % (OPTICAL_FRAME_SUFFIX, cid),
            )
        if cid in seen:
            _fail(source, where + ".id", "duplicate camera id %r" % cid)
        seen.add(cid)
        xyz = _numbers(raw["xyz"], source, where + ".xyz", 3)
        target = _numbers(raw["target"], source, where + ".target", 3)
        view = [t - x for t, x in zip(target, xyz)]
        view_norm = math.sqrt(sum(v * v for v in view))
        if view_norm < 1e-6:
            _fail(
                source,
                where + ".target",
                "must differ from xyz (the view direction is target - xyz), got %r" % (list(target),),
            )
        up = _numbers(raw.get("up", [0.0, 0.0, 1.0]), source, where + ".up", 3)
        up_norm = math.sqrt(sum(u * u for u in up))
        if up_norm < 1e-9:
            _fail(source, where + ".up", "must be a non-zero vector, got %r" % (list(up),))
        cross = (
            view[1] * up[2] - view[2] * up[1],
            view[2] * up[0] - view[0] * up[2],
            view[0] * up[1] - view[1] * up[0],
        )
        if math.sqrt(sum(c * c for c in cross)) < MIN_UP_ANGLE_SIN * view_norm * up_norm:
            _fail(
                source,
                where + ".up",
                "must not be parallel to the view direction target - xyz = %r, got %r"
                % ([round(v, 6) for v in view], list(up)),
            )
        width = _positive_int(raw["width"], source, where + ".width")
        height = _positive_int(raw["height"], source, where + ".height")
        fov = _number(raw["fov"], source, where + ".fov")
        if not 0.0 < fov < 180.0:
            _fail(source, where + ".fov", "vertical field of view must be in (0, 180) degrees, got %r" % (fov,))
        near = _number(raw["near"], source, where + ".near")
        far = _number(raw["far"], source, where + ".far")
        if near <= 0.0:
            _fail(source, where + ".near", "must be > 0 (metres), got %r" % (near,))
        if far <= near:
            _fail(source, where + ".far", "must be > near = %r (metres), got %r" % (near, far))
        rate = _number(raw["rate"], source, where + ".rate")
        if rate <= 0.0:
            _fail(source, where + ".rate", "must be > 0 (renders per simulated second), got %r" % (rate,))
        cameras.append(
            WorldCamera(
                id=cid,
                xyz=xyz,
                target=target,
                up=up,
                width=width,
                height=height,
                fov=fov,
                near=near,
                far=far,
                rate=rate,
            )
        )
    return tuple(cameras)


def parse_world(data, source="<memory>"):
    """Validate an already-loaded YAML document (a dict) and build a World."""
    from .people import parse_people  # (it raises this module's WorldFileError)

    if not isinstance(data, dict):
        raise WorldFileError(
            "%s: expected a mapping with keys %s at the top level, got %s"
            % (source, sorted(_TOP_KEYS), type(data).__name__)
        )
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
    goal_region = _goal_region(data.get("goal_region"), source)
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
            _fail(
                source,
                "%s.%s" % (where, sorted(unknown)[0]),
                "unknown key (allowed: %s)" % ", ".join(sorted(_OBJECT_KEYS)),
            )
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
        motion = None
        if raw.get("motion") is not None:
            motion = _parse_motion(raw["motion"], source, where + ".motion")
        objects.append(WorldObject(id=oid, shape=shape, size=size, xyz=xyz, rpy=rpy, observed=observed, motion=motion))
    cameras = _parse_cameras(data.get("cameras"), source)
    speed_bound = None
    unknown_occupied = True
    sensing = data.get("sensing")
    if sensing is not None:
        if not isinstance(sensing, dict):
            _fail(source, "sensing", "expected a mapping with keys %s, got %r" % (sorted(_SENSING_KEYS), sensing))
        unknown = set(map(str, sensing)) - _SENSING_KEYS
        if unknown:
            _fail(
                source, "sensing." + sorted(unknown)[0], "unknown key (allowed: %s)" % ", ".join(sorted(_SENSING_KEYS))
            )
        if "speed_bound" in sensing:
            speed_bound = _numbers([sensing["speed_bound"]], source, "sensing.speed_bound", 1)[0]
            if not (speed_bound >= 0.0 and math.isfinite(speed_bound)):
                _fail(source, "sensing.speed_bound", "must be finite and >= 0 (m/s), got %r" % (speed_bound,))
        unknown_occupied = sensing.get("unknown_occupied", True)
        if not isinstance(unknown_occupied, bool):
            _fail(source, "sensing.unknown_occupied", "expected true or false, got %r" % (unknown_occupied,))
    return World(
        name=name,
        frame=frame,
        goal=goal,
        goal_region=goal_region,
        objects=tuple(objects),
        source=source,
        cameras=cameras,
        sensed_speed_bound=speed_bound,
        sensed_unknown_occupied=unknown_occupied,
        people=parse_people(data.get("people"), objects, source),
    )


def _goal_region(raw, source):
    """``goal_region: {low: [x, y, z], high: [x, y, z]}`` checked: each low below its high; None when not given."""
    if raw is None:
        return None
    if not isinstance(raw, dict) or set(map(str, raw)) != {"low", "high"}:
        _fail(source, "goal_region", "expected a mapping with keys low and high, got %r" % (raw,))
    low = _numbers(raw["low"], source, "goal_region.low", 3)
    high = _numbers(raw["high"], source, "goal_region.high", 3)
    if not all(a < b for a, b in zip(low, high)):
        _fail(source, "goal_region", "each low must lie below its high, got low %r, high %r" % (list(low), list(high)))
    return (tuple(low), tuple(high))


def sensing_problems(world, default_speed_bound, default_source="config/planning_scene.yaml's octomap/speed_bound"):
    """What makes a world unusable with sensed obstacles (obstacles: octomap, both or sensed), as messages naming the
    file and the key ([] when nothing): a speed bound below the fastest motion the world lists (the predictive margin
    would not cover it: a person would walk into the robot between two views), and no camera to sense with.

    Args:
        world: a World.
        default_speed_bound: the bound (m/s) that applies when the world gives none.
        default_source: where that default lives, for the message.
    """
    problems = []
    fastest = world.fastest_object
    if world.sensed_speed_bound is None:
        bound, where = default_speed_bound, "no 'sensing.speed_bound' (so %s)" % default_source
    else:
        bound, where = world.sensed_speed_bound, "'sensing.speed_bound'"
    if fastest is not None and bound < fastest.motion.max_speed - 1e-9:
        problems.append(
            "%s: %s = %g m/s is below the fastest motion the world lists (%s: %.4g m/s): the sensed map's predictive "
            "margin would not cover it. Give 'sensing: speed_bound:' at least %.4g m/s in this file"
            % (world.source, where, bound, fastest.id, fastest.motion.max_speed, fastest.motion.max_speed)
        )
    if not world.cameras:
        problems.append(
            "%s: 'cameras': none listed; the sensed modes see only through the cameras a world file lists (their "
            "frames are <id>%s; with simulator:=false, the real cameras' clouds carry those frames)"
            % (world.source, OPTICAL_FRAME_SUFFIX)
        )
    return problems
