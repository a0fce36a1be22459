"""Malformed inputs for every service and subscribed topic of a MoveRL graph (the generators need message classes
only, no roscore; tools/fuzz_graph.py sends them to a live graph and checks every node survives and answers).

Each generator returns (label, message) pairs, built from a valid example so that exactly one thing is wrong: wrong
sizes, NaN / inf / huge values, unknown or duplicated joint names, empty or non-monotonic trajectories, malformed
worlds, point clouds with missing or wrong fields.
"""

from __future__ import annotations

import copy
import math

POISON = (("nan", math.nan), ("inf", math.inf), ("-inf", -math.inf), ("huge", 1e300), ("-huge", -1e300))


def float_vectors(valid: list[float]) -> list[tuple[str, list[float]]]:
    """Wrong sizes and poisoned values of a joint vector."""
    n = len(valid)
    out = [("empty", []), ("one short", valid[:-1]), ("one long", valid + [0.0]), ("10000 long", [0.0] * 10000)]
    for name, x in POISON:
        for i in sorted({0, n // 2, n - 1}):
            v = list(valid)
            v[i] = x
            out.append((f"{name} at {i}", v))
    return out


def trajectories(joints: list[str], q: list[float]):
    """trajectory_msgs/JointTrajectory variants (a valid one is a 0.5 s move from q)."""
    import rospy
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    def traj(names=None, points=None):
        t = JointTrajectory()
        t.joint_names = list(joints if names is None else names)
        t.points = points if points is not None else [point(q, 0.0), point([x + 0.05 for x in q], 0.5)]
        return t

    def point(pos, t, vel=(), acc=()):
        return JointTrajectoryPoint(
            positions=list(pos),
            velocities=list(vel),
            accelerations=list(acc),
            time_from_start=rospy.Duration.from_sec(t),
        )

    moved = [x + 0.05 for x in q]
    out = [
        ("no points", traj(points=[])),
        ("no joint names", traj(names=[])),
        ("unknown joint", traj(names=joints[:-1] + ["no_such_joint"])),
        ("duplicated joint", traj(names=joints[:-1] + [joints[0]])),
        ("missing joint", traj(names=joints[:-1])),
        ("shuffled joints", traj(names=joints[::-1], points=[point(q[::-1], 0.0), point(moved[::-1], 0.5)])),
        ("non-monotonic times", traj(points=[point(q, 0.0), point(moved, 0.5), point(q, 0.25)])),
        ("repeated time", traj(points=[point(q, 0.0), point(moved, 0.0)])),
        ("positions one short", traj(points=[point(q, 0.0), point(moved[:-1], 0.5)])),
        ("velocities one short", traj(points=[point(q, 0.0), point(moved, 0.5, vel=[0.0] * (len(q) - 1))])),
        ("far beyond the limits", traj(points=[point(q, 0.0), point([x + 10.0 for x in q], 0.5)])),
        ("too fast", traj(points=[point(q, 0.0), point([x + 1.0 for x in q], 0.01)])),
        ("10000 points", traj(points=[point(q, 0.0)] + [point(moved, 0.5 + 1e-4 * k) for k in range(10000)])),
    ]
    for name, x in POISON:
        bad = list(moved)
        bad[len(bad) // 2] = x
        out.append((f"{name} position", traj(points=[point(q, 0.0), point(bad, 0.5)])))
        vel = [0.0] * len(q)
        vel[0] = x
        out.append((f"{name} velocity", traj(points=[point(q, 0.0), point(moved, 0.5, vel=vel)])))
    return out


def joint_states(joints: list[str], q: list[float]):
    """sensor_msgs/JointState variants (what a broken driver may publish)."""
    import rospy
    from sensor_msgs.msg import JointState

    def js(names, pos, vel=None, stamp=None):
        m = JointState(name=list(names), position=list(pos), velocity=list(vel if vel is not None else []))
        m.header.stamp = stamp if stamp is not None else rospy.Time(0)
        return m

    out = [
        ("empty", js([], [])),
        ("unknown names only", js([f"x{i}" for i in range(len(q))], q)),
        ("missing a joint", js(joints[:-1], q[:-1])),
        ("duplicated joint", js(joints + [joints[0]], q + [q[0] + 0.5])),
        ("more names than positions", js(joints, q[:-1])),
        ("more positions than names", js(joints[:-1], q)),
        ("velocities one short", js(joints, q, vel=[0.0] * (len(q) - 1))),
        ("far beyond the limits", js(joints, [x + 10.0 for x in q])),
        ("stamp far in the future", js(joints, q, stamp=rospy.Time(4e9))),
        ("100000 unknown joints", js([f"j{i}" for i in range(100000)], [0.0] * 100000)),
    ]
    for name, x in POISON:
        bad = list(q)
        bad[0] = x
        out.append((f"{name} position", js(joints, bad)))
    return out


def worlds(valid):
    """moverl_msgs/World variants of a valid world message."""
    from shape_msgs.msg import SolidPrimitive

    from moverl_msgs.msg import ObstacleMotion, WorldObject

    def variant(edit):
        w = copy.deepcopy(valid)
        edit(w)
        return w

    def first(w):
        return w.objects[0]

    def set_(attr_path, value):
        def edit(w):
            obj = first(w)
            *path, last = attr_path.split(".")
            for a in path:
                obj = getattr(obj, a)
            setattr(obj, last, value)

        return edit

    def oscillate(axis=(0.0, 0.0, 1.0), amplitude=0.1, period=1.0, phase=0.0):
        return set_(
            "motion",
            ObstacleMotion(
                type=ObstacleMotion.OSCILLATE, axis=list(axis), amplitude=amplitude, period=period, phase=phase
            ),
        )

    def reach(period=4.0, move=0.25, hold=0.5, chance=0.5):
        return set_(
            "motion",
            ObstacleMotion(
                type=ObstacleMotion.REACH,
                axis=[1.0, 0.0, 0.0],
                amplitude=0.3,
                period=period,
                move=move,
                hold=hold,
                chance=chance,
                seed=1,
            ),
        )

    out = [
        ("unknown shape type", variant(set_("shape.type", 99))),
        (
            "box with 2 dimensions",
            variant(set_("shape", SolidPrimitive(type=SolidPrimitive.BOX, dimensions=[0.1, 0.1]))),
        ),
        ("sphere with no dimension", variant(set_("shape", SolidPrimitive(type=SolidPrimitive.SPHERE)))),
        ("negative size", variant(set_("shape", SolidPrimitive(type=SolidPrimitive.BOX, dimensions=[-0.1, 0.1, 0.1])))),
        ("huge size", variant(set_("shape", SolidPrimitive(type=SolidPrimitive.BOX, dimensions=[1e300] * 3)))),
        ("nan size", variant(set_("shape", SolidPrimitive(type=SolidPrimitive.BOX, dimensions=[math.nan, 0.1, 0.1])))),
        ("nan position", variant(set_("pose.position.x", math.nan))),
        ("inf position", variant(set_("pose.position.z", math.inf))),
        ("nan orientation", variant(set_("pose.orientation.w", math.nan))),
        ("unknown motion type", variant(set_("motion.type", 42))),
        ("zero period", variant(oscillate(period=0.0))),
        ("negative amplitude", variant(oscillate(amplitude=-1.0))),
        ("nan axis", variant(oscillate(axis=(math.nan, 0.0, 0.0)))),
        ("zero axis", variant(oscillate(axis=(0.0, 0.0, 0.0)))),
        ("inf phase", variant(oscillate(phase=math.inf))),
        ("reach longer than its period", variant(reach(period=0.9))),
        ("reach with no move time", variant(reach(move=0.0))),
        ("reach with a nan chance", variant(reach(chance=math.nan))),
        ("duplicated ids", variant(lambda w: w.objects.append(copy.deepcopy(w.objects[0])))),
        (
            "10000 objects",
            variant(
                lambda w: w.objects.extend(
                    WorldObject(
                        id=f"o{k}",
                        shape=SolidPrimitive(type=SolidPrimitive.SPHERE, dimensions=[0.01]),
                        pose=copy.deepcopy(w.objects[0].pose),
                    )
                    for k in range(10000)
                )
            ),
        ),
    ]
    return out


def point_clouds(frame: str):
    """sensor_msgs/PointCloud2 variants (a valid one: 4 x 3 organised float32 xyz points, 2 m ahead)."""
    import struct

    from sensor_msgs.msg import PointCloud2, PointField

    def cloud(fields=None, point_step=12, width=4, height=3, data=None, frame_id=frame, values=None):
        m = PointCloud2()
        m.header.frame_id = frame_id
        m.height, m.width = height, width
        m.fields = (
            fields
            if fields is not None
            else [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, n in enumerate("xyz")]
        )
        m.point_step, m.row_step = point_step, point_step * width
        m.is_bigendian, m.is_dense = False, True
        if data is None:
            vals = values if values is not None else [0.0, 0.0, 2.0]
            data = b"".join(struct.pack("<fff", *vals) for _ in range(width * height))
        m.data = data
        return m

    f32 = PointField.FLOAT32
    return [
        ("no fields", cloud(fields=[])),
        (
            "no z field",
            cloud(fields=[PointField(name=n, offset=4 * i, datatype=f32, count=1) for i, n in enumerate("xy")]),
        ),
        (
            "x as uint8",
            cloud(
                fields=[PointField(name="x", offset=0, datatype=PointField.UINT8, count=1)]
                + [PointField(name=n, offset=4 * (i + 1), datatype=f32, count=1) for i, n in enumerate("yz")]
            ),
        ),
        (
            "field beyond point_step",
            cloud(fields=[PointField(name=n, offset=40 + 4 * i, datatype=f32, count=1) for i, n in enumerate("xyz")]),
        ),
        ("point_step 4", cloud(point_step=4)),
        ("data too short", cloud(data=b"\0" * 10)),
        ("claims 1e9 points", cloud(width=100000, height=10000, data=b"\0" * 144)),
        ("empty", cloud(width=0, height=0, data=b"")),
        ("nan points", cloud(values=[math.nan, math.nan, math.nan])),
        ("inf points", cloud(values=[math.inf, 0.0, 1.0])),
        ("unknown frame", cloud(frame_id="no_such_frame")),
        ("no frame", cloud(frame_id="")),
    ]
