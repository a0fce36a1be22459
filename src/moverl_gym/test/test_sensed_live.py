#!/usr/bin/env python3
"""rostest: an obstacle the planning scene knows only from depth-camera points (sensed_obstacle.test).

The planning scene runs with obstacles:=octomap: it ignores the world file's objects and builds an OctoMap from the
simulator's two depth cameras (/sim/points). Test world worlds/sensed_box.yaml: a box stands in front of the robot
at motion time 0 and slides sideways: 0.37 m away at 25 s, more than 0.3 m from 20 s to 40 s.
  (a) ground truth: the unchecked shield_off moving the hand into the box makes contact with it;
  (b) the scene flags the target inside the box as a collision with the sensed map ("octomap", never "box"), and
      the shield discards the step: no contact;
  (c) after the box has moved away, new camera views clear its old cells: the same target becomes free and the
      shield executes the move, without contact (the box is still far: the map only knows where things were
      when last seen, so the sensed mode is for static or slow obstacles);
  (d) the map filtered the robot's own points: 300 random env steps in 10-step episodes (30 resets, renders
      racing with the joint states) go through, each reset sampling a collision-free start near home from the
      scene, and afterwards home and every episode start are still free in the map (a robot left behind as an
      obstacle would block them). Not asserted for every configuration visited: a visited pose can touch cells
      that were unknown (hidden by the robot itself) at the time and were seen later, a legitimate verdict.
"""

import time
import unittest

import gymnasium as gym
import numpy as np
import rospy
import rostest
from live_helpers import LiveAssertions

import moverl_gym  # noqa: F401
from moverl_msgs.msg import OctomapStatus
from moverl_msgs.srv import CheckPath, CheckStateResponse, ShieldStepResponse

SAFE, REPLANNED, DISCARDED_POSE, UNCHECKED = (
    ShieldStepResponse.SAFE,
    ShieldStepResponse.REPLANNED,
    ShieldStepResponse.DISCARDED_POSE,
    ShieldStepResponse.UNCHECKED,
)
VALID, WORLD = CheckStateResponse.VALID, CheckStateResponse.WORLD_COLLISION
HOME = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]
# The hand at (0.50, 0.01, 0.22): inside the box at motion time 0, clear of the table and of itself.
Q_BOX = [-0.265, 0.294, 0.335, -2.261, -0.714, 2.151, -0.309]
DT = 0.05
WAIT = 30.0  # s (wall) for the map to take in new views
ENV_STEPS = 300


class SensedObstacleLive(LiveAssertions, unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.connect_shield_pair("sensed_obstacle_test", "/planning_scene/check_path")
        cls.check_path = rospy.ServiceProxy("/planning_scene/check_path", CheckPath)
        cls.status = None
        cls.status_sub = rospy.Subscriber("/planning_scene/octomap_status", OctomapStatus, cls._on_status)

    @classmethod
    def _on_status(cls, msg):
        cls.status = msg

    def wait_for_clouds(self, n):
        """One hold of a camera period (lockstep sim time moves on, so the cameras render again), then wait until
        n more clouds were integrated."""
        deadline = time.monotonic() + WAIT
        while self.status is None and time.monotonic() < deadline:
            time.sleep(0.05)
        self.assertIsNotNone(self.status, "no /planning_scene/octomap_status")
        start = self.status.clouds
        self.assert_no_contacts(self.step(target=self.current, duration=0.25))
        while self.status.clouds < start + n:
            self.assertLess(
                time.monotonic(),
                deadline,
                "the map integrated %d of %d clouds in %.0f s" % (self.status.clouds - start, n, WAIT),
            )
            time.sleep(0.02)

    def test_sensed_box(self):
        # (a) ground truth: the box is physically there.
        self.place(HOME, self.reset_off)
        off = self.step_off(target=Q_BOX, duration=DT)
        self.assertEqual(off.verdict, UNCHECKED, off.message)
        self.assertGreater(sum(1 for p in off.contacts.pairs if p.b == "box"), 0, off.contacts.pairs)

        # (b) motion time 0 again: the box stands in front of the robot; the cameras see it.
        self.current = HOME
        self.place(HOME)
        self.wait_for_clouds(2)
        res = self.check_state(positions=Q_BOX)
        self.assertEqual(res.outcome, WORLD, res.message)
        self.assertTrue(res.pairs and all(p.b == "octomap" for p in res.pairs), res.pairs)
        step = self.step(target=Q_BOX, duration=DT)
        self.assertEqual(step.verdict, DISCARDED_POSE, step.message)
        self.assert_no_contacts(step)
        np.testing.assert_allclose(step.state.position[:7], HOME, atol=1e-9)

        # (c) 25 s later the box is 0.37 m to the side; fresh views clear its old cells.
        for _ in range(25):
            hold = self.step(target=HOME, duration=1.0)
            self.assertEqual(hold.verdict, SAFE, hold.message)
            self.assert_no_contacts(hold)

        # Forgotten: the target and the straight way there from home are free again (the state alone can be free
        # while cells of the box's trace on the approach are still occupied).
        def forgotten():
            return (
                self.check_state(positions=Q_BOX).outcome == VALID
                and self.check_path(start=HOME, goal=Q_BOX).outcome == VALID
            )

        for _ in range(60):  # at most 15 s of motion time: the box stays > 0.3 m away
            if forgotten():
                break
            self.wait_for_clouds(2)
        self.assertTrue(forgotten(), "the box's old cells were never cleared")
        rospy.loginfo("sensed box forgotten after %d clouds", self.status.clouds)
        step = self.step(target=Q_BOX, duration=DT)
        self.assertIn(step.verdict, (SAFE, REPLANNED), step.message)
        self.assert_no_contacts(step)
        np.testing.assert_allclose(step.state.position[:7], Q_BOX, atol=1e-6)

        # (d) the robot's own points were filtered, and the map holds the rest of the world.
        self.assertGreater(self.status.robot_points, 0)
        self.assertGreater(self.status.occupied_leaves, 100)
        self.assertGreater(self.status.hit_cells, 0)
        # The env's random episodes (short ones: many resets, each sampling a collision-free start through the
        # scene, which fails if the robot left itself behind in the map).
        env = gym.make("MoveRL/PandaReachTable-v0", graph="attach", world="sensed_box", task={"max_episode_steps": 10})
        starts = []
        try:
            env.action_space.seed(4)
            env.reset(seed=4)
            starts.append(env.unwrapped.q[:7].tolist())
            for _ in range(ENV_STEPS):
                _, _, term, trunc, info = env.step(env.action_space.sample())
                if term or trunc:
                    env.reset()
                    starts.append(env.unwrapped.q[:7].tolist())
            self.current = env.unwrapped.q[:7].tolist()
        finally:
            env.close()
        self.assertGreaterEqual(len(starts), ENV_STEPS // 10)
        self.wait_for_clouds(4)
        blocked = [
            (q, [(p.a, p.b) for p in r.pairs])
            for q in [HOME] + starts
            for r in [self.check_state(positions=q)]
            if r.outcome != VALID
        ]
        self.assertEqual(blocked, [], "home or episode starts are now in collision with the map")


if __name__ == "__main__":
    rostest.rosrun("moverl_gym", "sensed_obstacle", SensedObstacleLive)
