"""The shield with robots that do not track perfectly and with the standard driver in real time (each test launches its
own graph on a free port).

A policy that keeps pushing into the obstacles (a fixed direction plus noise) finds what random actions near home do
not. Ground truth is the simulator's: the env's info["contacts"] with the lockstep services, the simulator's ~contacts
reports with the standard driver (which has none).
  - dynamic control (position-controlled motors at 1 kHz, min_jerk trajectories, path tolerances from the tracking
    budget), lockstep: pushing into the case, and into the moving wall: zero contacts, no error (states a little
    beyond a joint limit are clamped, not refused);
  - the standard FollowJointTrajectory driver in real time with dynamic control, the moving wall: a move the wall
    crosses is never executed straight, and pushing towards the wall makes zero contacts.
"""

import os

import gymnasium as gym
import numpy as np
import pytest
import rospy
from live_helpers import GroundTruthContacts

import moverl_gym  # noqa: F401

pytestmark = pytest.mark.live

TEST_WORLDS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "worlds")
HOME = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]
NEAR_WALL = [-0.65] + HOME[1:]  # clear of the moving wall's swing; joint 1 towards +0.8 crosses it
LEFT, RIGHT = [-0.8] + HOME[1:], [0.8] + HOME[1:]
# Pushing directions (normalised joint actions): reach down and forward into the case; turn into the wall.
INTO_CASE = np.array([0.0, 1.0, 0.0, 1.0, 0.0, -0.5, 0.0])
INTO_WALL = np.array([1.0, 0.3, 0.0, 0.3, 0.0, 0.0, 0.0])


def push(env, direction, steps, seed, start=None, truth=None):
    """Pushing policy: direction * 0.8 + N(0, 0.5) noise, clipped. Returns (verdict counts, contact pairs, errors)."""
    rng = np.random.default_rng(seed)
    env.reset(seed=seed, options={"start": start} if start else None)
    counts, contacts = {}, 0
    for _ in range(steps):
        a = np.clip(direction * 0.8 + rng.normal(0.0, 0.5, 7), -1, 1).astype(np.float32)
        _, _, term, trunc, info = env.step(a)
        counts[info["verdict"]] = counts.get(info["verdict"], 0) + 1
        contacts += max(0, info["contacts"])
        if term or trunc:
            env.reset(options={"start": start} if start else None)
    return counts, contacts


@pytest.mark.parametrize(
    "env_id, world, direction, start, steps",
    [
        ("MoveRL/PandaReachCase-v0", "case", INTO_CASE, None, 600),
        ("MoveRL/PandaReachTable-v0", os.path.join(TEST_WORLDS, "moving_wall.yaml"), INTO_WALL, NEAR_WALL, 400),
    ],
)
def test_dynamic_control_pushing_makes_no_contact(env_id, world, direction, start, steps):
    env = gym.make(env_id, world=world, launch_args={"control": "dynamic"})
    try:
        counts, contacts = push(env, direction, steps, seed=0, start=start)
        print(
            "\ndynamic control, %s, pushing: %d steps, verdicts %s, %d contact pairs"
            % (os.path.basename(world), steps, counts, contacts)
        )
        assert contacts == 0, counts
        assert sum(v for k, v in counts.items() if k.startswith("discarded")) > steps // 10, counts  # it pushed
    finally:
        env.close()


def test_standard_driver_real_time_moving_wall():
    from moverl_msgs.srv import ShieldStep, ShieldStepResponse

    env = gym.make(
        "MoveRL/PandaReachTable-v0",
        world=os.path.join(TEST_WORLDS, "moving_wall.yaml"),
        launch_args={"driver": "follow_joint_trajectory", "control": "dynamic", "initial_positions": str(LEFT)},
    )  # home is inside the wall's swing
    try:
        truth = GroundTruthContacts()
        env.reset(seed=0, options={"start": LEFT})
        step = rospy.ServiceProxy("/shield/step", ShieldStep)
        # Turning between LEFT and RIGHT takes 0.74 s; the wall (1 s period) crosses that path during any such window.
        # Each call turns towards the other side from where the robot stands: a call is answered either by
        # DISCARDED_PATH (held still) or by REPLANNED (a plan around the wall, executed), depending on the wall's phase
        # in real time. Turning back from where the robot stands keeps a reset across the swing (8-17 s) out of it.
        right, turns = False, []
        for _ in range(3):
            res = step(target=LEFT if right else RIGHT, duration=0.05)
            assert res.verdict != ShieldStepResponse.SAFE, res.message
            turns.append(res.verdict)
            right = res.state.position[0] > 0.0
        # Push towards the wall from the side the robot stands on (the wall lies in the plane y = 0, so the mirror
        # image of a start and a direction is the same test).
        mirror = np.array([-1.0 if right else 1.0] + [1.0] * 6)
        start = list(np.array(NEAR_WALL) * mirror)
        counts, _ = push(env, INTO_WALL * mirror, 150, seed=1, start=start)
        rospy.sleep(0.3)  # the last contact reports arrive
        pairs, substeps, reports = truth.snapshot()
        print(
            "\nstandard driver, real time, dynamic control, moving wall: turns across the swing %s;"
            " pushing from the %s: verdicts %s, %d ground-truth contact pairs (%d reports)"
            % (turns, "right" if right else "left", counts, pairs, reports)
        )
        assert reports > 0
        assert (pairs, substeps) == (0, 0), truth.pairs
        assert counts.get("safe", 0) > 0
    finally:
        env.close()
