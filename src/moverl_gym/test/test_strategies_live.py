#!/usr/bin/env python3
"""rostest on the live headless graph (strategies_live.test, world test/worlds/thin_wall.yaml).

Three shield nodes share one simulator and planning scene and differ only in ~strategy:
/shield (plan), /shield_discard (discard) and /shield_last_safe (last_safe). Each test resets the robot
through the shield it then steps, so that shield knows the state it starts from.
"""

import unittest

import numpy as np
import rospy
import rostest
from live_helpers import LiveAssertions

from moverl_msgs.srv import CheckPath, CheckState, ResetRobot, ShieldStep, ShieldStepResponse, ValidateMotionResponse

HOME = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]
TABLE_COLLIDING = [0.0, 1.2, 0.0, -1.0, 0.0, 1.571, 0.785]  # arm bent down: fingers in the table
WALL_LEFT = [-0.6] + HOME[1:]  # hand right of the wall
WALL_RIGHT = [0.6] + HOME[1:]  # hand left of the wall; turning joint 1 sweeps the hand through it

SAFE, REPLANNED, DISCARDED_SELF, DISCARDED_POSE, DISCARDED_PATH = (
    ShieldStepResponse.SAFE,
    ShieldStepResponse.REPLANNED,
    ShieldStepResponse.DISCARDED_SELF,
    ShieldStepResponse.DISCARDED_POSE,
    ShieldStepResponse.DISCARDED_PATH,
)
TRUNCATED = ShieldStepResponse.TRUNCATED
CAUSE_POSE, CAUSE_PATH = ValidateMotionResponse.POSE_COLLISION, ValidateMotionResponse.PATH_COLLISION
SHIELDS = {"plan": "/shield", "discard": "/shield_discard", "last_safe": "/shield_last_safe"}


class StrategiesLive(LiveAssertions, unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("strategies_live_test", anonymous=True, disable_signals=True)
        cls.step, cls.reset = {}, {}
        for strategy, ns in SHIELDS.items():
            rospy.wait_for_service(ns + "/step", timeout=60)
            rospy.wait_for_service(ns + "/reset", timeout=60)
            cls.step[strategy] = rospy.ServiceProxy(ns + "/step", ShieldStep, persistent=True)
            cls.reset[strategy] = rospy.ServiceProxy(ns + "/reset", ResetRobot, persistent=True)
        rospy.wait_for_service("/planning_scene/check_state", timeout=60)
        cls.check_state = rospy.ServiceProxy("/planning_scene/check_state", CheckState)
        cls.check_path = rospy.ServiceProxy("/planning_scene/check_path", CheckPath)

    def place(self, strategy, q):
        res = self.reset[strategy](positions=q)
        self.assertTrue(res.success, res.message)
        np.testing.assert_allclose(res.state.position[:7], q, atol=1e-9)

    def test_each_shield_reports_its_strategy_on_a_safe_move(self):
        for strategy in SHIELDS:
            self.place(strategy, WALL_LEFT)
            target = list(np.array(WALL_LEFT) + 0.05)
            res = self.step[strategy](target=target, duration=0.05)
            self.assertEqual(res.verdict, SAFE, res.message)
            self.assertEqual(res.strategy, strategy)
            self.assertEqual(res.unsafe_cause, 0)
            self.assertEqual(res.truncated_fraction, -1.0)
            np.testing.assert_allclose(res.state.position, target, atol=1e-6)

    def test_plan_replans_across_the_wall(self):
        self.place("plan", WALL_LEFT)
        res = self.step["plan"](target=WALL_RIGHT, duration=0.05)
        self.assertEqual(res.verdict, REPLANNED, res.message)
        self.assertEqual(res.strategy, "plan")
        self.assertEqual(res.unsafe_cause, CAUSE_PATH)
        np.testing.assert_allclose(res.state.position, WALL_RIGHT, atol=1e-6)
        self.assert_no_contacts(res)

    def test_discard_holds_still_across_the_wall(self):
        self.place("discard", WALL_LEFT)
        res = self.step["discard"](target=WALL_RIGHT, duration=0.05)
        self.assertEqual(res.verdict, DISCARDED_PATH, res.message)
        self.assertEqual(res.strategy, "discard")
        self.assertEqual(res.unsafe_cause, CAUSE_PATH)
        self.assertEqual(res.planning_time, 0.0, "discard never plans")
        np.testing.assert_allclose(res.state.position, WALL_LEFT, atol=1e-9)
        # Nothing moved: no contacts (this shield never executed, so the driver's report may be unavailable).
        self.assertEqual(res.contacts.world_contacts + res.contacts.self_contacts, 0, res.contacts.pairs)

    def test_last_safe_stops_before_the_wall(self):
        self.place("last_safe", WALL_LEFT)
        res = self.step["last_safe"](target=WALL_RIGHT, duration=0.05)
        self.assertEqual(res.verdict, TRUNCATED, res.message)
        self.assertEqual(res.strategy, "last_safe")
        self.assertEqual(res.unsafe_cause, CAUSE_PATH)
        self.assertEqual(res.planning_time, 0.0, "last_safe never plans")
        q = np.array(res.state.position)
        self.assertGreater(np.abs(q - WALL_LEFT).max(), 0.05, "the robot moved")
        # Along the straight path (only joint 1 changes) and stopped before the wall (at joint 1 ~ 0).
        np.testing.assert_allclose(q[1:], WALL_LEFT[1:], atol=1e-6)
        self.assertLess(q[0], 0.0)
        self.assertGreater(res.truncated_fraction, 0.0)
        self.assertLess(res.truncated_fraction, 0.5)
        path = self.check_path(start=WALL_LEFT, goal=WALL_RIGHT)
        self.assertGreater(path.collision_fraction, res.truncated_fraction)
        self.assert_no_contacts(res)
        reached = self.check_state(positions=list(q))
        self.assertEqual(reached.outcome, 0, reached.message)  # VALID

    def test_last_safe_on_a_table_colliding_target(self):
        self.place("last_safe", WALL_LEFT)
        self.assertEqual(self.check_state(positions=TABLE_COLLIDING).outcome, 2)  # WORLD_COLLISION
        res = self.step["last_safe"](target=TABLE_COLLIDING, duration=0.05)
        self.assertIn(res.verdict, (TRUNCATED, DISCARDED_POSE), res.message)
        self.assertEqual(res.strategy, "last_safe")
        self.assertEqual(res.unsafe_cause, CAUSE_POSE)
        if res.verdict == TRUNCATED:
            self.assert_no_contacts(res)
        else:
            self.assertEqual(res.contacts.world_contacts + res.contacts.self_contacts, 0, res.contacts.pairs)
        reached = self.check_state(positions=list(res.state.position))
        self.assertEqual(reached.outcome, 0, reached.message)
        if res.verdict == DISCARDED_POSE:
            np.testing.assert_allclose(res.state.position, WALL_LEFT, atol=1e-9)
        rospy.loginfo("last_safe on the table target: %s at fraction %.3f", res.verdict, res.truncated_fraction)

    def test_env_info_reports_the_strategy(self):
        """The env (attached to /shield) reports the shield's strategy in info; truncated counts as discarded."""
        import gymnasium as gym

        import moverl_gym  # noqa: F401
        from moverl_gym.env import COLLISION_TYPES, DISCARDED, VERDICTS

        self.assertEqual(VERDICTS[TRUNCATED], "truncated")
        self.assertIn(TRUNCATED, DISCARDED)
        self.assertIn(TRUNCATED, COLLISION_TYPES)
        env = gym.make("MoveRL/PandaReachTable-v0", graph="attach", world="thin_wall")
        try:
            env.reset(seed=0)
            _, _, _, _, info = env.step(np.zeros(7, dtype=np.float32))
            self.assertEqual(info["strategy"], "plan")
        finally:
            env.close()


if __name__ == "__main__":
    rostest.rosrun("moverl_gym", "strategies_live", StrategiesLive)
