"""A validated joint trajectory sampled at every physics substep: the one implementation Simulator.prepare uses, in
its kinematic fast path and in its checked path (issue 54). ROS-free and pybullet-free.

The trajectory arrives here checked, starting at t = 0 from the current state and clamped into the joint limits
(Simulator.prepare does that, and names what is wrong); this module only samples it:

* ``substep_count``: how many substeps a motion of some duration takes;
* ``segment_velocities``: each segment's velocity per joint (what the velocity limits are checked against);
* ``sample_linear``: the robot's position after each substep, moving linearly between the points, and the velocity of
  the segment it is on, in the form Motion holds them (one ``[q]`` list per joint).

Plain Python on lists of floats, not numpy: an env step's motion has a point or two and about a dozen substeps, where
numpy's per-call overhead costs more than the arithmetic (kinematic prepare() of a one-point, 0.05 s step: 26 us in
plain Python, 57 us with numpy, measured). The operations and their order are those of the numpy code this replaced
(elementwise IEEE doubles), so the samples are the same doubles, bit for bit (test_trajectory.py keeps them).
"""

import math

__all__ = ["substep_count", "segment_velocities", "sample_linear"]


def substep_count(duration, physics_hz):
    """Physics substeps of a motion lasting `duration` seconds: a last partial substep counts as one (1e-9 keeps a
    duration on the substep grid from gaining one through rounding)."""
    return int(math.ceil(duration * physics_hz - 1e-9)) if duration > 0 else 0


def segment_velocities(times, positions):
    """Per segment (point i to point i + 1), per joint: (q[i + 1] - q[i]) / (t[i + 1] - t[i]), a list of rows."""
    return [
        [(b - a) / dt for a, b in zip(p0, p1)]
        for dt, p0, p1 in zip([t1 - t0 for t0, t1 in zip(times, times[1:])], positions, positions[1:])
    ]


def sample_linear(times, positions, velocities, dt, n):
    """Targets and velocities of substeps 1..n, moving linearly between the points.

    Args:
        times (List[float]): strictly increasing, times[0] == 0.0, at least two when n > 0.
        positions (List[List[float]]): one row per time.
        velocities (List[List[float]]): segment_velocities(times, positions).
        dt (float): the substep (1 / physics_hz).
        n (int): substep_count(times[-1], physics_hz).

    Returns:
        Tuple[list, list]: per substep k, the position at min(k * dt, times[-1]) (the last one: the last point
        exactly) and the velocity of the segment it is on (the segment whose end is the first time >= that instant),
        each as one [value] list per joint. A segment's substeps share its velocity lists.
    """
    targets, rates = [], []
    if n == 0:
        return targets, rates
    T = times[-1]
    segments = len(times) - 1
    s = 0
    start, t0, span, rows = positions[0], times[0], times[1] - times[0], [[v] for v in velocities[0]]
    step = [y - x for x, y in zip(positions[0], positions[1])]
    for k in range(1, n + 1):
        ts = min(k * dt, T)
        if s + 1 < segments and times[s + 1] < ts:
            while s + 1 < segments and times[s + 1] < ts:
                s += 1
            start, t0, span, rows = positions[s], times[s], times[s + 1] - times[s], [[v] for v in velocities[s]]
            step = [y - x for x, y in zip(positions[s], positions[s + 1])]
        alpha = (ts - t0) / span
        targets.append([[x + alpha * d] for x, d in zip(start, step)])
        rates.append(rows)
    targets[-1] = [[x] for x in positions[-1]]
    return targets, rates
