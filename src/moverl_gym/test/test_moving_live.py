#!/usr/bin/env python3
"""rostest on the live headless graph with a moving obstacle (moving_obstacle.test, test/worlds/moving_wall.yaml).

A 5 mm wall falls and rises across the arm's path with a 1 s period (at its top at motion time 0). Motion time
restarts at every reset, so each test starts from a known phase.
  (a) the world reports the wall's motion;
  (b) a move whose start and target are clear of the wall, and whose straight path is free of the wall where it is
      when the step begins, but which the wall crosses while the move executes: the shield does not execute it
      straight (replanned around the whole swing, or held still), zero contacts; the unchecked shield_off
      executing the same move hits the wall;
  (c) a move away from the wall executes (SAFE), and a discarded step still lets time pass;
  (d) random policy with the shield on (env, 1000 steps near the wall): zero contacts; with the shield off
      (/shield_off, the same actions scaled as the env does): contacts with the wall;
  (e) reset(seed) twice with the same actions gives identical observations, moving wall pose included.
"""

import unittest

import gymnasium as gym
import numpy as np
import rospy
import rostest
from live_helpers import LiveAssertions

import moverl_gym  # noqa: F401
from moverl_msgs.msg import ObstacleMotion
from moverl_msgs.srv import CheckStateResponse, GetWorld, ShieldStepResponse, ValidateMotion

SAFE, REPLANNED, DISCARDED_POSE, DISCARDED_PATH, UNCHECKED = (
    ShieldStepResponse.SAFE,
    ShieldStepResponse.REPLANNED,
    ShieldStepResponse.DISCARDED_POSE,
    ShieldStepResponse.DISCARDED_PATH,
    ShieldStepResponse.UNCHECKED,
)
VALID = CheckStateResponse.VALID
HOME = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]
LEFT = [-0.8] + HOME[1:]  # hand well to the right (-y) of the wall's plane
RIGHT = [0.8] + HOME[1:]
AWAY = [-1.2] + HOME[1:]
NEAR = [-0.65] + HOME[1:]  # the closest home-like posture clear of the wall's swing: random actions cross it
RANDOM_STEPS = 1000
OFF_STEPS = 400
DT = 0.05


class MovingObstacleLive(LiveAssertions, unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.connect_shield_pair("moving_obstacle_test", "/planning_scene/validate_motion", "/sim/get_world")
        cls.validate = rospy.ServiceProxy("/planning_scene/validate_motion", ValidateMotion)
        cls.world = rospy.ServiceProxy("/sim/get_world", GetWorld)().world

    def assert_no_contacts(self, res):
        super().assert_no_contacts(res, substeps=False)

    @staticmethod
    def wall_contacts(res):
        return sum(1 for p in res.contacts.pairs if p.b == "wall")

    # (a) ------------------------------------------------------------------------------------------------
    def test_a_world_reports_the_motion(self):
        self.assertEqual(self.world.name, "moving_wall")
        wall = {o.id: o for o in self.world.objects}["wall"]
        self.assertEqual(wall.motion.type, ObstacleMotion.OSCILLATE)
        self.assertEqual(list(wall.motion.axis), [0.0, 0.0, 1.0])
        self.assertAlmostEqual(wall.pose.position.z, 1.95)  # pose at motion time 0: top of the swing
        for q in (LEFT, RIGHT, AWAY, NEAR):
            self.assertEqual(self.check_state(positions=q).outcome, VALID, q)
        self.assertNotEqual(self.check_state(positions=HOME).outcome, VALID)  # home is in the wall's swing

    # (b) ------------------------------------------------------------------------------------------------
    def test_b_a_crossing_wall_is_caught(self):
        for attempt in range(3):
            self.place(LEFT)  # motion time 0: the wall is at its top
            # A check against the wall's pose when the step begins (an instant) passes:
            instant = self.validate(
                start=LEFT, goal=RIGHT, plan_on_path_collision=False, find_last_free=False, start_time=0.0, duration=0.0
            )
            self.assertEqual(instant.outcome, VALID, instant.message)
            self.assertTrue(instant.moving_obstacles)
            # ... but the move takes 0.74 s (joint 1 at its velocity limit) and the wall comes down meanwhile.
            res = self.step(target=RIGHT, duration=DT)
            self.assertIn(res.verdict, (REPLANNED, DISCARDED_PATH), res.message)
            self.assert_no_contacts(res)
            self.assertGreater(res.contacts.substeps, 0)  # executed (a plan or a hold): time went on
            if res.verdict == REPLANNED:
                np.testing.assert_allclose(res.state.position[:7], RIGHT, atol=1e-6)
                break
            np.testing.assert_allclose(res.state.position[:7], LEFT, atol=1e-9)
        rospy.loginfo("crossing wall: %s", res.message)
        # Ground truth: executed unchecked, the same move hits the wall.
        self.place(LEFT, self.reset_off)
        off = self.step_off(target=RIGHT, duration=DT)
        self.assertEqual(off.verdict, UNCHECKED, off.message)
        self.assertGreater(self.wall_contacts(off), 0, off.contacts.pairs)

    # (c) ------------------------------------------------------------------------------------------------
    def test_c_a_move_away_executes_and_holds_let_time_pass(self):
        self.place(LEFT)
        res = self.step(target=AWAY, duration=DT)
        self.assertEqual(res.verdict, SAFE, res.message)
        self.assert_no_contacts(res)
        np.testing.assert_allclose(res.state.position[:7], AWAY, atol=1e-6)
        t0 = res.state.header.stamp
        res = self.step(target=HOME, duration=DT)  # home is in the wall's swing: discarded, held still
        self.assertEqual(res.verdict, DISCARDED_POSE, res.message)
        self.assert_no_contacts(res)
        np.testing.assert_allclose(res.state.position[:7], AWAY, atol=1e-9)
        self.assertAlmostEqual((res.state.header.stamp - t0).to_sec(), DT, delta=1.5 / 240)

    # (d) ------------------------------------------------------------------------------------------------
    def test_d_random_policy_shield_on_no_contacts_shield_off_contacts(self):
        env = gym.make("MoveRL/PandaReachTable-v0", graph="attach", world="moving_wall")
        try:
            env.action_space.seed(0)
            env.reset(seed=0, options={"start": NEAR})
            counts = self.random_rollout_without_contact(env, RANDOM_STEPS, NEAR)
            msg = "shield on: %d random steps, verdicts %s, zero contacts" % (RANDOM_STEPS, counts)
            rospy.loginfo(msg)
            print(msg)
            self.assertGreater(sum(v for k, v in counts.items() if k != "safe"), 0)  # the shield had work
            scaler = env.unwrapped.scaler  # the env's action scaling, reused for the unchecked run
        finally:
            env.close()
        # The same kind of policy through the unchecked shield: it runs into the moving wall.
        rng = np.random.default_rng(0)
        res = self.place(NEAR, self.reset_off)
        q = np.array(res.state.position[:7])
        wall, total = 0, 0
        for k in range(OFF_STEPS):
            if k % 100 == 99:
                q = np.array(self.place(NEAR, self.reset_off).state.position[:7])
            target = scaler.command(q, rng.uniform(-1, 1, 7))
            res = self.step_off(target=target.tolist(), duration=DT)
            self.assertEqual(res.verdict, UNCHECKED, res.message)
            q = np.array(res.state.position[:7])
            wall += self.wall_contacts(res)
            total += res.contacts.world_contacts + res.contacts.self_contacts
        msg = "shield off: %d random steps, %d contact pairs (%d with the wall)" % (OFF_STEPS, total, wall)
        rospy.loginfo(msg)
        print(msg)
        self.assertGreater(wall, 0)

    # (e) ------------------------------------------------------------------------------------------------
    def test_e_seeding_is_deterministic_with_the_moving_wall(self):
        env = gym.make("MoveRL/PandaReachTable-v0", graph="attach", world="moving_wall")
        try:
            actions = np.random.default_rng(5).uniform(-1, 1, (60, 7)).astype(np.float32)
            runs = []
            for _ in range(2):
                obs, _ = env.reset(seed=11)
                trace = [obs]
                for a in actions:
                    obs, r, term, trunc, info = env.step(a)
                    trace.append(obs)
                    trace.append(np.array([r, info["contacts"]]))
                runs.append(trace)
            for a, b in zip(*runs):
                np.testing.assert_array_equal(a, b)
            # The wall is observed (last 7 numbers) and moves between steps; its z is the motion's at the step's time.
            zs = [o[-5] for o in [runs[0][0]] + runs[0][1::2]]
            self.assertGreater(max(zs) - min(zs), 0.5, zs)
            self.assertAlmostEqual(float(runs[0][0][-5]), 1.95, places=5)
        finally:
            env.close()


if __name__ == "__main__":
    rostest.rosrun("moverl_gym", "moving_obstacle", MovingObstacleLive)
