"""The same env in the simulator's real-time clock mode (launches its own graph on a free port).

Lockstep is only a speed extra: in real time the physics runs at wall-clock pace, the simulator publishes
/clock, and the env and shield work unchanged through the same driver interface.
"""

import time

import gymnasium as gym
import numpy as np
import pytest

import moverl_gym  # noqa: F401

pytestmark = pytest.mark.quick

STEPS = 20


def test_realtime_mode_runs_at_wall_clock_pace():
    import rospy
    from rosgraph_msgs.msg import Clock

    env = gym.make("MoveRL/PandaReachTable-v0", launch_args={"mode": "realtime"})
    try:
        env.reset(seed=3)
        clock0 = rospy.wait_for_message("/clock", Clock, timeout=10).clock.to_sec()
        t0 = time.monotonic()
        for _ in range(STEPS):
            _, _, term, trunc, info = env.step(np.zeros(7, dtype=np.float32) + 0.3)
            assert info["contacts"] == 0
            if term or trunc:
                env.reset()
        wall = time.monotonic() - t0
        clock1 = rospy.wait_for_message("/clock", Clock, timeout=10).clock.to_sec()
        dt = env.unwrapped.config.dt
        # Every executed step lasts dt of simulated time, paced by the wall clock.
        assert wall >= 0.9 * STEPS * dt, wall
        assert clock1 - clock0 >= 0.9 * STEPS * dt, (clock0, clock1)
    finally:
        env.close()
