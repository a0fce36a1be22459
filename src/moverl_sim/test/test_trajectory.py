"""Trajectory sampling (Simulator.prepare, its kinematic fast path and its checked path) gives the doubles it gave
when this test was written, bit for bit, on many random trajectories, valid and not, under kinematic and dynamic
control; the fast path gives the checked path's doubles and refuses what the checked path refuses. No roscore.

The trajectories: segments shorter and longer than a substep, ends on and off the substep grid, a first point at
t = 0 or not, points beyond a limit by less than its tolerance (clamped), path tolerances (checked; then unused under
kinematic control), per-point velocities and accelerations (the dynamic robot follows the spline through them), and
one thing wrong in some (a NaN or inf, times not increasing or negative, a limit, a start away from the current
state, a row or a path tolerance of the wrong size, no points).

The outputs (every motion's targets, velocities, setpoints, final state and path tolerance, or the exception's type
and message) are hashed through their repr, which names each double exactly (the sign of a zero too): a change of
one bit in one sample changes the digest. The digest was recorded from the code before moverl_sim.trajectory
existed; a change that means to change the sampling records a new one and says why in its commit.
"""

import hashlib
import math

import numpy as np
import pytest
from conftest import HOME, make_sim

from moverl_sim.core import InvalidTrajectory, LimitViolation

pytestmark = pytest.mark.core

CASES = 400  # random trajectories per control mode
DIGEST = {
    "kinematic": "115e94716b7c952e8ca8126b677c34eb3a79d36f221939e665d93014be00dcb2",
    "dynamic": "6f0377062be62936f2d169b3444aeda0e50a8d133be0cce97eea5bb76cd9eec6",
}


def random_case(rng, i, lower, upper, vmax, hz):
    """(start, times, positions, path_tolerance, velocities, accelerations) of random trajectory i: mostly valid,
    some with one thing wrong, segments shorter and longer than a substep, on and off the substep grid."""
    start = np.array(HOME, dtype=float)
    if i % 5 == 0:
        start[3] = upper[3]  # at a limit (points beyond it by less than the tolerance, below)
    if i % 11 == 0:
        start[0] = lower[0]
    m = int(rng.integers(1, 7))
    kind = rng.integers(0, 4)
    if kind == 0:
        steps = rng.uniform(0.0005, 0.004, size=m)  # shorter than a substep and about one
    elif kind == 1:
        steps = rng.uniform(0.004, 0.3, size=m)
    elif kind == 2:
        steps = rng.integers(1, 30, size=m) / hz  # on the substep grid
    else:
        steps = rng.choice([rng.uniform(0.0005, 0.004), rng.uniform(0.004, 1.0)], size=m)
    times = np.cumsum(steps)
    if i % 3 == 0:
        times = np.concatenate(([0.0], times))
    q, rows = start.copy(), []
    for k, t in enumerate(times):
        dt = t - (times[k - 1] if k else 0.0)
        if t > 0:
            q = np.clip(q + rng.uniform(-0.95, 0.95, q.size) * vmax * dt, lower, upper)
        rows.append(q.tolist())
        if i % 5 == 0:
            rows[-1][3] = upper[3] + 5e-7
        if i % 11 == 0:
            rows[-1][0] = lower[0] - 3e-7
    times = times.tolist()
    tolerance = [[], [0.1] * 7, [0.0] * 7, [0.05] * 3 + [0.0] * 4][i % 4]
    velocities = accelerations = None
    if i % 7 in (1, 2, 3):  # per point: the dynamic robot follows the spline through them
        velocities = [rng.uniform(-0.5, 0.5, 7).tolist() for _ in rows]
        if i % 7 == 2:
            accelerations = [rng.uniform(-2, 2, 7).tolist() for _ in rows]
        if i % 7 == 3:
            velocities[-1] = []  # not every point has them: linear
    wrong = i % 29
    if wrong == 1:
        rows[-1][2] = math.nan
    elif wrong == 2 and len(times) > 1:
        times[-1] = times[-2]
    elif wrong == 3:
        rows[-1][3] = upper[3] + 1e-3
    elif wrong == 4:
        rows[-1][1] += 1.5 * vmax[1] * (times[-1] - (times[-2] if len(times) > 1 else 0.0))
    elif wrong == 5:
        tolerance = [0.1] * 6
    elif wrong == 6:
        tolerance = [0.1] * 6 + [-0.1]
    elif wrong == 7 and times[0] == 0.0:
        rows[0][4] += 1e-3  # the t = 0 point away from the current state
    elif wrong == 8:
        times[0] = -times[0] - 0.01
    elif wrong == 9:
        times = [0.0]
        rows = [start.tolist()]  # one point at t = 0: no substeps
        velocities = accelerations = None
    elif wrong == 10:
        rows[-1] = rows[-1][:6]
    elif wrong == 11 and velocities is not None and velocities[0]:
        velocities[0][0] = math.inf
    elif wrong == 12:
        times[-1] = math.inf
    elif wrong == 13:
        times, rows, velocities, accelerations = [], [], None, None
    return start.tolist(), times, rows, tolerance, velocities, accelerations


def motion_record(motion):
    if motion is None:
        return None
    tolerance = motion.path_tolerance
    return (
        motion.n,
        motion.targets,
        motion.velocities,
        motion.setpoints,
        motion.final,
        None if tolerance is None else tolerance.tolist(),
    )


def outcome(call, *args):
    try:
        return ("motion", motion_record(call(*args)))
    except (InvalidTrajectory, LimitViolation) as exc:
        return (type(exc).__name__, str(exc))


def records(sim, seed):
    """Every path's output on CASES random trajectories; also how many of them each path took."""
    rng = np.random.default_rng(seed)
    lower, upper, vmax = np.array(sim.lower), np.array(sim.upper), np.array(sim.velocity_limits)
    out, counts = [], {"fast": 0, "motion": 0, "refused": 0}
    for i in range(CASES):
        start, times, rows, tolerance, velocities, accelerations = random_case(
            rng, i, lower, upper, vmax, sim.physics_hz
        )
        sim.reset_robot(start)
        record = [outcome(sim.prepare, times, rows, tolerance, velocities, accelerations)]
        record.append(outcome(sim._prepare_checked, times, rows, tolerance, velocities, accelerations))
        if sim.control == "kinematic":
            fast = sim._prepare_linear(times, rows, tolerance)
            record.append(motion_record(fast))
            counts["fast"] += fast is not None
            # The fast path gives the checked path's doubles, and refuses (None) what the checked path refuses.
            assert record[1] == ("motion", record[-1]) if fast is not None else record[1][0] != "motion", i
        counts["motion" if record[0][0] == "motion" else "refused"] += 1
        out.append(record)
    return out, counts


def digest(recs):
    return hashlib.sha256(repr(recs).encode()).hexdigest()


@pytest.mark.parametrize("control", ["kinematic", "dynamic"])
def test_prepare_gives_the_recorded_doubles(panda_urdf, table_world, control):
    sim = make_sim(panda_urdf, table_world, control=control, physics_hz=240.0)  # (the digest is of 240 Hz)
    try:
        recs, counts = records(sim, seed=54)
    finally:
        sim.close()
    assert counts["motion"] > 0.6 * CASES and counts["refused"] > 0.2 * CASES, counts
    if control == "kinematic":
        assert counts["fast"] == counts["motion"], counts  # kinematic: every valid one takes it
    assert digest(recs) == DIGEST[control], counts
