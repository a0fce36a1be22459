#!/usr/bin/env python3
"""rostest (minimal_driver.test): the env drives a robot through a FollowJointTrajectory driver that is not ours.

(a) the env, unchanged, passes Gymnasium's and SB3's check_env and steps; resets are planned moves; contacts are
    unknown (-1) since this driver has no ground truth;
(b) driver faults each give a clear error and nothing moves unchecked:
    a goal rejected (INVALID_JOINTS): MoveRLError naming the code, the robot did not move;
    a goal aborted mid-way (PATH_TOLERANCE_VIOLATED, an arm blocked): the episode ends (truncated), info says why;
    a driver that never answers: the goal is cancelled and the env raises within 5 s;
    joint states that stop: the shield fails closed and the env raises within 5 s.
"""

import time
import unittest

import gymnasium as gym
import numpy as np
import rospy
import rostest
from sensor_msgs.msg import JointState
from std_msgs.msg import String

import moverl_gym  # noqa: F401
from moverl_gym.env import MoveRLError

WORLD = "thin_wall"
FREE = [-0.6, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]  # hand right of the test wall
STEP_TOWARDS = np.array([0.5, 0.5, 0.0, 0.5, 0.0, 0.0, 0.0], dtype=np.float32)


class MinimalDriverLive(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("minimal_driver_test", anonymous=True, disable_signals=True)
        rospy.wait_for_service("/shield/step", timeout=60)
        cls.fault_pub = rospy.Publisher("/minimal_driver/fault", String, queue_size=1, latch=True)
        cls.env = gym.make("MoveRL/PandaReachTable-v0", graph="attach", world=WORLD)

    @classmethod
    def tearDownClass(cls):
        cls.env.close()

    def setUp(self):
        self.fault("none")

    def fault(self, name):
        self.fault_pub.publish(String(data=name))
        time.sleep(0.3)  # the driver's subscriber gets it (test set-up, not a step)

    def joint_state(self):
        msg = rospy.wait_for_message("/minimal_driver/joint_states", JointState, timeout=5)
        return np.array([dict(zip(msg.name, msg.position))[j] for j in self.env.unwrapped.limits.names])

    def start_free(self):
        obs, info = self.env.reset(options={"start": FREE})
        np.testing.assert_allclose(self.joint_state(), FREE, atol=1e-3)
        return obs

    # (a) ------------------------------------------------------------------------------------------------
    def test_a_env_unchanged_check_env_and_steps(self):
        from gymnasium.utils.env_checker import check_env
        from stable_baselines3.common.env_checker import check_env as sb3_check_env

        check_env(self.env.unwrapped, skip_render_check=True)
        sb3_check_env(self.env.unwrapped, warn=True)
        self.env.reset(seed=1)
        self.env.action_space.seed(1)
        verdicts = {}
        for _ in range(60):
            _, _, term, trunc, info = self.env.step(self.env.action_space.sample())
            self.assertEqual(info["contacts"], -1)  # no ground truth from a real driver
            verdicts[info["verdict"]] = verdicts.get(info["verdict"], 0) + 1
            if term or trunc:
                self.env.reset()
        self.assertGreater(verdicts.get("safe", 0), 30, verdicts)
        # The env's joint angles are the driver's, matched by name (its message is shuffled and has a gripper).
        obs = self.start_free()
        np.testing.assert_allclose(obs[:7], self.joint_state(), atol=1e-3)

    # (b) ------------------------------------------------------------------------------------------------
    def test_b_rejected_goal_raises_and_nothing_moves(self):
        self.start_free()
        before = self.joint_state()
        self.fault("reject_joints")
        with self.assertRaises(MoveRLError) as err:
            self.env.step(STEP_TOWARDS)
        self.assertIn("INVALID_JOINTS", str(err.exception))
        np.testing.assert_allclose(self.joint_state(), before, atol=1e-9)

    def test_c_aborted_goal_ends_the_episode(self):
        self.start_free()
        self.fault("abort_path")
        _, _, term, trunc, info = self.env.step(STEP_TOWARDS)
        self.assertTrue(trunc, info)
        self.assertFalse(term)
        self.assertEqual(info["verdict"], "aborted")
        self.assertEqual(info["driver_error"], "PATH_TOLERANCE_VIOLATED")
        self.assertIn("blocked", info["driver_message"])

    def test_d_stalled_driver_is_cancelled_and_the_env_raises_within_5_s(self):
        self.start_free()
        before = self.joint_state()
        self.fault("stall")
        t0 = time.monotonic()
        with self.assertRaises(MoveRLError) as err:
            self.env.step(STEP_TOWARDS)
        took = time.monotonic() - t0
        self.assertLess(took, 5.0)
        self.assertIn("robot driver", str(err.exception))
        self.assertIn("cancelled", str(err.exception))
        np.testing.assert_allclose(self.joint_state(), before, atol=1e-9)
        rospy.loginfo("stalled driver: env raised after %.2f s: %s", took, err.exception)

    def test_e_silent_joint_states_fail_closed(self):
        self.start_free()
        self.fault("silence")
        time.sleep(0.6)  # longer than the shield's max_state_age
        t0 = time.monotonic()
        with self.assertRaises(MoveRLError) as err:
            self.env.step(STEP_TOWARDS)
        took = time.monotonic() - t0
        self.assertLess(took, 5.0)
        self.assertIn("joint states", str(err.exception))
        self.fault("none")
        np.testing.assert_allclose(self.joint_state(), FREE, atol=1e-3)  # it never moved


if __name__ == "__main__":
    rostest.rosrun("moverl_gym", "minimal_driver", MinimalDriverLive)
