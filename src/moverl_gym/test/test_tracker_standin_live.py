#!/usr/bin/env python3
"""rostest (tracker_standin.test): with simulator:=false, a tracker node that is not the simulator feeds the env.

(a) the env, attached, observes the person as the stand-in tracker publishes it: the human world's walk at the time
    each pose was measured (the step's stamp minus info["track_ages"]) within the tracker's noise, the poses as old as
    its latency at least;
(b) the tracker dies: within track_timeout every track counts as lost (info["tracks_lost"]), the poses are held where
    they were last seen, and the env and the shield go on (the shield never reads them).
"""

import subprocess
import time
import unittest

import gymnasium as gym
import numpy as np
import rospy
import rostest
import yaml

import moverl_gym  # noqa: F401
from moverl_gym.paths import config_file, world_file
from moverl_sim.world import load_world

TRACKER = yaml.safe_load(config_file("sim.yaml").read_text())["tracker"]
IDS = ("human_torso", "human_head", "human_left_arm", "human_right_arm")


class TrackerStandinLive(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("tracker_standin_test", anonymous=True, disable_signals=True)
        rospy.wait_for_service("/shield/step", timeout=60)
        cls.env = gym.make("MoveRL/PandaReachHuman-v0", graph="attach", world="human")
        cls.world = {o.id: o for o in load_world(str(world_file("human"))).objects}

    @classmethod
    def tearDownClass(cls):
        cls.env.close()

    def steps(self, n):
        out = []
        for _ in range(n):
            obs, _, _, _, info = self.env.step(np.zeros(7, dtype=np.float32))
            self.assertEqual(info["verdict"], "safe", info["message"])
            seen = np.asarray(obs[-28:], dtype=np.float64).reshape(4, 7)[:, :3]
            out.append((self.env.unwrapped._stamp, info["track_ages"].copy(), seen, info["tracks_lost"]))
        return out

    def test_a_observation_is_the_standin_trackers(self):
        u = self.env.unwrapped
        self.assertEqual(u._tracked.ids, IDS)
        self.env.reset(options={"start": "current"})
        # The world server's epoch (0): motion time = ROS time; the stand-in plays the walk on the same clock.
        self.assertEqual(u._motion_epoch, 0.0)
        time.sleep(0.5)  # the stand-in's first poses (its subscribers connect after the env attached)
        errors, ages = [], []
        for stamp, age, seen, lost in self.steps(40):
            self.assertEqual(lost, 0, f"ages {age}")
            for k, oid in enumerate(IDS):
                ages.append(age[k])
                errors.append(seen[k] - np.array(self.world[oid].position_at(stamp - age[k])))
        errors, ages = np.array(errors), np.array(ages)
        noise, latency = TRACKER["noise"], TRACKER["latency"]
        self.assertLess(np.abs(errors).max(), 5 * noise + 1e-4)
        self.assertGreater(errors.std(), 0.6 * noise)  # the tracker's noise, not the world file's exact poses
        self.assertLess(errors.std(), 1.4 * noise)
        self.assertGreaterEqual(np.median(ages), latency)
        self.assertLess(np.median(ages), latency + 3.0 / TRACKER["rate"] + 0.1)

    def test_b_a_dead_tracker_is_a_lost_track_not_a_failure(self):
        self.env.reset(options={"start": "current"})
        self.steps(2)
        subprocess.run(["rosnode", "kill", "/tracker"], check=True, capture_output=True, timeout=30)
        time.sleep(self.env.unwrapped.config.track_timeout + 0.2)
        (s1, a1, p1, lost1), (s2, a2, p2, lost2) = self.steps(2)
        self.assertEqual((lost1, lost2), (4, 4))
        self.assertTrue((a1 > self.env.unwrapped.config.track_timeout).all() and (a2 > a1).all())
        np.testing.assert_array_equal(p1, p2)  # held where they were last seen


if __name__ == "__main__":
    rostest.rosrun("moverl_gym", "tracker_standin_test", TrackerStandinLive)
