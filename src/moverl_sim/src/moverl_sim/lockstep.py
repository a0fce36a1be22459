"""The simulator's lockstep driver without ROS: ~execute and ~reset_robot (moverl_msgs ExecuteTrajectory, ResetRobot).

ROS-free; the sim node converts messages and calls these with its simulator lock held:

* ``trajectory_arrays``: an ExecuteTrajectory request's joint names and points, checked and put in the simulator's
  joint order (both modes: in real time the node hands the prepared motion to moverl_sim.realtime);
* ``run_motion``: lockstep, a prepared motion run to its end in one call, or, when the cameras are watched, in pieces
  that stop at every substep where a camera falls due (moverl_sim.camera_schedule), so the clouds are rendered with
  the robot and the moving obstacles where they are at that sim time. The pieces change nothing else: the substeps,
  contacts and final state are those of the one call (test_lockstep.py compares them);
* ``reset_robot``: teleport the robot and restart the obstacles' motions, refused where the target touches the world.
"""

import math

from .core import VELOCITY_TOLERANCE, InvalidTrajectory, LimitViolation

__all__ = ["trajectory_arrays", "run_motion", "reset_robot", "Unreachable"]


class Unreachable(Exception):
    """A reset target the robot cannot be placed at (it touches the world): the caller samples another."""


def trajectory_arrays(joints, velocity_limits, names, points, times):
    """Check an ExecuteTrajectory request and reorder it into the simulator's joint order.

    Args:
        joints (Sequence[str]): the simulator's controlled joints, in its order.
        velocity_limits (Sequence[float]): per joint of ``joints``.
        names (Sequence[str]): the request's joint_names (any order, each controlled joint exactly once).
        points (Sequence): trajectory_msgs/JointTrajectoryPoint-like objects (positions, velocities, accelerations).
        times (Sequence[float]): each point's time_from_start in seconds.

    Returns:
        Tuple[list, list, list, list]: times, positions, velocities and accelerations per point (velocities /
        accelerations of a point: [] when it gave none), as Simulator.prepare takes them.

    Raises:
        InvalidTrajectory: joints not exactly the controlled ones, no points, a point with the wrong number of values
            or non-finite velocities / accelerations.
        LimitViolation: a point's velocity above its joint's limit.
    """
    names = list(names)
    n = len(joints)
    if len(names) != n or set(names) != set(joints):
        missing = [j for j in joints if j not in names]
        unknown = [j for j in names if j not in joints]
        dup = sorted({j for j in names if names.count(j) > 1})
        raise InvalidTrajectory(
            "joint_names must list the controlled joints %s exactly once (missing %s, unknown %s, duplicated %s)"
            % (list(joints), missing, unknown, dup)
        )
    if not points:
        raise InvalidTrajectory("empty trajectory")
    order = [names.index(j) for j in joints]
    positions, velocities, accelerations = [], [], []
    for i, pt in enumerate(points):
        if len(pt.positions) != n:
            raise InvalidTrajectory("point %d has %d positions, expected %d" % (i, len(pt.positions), n))
        for kind in ("velocities", "accelerations"):
            values = getattr(pt, kind)
            if len(values) not in (0, n) or not all(math.isfinite(v) for v in values):
                raise InvalidTrajectory("point %d: %s must be empty or %d finite values" % (i, kind, n))
        if any(
            abs(pt.velocities[k]) > v * (1.0 + VELOCITY_TOLERANCE)
            for k, v in zip(order, velocity_limits)
            if len(pt.velocities) == n
        ):
            raise LimitViolation("point %d: a velocity is above its joint's limit" % i)
        positions.append([pt.positions[k] for k in order])
        velocities.append([pt.velocities[k] for k in order] if len(pt.velocities) == n else [])
        accelerations.append([pt.accelerations[k] for k in order] if len(pt.accelerations) == n else [])
    return times, positions, velocities, accelerations


def run_motion(sim, motion, schedule=None, on_due=None):
    """Run a prepared motion to its end (lockstep), rendering the cameras that fall due on the way.

    Without a schedule (no cameras, or nobody watches them) the motion runs in one call. With one, the cameras due at
    the start render first (pending ones: a new subscriber, never rendered); then the motion runs in pieces of
    ``schedule.piece`` substeps, and after each piece that does not end the motion the cameras due at that substep
    render. Cameras due at the end are the caller's (after it published the final state).

    Args:
        sim (moverl_sim.core.Simulator): the simulator (not thread safe: the caller holds its lock).
        motion (moverl_sim.core.Motion): from sim.prepare, not started.
        schedule (Optional[moverl_sim.camera_schedule.CameraSchedule]): the cameras' render times.
        on_due (Callable[[List[int], bool], list]): called with the due cameras (camera order) and whether the motion
            is under way (False: at its start), the simulator at that substep; renders them (and tells the schedule,
            CameraSchedule.rendered, or stops it on a failure) and returns what to publish.

    Returns:
        Tuple[moverl_sim.core.ExecutionResult, list]: sim.finish's result and what the on_due calls returned, in order.
    """
    if schedule is None:
        sim.advance(motion, motion.n)
        return sim.finish(motion), []
    out = []
    due = schedule.due_now(sim.sim_time)
    if due:
        out += on_due(due, False)
    while not motion.done:
        want = schedule.piece(sim.sim_time, motion.remaining, sim.physics_hz)
        if sim.advance(motion, want) < want or motion.done:
            break  # (an aborted motion ran fewer: it is over)
        due = schedule.due_now(sim.sim_time)
        if due:
            out += on_due(due, True)
    return sim.finish(motion), out


def reset_robot(sim, positions, clearance_time=0.0, restart=True, settle_substeps=0):
    """~reset_robot: teleport the robot to positions (no contacts counted) and, with `restart`, restart the obstacles'
    motions (motion time 0 = now). Without it (the sensed modes: the scene knows moving things only from the cameras,
    and a person does not teleport back to the start of its walk under their eyes) the motions go on.

    A robot cannot be placed inside an obstacle (where the motions restart, a person may stand on the sampled start),
    nor where a moving one will touch it within `clearance_time` (s of its motion, sim.yaml reset_clearance_time): a
    real robot never appears in a person's way, it gets there through moves the shield checked.
    Such a target is refused like a planned reset's unreachable target, the robot put back where it was.

    After a teleport, `settle_substeps` physics substeps pass with the robot held, so that the state and the camera
    renders published after the reset carry a stamp later than the last one before it (the node: 1 in lockstep when
    cameras render). Without it, the robot's old and new configurations share one stamp, and a planning scene that
    filters a reset's cloud before the new state has reached it (two topics, no order between them) takes the robot
    at its new place for an obstacle: a ghost of the arm around its own links, which then blocks every configuration.

    Raises:
        ValueError: the target is not a valid configuration (Simulator.reset_robot's message); nothing changed.
        Unreachable: the target touches the world, or a moving obstacle will touch it within clearance_time (the
            message names the pairs). The robot is put back; restarted motions stay restarted.
        RuntimeError: the robot cannot be put back (a dynamic robot pushed beyond a joint limit is not a valid
            configuration): it stays at the target. Not a refusal: the node's service answers with an error.
    """
    before = list(sim.joint_positions())
    sim.reset_robot(list(positions))
    if restart:
        sim.restart_motions()
    touching = sim.contacts_now().world_pairs
    near = [] if touching else sim.touched_within(clearance_time)
    if touching or near:
        try:
            sim.reset_robot(before)
        except ValueError as exc:
            raise RuntimeError("cannot put the robot back where it was: %s" % exc) from exc
        if touching:
            pairs = ", ".join(f"{a} / {b}" for a, b in sorted(touching))
            raise Unreachable(f"the target touches the world where the obstacles' motions restart ({pairs})")
        pairs = ", ".join(f"{a} / {b}" for a, b in near)
        raise Unreachable(
            f"a moving obstacle will touch the target within reset_clearance_time ({clearance_time} s of its motion) "
            f"({pairs})"
        )
    sim.hold(settle_substeps)
