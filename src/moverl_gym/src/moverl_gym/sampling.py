"""Where an episode starts and where its goal comes from (ROS-free).

A start is a random collision-free configuration whose end effector is not already at the goal: within +-noise rad of
home first (noise > 0), then over the whole joint range. A goal is the end-effector position of a random
collision-free configuration, so that every goal can be reached: drawn within +-noise rad of home (noise > 0) or over
the whole joint range, and with a world's ``goal_region`` (worlds/table.yaml's header) only those whose end effector
lies in the box count. The backend answers what is asked of a sample (moverl_gym.backend.Backend: check_state,
ee_pose).
"""

from __future__ import annotations

import numpy as np


def in_region(position, region) -> bool:
    """Whether position (x, y, z) lies in region ((low x, y, z), (high x, y, z)), bounds included."""
    low, high = np.asarray(region[0], dtype=float), np.asarray(region[1], dtype=float)
    p = np.asarray(position, dtype=float)[:3]
    return bool(np.all(p >= low) and np.all(p <= high))


def _near_home(lower, upper, home, noise: float):
    """The joint box within +-noise rad of home, clipped to [lower, upper]."""
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    return np.maximum(lo, np.asarray(home) - noise), np.minimum(hi, np.asarray(home) + noise)


def sample_goal(rng, backend, lower, upper, home, noise: float, attempts: int, region=None):
    """(goal (x, y, z), its configuration) from at most `attempts` random configurations; None when none was free
    (and, with a region, had its end effector in it)."""
    lo, hi = _near_home(lower, upper, home, noise) if noise > 0 else (np.asarray(lower), np.asarray(upper))
    for _ in range(attempts):
        q = rng.uniform(lo, hi)
        if region is not None:
            ee = backend.ee_pose(q)[:3]
            if not in_region(ee, region) or not backend.check_state(q):
                continue
            return np.asarray(ee, dtype=float), q
        if backend.check_state(q):
            return np.asarray(backend.ee_pose(q)[:3], dtype=float), q
    return None


def sample_start(rng, backend, lower, upper, home, noise: float, attempts: int, at_goal, over_range: bool = True):
    """A free configuration from at most `attempts` random ones within +-noise rad of home (noise > 0), then (unless
    over_range is false) as many over the joint range, whose end effector's (x, y, z) is not at_goal; None when there
    is none."""
    ranges = [(np.asarray(lower, dtype=float), np.asarray(upper, dtype=float))] if over_range or noise <= 0 else []
    if noise > 0:
        ranges.insert(0, _near_home(lower, upper, home, noise))
    for a, b in ranges:
        for _ in range(attempts):
            q = rng.uniform(a, b)
            if backend.check_state(q) and not at_goal(backend.ee_pose(q)[:3]):
                return q
    return None
