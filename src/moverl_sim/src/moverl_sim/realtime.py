"""The simulator's real-time driver without ROS: wall-clock pacing, the FollowJointTrajectory goal being followed, an
ExecuteTrajectory motion handed over by ~execute, and what happens when the process was stalled.

ROS-free, time injected: the sim node's real-time loop reads the wall clock and passes it in (``Pacer.due``,
``RealtimeController.beat``, ``RealtimeController.step``); ``RealtimeController.goal_is_stale`` reads the clock it was
given (time.monotonic in the node, a fake one in the tests). The controller's rules for a goal (validation, splines,
tolerances) are moverl_sim.follow's; this module keeps the state between the node's callbacks:

* ``Pacer``: how many physics substeps are due at a wall time (sim time = wall time since the start; when the loop
  cannot keep up, at most CATCH_UP seconds of sim time run per iteration and sim time slips);
* ``RealtimeController``: the active goal (accept preempts the active one, cancel ends it, the robot then holds where
  it is), the controller's setpoint while it holds, an ExecuteTrajectory motion (the loop runs it, ~execute waits),
  idle contacts (a moving obstacle may come to the resting robot), and the stall guard.

A real controller is hard real time; this one is a process that can be stalled (SIGSTOP, swap). Goals that arrived
while it was (their sender gave up on them and cancelled) must never move the robot when it wakes: the loop beats
every few ms; a goal that comes while the beat is older than STALL_GAP, or within STALE_WINDOW of the loop noticing a
stall, is stale (rejected), and a stall aborts the active goal.

Not locked: the node calls every method but ``goal_is_stale`` and ``beat`` (plain reads and writes of floats) with
its simulator lock held.
"""

import threading
import time
from typing import NamedTuple

from . import follow
from .core import ContactStats

__all__ = ["STALL_GAP", "STALE_WINDOW", "CATCH_UP", "IDLE_REPORT_PERIOD", "Pacer", "Goal", "RealtimeController"]

STALL_GAP = 0.25  # s (wall) between two beats of the real-time loop that mean this process was stalled
STALE_WINDOW = 0.2  # s (wall) after noticing a stall during which arriving goals are stale (queued meanwhile)
CATCH_UP = 0.05  # s of sim time run at most per loop iteration when behind (beyond it, sim time slips)
IDLE_REPORT_PERIOD = 0.1  # s (wall) at least between two reports of the contacts while idle


class Pacer:
    """Physics at wall-clock pace: substep k is due at wall time start + k / physics_hz.

    Attributes:
        start (float): wall time of substep 0 (moves forward when sim time slips).
        done (int): substeps due so far (returned by due()).
    """

    def __init__(self, physics_hz: float, start: float):
        """Args:
        physics_hz: substeps per simulated second.
        start: the wall time (s) at which sim time starts running.
        """
        self.physics_hz = physics_hz
        self.max_batch = max(1, int(physics_hz * CATCH_UP))
        self.start = start
        self.done = 0

    def due(self, now: float) -> int:
        """The substeps to run at wall time now (counted as done): those since the last call, at most max_batch (when
        more are due the loop is too slow to keep up, and sim time slips by the rest). 0 or less: none."""
        hz = self.physics_hz
        due = int((now - self.start) * hz) - self.done
        if due > self.max_batch:
            self.start += (due - self.max_batch) / hz
            due = self.max_batch
        if due > 0:
            self.done += due
        return due

    def next_wake(self) -> float:
        """The wall time at which the next substep is due."""
        return self.start + (self.done + 1) / self.physics_hz


class Goal(NamedTuple):
    """The FollowJointTrajectory goal being followed: the caller's handle, the accepted trajectory, its contacts."""

    handle: object
    trajectory: follow.Trajectory
    stats: ContactStats


class RealtimeController:
    """What the real-time loop does with the simulator between the node's callbacks.

    Attributes:
        goal (Optional[Goal]): the goal being followed (None: the robot holds setpoint, or runs motion).
        motion (Optional[moverl_sim.core.Motion]): an ExecuteTrajectory motion the loop runs (None: none).
        motion_done (threading.Event): set when the loop finished the motion (motion_result holds its result).
        setpoint (list): where the controller holds the robot while no goal runs.
    """

    def __init__(self, sim, tolerances: follow.Tolerances, clock=time.monotonic):
        """Args:
        sim (moverl_sim.core.Simulator): the simulator (its joint order is the controller's).
        tolerances: the controller's default tolerances (a goal's own replace them, follow.accept).
        clock: the wall clock (s, monotonic) goal_is_stale reads; the loop beats now, so nothing is stale at first.
        """
        self.sim = sim
        self.tolerances = tolerances
        self.clock = clock
        self.goal = None
        self.motion = None
        self.motion_done = threading.Event()
        self.motion_result = None
        self.setpoint = list(sim.joint_positions())
        self._idle_stats = ContactStats()
        self._idle_report_wall = 0.0
        self._beat = clock()
        self._stale_until = 0.0

    @property
    def busy(self) -> bool:
        """True while a goal or a motion runs (a reset is refused then)."""
        return self.motion is not None or self.goal is not None

    # ------------------------------------------------------------------ stalls
    def goal_is_stale(self) -> bool:
        """A goal arriving now is stale: the loop has not beaten for STALL_GAP (this process is stalled), or noticed a
        stall less than STALE_WINDOW ago (the goal was queued meanwhile)."""
        wall = self.clock()
        return wall - self._beat > STALL_GAP or wall < self._stale_until

    def beat(self, now: float) -> bool:
        """The loop's beat at wall time now; True when the previous one is older than STALL_GAP: this process was
        stalled, goals arriving within STALE_WINDOW are stale, and the caller aborts the active one (abort_goal)."""
        stalled = now - self._beat > STALL_GAP
        if stalled:
            self._stale_until = now + STALE_WINDOW
        self._beat = now
        return stalled

    # ------------------------------------------------------------------ goals
    def accept(self, handle, joint_names, points, start, path_tolerance=(), goal_tolerance=(), goal_time=0.0):
        """A new goal (follow.accept's arguments, at the current sim time): it preempts the active one.

        The controller first holds where the active goal's setpoint is now (what the new goal is bridged from), then
        validates the new one. An empty trajectory stops the robot where it is (the goal is done at once).

        Returns:
            Tuple[object, follow.Trajectory]: the preempted goal's handle (None: none) and the accepted trajectory
            (no times: empty, succeeded at once).

        Raises:
            follow.GoalRejected: invalid, or an ExecuteTrajectory motion is running; the active goal runs on.
        """
        sim = self.sim
        now = sim.sim_time
        if self.goal is not None:  # preempting: the controller holds where the active goal's setpoint is now
            self.setpoint = list(self.goal.trajectory.desired(now)[0])
        if self.motion is not None:
            raise follow.GoalRejected(follow.INVALID_GOAL, "an ExecuteTrajectory motion is executing")
        accepted = follow.accept(
            sim.joint_names,
            sim.lower,
            sim.upper,
            joint_names,
            points,
            start,
            now,
            self.setpoint,
            self.tolerances,
            path_tolerance,
            goal_tolerance,
            goal_time,
            sim.velocity_limits,
        )
        previous = self.goal
        self.goal = Goal(handle, accepted, ContactStats()) if len(accepted.times) else None
        if not len(accepted.times):  # empty trajectory: stop where the robot is
            self.setpoint = list(sim.stop())
        return (previous.handle if previous is not None else None), accepted

    def cancel(self, handle) -> bool:
        """Cancel the goal of this handle: True when it was the active one (it ends, the robot holds where it is)."""
        if self.goal is None or self.goal.handle != handle:
            return False
        self.goal = None
        self.setpoint = list(self.sim.stop())
        return True

    def abort_goal(self):
        """The active goal ends (a stall): its handle (None: none); the robot holds where it is."""
        goal, self.goal = self.goal, None
        if goal is None:
            return None
        self.setpoint = list(self.sim.stop())
        return goal.handle

    # ------------------------------------------------------------------ ExecuteTrajectory
    def submit(self, motion):
        """Hand a prepared motion (Simulator.prepare) to the loop; motion_done is set when it has run."""
        self.motion_done.clear()
        self.motion = motion

    def reset_done(self):
        """The robot was teleported (~reset_robot): the controller holds it there."""
        self.setpoint = list(self.sim.joint_positions())

    # ------------------------------------------------------------------ the loop's substeps
    def step(self, substeps: int, now: float):
        """Run this many physics substeps at wall time now: the motion first (it ends when done), then the active
        goal, one substep at a time (each checks its tolerances and may end it), then the robot holds still, its
        contacts counted (reported at most every IDLE_REPORT_PERIOD of wall time, when there were any).

        Returns:
            Tuple[list, list]: goals that ended, as (handle, follow error code, message); contacts to report, as
            (ContactStats, sim time): an ended goal's, the idle ones.
        """
        sim = self.sim
        ended, reports = [], []
        motion = self.motion
        ran = 0
        if motion is not None:
            ran = sim.advance(motion, substeps)
            if motion.done:
                self.motion_result = sim.finish(motion)
                self.motion = None
                self.motion_done.set()
        while ran < substeps and self.goal is not None:
            self._follow_substep(ended, reports)
            ran += 1
        if ran < substeps:
            sim.hold(substeps - ran, self._idle_stats)
            if self._idle_stats.substeps_in_contact and now >= self._idle_report_wall:
                reports.append((self._idle_stats, sim.sim_time))
                self._idle_stats = ContactStats()
                self._idle_report_wall = now + IDLE_REPORT_PERIOD
        return ended, reports

    def _follow_substep(self, ended, reports):
        """One physics substep of the active goal: track its setpoint, check its tolerances; when it ends, add
        (handle, code, message) to ended and its contacts to reports."""
        sim = self.sim
        handle, traj, stats = self.goal
        t = sim.sim_time
        q, v = traj.desired(t)
        sim.servo(q, v, stats, traj.desired(t + 1.0 / sim.physics_hz)[0])
        status = follow.check(traj, sim.sim_time, sim.joint_positions(), sim.joint_velocities())
        if status is None:
            return
        code, message = status
        self.goal = None
        self.setpoint = list(traj.positions[-1]) if code == follow.SUCCESSFUL else list(sim.stop())
        ended.append((handle, code, message))
        reports.append((stats, sim.sim_time))
