#!/usr/bin/env python3
"""A minimal robot driver for the tests: control_msgs/FollowJointTrajectory and sensor_msgs/JointState, written
independently of moverl_sim so that it catches mistakes our simulator's server would share with our client.

Like a real robot's driver on its own host: stamps are wall-clock time (no /clock), joint_states lists the joints in
its own order with two gripper joints among them, and nothing but the standard interface exists. The "robot" is
kinematic: it follows the trajectory's points by linear interpolation in wall time, 200 times a second.

Faults, for the fault tests, set by a std_msgs/String on ~fault:
  none            behave
  reject_joints   reject the next goals with INVALID_JOINTS (as a controller configured for other joints)
  abort_path      abort the next goals half-way with PATH_TOLERANCE_VIOLATED and stop (as an arm that was blocked)
  stall           accept goals but never move nor answer (a driver that hangs)
  silence         stop publishing joint states (a dead encoder bus); goals still execute
"""

import threading
import time

import rospy
from actionlib import ActionServer
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from control_msgs.msg import FollowJointTrajectoryAction, FollowJointTrajectoryResult

RATE = 200.0


class MinimalDriver:
    def __init__(self):
        self.joints = list(rospy.get_param("/robot/joints"))
        start = list(rospy.get_param("~start", rospy.get_param("/robot/home")))  # where the robot stands at start-up
        self.q = dict(zip(self.joints, start))
        # Published order: reversed, with the gripper's two joints in the middle.
        self.order = self.joints[::-1]
        self.order[3:3] = ["gripper_finger_left", "gripper_finger_right"]
        self.fault = "none"
        self.lock = threading.Lock()
        self.active = None  # (goal handle, start wall time, [(t, {joint: q})])
        self.pub = rospy.Publisher("~joint_states", JointState, queue_size=10)
        rospy.Subscriber("~fault", String, self.on_fault)
        self.server = ActionServer(
            "~follow_joint_trajectory", FollowJointTrajectoryAction, self.on_goal, self.on_cancel, auto_start=False
        )
        self.server.start()

    def on_fault(self, msg):
        with self.lock:
            self.fault = msg.data
        rospy.loginfo("minimal driver: fault %s", msg.data)

    def on_goal(self, gh):
        goal = gh.get_goal()
        traj = goal.trajectory
        with self.lock:
            fault = self.fault
        if fault == "reject_joints" or sorted(traj.joint_names) != sorted(self.joints):
            gh.set_rejected(
                FollowJointTrajectoryResult(
                    error_code=FollowJointTrajectoryResult.INVALID_JOINTS,
                    error_string="this controller drives %s" % self.joints,
                )
            )
            return
        if not traj.points:
            gh.set_accepted()
            gh.set_succeeded(FollowJointTrajectoryResult())
            return
        start = traj.header.stamp.to_sec() or time.time()
        points = [(p.time_from_start.to_sec(), dict(zip(traj.joint_names, p.positions))) for p in traj.points]
        with self.lock:
            if self.active is not None:
                self.active[0].set_canceled(FollowJointTrajectoryResult(error_string="preempted"))
            # Interpolate from where the robot is, at the trajectory's start, to its points.
            if points[0][0] > 0.0:
                points.insert(0, (0.0, dict(self.q)))
            self.active = (gh, start, points, fault)
        gh.set_accepted()

    def on_cancel(self, gh):
        with self.lock:
            if self.active is not None and self.active[0] == gh:
                self.active = None
                gh.set_canceled(FollowJointTrajectoryResult(error_string="cancelled"))

    def tick(self):
        now = time.time()
        done = None
        with self.lock:
            if self.active is not None:
                gh, start, points, fault = self.active
                t = now - start
                end = points[-1][0]
                if fault == "stall":
                    pass  # accepted, never moves, never answers
                elif fault == "abort_path" and t >= end / 2:
                    self.active = None
                    done = (
                        gh,
                        FollowJointTrajectoryResult(
                            error_code=FollowJointTrajectoryResult.PATH_TOLERANCE_VIOLATED,
                            error_string="%s path error 0.05 (blocked)" % self.joints[1],
                        ),
                        False,
                    )
                elif t >= 0.0:
                    k = 0
                    while k + 1 < len(points) and points[k + 1][0] <= t:
                        k += 1
                    if k + 1 < len(points):
                        (t0, q0), (t1, q1) = points[k], points[k + 1]
                        a = (t - t0) / (t1 - t0)
                        self.q = {j: q0[j] + a * (q1[j] - q0[j]) for j in self.joints}
                    else:
                        self.q = dict(points[-1][1])
                        self.active = None
                        done = (gh, FollowJointTrajectoryResult(), True)
            q = dict(self.q)
            silent = self.fault == "silence"
        if done is not None:
            gh, result, ok = done
            (gh.set_succeeded if ok else gh.set_aborted)(result)
        if not silent:
            msg = JointState()
            msg.header.stamp = rospy.Time.from_sec(now)
            msg.name = self.order
            msg.position = [q.get(j, 0.01) for j in self.order]
            msg.velocity = [0.0] * len(self.order)
            self.pub.publish(msg)


def main():
    rospy.init_node("minimal_driver")
    driver = MinimalDriver()
    rospy.loginfo("minimal driver: %s, joints %s", driver.server.ns, driver.joints)
    period = 1.0 / RATE
    while not rospy.is_shutdown():
        driver.tick()
        time.sleep(period)


if __name__ == "__main__":
    main()
