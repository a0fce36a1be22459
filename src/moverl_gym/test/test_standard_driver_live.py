#!/usr/bin/env python3
"""rostest (standard_driver.test): the shield drives the simulator through the standard interface only, in real time.

(a) the simulator offers only what a real robot offers: no ExecuteTrajectory, ResetRobot or world services; the
    graph runs on the simulator's clock;
(b) Gymnasium's and SB3's check_env pass on the unchanged env (its resets are planned moves);
(c) self, pose and path collisions are classified; the path collision is replaced by a plan that executes with zero
    contacts (the simulator's ground truth, read here: the env reports -1 with this driver);
(d) 1,000 random steps make zero contacts (ground truth).
"""

import unittest

import gymnasium as gym
import numpy as np
import rosgraph
import rospy
import rostest
from live_helpers import GroundTruthContacts, LiveAssertions

import moverl_gym  # noqa: F401
from moverl_msgs.srv import ResetRobot, ShieldStep, ShieldStepResponse

HOME = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]
SELF_COLLIDING = [0.0, 0.3, 0.0, -3.0, 0.0, 0.0, 0.0]
TABLE_COLLIDING = [0.0, 1.2, 0.0, -1.0, 0.0, 1.571, 0.785]
WALL_LEFT = [-0.6] + HOME[1:]
WALL_RIGHT = [0.6] + HOME[1:]
SAFE, REPLANNED, DISCARDED_SELF, DISCARDED_POSE = (
    ShieldStepResponse.SAFE,
    ShieldStepResponse.REPLANNED,
    ShieldStepResponse.DISCARDED_SELF,
    ShieldStepResponse.DISCARDED_POSE,
)
RANDOM_STEPS = 1000


class StandardDriverLive(LiveAssertions, unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("standard_driver_test", anonymous=True, disable_signals=True)
        for name in ("/shield/step", "/shield/reset", "/planning_scene/check_state"):
            rospy.wait_for_service(name, timeout=60)
        cls.step = rospy.ServiceProxy("/shield/step", ShieldStep, persistent=True)
        cls.reset = rospy.ServiceProxy("/shield/reset", ResetRobot, persistent=True)
        cls.truth = GroundTruthContacts()

    def place(self, q):
        res = super().place(q)
        np.testing.assert_allclose(res.state.position, q, atol=1e-6)  # kinematic control: exactly there
        return res

    def assert_no_new_contacts(self, before):
        pairs, substeps, _ = self.truth.snapshot()
        self.assertEqual((pairs, substeps), before[:2], self.truth.pairs)

    # (a) ------------------------------------------------------------------------------------------------
    def test_a_only_the_standard_interface(self):
        master = rosgraph.Master("/standard_driver_test")
        services = {name for name, _ in master.getSystemState()[2]}
        for extra in ("/sim/execute", "/sim/reset_robot", "/sim/get_world"):
            self.assertNotIn(extra, services)
        topics = dict(master.getTopicTypes())
        self.assertEqual(
            topics["/arm_controller/follow_joint_trajectory/goal"], "control_msgs/FollowJointTrajectoryActionGoal"
        )
        self.assertEqual(topics["/joint_states"], "sensor_msgs/JointState")
        self.assertTrue(rospy.get_param("/use_sim_time"))

    # (b) ------------------------------------------------------------------------------------------------
    def test_b_check_env(self):
        from gymnasium.utils.env_checker import check_env
        from stable_baselines3.common.env_checker import check_env as sb3_check_env

        env = gym.make("MoveRL/PandaReachTable-v0", graph="attach", world="thin_wall")
        try:
            check_env(env.unwrapped, skip_render_check=True)
            sb3_check_env(env.unwrapped, warn=True)
            _, info = env.reset(seed=3)
            _, _, _, _, info = env.step(env.action_space.sample())
            self.assertEqual(info["contacts"], -1)  # the standard driver has no ground truth
        finally:
            env.close()

    # (c) ------------------------------------------------------------------------------------------------
    def test_c_collisions_classified_and_the_plan_executes_without_contact(self):
        self.place(WALL_LEFT)
        res = self.step(target=SELF_COLLIDING, duration=0.05)
        self.assertEqual(res.verdict, DISCARDED_SELF, res.message)
        res = self.step(target=TABLE_COLLIDING, duration=0.05)
        self.assertEqual(res.verdict, DISCARDED_POSE, res.message)
        self.assertIn("table", res.message)
        np.testing.assert_allclose(res.state.position, WALL_LEFT, atol=1e-6)  # held still
        before = self.truth.snapshot()
        res = self.step(target=WALL_RIGHT, duration=0.05)
        self.assertEqual(res.verdict, REPLANNED, res.message)
        np.testing.assert_allclose(res.state.position, WALL_RIGHT, atol=1e-6)
        rospy.sleep(0.2)  # the last contact report arrives
        self.assertGreater(self.truth.snapshot()[2], before[2])  # the simulator reported the motion
        self.assert_no_new_contacts(before)

    # (d) ------------------------------------------------------------------------------------------------
    def test_d_random_policy_without_contact(self):
        env = gym.make("MoveRL/PandaReachTable-v0", graph="attach", world="thin_wall")
        try:
            env.action_space.seed(0)
            env.reset(seed=0, options={"start": WALL_LEFT})
            before = self.truth.snapshot()
            counts, episode = {}, 0
            for _ in range(RANDOM_STEPS):
                _, _, term, trunc, info = env.step(env.action_space.sample())
                counts[info["verdict"]] = counts.get(info["verdict"], 0) + 1
                if term or trunc:
                    episode += 1
                    env.reset(options={"start": WALL_LEFT} if episode % 2 == 0 else None)
            rospy.sleep(0.2)
            msg = "standard driver, real time: %d random steps, verdicts %s, ground-truth contacts %s" % (
                RANDOM_STEPS,
                counts,
                self.truth.pairs or 0,
            )
            rospy.loginfo(msg)
            print(msg)
            self.assertGreater(sum(v for k, v in counts.items() if k != "safe"), 0)  # the shield had work
            self.assertEqual(counts.get("aborted", 0), 0)
            self.assert_no_new_contacts(before)
        finally:
            env.close()


if __name__ == "__main__":
    rostest.rosrun("moverl_gym", "standard_driver", StandardDriverLive)
