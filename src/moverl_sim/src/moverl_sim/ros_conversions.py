"""Conversions between the ROS-free core (world, contacts, joint state) and ROS messages.

Imports message modules only (no roscore needed), so it is unit-testable.
"""

import rospy
from geometry_msgs.msg import Pose, PoseStamped

from moverl_msgs.msg import CollisionPair, ContactReport
from moverl_msgs.msg import World as WorldMsg
from moverl_msgs.msg import WorldObject as WorldObjectMsg

try:  # added with moving obstacles
    from moverl_msgs.msg import ObstacleMotion
except ImportError:  # pragma: no cover - messages built before moving obstacles
    ObstacleMotion = None
from sensor_msgs.msg import JointState, PointCloud2, PointField
from shape_msgs.msg import SolidPrimitive

_XYZ_FIELDS = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, n in enumerate("xyz")]
_SHAPE_TYPES = {"box": SolidPrimitive.BOX, "sphere": SolidPrimitive.SPHERE, "cylinder": SolidPrimitive.CYLINDER}


#: The scalar fields moverl_msgs/ObstacleMotion and moverl_sim.world.ObjectMotion share (same names, same units).
MOTION_FIELDS = ("amplitude", "period", "phase", "move", "hold", "chance", "seed")


def motion_from_msg(m):
    """moverl_msgs/ObstacleMotion -> moverl_sim.world.ObjectMotion; None for a static one (NONE, or amplitude 0)."""
    from .world import ObjectMotion

    if m.type == m.NONE or not m.amplitude > 0.0:
        return None
    return ObjectMotion(
        type="reach" if m.type == m.REACH else "oscillate",
        axis=tuple(m.axis),
        **{f: getattr(m, f) for f in MOTION_FIELDS},
    )


def sim_stamp(seconds):
    return rospy.Time.from_sec(max(0.0, seconds))


def world_to_msg(world, stamp_sec=0.0, motion_epoch_sec=0.0):
    """moverl_sim.world.World -> moverl_msgs/World (SolidPrimitive conventions, rpy -> quaternion).

    Poses are those at motion time 0; moving objects carry their motion (ObstacleMotion); motion_epoch_sec is when
    motion time was 0 (seconds on the driver's clock)."""
    msg = WorldMsg()
    msg.header.frame_id = world.frame
    msg.header.stamp = sim_stamp(stamp_sec)
    msg.motion_epoch = sim_stamp(motion_epoch_sec)
    msg.name = world.name
    if "goal" in WorldMsg.__slots__:  # float64[] goal, added to World.msg after the first contract
        msg.goal = list(world.goal) if world.goal is not None else []
        msg.goal_region = [v for corner in world.goal_region for v in corner] if world.goal_region else []
    msg.sensed_speed_bound = -1.0 if world.sensed_speed_bound is None else world.sensed_speed_bound
    msg.sensed_unknown_occupied = world.sensed_unknown_occupied
    msg.camera_frames = [c.optical_frame for c in world.cameras]
    for obj in world.objects:
        o = WorldObjectMsg()
        o.id = obj.id
        o.shape = SolidPrimitive(type=_SHAPE_TYPES[obj.shape], dimensions=list(obj.size))
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = obj.position_at(0.0)
        q = obj.quaternion
        pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = q
        o.pose = pose
        o.observed = bool(obj.observed)
        if obj.motion is not None:
            if ObstacleMotion is None:
                raise ValueError("object %r has a motion but moverl_msgs has no ObstacleMotion: rebuild" % obj.id)
            m = obj.motion
            o.motion = ObstacleMotion(
                type=ObstacleMotion.REACH if m.type == "reach" else ObstacleMotion.OSCILLATE,
                axis=list(m.axis),
                **{f: getattr(m, f) for f in MOTION_FIELDS},
            )
        msg.objects.append(o)
    return msg


def contacts_to_msg(stats, stamp_sec):
    """core.ContactStats -> moverl_msgs/ContactReport (available=true). World pairs: a=link, b=object id."""
    msg = ContactReport()
    msg.header.stamp = sim_stamp(stamp_sec)
    msg.available = True
    msg.substeps = stats.substeps
    msg.substeps_in_contact = stats.substeps_in_contact
    msg.world_contacts = stats.world_contacts
    msg.self_contacts = stats.self_contacts
    msg.moving_contacts = stats.moving_contacts
    msg.resting_contacts = stats.resting_contacts
    msg.total_contact_substeps = stats.total_contact_substeps
    for (a, b), depth in sorted(stats.world_pairs.items()):
        msg.pairs.append(CollisionPair(a=a, b=b, depth=depth))
    for (a, b), depth in sorted(stats.self_pairs.items()):
        msg.pairs.append(CollisionPair(a=a, b=b, depth=depth))
    return msg


class FollowPoint:
    """A trajectory_msgs/JointTrajectoryPoint as moverl_sim.follow reads it (time_from_start in seconds)."""

    __slots__ = ("positions", "velocities", "accelerations", "time_from_start")

    def __init__(self, p):
        self.positions, self.velocities, self.accelerations = p.positions, p.velocities, p.accelerations
        self.time_from_start = p.time_from_start.to_sec()


def joint_state_msg(names, positions, velocities, stamp_sec):
    msg = JointState()
    msg.header.stamp = sim_stamp(stamp_sec)
    msg.name = list(names)
    msg.position = list(positions)
    msg.velocity = list(velocities)
    return msg


def points_to_msg(points, width, height, frame_id, stamp_sec):
    """(height * width) x 3 float32 points (row-major image order, moverl_sim.camera) -> an organised
    sensor_msgs/PointCloud2 with float32 fields x, y, z (12 bytes per point, little endian, no NaN)."""
    import numpy as np

    pts = np.ascontiguousarray(points, dtype="<f4")
    if pts.shape != (width * height, 3):
        raise ValueError(
            "expected %d x 3 points for a %d x %d image, got shape %s" % (width * height, width, height, pts.shape)
        )
    msg = PointCloud2()
    msg.header.frame_id = frame_id
    msg.header.stamp = sim_stamp(stamp_sec)
    msg.height, msg.width = height, width
    msg.fields = _XYZ_FIELDS
    msg.is_bigendian = False
    msg.point_step = 12
    msg.row_step = 12 * width
    msg.data = pts.tobytes()
    msg.is_dense = True
    return msg


def tracked_pose_msg(measurement, frame_id):
    """moverl_sim.tracker.Measurement -> geometry_msgs/PoseStamped (stamp: when it was measured)."""
    msg = PoseStamped()
    msg.header.stamp = sim_stamp(measurement.stamp)
    msg.header.frame_id = frame_id
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z, o.x, o.y, o.z, o.w = measurement.pose
    return msg


def part_frame_msgs(frames, parent):
    """moverl_sim.people.part_frames' (frame, stamp, pose) -> geometry_msgs/TransformStamped (stamp: when measured)."""
    from geometry_msgs.msg import TransformStamped

    out = []
    for frame, stamp, pose in frames:
        t = TransformStamped()
        t.header.stamp = sim_stamp(stamp)
        t.header.frame_id = parent
        t.child_frame_id = frame
        tr, r = t.transform.translation, t.transform.rotation
        tr.x, tr.y, tr.z, r.x, r.y, r.z, r.w = pose
        out.append(t)
    return out


def tracked_bodies_msg(bodies, stamp, frame_id):
    """The tracked bodies' ids -> hri_msgs/IdsList (REP 155's /humans/bodies/tracked)."""
    from hri_msgs.msg import IdsList

    msg = IdsList(ids=list(bodies))
    msg.header.stamp = sim_stamp(stamp)
    msg.header.frame_id = frame_id
    return msg
