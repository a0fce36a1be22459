"""What a joint_trajectory_controller does with a control_msgs/FollowJointTrajectory goal, without ROS.

The simulator serves the standard action in real time (as gazebo_ros_control does for Gazebo); this module holds the
controller's rules so that they are unit-tested, and the node only wires actionlib to them. Modelled on ros_controllers'
joint_trajectory_controller (Noetic, 0.21):

- A goal must name exactly the controller's joints (any order): else INVALID_JOINTS. Points must have one position
  per joint (velocities / accelerations empty or one per joint), finite values, strictly increasing times: else
  INVALID_GOAL. An empty trajectory stops the robot where it is (success).
- The trajectory starts at header.stamp (zero: now). Points whose time has passed are dropped, and the robot is
  bridged from where the controller is now to the first point still ahead; a first point at time 0 with a zero stamp
  is replaced by that bridge. A trajectory entirely in the past is INVALID_GOAL. Before its start the robot holds.
- Tolerances: the controller's defaults (0: not checked), replaced per joint by the goal's values (> 0: that value;
  -1: not checked; 0: keep the default). While the trajectory runs, a joint farther than its path tolerance from its
  setpoint aborts the goal (PATH_TOLERANCE_VIOLATED); after its end the goal succeeds once every joint is within its
  goal tolerance (position, and velocity against stopped_velocity_tolerance), or aborts with GOAL_TOLERANCE_VIOLATED
  when that has not happened goal_time_tolerance after the end.
- A new goal preempts the active one.

Between points the setpoint follows joint_trajectory_controller's splines: linear with positions only, cubic with
velocities, quintic with velocities and accelerations (the bridge from the current setpoint starts at rest).
Differences, stated: points outside the joint position limits, segments between points faster than the velocity
limits and point velocities beyond them are refused (INVALID_GOAL; a real controller leaves limits to the hardware,
which faults); and on an abort the robot holds where it is (joint_trajectory_controller 0.21 only drops the goal).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

# control_msgs/FollowJointTrajectoryResult error codes (the node checks them against the generated message).
SUCCESSFUL = 0
INVALID_GOAL = -1
INVALID_JOINTS = -2
OLD_HEADER_TIMESTAMP = -3
PATH_TOLERANCE_VIOLATED = -4
GOAL_TOLERANCE_VIOLATED = -5

LIMIT_TOLERANCE = 1e-6  # rad (m): points may touch the joint limits
VELOCITY_TOLERANCE = 1e-6  # relative: segments may run at the velocity limits


class GoalRejected(ValueError):
    """A goal the controller refuses before moving: code is INVALID_JOINTS or INVALID_GOAL."""

    def __init__(self, code: int, message: str):
        super().__init__(message)
        self.code = code


@dataclass
class Tolerances:
    """Per-joint tolerances (0 = not checked) and the goal time, in the controller's joint order."""

    path: np.ndarray
    goal: np.ndarray
    goal_velocity: np.ndarray
    goal_time: float = 0.0

    @classmethod
    def defaults(cls, n: int, path=0.0, goal=0.0, stopped_velocity=0.01, goal_time=0.0) -> "Tolerances":
        return cls(
            np.full(n, float(path)), np.full(n, float(goal)), np.full(n, float(stopped_velocity)), float(goal_time)
        )

    @classmethod
    def from_constraints(cls, joints, constraints: dict) -> "Tolerances":
        """A joint_trajectory_controller's `constraints` parameters (config/sim.yaml): per joint {trajectory, goal}
        (absent: 0, not checked), stopped_velocity_tolerance (absent: 0.01) and goal_time (absent: 0)."""
        joints = list(joints)
        return cls(
            np.array([float(constraints.get(j, {}).get("trajectory", 0.0)) for j in joints]),
            np.array([float(constraints.get(j, {}).get("goal", 0.0)) for j in joints]),
            np.full(len(joints), float(constraints.get("stopped_velocity_tolerance", 0.01))),
            float(constraints.get("goal_time", 0.0)),
        )

    def merged(self, joints, path_tolerance, goal_tolerance, goal_time: float) -> "Tolerances":
        """The goal's tolerances over these defaults (control_msgs/JointTolerance: > 0 set, -1 off, 0 keep).

        path_tolerance / goal_tolerance: iterables of objects with name, position, velocity. Unknown names are
        INVALID_GOAL."""
        index = {j: i for i, j in enumerate(joints)}
        out = Tolerances(
            self.path.copy(),
            self.goal.copy(),
            self.goal_velocity.copy(),
            goal_time if goal_time > 0 else self.goal_time,
        )

        def apply(target, value, name):
            if name not in index:
                raise GoalRejected(INVALID_GOAL, f"tolerance for unknown joint {name!r}")
            if not math.isfinite(value):
                raise GoalRejected(INVALID_GOAL, f"tolerance of {name} is not finite")
            if value > 0:
                target[index[name]] = value
            elif value == -1:
                target[index[name]] = 0.0

        for t in path_tolerance:
            apply(out.path, t.position, t.name)
        for t in goal_tolerance:
            apply(out.goal, t.position, t.name)
            apply(out.goal_velocity, t.velocity, t.name)
        return out


@dataclass
class Trajectory:
    """A validated goal in the controller's joint order: absolute times (s, the controller's clock), positions and,
    when the goal gave them, velocities and accelerations (else None).

    Before times[0] the robot holds `hold`; between points it follows the spline the given data define (linear,
    cubic or quintic, as joint_trajectory_controller); after the last point it holds the last.
    """

    times: np.ndarray
    positions: np.ndarray
    hold: np.ndarray
    tolerances: Tolerances
    velocities: "np.ndarray | None" = None
    accelerations: "np.ndarray | None" = None
    end: float = field(init=False)

    def __post_init__(self):
        self.end = float(self.times[-1]) if len(self.times) else -math.inf

    def desired(self, t: float):
        """Setpoint (position, velocity) at time t."""
        times = self.times
        if len(times) == 0 or t < times[0]:
            return self.hold, np.zeros_like(self.hold)
        q, v = spline_at(times, self.positions, self.velocities, self.accelerations, np.array([t]))
        return q[0], v[0]


def spline_at(times, P, V, A, ts):
    """Positions and velocities at the times ts (clipped into [times[0], times[-1]]) of the spline through the points
    (times, P) with velocities V and accelerations A (each None or one row per point): linear with positions only,
    cubic Hermite with velocities, quintic with both (joint_trajectory_controller's segments). At rest outside."""
    ts = np.asarray(ts, dtype=float)
    k = np.clip(np.searchsorted(times, ts, side="right") - 1, 0, max(len(times) - 2, 0))
    if len(times) < 2:
        return np.repeat(P[:1], len(ts), axis=0), np.zeros((len(ts), P.shape[1]))
    T = (times[k + 1] - times[k])[:, None]
    s = np.clip(ts - times[k], 0.0, None)[:, None]
    s = np.minimum(s, T)
    p0, p1 = P[k], P[k + 1]
    if V is None:
        q, v = p0 + (s / T) * (p1 - p0), (p1 - p0) / T
    elif A is None:  # cubic Hermite
        v0, v1 = V[k], V[k + 1]
        c2 = (3 * (p1 - p0) - (2 * v0 + v1) * T) / T**2
        c3 = (2 * (p0 - p1) + (v0 + v1) * T) / T**3
        q, v = p0 + v0 * s + c2 * s**2 + c3 * s**3, v0 + 2 * c2 * s + 3 * c3 * s**2
    else:  # quintic with position, velocity and acceleration at both ends
        v0, v1, a0, a1 = V[k], V[k + 1], A[k], A[k + 1]
        h = p1 - p0
        c3 = (20 * h - (8 * v1 + 12 * v0) * T - (3 * a0 - a1) * T**2) / (2 * T**3)
        c4 = (-30 * h + (14 * v1 + 16 * v0) * T + (3 * a0 - 2 * a1) * T**2) / (2 * T**4)
        c5 = (12 * h - 6 * (v1 + v0) * T + (a1 - a0) * T**2) / (2 * T**5)
        q = p0 + v0 * s + a0 / 2 * s**2 + c3 * s**3 + c4 * s**4 + c5 * s**5
        v = v0 + a0 * s + 3 * c3 * s**2 + 4 * c4 * s**3 + 5 * c5 * s**4
    after = ts >= times[-1]
    if after.any():
        q[after], v[after] = P[-1], 0.0
    return q, v


def accept(
    joints,
    lower,
    upper,
    goal_joint_names,
    points,
    start: float,
    now: float,
    hold,
    defaults: Tolerances,
    path_tolerance=(),
    goal_tolerance=(),
    goal_time: float = 0.0,
    velocity_limits=None,
) -> Trajectory:
    """Validate a goal and turn it into a Trajectory in the controller's joint order, or raise GoalRejected.

    points: iterables of objects with positions, velocities, accelerations and time_from_start (seconds, float).
    start: the goal's header.stamp in seconds (0: now). hold: the controller's current setpoint (where it holds now).
    velocity_limits: per joint (controller order); None: not checked.
    """
    joints = list(joints)
    names = list(goal_joint_names)
    if len(names) != len(joints) or set(names) != set(joints) or len(set(names)) != len(names):
        missing = [j for j in joints if j not in names]
        unknown = [j for j in names if j not in joints]
        raise GoalRejected(
            INVALID_JOINTS,
            f"the goal's joints {names} do not match the controller's {joints} (missing {missing}, unknown {unknown})",
        )
    tol = defaults.merged(joints, path_tolerance, goal_tolerance, goal_time)
    hold = np.asarray(hold, dtype=float)
    if not points:
        return Trajectory(np.zeros(0), np.zeros((0, len(joints))), hold, tol)
    order = [names.index(j) for j in joints]
    n = len(joints)
    times, rows, vel_rows, acc_rows = [], [], [], []
    for i, p in enumerate(points):
        if len(p.positions) != n:
            raise GoalRejected(INVALID_GOAL, f"point {i} has {len(p.positions)} positions, expected {n}")
        for kind in ("velocities", "accelerations"):
            values = getattr(p, kind)
            if len(values) not in (0, n):
                raise GoalRejected(INVALID_GOAL, f"point {i} has {len(values)} {kind}, expected 0 or {n}")
            if not all(math.isfinite(v) for v in values):
                raise GoalRejected(INVALID_GOAL, f"point {i}: {kind} are not finite")
        row = [float(p.positions[k]) for k in order]
        if not all(math.isfinite(v) for v in row) or not math.isfinite(p.time_from_start):
            raise GoalRejected(INVALID_GOAL, f"point {i} is not finite")
        if velocity_limits is not None and len(p.velocities):
            over = [
                j for j, k in enumerate(order) if abs(p.velocities[k]) > velocity_limits[j] * (1.0 + VELOCITY_TOLERANCE)
            ]
            if over:
                j = over[0]
                raise GoalRejected(
                    INVALID_GOAL,
                    f"point {i}: {joints[j]} velocity {p.velocities[order[j]]:.6g} "
                    f"above its limit {velocity_limits[j]:.6g}",
                )
        times.append(float(p.time_from_start))
        rows.append(row)
        vel_rows.append([float(p.velocities[k]) for k in order] if len(p.velocities) else None)
        acc_rows.append([float(p.accelerations[k]) for k in order] if len(p.accelerations) else None)
    t = np.array(times)
    P = np.array(rows)
    # Splines as the controller's: velocities (cubic) and accelerations (quintic) only when every point has them.
    V = np.array(vel_rows) if all(r is not None for r in vel_rows) else None
    A = np.array(acc_rows) if V is not None and all(r is not None for r in acc_rows) else None
    if np.any(np.diff(t) <= 0):
        raise GoalRejected(INVALID_GOAL, "trajectory points are not strictly increasing in time")
    if t[0] < 0:
        raise GoalRejected(INVALID_GOAL, "negative time_from_start")
    bad = (P < np.asarray(lower) - LIMIT_TOLERANCE) | (P > np.asarray(upper) + LIMIT_TOLERANCE)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise GoalRejected(
            INVALID_GOAL, f"point {i}: {joints[j]} = {P[i, j]:.6g} outside its limits [{lower[j]:.6g}, {upper[j]:.6g}]"
        )
    if velocity_limits is not None:
        vmax = np.asarray(velocity_limits, dtype=float) * (1.0 + VELOCITY_TOLERANCE)
        if len(t) > 1:
            speed = np.abs(np.diff(P, axis=0)) / np.diff(t)[:, None]
            if (speed > vmax).any():
                i, j = np.argwhere(speed > vmax)[0]
                raise GoalRejected(
                    INVALID_GOAL,
                    f"points {i}-{i + 1}: {joints[j]} moves at {speed[i, j]:.6g}, above "
                    f"its velocity limit {velocity_limits[j]:.6g}",
                )

    zero_stamp = start == 0.0
    t0 = now if zero_stamp else start
    abs_t = t0 + t
    if abs_t[-1] <= now:
        raise GoalRejected(
            INVALID_GOAL, f"every point of the trajectory is in the past (the last by {now - abs_t[-1]:.3f} s)"
        )
    ahead = abs_t > now
    if zero_stamp and t[0] == 0.0:
        ahead[0] = False  # a first point at time 0 with no start time: replaced by the bridge from where we are
    first = int(np.argmax(ahead))
    if first > 0 or (zero_stamp and t[0] == 0.0):
        # Bridge: from the current setpoint (at rest), now, to the first point still ahead.
        abs_t = np.concatenate(([now], abs_t[first:]))
        P = np.vstack((hold, P[first:]))
        zeros = np.zeros((1, n))
        V = np.vstack((zeros, V[first:])) if V is not None else None
        A = np.vstack((zeros, A[first:])) if A is not None else None
    return Trajectory(abs_t, P, hold, tol, V, A)


def check(traj: Trajectory, t: float, q, v):
    """The goal's state at time t with measured positions q and velocities v (controller order):
    None (running), (SUCCESSFUL, "") or (code, message) for an abort."""
    q = np.asarray(q)
    tol = traj.tolerances
    if t < traj.end:
        if tol.path.any():
            qd, _ = traj.desired(t)
            err = np.abs(q - qd)
            over = (tol.path > 0) & (err > tol.path)
            if over.any():
                j = int(np.argmax(over))
                return PATH_TOLERANCE_VIOLATED, (
                    f"joint {j} path error {err[j]:.6g} exceeds its tolerance {tol.path[j]:.6g}"
                )
        return None
    err = np.abs(q - traj.positions[-1]) if len(traj.times) else np.zeros_like(q)
    verr = np.abs(np.asarray(v))
    over = ((tol.goal > 0) & (err > tol.goal)) | ((tol.goal_velocity > 0) & (verr > tol.goal_velocity))
    if not over.any():
        return SUCCESSFUL, ""
    if t < traj.end + tol.goal_time:
        return None
    j = int(np.argmax(over))
    return GOAL_TOLERANCE_VIOLATED, (
        f"joint {j} goal error {err[j]:.6g} (tolerance {tol.goal[j]:.6g}), velocity "
        f"{verr[j]:.6g} (tolerance {tol.goal_velocity[j]:.6g}) "
        f"{t - traj.end:.3f} s after the end"
    )
