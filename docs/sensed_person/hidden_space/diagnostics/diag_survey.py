"""Diagnostic (issue 52 audits; private env API): does a look from elsewhere let a one-camera world start? After the
first reset fails, stand the robot at random configurations the simulator accepts (as the env's look-again does for
k > 0), then check 300 samples and reset again.

    python diag_survey.py <world> <robot config> <looks>
"""

import sys
import time

import numpy as np

from moverl_gym.env import MoveRLReachEnv

world, robot, looks = sys.argv[1], sys.argv[2], int(sys.argv[3])
env = MoveRLReachEnv(
    world=world, shield=True, graph="launch", launch_args={"robot_config": robot, "obstacles": "sensed"}
)
try:
    env.reset(seed=0)
    print("first reset OK")
except Exception as e:
    print("first reset failed:", str(e)[:160])
b = env._backend
import rospy  # noqa: E402 (after the env has initialised rospy)

from moverl_msgs.msg import OctomapStatus  # noqa: E402

last = {}


def on_status(m):
    last.update(
        clouds=m.clouds,
        stamp=round(m.header.stamp.to_sec(), 3),
        frame=m.sensor_frame,
        map_time=round(m.map_time, 3),
        stale=m.stale_cells,
        unobs=m.unobserved_cells,
        hidden=m.hidden_cells,
        turned=m.turned_stale,
        occ=m.occupied_leaves,
        dropped=m.dropped,
    )


rospy.Subscriber("/planning_scene/octomap_status", OctomapStatus, on_status, queue_size=100)
time.sleep(1.0)
print("status before looks", last)
rng = np.random.default_rng(1)
lo, hi = env.limits.lower, env.limits.upper
done = 0
for k in range(200):
    if done >= looks:
        break
    q = rng.uniform(lo, hi)
    if b.reset(q).success:
        done += 1
        print("look", done, "at", np.round(q, 2).tolist())
        time.sleep(1.0)
        print("   status after look", last)
        free = 0
        for j in range(300):
            qq = env._home + rng.uniform(-0.2, 0.2, size=len(lo)) if j < 150 else rng.uniform(lo, hi)
            qq = np.clip(qq, lo, hi)
            r = b._check(b._srv["check"](positions=[float(x) for x in qq]))
            free += r.outcome == 0
            if j in (0, 150):
                print("   e.g.", r.outcome, r.message[:160])
        print("  free of 300 samples (150 near home, 150 uniform) after the look:", free)
        try:
            t0 = time.time()
            env.reset()
            print("  reset after look OK in %.1f s" % (time.time() - t0))
            ok = 0
            for i in range(100):
                _, _, term, trunc, info = env.step(env.action_space.sample())
                ok += not info["discarded"] or info["verdict"] == "retreated"
                if term or trunc:
                    env.reset()
            print("  100 random steps: executed", ok)
            break
        except Exception as e:
            print("  reset after look failed:", str(e)[:300])
env.close()
