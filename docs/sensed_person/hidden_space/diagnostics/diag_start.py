"""Diagnostic (issue 52 audits; private env API): why no start is free in a world: CheckState's colliding pairs at
home and the outcomes of 300 uniform samples, after the env's first reset.

    python diag_start.py <world> <robot config>
"""

import collections
import sys

import numpy as np

from moverl_gym.env import MoveRLReachEnv

world, robot = sys.argv[1], sys.argv[2]
env = MoveRLReachEnv(
    world=world, shield=True, graph="launch", launch_args={"robot_config": robot, "obstacles": "sensed"}
)
try:
    env.reset(seed=0)
    print("reset OK")
except Exception as e:
    print("reset failed:", str(e)[:200])
b = env._backend
home = env._home


def check(q):
    return b._check(b._srv["check"](positions=[float(x) for x in q]))


r = check(home)
print(
    "home:",
    r.outcome,
    r.message[:300],
    "margin",
    r.sensed_margin,
    [(p.link_a if hasattr(p, 'link_a') else str(p).replace('\n', ' ')) for p in r.pairs][:10],
)
rng = np.random.default_rng(0)
lo, hi = env.limits.lower, env.limits.upper
cnt = collections.Counter()
for i in range(300):
    q = rng.uniform(lo, hi)
    r = check(q)
    key = (r.outcome, tuple(sorted(set(str(p).replace('\n', ' ') for p in r.pairs)))[:3])
    cnt[(r.outcome, tuple(sorted(set(p.a + "|" + p.b for p in r.pairs))))] += 1
    if i < 3:
        print("sample", i, r.outcome, r.message[:200], [str(p).replace('\n', ' ') for p in r.pairs][:4])
for k, n in cnt.most_common(12):
    print(n, k)
env.close()
