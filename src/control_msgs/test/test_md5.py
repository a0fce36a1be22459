"""The generated control_msgs types must be byte-compatible with real drivers: same MD5 sums as control_msgs 1.5
(ROS Noetic), the release that ros_control's joint_trajectory_controller, franka_ros and ur_robot_driver use.
A mismatch means a driver refuses our goals ("md5sum mismatch") at connection time."""

import pytest

from control_msgs import msg

pytestmark = pytest.mark.core

# From the control_msgs 1.5 release (ROS Noetic), as published drivers see them.
NOETIC_MD5 = {
    "FollowJointTrajectoryGoal": "69636787b6ecbde4d61d711979bc7ecb",
    "FollowJointTrajectoryActionGoal": "cff5c1d533bf2f82dd0138d57f4304bb",
    "FollowJointTrajectoryResult": "493383b18409bfb604b4e26c676401d2",
    "FollowJointTrajectoryActionResult": "c4fb3b000dc9da4fd99699380efcc5d9",
    "FollowJointTrajectoryFeedback": "10817c60c2486ef6b33e97dcd87f4474",
    "FollowJointTrajectoryActionFeedback": "d8920dc4eae9fc107e00999cce4be641",
}


@pytest.mark.parametrize("name", sorted(NOETIC_MD5))
def test_md5_equals_control_msgs_1_5(name):
    cls = getattr(msg, name)
    assert cls._type == f"control_msgs/{name}"
    assert cls._md5sum == NOETIC_MD5[name]


def test_result_codes():
    r = msg.FollowJointTrajectoryResult
    assert (
        r.SUCCESSFUL,
        r.INVALID_GOAL,
        r.INVALID_JOINTS,
        r.OLD_HEADER_TIMESTAMP,
        r.PATH_TOLERANCE_VIOLATED,
        r.GOAL_TOLERANCE_VIOLATED,
    ) == (0, -1, -2, -3, -4, -5)
