#!/usr/bin/env python3
"""rostest on the live headless graph (shield_live.test, world test/worlds/thin_wall.yaml).

Self, pose and path collisions are detected and classified; the path case is replaced by a plan that
executes with zero physical contacts; a free move executes directly; bad input never kills a node; and
with the planning scene down the shield fails closed (robot held still) and the env raises quickly.
"""

import subprocess
import time
import unittest

import numpy as np
import rospy
import rostest
from live_helpers import LiveAssertions

from moverl_msgs.srv import CheckPath, CheckState, ResetRobot, ShieldStep, ShieldStepResponse

HOME = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]
SELF_COLLIDING = [0.0, 0.3, 0.0, -3.0, 0.0, 0.0, 0.0]  # forearm folded back: hand hits link5 / link1
TABLE_COLLIDING = [0.0, 1.2, 0.0, -1.0, 0.0, 1.571, 0.785]  # arm bent down: fingers in the table
WALL_LEFT = [-0.6] + HOME[1:]  # hand right of the wall
WALL_RIGHT = [0.6] + HOME[1:]  # hand left of the wall; turning joint 1 sweeps the hand through it
FREE = WALL_LEFT  # (the home posture itself has the hand in the wall of this test world)

SAFE, REPLANNED, DISCARDED_SELF, DISCARDED_POSE = (
    ShieldStepResponse.SAFE,
    ShieldStepResponse.REPLANNED,
    ShieldStepResponse.DISCARDED_SELF,
    ShieldStepResponse.DISCARDED_POSE,
)
INVALID_REQUEST, SCENE_UNAVAILABLE = 10, 11


class ShieldLive(LiveAssertions, unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("shield_live_test", anonymous=True, disable_signals=True)
        for name in ("/shield/step", "/shield/reset", "/planning_scene/check_state", "/planning_scene/check_path"):
            rospy.wait_for_service(name, timeout=60)
        cls.step = rospy.ServiceProxy("/shield/step", ShieldStep, persistent=True)
        cls.reset = rospy.ServiceProxy("/shield/reset", ResetRobot, persistent=True)
        cls.check_state = rospy.ServiceProxy("/planning_scene/check_state", CheckState)
        cls.check_path = rospy.ServiceProxy("/planning_scene/check_path", CheckPath)

    def place(self, q):
        res = self.reset(positions=q)
        self.assertTrue(res.success, res.message)
        np.testing.assert_allclose(res.state.position[:7], q, atol=1e-9)

    def assert_held(self, res, q):
        np.testing.assert_allclose(res.state.position, q, atol=1e-9)

    def test_free_move_executes_directly(self):
        self.place(FREE)
        target = list(np.array(FREE) + 0.05)
        res = self.step(target=target, duration=0.05)
        self.assertEqual(res.verdict, SAFE, res.message)
        np.testing.assert_allclose(res.state.position, target, atol=1e-6)
        self.assert_no_contacts(res)
        self.assertGreater(res.contacts.substeps, 0)

    def test_self_collision_is_discarded(self):
        self.assertEqual(self.check_state(positions=SELF_COLLIDING).outcome, 1)  # SELF_COLLISION
        self.place(FREE)
        res = self.step(target=SELF_COLLIDING, duration=0.05)
        self.assertEqual(res.verdict, DISCARDED_SELF, res.message)
        self.assertTrue(res.pairs, "the colliding pair is reported")
        self.assertTrue(all(p.a.startswith("panda_") and p.b.startswith("panda_") for p in res.pairs), res.pairs)
        self.assert_held(res, FREE)

    def test_table_collision_is_discarded(self):
        self.assertEqual(self.check_state(positions=TABLE_COLLIDING).outcome, 2)  # WORLD_COLLISION
        self.place(FREE)
        res = self.step(target=TABLE_COLLIDING, duration=0.05)
        self.assertEqual(res.verdict, DISCARDED_POSE, res.message)
        self.assertIn("table", {p.a for p in res.pairs} | {p.b for p in res.pairs})
        self.assert_held(res, FREE)

    def test_path_collision_is_replanned_and_executes_without_contact(self):
        # Both ends free, the straight segment between them crosses the wall.
        self.assertEqual(self.check_state(positions=WALL_LEFT).outcome, 0)
        self.assertEqual(self.check_state(positions=WALL_RIGHT).outcome, 0)
        path = self.check_path(start=WALL_LEFT, goal=WALL_RIGHT)
        self.assertEqual(path.outcome, 2, path.message)  # WORLD_COLLISION
        self.assertIn("wall", {p.a for p in path.pairs} | {p.b for p in path.pairs})
        self.place(WALL_LEFT)
        res = self.step(target=WALL_RIGHT, duration=0.05)
        self.assertEqual(res.verdict, REPLANNED, res.message)
        self.assertGreater(res.planning_time, 0.0)
        np.testing.assert_allclose(res.state.position, WALL_RIGHT, atol=1e-6)
        self.assert_no_contacts(res)

    def test_markers_show_the_scene_and_the_collision(self):
        from visualization_msgs.msg import MarkerArray

        world = rospy.wait_for_message("/shield_markers/world_markers", MarkerArray, timeout=30)
        self.assertEqual({m.text for m in world.markers if m.ns == "obstacles"}, {"table", "wall"})
        got = []
        sub = rospy.Subscriber("/shield_markers/markers", MarkerArray, got.append)
        try:
            deadline = time.monotonic() + 10
            while sub.get_num_connections() == 0 and time.monotonic() < deadline:
                time.sleep(0.05)
            self.place(FREE)
            self.step(target=TABLE_COLLIDING, duration=0.05)  # discarded: the fingers would be in the table
            while not any(any(m.ns == "colliding" and m.action == m.ADD for m in a.markers) for a in got):
                self.assertLess(time.monotonic(), deadline, "no collision markers after a discarded step")
                time.sleep(0.05)
        finally:
            sub.unregister()
        markers = [m for a in got for m in a.markers]
        colliding = [m for m in markers if m.ns == "colliding" and m.action == m.ADD]
        self.assertTrue(any(m.type == m.MESH_RESOURCE and m.header.frame_id.startswith("panda_") for m in colliding))
        verdict = [m.text for m in markers if m.ns == "verdict"]
        self.assertTrue(any(v.startswith("discarded_pose") for v in verdict), verdict)

    def test_bad_requests_get_clear_errors_and_nodes_survive(self):
        self.place(FREE)
        res = self.step(target=FREE[:6], duration=0.05)
        self.assertEqual(res.verdict, INVALID_REQUEST)
        self.assertIn("7 controlled joints", res.message)
        res = self.step(target=[float("nan")] + FREE[1:], duration=0.05)
        self.assertEqual(res.verdict, INVALID_REQUEST)
        self.assertIn("not finite", res.message)
        bad = self.check_state(positions=[0.0] * 3)
        self.assertEqual(bad.outcome, 3)  # INVALID_REQUEST
        self.assertTrue(bad.message)
        self.assertFalse(self.reset(positions=[0.0]).success)
        # Everything still answers.
        self.assertEqual(self.step(target=FREE, duration=0.05).verdict, SAFE)

    def test_z_scene_down_fails_closed(self):
        """Runs last (name order): kills the planning scene under a running env."""
        import gymnasium as gym

        import moverl_gym  # noqa: F401
        from moverl_gym.env import MoveRLError

        env = gym.make("MoveRL/PandaReachTable-v0", graph="attach", world="thin_wall")
        try:
            env.reset(seed=0)
            self.place(FREE)
            subprocess.run(["rosnode", "kill", "/planning_scene"], check=True, capture_output=True, timeout=30)
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline:  # until the node is gone
                try:
                    rospy.wait_for_service("/planning_scene/validate_motion", timeout=0.2)
                except rospy.ROSException:
                    break
            t0 = time.monotonic()
            res = self.step(target=list(np.array(FREE) + 0.05), duration=0.05)
            self.assertLess(time.monotonic() - t0, 5.0, "the shield answers within seconds")
            self.assertEqual(res.verdict, SCENE_UNAVAILABLE, res.message)
            self.assertIn("unreachable", res.message)
            self.assert_held(res, FREE)
            t0 = time.monotonic()
            with self.assertRaisesRegex(MoveRLError, "scene_unavailable"):
                env.step(np.zeros(7, dtype=np.float32))
            self.assertLess(time.monotonic() - t0, 5.0, "the env raises within seconds")
        finally:
            env.close()


if __name__ == "__main__":
    rostest.rosrun("moverl_gym", "shield_live", ShieldLive)
