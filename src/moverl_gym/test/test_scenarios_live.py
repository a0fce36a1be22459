#!/usr/bin/env python3
"""rostest on the live headless graph of one paper scenario (scenario_human.test, scenario_case.test).

The test node's private param ~world names the scenario the graph runs (worlds/<world>.yaml):
  (a) a target configuration inside an obstacle of that world is discarded (DISCARDED_POSE, object named);
  (b) case: a move through a case wall (both ends free) is a path collision, replaced by a plan that
      executes with zero contacts and ends at the target;
  (c) case: from above the opening the robot steps (<= 0.1 rad per joint) into the case to the goal;
  (d) every env id of the scenario passes Gymnasium's check_env, reset(seed) with the same actions gives the
      same observations (the walking person included), random starts are collision-free, and a random policy
      makes zero contacts with the shield on.
"""

import time
import unittest

import gymnasium as gym
import numpy as np
import rospy
import rostest
from live_helpers import LiveAssertions, seeded_traces

import moverl_gym  # noqa: F401
from moverl_gym.registration import OBSERVATIONS, SCENARIOS, env_id
from moverl_msgs.srv import (
    CheckPath,
    CheckState,
    CheckStateResponse,
    GetWorld,
    ResetRobot,
    ShieldStep,
    ShieldStepResponse,
)

SAFE, REPLANNED, DISCARDED_POSE, DISCARDED_PATH = (
    ShieldStepResponse.SAFE,
    ShieldStepResponse.REPLANNED,
    ShieldStepResponse.DISCARDED_POSE,
    ShieldStepResponse.DISCARDED_PATH,
)
VALID, WORLD_COLLISION = CheckStateResponse.VALID, CheckStateResponse.WORLD_COLLISION
HOME = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]

# Configurations (found with PyBullet IK, checked with the planning scene; see the world file headers).
HUMAN_GOAL = [-0.022, 0.052, 0.023, -2.379, -0.002, 2.431, 0.003]  # flange at the goal, 5.6 cm to the torso
HUMAN_NEAR = [0.35] + HUMAN_GOAL[1:]  # hand 0.17 m to the left of the goal
HUMAN_INTO_TORSO = [-0.091, 0.591, 0.112, -1.568, -0.075, 2.155, 0.043]  # flange at (0.7, 0, 0.3): in the torso
CASE_GOAL = [-0.06, 0.077, 0.059, -2.724, -0.016, 2.801, 0.013]  # flange at the goal inside the case
CASE_ABOVE = [-0.04, -0.411, 0.039, -2.584, 0.019, 2.173, -0.015]  # flange 0.2 m above the goal
CASE_OUTSIDE = [1.0] + CASE_GOAL[1:]  # joint 1 turned: the hand is outside the left (+y) wall, same height
CASE_IN_WALL = [0.6] + CASE_GOAL[1:]  # halfway: wrist and hand in the left wall

RANDOM_STEPS = 300
REPLAN_ATTEMPTS = 5  # the planner has a wall-clock budget (0.1 s): on a busy machine one attempt can time out


class ScenarioLive(LiveAssertions, unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("scenario_live_test", anonymous=True, disable_signals=True)
        cls.world = rospy.get_param("~world")
        for name in (
            "/shield/step",
            "/shield/reset",
            "/planning_scene/check_state",
            "/planning_scene/check_path",
            "/sim/get_world",
        ):
            rospy.wait_for_service(name, timeout=60)
        cls.step = rospy.ServiceProxy("/shield/step", ShieldStep, persistent=True)
        cls.reset = rospy.ServiceProxy("/shield/reset", ResetRobot, persistent=True)
        cls.check_state = rospy.ServiceProxy("/planning_scene/check_state", CheckState)
        cls.check_path = rospy.ServiceProxy("/planning_scene/check_path", CheckPath)
        w = rospy.ServiceProxy("/sim/get_world", GetWorld)().world
        assert w.name == cls.world, (w.name, cls.world)
        cls.goal = np.array(w.goal) if hasattr(w, "goal") else None

    def require(self, *worlds):
        if self.world not in worlds:
            self.skipTest("only in world(s) %s" % ", ".join(worlds))

    def place(self, q):
        res = self.reset(positions=q)
        self.assertTrue(res.success, res.message)

    def assert_no_contacts(self, res):
        super().assert_no_contacts(res, substeps=False)

    @staticmethod
    def ids(pairs):
        return {p.a for p in pairs} | {p.b for p in pairs}

    # (a) ------------------------------------------------------------------------------------------------
    def test_a_pose_collision_is_discarded(self):
        start, target, obstacle = {
            "human": (HOME, HUMAN_INTO_TORSO, "human_torso"),
            "case": (CASE_GOAL, CASE_IN_WALL, "case_wall_left"),
        }[self.world]
        self.assertEqual(self.check_state(positions=start).outcome, VALID)
        self.assertEqual(self.check_state(positions=target).outcome, WORLD_COLLISION)
        self.place(start)
        res = self.step(target=target, duration=0.05)
        self.assertEqual(res.verdict, DISCARDED_POSE, res.message)
        self.assertIn(obstacle, self.ids(res.pairs))
        np.testing.assert_allclose(res.state.position[:7], start, atol=1e-9)  # held still: nothing executed

    # (b) ------------------------------------------------------------------------------------------------
    def test_b_wall_move_is_replanned_without_contact(self):
        self.require("case")
        self.assertEqual(self.check_state(positions=CASE_GOAL).outcome, VALID)
        self.assertEqual(self.check_state(positions=CASE_OUTSIDE).outcome, VALID)
        path = self.check_path(start=CASE_GOAL, goal=CASE_OUTSIDE)
        self.assertEqual(path.outcome, WORLD_COLLISION, path.message)
        self.assertTrue(any(i.startswith("case_wall") for i in self.ids(path.pairs)), path.pairs)
        verdicts = []
        for _ in range(REPLAN_ATTEMPTS):
            self.place(CASE_GOAL)
            res = self.step(target=CASE_OUTSIDE, duration=0.05)
            verdicts.append(res.verdict)
            self.assertIn(res.verdict, (REPLANNED, DISCARDED_PATH), res.message)
            if res.verdict == REPLANNED:
                self.assert_no_contacts(res)
                self.assertGreater(res.planning_time, 0.0)
                np.testing.assert_allclose(res.state.position[:7], CASE_OUTSIDE, atol=1e-6)
                break
            np.testing.assert_allclose(res.state.position[:7], CASE_GOAL, atol=1e-9)  # no plan: held still
        print("wall move: verdicts of %d attempt(s): %s" % (len(verdicts), verdicts))
        self.assertEqual(verdicts[-1], REPLANNED, "no plan in %d attempts: %s" % (len(verdicts), verdicts))

    # (c) ------------------------------------------------------------------------------------------------
    def test_c_goal_inside_the_case_is_reached(self):
        self.require("case")
        self.place(CASE_ABOVE)
        q, target = np.array(CASE_ABOVE), np.array(CASE_GOAL)
        for _ in range(20):
            nxt = q + np.clip(target - q, -0.1, 0.1)
            res = self.step(target=nxt.tolist(), duration=0.05)
            self.assertIn(res.verdict, (SAFE, REPLANNED, DISCARDED_PATH), res.message)
            if res.verdict != DISCARDED_PATH:  # (a discarded step executes nothing: no contact report)
                self.assert_no_contacts(res)
            q = np.array(res.state.position[:7])
            if np.allclose(q, target, atol=1e-6):
                break
        np.testing.assert_allclose(q, target, atol=1e-6)
        p = res.ee_pose.position
        self.assertLess(np.linalg.norm(np.array([p.x, p.y, p.z]) - self.goal), 0.1)

    # (d) ------------------------------------------------------------------------------------------------
    def test_d_env_ids_check_env_and_random_policy_without_contact(self):
        from gymnasium.utils.env_checker import check_env

        scenario = {w: s for s, w in SCENARIOS.items()}[self.world]
        for suffix in OBSERVATIONS:
            name = env_id(rospy.get_param("/robot/name"), scenario, suffix)
            with self.subTest(env_id=name):
                env = gym.make(name, graph="attach")
                try:
                    check_env(env.unwrapped, skip_render_check=True)
                    # Seeding is deterministic, moving obstacles (the walking person) included.
                    trace = seeded_traces(env)
                    if self.world == "human":  # observed: torso, head, arms (7 each, last); torso y walks
                        torso_y = [o[-28 + 1] for o in trace]
                        self.assertGreater(max(torso_y) - min(torso_y), 0.05, torso_y)
                    t0 = time.monotonic()
                    for seed in range(5):
                        env.reset(seed=seed)
                        q = env.unwrapped.q
                        self.assertEqual(self.check_state(positions=list(q)).outcome, VALID)
                    t_reset = (time.monotonic() - t0) / 5
                    # Episodes alternate between a start next to the scenario's obstacles (hand above the case
                    # opening / between the person's torso and left arm, both > goal_tolerance from the goal)
                    # and a random start, so that random actions do run into the obstacles.
                    near = {"human": HUMAN_NEAR, "case": CASE_ABOVE}[self.world]
                    self.assertEqual(self.check_state(positions=near).outcome, VALID)
                    env.action_space.seed(len(suffix))
                    t0 = time.monotonic()
                    env.reset(seed=100 + len(suffix), options={"start": near})
                    counts = self.random_rollout_without_contact(env, RANDOM_STEPS, near)
                    rospy.loginfo(
                        "%s: reset %.3f s; %d random steps in %.1f s, verdicts %s, zero contacts",
                        name,
                        t_reset,
                        RANDOM_STEPS,
                        time.monotonic() - t0,
                        counts,
                    )
                    print(
                        "%s: reset %.3f s; %d random steps in %.1f s, verdicts %s, zero contacts"
                        % (name, t_reset, RANDOM_STEPS, time.monotonic() - t0, counts)
                    )
                finally:
                    env.close()


if __name__ == "__main__":
    rostest.rosrun("moverl_gym", "scenario_live", ScenarioLive)
