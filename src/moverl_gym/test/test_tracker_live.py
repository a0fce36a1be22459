"""The env reads the person from a tracker (launch argument obstacle_poses:=tracker; launches its own graph).

The simulator plays the tracker of config/sim.yaml (30 Hz, 0.05 s latency, 0.01 m noise, 5 % dropouts in bursts): the
env's observation of the walking person must match the world file's motion at the time each pose was measured (the
step's stamp minus info["track_ages"]) within the noise, be as old as the latency at least, show the dropouts as
ages, and keep the observation space of the world-file mode; in lockstep and in real time.
"""

import gymnasium as gym
import numpy as np
import pytest
import yaml

import moverl_gym  # noqa: F401
from moverl_gym.paths import config_file
from moverl_sim.world import load_world

pytestmark = pytest.mark.live

TRACKER = yaml.safe_load(config_file("sim.yaml").read_text())["tracker"]
ENV_ID = "MoveRL/PandaReachHuman-v0"


def truth(world, ids, t):
    """The observed objects' positions at motion time t, from the world file (3 per object)."""
    objects = {o.id: o for o in world.objects}
    return np.concatenate([objects[i].position_at(t) for i in ids])


def walk(mode, steps):
    env = gym.make(ENV_ID, launch_args={"obstacle_poses": "tracker", "mode": mode})
    try:
        u = env.unwrapped
        reference = gym.make(ENV_ID, backend="bullet", shield=False)  # the world file's observation, no ROS
        try:
            assert u.observation_space == reference.observation_space  # a world-file policy loads unchanged
        finally:
            reference.close()
        world = load_world(str(moverl_gym.paths.world_file("human")))
        ids = u._tracked.ids
        assert ids == ("human_torso", "human_head", "human_left_arm", "human_right_arm")
        obs, info = env.reset(seed=1)
        assert info["track_ages"].shape == (4,)
        rows = []  # (stamp, ages, observed positions) per step
        rng = np.random.default_rng(0)
        for _ in range(steps):
            obs, _, term, trunc, info = env.step(rng.uniform(-0.3, 0.3, 7).astype(np.float32))
            assert info["contacts"] == 0
            seen = np.asarray(obs[-28:], dtype=np.float64).reshape(4, 7)[:, :3]
            rows.append((u._stamp - u._motion_epoch, info["track_ages"].copy(), seen, info["tracks_lost"]))
            if term or trunc:
                break
        return world, ids, rows
    finally:
        env.close()


def check(world, ids, rows, mode):
    latency, noise, rate = TRACKER["latency"], TRACKER["noise"], TRACKER["rate"]
    errors, ages = [], []
    for t, age, seen, lost in rows:
        assert lost == int(np.count_nonzero(age > 0.5))
        for k in range(4):
            if not np.isfinite(age[k]) or t - age[k] < 0.0:
                # No pose yet, or one measured before the reset restarted the walk (the person teleported). One
                # measured at that very instant is of the new walk: the simulator takes it again after the teleport
                # (Tracker.retake_from; the tracker's 30 Hz grid meets the reset's substep one time in eight).
                continue
            ages.append(age[k])
            measured = truth(world, ids, t - age[k])[3 * k : 3 * k + 3]
            errors.append(seen[k] - measured)
    errors, ages = np.array(errors), np.array(ages)
    assert len(ages) >= 3 * len(rows), f"{mode}: too few tracked poses ({len(ages)} in {len(rows)} steps)"
    # Within the noise: every axis within 5 sigma (float32 observations), the spread about sigma.
    assert np.abs(errors).max() < 5 * noise + 1e-4, f"{mode}: largest error {np.abs(errors).max():.4f} m"
    assert 0.6 * noise < errors.std() < 1.4 * noise, f"{mode}: error std {errors.std():.4f} m"
    # As old as the latency (a pose delivered a moment after the step's state was stamped may be younger by up to
    # that moment), and newer ones keep coming.
    assert np.median(ages) >= latency, f"{mode}: median age {np.median(ages):.3f} s"
    assert np.median(ages) < latency + 3.0 / rate + 0.06, f"{mode}: median age {np.median(ages):.3f} s"
    return ages


def test_lockstep_observation_is_the_trackers():
    world, ids, rows = walk("lockstep", 100)
    ages = check(world, ids, rows, "lockstep")
    # The dropouts show as older poses: some step saw one pose at least two measurements older than usual.
    assert ages.max() > TRACKER["latency"] + 2.0 / TRACKER["rate"] + 0.05, f"no dropout seen (ages up to {ages.max()})"


def test_realtime_observation_is_the_trackers():
    world, ids, rows = walk("realtime", 60)
    check(world, ids, rows, "realtime")
