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
      racing with the joint states; each reset's state stamped after the state before it) go through, each reset
      sampling a collision-free start near home from the scene, and afterwards home and every episode start are
      still free in the map (a robot left behind as an
      obstacle would block them). Not asserted for every configuration visited: a visited pose can touch cells
      that were unknown (hidden by the robot itself) at the time and were seen later, a legitimate verdict.
  (e) lockstep renders keep simulated time (test_camera_schedule): after a reset every camera renders at the reset's
      sim time; over 20 env steps of dt = 0.05 s and one 0.6 s hold each camera's clouds are stamped exactly
      1/camera_rate of sim time apart (also in the middle of a move, with a joint state stamped alike for the self
      filter), and a cloud stamped within a step has arrived when the step's call returns (most within ARRIVAL_SLACK:
      see its use). The lockstep lag (octomap/lockstep_lag): each step's check read exactly the clouds up to the
      previous check's state, none of the latest step's (info["map_age"] / ShieldStep.map_age, predicted from the
      render times), and its margin covered that age and the move (sensed_margin >= the world's speed_bound x
      (map_age + the move's duration)).
  (f) unknown is occupied (a world's `sensing: unknown_occupied: true`, switched on here by publishing the world with
      it): with the same map, every configuration that collides with unknown cells free also collides with them
      occupied, some free ones now collide with the cells no camera has seen, home stays free (the cells inside the
      robot are known free), and switching it off gives back the first verdicts.
"""

import os
import struct
import threading
import time
import unittest

import gymnasium as gym
import numpy as np
import rospy
import rostest
from live_helpers import LiveAssertions
from sensor_msgs.msg import JointState

import moverl_gym  # noqa: F401
from moverl_msgs.msg import OctomapStatus, World
from moverl_msgs.srv import CheckPath, CheckStateResponse, GetWorld, ShieldStepResponse
from moverl_sim.world import load_world

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
CAMERAS = ("right_optical_frame", "left_optical_frame")
# s of sim time: 1 / camera_rate of sensed_obstacle.test (5), which overrides the world file's rate (4.0): the stamps
# show that the launch argument reached the cameras.
CAMERA_PERIOD = 0.2
WORLD_FILE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "worlds", "sensed_box.yaml")
ARRIVAL_SLACK = 0.01  # s (wall) a cloud may be handled after the call that rendered it returned, mostly (see its use)


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
        """Holds of a camera period (lockstep sim time moves on, so the cameras render again) until n more clouds
        were integrated. One hold may not do: a camera's view that arrives while its previous one still waits to be
        integrated replaces it (the newest view is what counts), so a hold's renders may give fewer clouds."""
        deadline = time.monotonic() + WAIT
        while self.status is None and time.monotonic() < deadline:
            time.sleep(0.05)
        self.assertIsNotNone(self.status, "no /planning_scene/octomap_status")
        start = self.status.clouds
        while self.status.clouds < start + n:
            self.assertLess(
                time.monotonic(),
                deadline,
                "the map integrated %d of %d clouds in %.0f s" % (self.status.clouds - start, n, WAIT),
            )
            self.assert_no_contacts(self.step(target=self.current, duration=0.25))
            settle = time.monotonic() + 1.0  # the hold's clouds integrated (each takes milliseconds)
            while self.status.clouds < start + n and time.monotonic() < settle:
                time.sleep(0.02)

    def test_camera_schedule(self):
        clouds, states, lock = [], [], threading.Lock()  # clouds: (frame, stamp, monotonic arrival); states: stamps

        def on_cloud(msg):  # the header only (raw bytes: seq, stamp secs and nsecs, frame_id length, frame_id)
            _, secs, nsecs, n = struct.unpack_from("<4I", msg._buff, 0)
            with lock:
                clouds.append((msg._buff[16 : 16 + n].decode(), secs + 1e-9 * nsecs, time.monotonic()))

        def on_state(msg):
            with lock:
                states.append(msg.header.stamp.to_sec())

        def stamps(frame, since):
            with lock:
                return [t for f, t, _ in clouds if f == frame and t >= since - 1e-6]

        points_sub = rospy.Subscriber("/sim/points", rospy.AnyMsg, on_cloud, queue_size=100)
        states_sub = rospy.Subscriber("/joint_states", JointState, on_state, queue_size=100)
        try:
            # A new subscriber first gets one cloud from every camera (lockstep time stands still meanwhile).
            deadline = time.monotonic() + 10.0
            while not all(stamps(f, 0.0) for f in CAMERAS):
                self.assertLess(time.monotonic(), deadline, "no first cloud from every camera")
                time.sleep(0.01)
            with lock:
                del clouds[:]
            # (e) a reset renders every camera, stamped with the reset's sim time; then env steps and a hold. calls:
            # (first, last stamp rendered during the call, monotonic time it returned).
            t0 = self.place(HOME).state.header.stamp.to_sec()
            calls, prev, q = [(t0, t0, time.monotonic())], t0, list(HOME)
            ages = []  # (the check's state, map_age, sensed_margin, the move's duration)
            for k, duration in enumerate([DT] * 20 + [0.6]):  # the hold spans two due times in mid-move
                q[0] = HOME[0] + (0.05 if k % 2 == 0 else 0.0)
                res = self.step(target=q, duration=duration)
                ages.append((prev, res.map_age, res.sensed_margin, duration))
                now = res.state.header.stamp.to_sec()
                calls.append((prev + 1e-3, now, time.monotonic()))  # (stamps are whole substeps: 1/240 s)
                self.assertEqual(res.verdict, SAFE, res.message)
                self.assert_no_contacts(res)
                prev = now
            self.assertAlmostEqual(prev - t0, 20 * DT + 0.6, places=6)
            expected = [t0 + CAMERA_PERIOD * j for j in range(int((prev - t0) / CAMERA_PERIOD + 1e-6) + 1)]
            # The lag: the check at a state reads the clouds rendered up to the previous check's state, so its map is
            # as old as the state less the newest render at or before that one (the first check after the reset,
            # whose previous check came before it, left out). Without the lag every fourth check would read its own
            # state's render (age 0); with a cloud missing, an age would exceed a camera period plus a step.
            speed = load_world(WORLD_FILE).sensed_speed_bound
            for (before, _, _, _), (state, age, margin, duration) in zip(ages, ages[1:]):
                newest = max(t for t in expected if t <= before + 1e-6)
                self.assertAlmostEqual(age, state - newest, places=6, msg="the check at %.3f s" % (state - t0))
                self.assertGreaterEqual(margin, speed * (age + duration) - 1e-9, "the check at %.3f s" % (state - t0))
            self.assertEqual(sorted({round(a, 3) for _, a, _, _ in ages[1:]}), [0.05, 0.1, 0.15, 0.2], ages)
            deadline = time.monotonic() + 2.0  # (the last clouds may still be on their way: see below)
            while any(len(stamps(f, t0)) < len(expected) for f in CAMERAS) and time.monotonic() < deadline:
                time.sleep(0.01)
            for f in CAMERAS:
                np.testing.assert_allclose(stamps(f, t0), expected, atol=1e-6, err_msg="camera %s" % f)
            # Each cloud arrived before the call that rendered it returned. The cloud and the response travel on
            # different connections and this process's threads race to read them (the cloud's thread must take the
            # GIL): idle, ~1 % of clouds are handled up to 3 ms after the call returned; with both cores busy, in one
            # run of four the two clouds of one instant (of 9) came 16 ms after it (measured). A sim that rendered
            # after responding would make every cloud late by at least a render (~25 ms, more under load), so at most a
            # third may be late.
            with lock:
                rendered = [
                    (f, t, round(a - ret, 4))
                    for f, t, a in clouds
                    for lo, hi, ret in calls
                    if lo - 1e-6 <= t <= hi + 1e-6
                ]
            late = [c for c in rendered if c[2] > ARRIVAL_SLACK]
            self.assertEqual(len(rendered), len(CAMERAS) * len(expected), rendered)
            self.assertLessEqual(
                3 * len(late),
                len(rendered),
                "clouds that arrived after their call returned (frame, stamp, s late): %s" % late,
            )
            # The renders in the middle of the hold came with a joint state stamped like them.
            deadline = time.monotonic() + 2.0
            mid_move = [t for t in expected if prev - 0.6 + 1e-6 < t < prev - 1e-6]
            self.assertEqual(len(mid_move), 2, expected)
            while not all(any(abs(s - t) < 1e-6 for s in states) for t in mid_move):
                self.assertLess(time.monotonic(), deadline, "no joint state at %s: %s" % (mid_move, states[-5:]))
                time.sleep(0.01)
        finally:
            points_sub.unregister()
            states_sub.unregister()

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
                # every step was checked against the sensed map, and says how old it was (test_camera_schedule:
                # exactly) and what margin covered it
                self.assertTrue(0.0 <= info["map_age"] < 1.0 and info["sensed_margin"] > 0.0, info)
                if term or trunc:
                    before = env.unwrapped._stamp
                    env.reset()
                    starts.append(env.unwrapped.q[:7].tolist())
                    # The teleport's state (and the reset's clouds) stamped after the old state, never with it: the
                    # scene could filter a reset's cloud with the old configuration alone (lockstep.reset_robot).
                    self.assertGreater(env.unwrapped._stamp, before)
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

    def test_unknown_occupied(self):
        # (f) runs last (unittest's order): the world stays as published here until the next reset.
        get_world = rospy.ServiceProxy("/planning_scene/get_world", GetWorld)
        get_world.wait_for_service(10.0)
        world = get_world().world
        self.assertFalse(world.sensed_unknown_occupied, "worlds/sensed_box.yaml switches it off")
        world_pub = rospy.Publisher("/sim/world", World, queue_size=1, latch=True)
        rng = np.random.default_rng(16)
        configs = [list(np.asarray(HOME) + rng.uniform(-1.0, 1.0, 7)) for _ in range(150)]

        def verdicts():
            return [self.check_state(positions=q) for q in configs]

        def switch(on):  # the scene publishes its status once it has switched
            world.sensed_unknown_occupied = on
            world_pub.publish(world)
            deadline = time.monotonic() + WAIT
            while self.status is None or (self.status.unobserved_cells > 0) != on:
                self.assertLess(time.monotonic(), deadline, "unknown_occupied=%s not taken up" % on)
                time.sleep(0.02)

        self.current = HOME
        self.place(HOME)
        self.wait_for_clouds(2)
        try:
            switch(True)
            self.wait_for_clouds(2)  # the cells inside the robot are turned free with each cloud
            self.assertGreater(self.status.unobserved_cells, 1000, "the map has no unseen cells")
            # Both cameras stand in front of the robot: the pocket behind its base, seen free earlier, is hidden from
            # both and touches space neither has seen. Under unknown_occupied something may come from there, so the
            # pocket turns possibly occupied (stale) and may block home; the robot's own insides never do (they are
            # turned free with every cloud, and what blocks home goes with the pocket when unknown space is free).
            home = self.check_state(positions=HOME)
            if home.outcome != VALID:
                self.assertGreater(self.status.stale_cells, 0, "home blocked, not by hidden space: %s" % home.message)
            switch(False)
            home = self.check_state(positions=HOME)
            self.assertEqual(
                home.outcome, VALID, "home is blocked by its own cells: %s %s" % (home.message, home.pairs)
            )
            free = verdicts()  # the map as of now, with unknown cells free ...
            switch(True)
            occupied = verdicts()  # ... and with them occupied (lockstep: no cloud came in between)
        finally:
            world.sensed_unknown_occupied = False
            world_pub.publish(world)
        lost = [k for k in range(len(configs)) if free[k].outcome != VALID and occupied[k].outcome == VALID]
        self.assertEqual(lost, [], "configurations blocked by sensed cells became free under unknown_occupied")
        unseen = [k for k in range(len(configs)) if free[k].outcome == VALID and occupied[k].outcome != VALID]
        self.assertGreater(len(unseen), 0, "no configuration reaches into space no camera has seen")
        for k in unseen:
            self.assertEqual(occupied[k].outcome, WORLD, occupied[k].message)
            self.assertTrue(all(p.b == "octomap" for p in occupied[k].pairs), occupied[k].pairs)
        rospy.loginfo(
            "unknown_occupied: %d of %d configurations free with unknown cells free collide with them occupied "
            "(%d unseen cells)",
            len(unseen),
            sum(v.outcome == VALID for v in free),
            self.status.unobserved_cells,
        )


if __name__ == "__main__":
    rostest.rosrun("moverl_gym", "sensed_obstacle", SensedObstacleLive)
