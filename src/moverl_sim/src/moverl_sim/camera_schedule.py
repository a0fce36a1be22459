"""When the simulator's depth cameras render, in simulated time. ROS-free; no rendering here (moverl_sim.camera).

A camera renders at its rate in simulated time: it is due when sim time reaches its last render + 1 / rate, or when
it never rendered, or when it is pending (must render at once, whatever the time: a new ~points subscriber, a reset).
``due_cameras`` and ``substeps_until_due`` decide from the render times; ``CameraSchedule`` holds those times for the
sim node and answers its three questions:

* lockstep ``~execute`` / ``~reset_robot``: which cameras are due at the current substep (``due_now``), and how many
  substeps the motion may run before the next one falls due (``piece``; moverl_sim.lockstep.run_motion runs it so);
* the camera thread: which cameras to render together now, the most overdue first (``next_renders``), and when none
  is, the sim time at which one will be (``next_due``: the real-time loop wakes the thread once sim time reaches it);
* a render failed or the node closes: no camera renders again (``stop``).

Not locked: the sim node calls it with its simulator lock held, except ``request_all`` from a subscriber callback,
which replaces whole lists (each assignment atomic) that the readers then see under the lock.
"""

import math
import threading

__all__ = ["DUE_TOLERANCE", "due_cameras", "substeps_until_due", "CameraSchedule"]

# Seconds of simulated time by which a camera may fall short of its due time and still count as due: sim time is
# substeps / physics_hz, so "last render + 1 / rate" and the substep that reaches it can differ in the last bits.
# Far below any substep (1 / physics_hz), so it never makes a camera render a substep early.
DUE_TOLERANCE = 1e-6


def due_cameras(last_renders, periods, now):
    """The cameras due at simulated time ``now``, in camera order.

    Args:
        last_renders (Sequence[Optional[float]]): per camera, the sim time of its last render; None when it never
            rendered (or must render again at once, e.g. after a reset): such a camera is always due.
        periods (Sequence[float]): per camera, simulated seconds between renders (1 / rate).
        now (float): the simulated time.

    Returns:
        List[int]: indices of the cameras with ``now >= last + period`` (within DUE_TOLERANCE) or never rendered.
    """
    return [
        i
        for i, (last, period) in enumerate(zip(last_renders, periods))
        if last is None or now >= last + period - DUE_TOLERANCE
    ]


def substeps_until_due(last_renders, periods, now, physics_hz):
    """How many physics substeps to run from simulated time ``now`` until the first camera is due.

    Arguments as in due_cameras; physics_hz: substeps per simulated second. After k substeps sim time is
    now + k / physics_hz: the result is the smallest k at which due_cameras is not empty.

    Returns:
        Optional[int]: 0 when a camera is due now, else >= 1; None without cameras (never due).
    """
    if not periods:
        return None
    if due_cameras(last_renders, periods, now):
        return 0
    next_due = min(last + period for last, period in zip(last_renders, periods))
    return max(1, math.ceil((next_due - DUE_TOLERANCE - now) * physics_hz))


class CameraSchedule:
    """The render times of a node's cameras and what follows from them.

    Attributes:
        periods (List[float]): per camera, simulated seconds between renders (1 / rate).
        last (List[Optional[float]]): per camera, the sim time of its last render (None: never rendered).
        pending (List[bool]): per camera, render at once whatever the sim time (all, at the start).
        next_due (float): real time: the sim time at which the camera thread has something to render again
            (-inf: now; set by next_renders when it finds nothing due).
    """

    def __init__(self, periods):
        """Args:
        periods (Sequence[float]): per camera, simulated seconds between renders (1 / rate), in camera order.
        """
        self.periods = [float(p) for p in periods]
        self.last = [None] * len(self.periods)
        self.pending = [True] * len(self.periods)
        self.next_due = -math.inf
        self._stopped = threading.Event()

    def __len__(self):
        return len(self.periods)

    @property
    def stopped(self) -> bool:
        """True once stop() was called: nothing is due any more."""
        return self._stopped.is_set()

    def stop(self):
        """No camera renders again (a render failed, or the node is closing)."""
        self._stopped.set()

    def request_all(self):
        """Every camera renders at once, whatever the sim time (a new subscriber, a reset)."""
        self.pending = [True] * len(self.periods)
        self.next_due = -math.inf

    def rendered(self, i: int, now: float):
        """Camera i rendered at sim time now: it is scheduled from this render on."""
        self.last[i] = now
        self.pending[i] = False

    def due_now(self, now: float) -> list:
        """Lockstep: the cameras to render at sim time now, in camera order: the pending ones and those whose period
        has passed. Empty once stopped."""
        if self._stopped.is_set():
            return []
        pending = self.pending
        due = [i for i in range(len(self.periods)) if pending[i]]
        due += [i for i in due_cameras(self.last, self.periods, now) if i not in due]
        return sorted(due)

    def piece(self, now: float, remaining: int, physics_hz: float) -> int:
        """Lockstep: how many of a motion's remaining substeps to run from sim time now before rendering again: up to
        the first due time (at least 1: what was due now has rendered), all of them once stopped or without cameras.
        """
        if self._stopped.is_set() or not self.periods:
            return remaining
        return min(remaining, max(1, substeps_until_due(self.last, self.periods, now, physics_hz)))

    def next_renders(self, now: float, realtime: bool) -> list:
        """The cameras the camera thread renders together at sim time now (one instant, one stamp), or [].

        Pending cameras render in both modes; in real time also those whose period has passed. They render as one
        instant, as lockstep's due cameras do and a hardware-synchronised rig does: the planning scene integrates the
        clouds of one instant as one batch of its hidden space, closed once (cameras rendered one after another would
        each be a batch of their own). Listed most overdue first: pending ones, then those that never rendered, then
        the oldest render. When none is due, next_due is set: in real time to the earliest due time (less
        DUE_TOLERANCE), in lockstep to +inf (~execute renders there).
        """
        if self._stopped.is_set():
            return []
        last = self.last
        due = [i for i in range(len(self.periods)) if self.pending[i]]
        if not due and realtime:
            due = due_cameras(last, self.periods, now)
        if due:
            return sorted(due, key=lambda k: (not self.pending[k], -math.inf if last[k] is None else last[k]))
        if realtime and self.periods:
            self.next_due = min(t + p for t, p in zip(last, self.periods)) - DUE_TOLERANCE
        else:
            self.next_due = math.inf
        return []
