#!/usr/bin/env python3
"""rostest on the live headless graph (env_live.test): the Gymnasium env itself.

check_env (Gymnasium and SB3) pass; same seed + same actions give the same observations; bad actions
raise clear errors without harming the graph; a random policy makes zero physical contacts with the shield
on, and does make contacts with it off (so the audit can fail).
"""

import unittest

import gymnasium as gym
import numpy as np
import rospy
import rostest

import moverl_gym  # noqa: F401

AUDIT_STEPS = 3000


class EnvLive(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("env_live_test", anonymous=True, disable_signals=True)
        cls.shield = bool(rospy.get_param("~shield", True))
        cls.env = gym.make("MoveRL/PandaReachTable-v0", graph="attach", shield=cls.shield)

    @classmethod
    def tearDownClass(cls):
        cls.env.close()

    def test_gymnasium_check_env(self):
        from gymnasium.utils.env_checker import check_env

        check_env(self.env.unwrapped, skip_render_check=True)

    def test_sb3_check_env(self):
        from stable_baselines3.common.env_checker import check_env

        check_env(self.env.unwrapped, warn=True)

    def test_ee_observation_variant_passes_check_env(self):
        from gymnasium.utils.env_checker import check_env

        env = gym.make("MoveRL/PandaReachTableEE-v0", graph="attach", shield=self.shield)
        try:
            check_env(env.unwrapped, skip_render_check=True)
            obs, _ = env.reset(seed=4)
            self.assertEqual(obs.shape, (10,))  # ee pose (7) + goal (3)
        finally:
            env.close()

    def test_goals_can_be_sampled_from_the_reachable_region(self):
        env = gym.make("MoveRL/PandaReachTable-v0", graph="attach", shield=self.shield, task={"goal_noise": 0.6})
        try:
            goals = [env.reset(seed=s)[0][14:17] for s in (1, 2, 1)]
            np.testing.assert_array_equal(goals[0], goals[2])  # the seed decides the goal
            self.assertFalse(np.allclose(goals[0], goals[1]))
            self.assertFalse(np.allclose(goals[0], [0.4, 0.2, 0.2]))
            self.assertGreater(goals[0][2], 0.0)  # above the table top: the flange of a collision-free pose
        finally:
            env.close()

    def test_same_seed_same_actions_same_observations(self):
        actions = np.random.default_rng(3).uniform(-1, 1, size=(40, 7)).astype(np.float32)

        def rollout():
            obs, _ = self.env.reset(seed=11)
            out = [obs]
            for a in actions:
                obs, _, term, trunc, _ = self.env.step(a)
                out.append(obs)
                if term or trunc:
                    break
            return np.array(out)

        first, second = rollout(), rollout()
        np.testing.assert_array_equal(first, second)
        third = self.env.reset(seed=12)[0]
        self.assertFalse(np.array_equal(first[0], third), "another seed gives another start")

    def test_observation_layout(self):
        obs, info = self.env.reset(seed=1)
        # 7 joints + ee pose (7) + goal (3); the table is not an observed obstacle.
        self.assertEqual(obs.shape, (17,))
        np.testing.assert_allclose(obs[14:17], [0.4, 0.2, 0.2], atol=1e-6)
        self.assertAlmostEqual(np.linalg.norm(obs[10:14]), 1.0, places=5)  # ee quaternion

    def test_bad_actions_raise_clear_errors(self):
        self.env.reset(seed=2)
        with self.assertRaisesRegex(ValueError, "shape"):
            self.env.step(np.zeros(6, dtype=np.float32))
        with self.assertRaisesRegex(ValueError, "NaN or inf"):
            self.env.step(np.full(7, np.nan, dtype=np.float32))
        with self.assertRaisesRegex(ValueError, "NaN or inf"):
            self.env.step(np.full(7, np.inf, dtype=np.float32))
        obs, *_ = self.env.step(np.zeros(7, dtype=np.float32))  # the env still works
        self.assertEqual(obs.shape, (17,))

    def test_random_policy_contact_audit(self):
        env = self.env
        env.action_space.seed(5)
        env.reset(seed=5)
        contacts, verdicts = 0, {}
        for _ in range(AUDIT_STEPS):
            _, _, term, trunc, info = env.step(env.action_space.sample())
            self.assertGreaterEqual(info["contacts"], 0, "the simulator reports ground-truth contacts")
            contacts += info["contacts"]
            verdicts[info["verdict"]] = verdicts.get(info["verdict"], 0) + 1
            if term or trunc:
                env.reset()
        rospy.loginfo("audit: shield=%s contacts=%d verdicts=%s", self.shield, contacts, verdicts)
        if self.shield:
            self.assertEqual(contacts, 0, f"shield on must give zero contacts; verdicts {verdicts}")
            self.assertNotIn("unchecked", verdicts)
        else:
            self.assertGreater(contacts, 0, f"shield off should make contacts; verdicts {verdicts}")
            self.assertEqual(set(verdicts), {"unchecked"})


if __name__ == "__main__":
    rostest.rosrun("moverl_gym", "env_live", EnvLive)
