"""The observed obstacles' poses as a tracker reports them (launch argument ``obstacle_poses:=tracker``), ROS-free.

The env's observation holds 7 numbers per observed obstacle. With the world file's script (the default) they are the
motion's poses at the step's stamp. With a tracker they are the last pose the tracker delivered for each object,
whatever its age: TrackedPoses keeps them (the ROS backend's subscriber callbacks call update()), and read() gives the
pose vector with every object's age at the step's stamp. A lost track is explicit, never silent:

* the pose is held where it was last seen, and info["track_ages"] says how old it is (s, per observed obstacle);
* an object whose age exceeds ``track_timeout`` (config/env.yaml) counts in info["tracks_lost"];
* before its first pose an object is where the world file puts it at motion time 0, with age inf (lost).

The shield never reads these poses: it checks every action against its own obstacles (the world file's shapes or the
cameras' map), so a late, noisy or lost track costs the policy information, never safety.
"""

from __future__ import annotations

import math

import numpy as np


class TrackedPoses:
    """The latest pose of each tracked object, with its stamp.

    Args:
        ids: the observed obstacles' ids, in observation order.
        initial: their poses before any is delivered (7 numbers each, concatenated: the world file's at motion time 0).
        timeout: s; an older pose counts as lost.
        frame: the world's frame: a pose in another frame is ignored (counted in wrong_frame; the object stays lost).
    """

    def __init__(self, ids, initial: np.ndarray, timeout: float, frame: str = "world"):
        if not (math.isfinite(timeout) and timeout > 0.0):
            raise ValueError(f"track_timeout must be a positive number of seconds, got {timeout!r}")
        self.ids = tuple(ids)
        initial = np.asarray(initial, dtype=np.float64)
        if initial.shape != (7 * len(self.ids),):
            raise ValueError(f"initial poses: expected {7 * len(self.ids)} numbers, got shape {initial.shape}")
        self.timeout = float(timeout)
        self.frame = frame
        self._index = {oid: 7 * k for k, oid in enumerate(self.ids)}
        self._poses = initial.copy()
        self._stamps = np.full(len(self.ids), -np.inf)
        self.received = 0  # poses delivered so far
        self.out_of_order = 0  # of them, older than the one held (ignored)
        self.wrong_frame = 0  # of them, in another frame than the world's (ignored)

    def update(self, oid: str, stamp: float, pose, frame: str = "") -> None:
        """A delivered pose of object `oid` measured at `stamp` (7 numbers) in `frame` (empty: the world's). An id that
        is not tracked raises KeyError; a pose older than the one held, or in another frame, is ignored (counted in
        out_of_order, wrong_frame)."""
        i = self._index[oid]
        k = i // 7
        self.received += 1
        if frame and frame != self.frame:
            self.wrong_frame += 1
            return
        if stamp < self._stamps[k]:
            self.out_of_order += 1
            return
        # One slice assignment, then the stamp: a reader in another thread sees an old pose with its old stamp at
        # worst for the instant between the two (the GIL makes each assignment whole).
        self._poses[i : i + 7] = pose
        self._stamps[k] = stamp

    def read(self, now: float) -> "tuple[np.ndarray, np.ndarray]":
        """(poses, ages): a copy of the held poses (7 numbers per object) and each object's age at `now` (s; inf
        before its first pose)."""
        stamps = self._stamps.copy()
        return self._poses.copy(), now - stamps

    def lost(self, ages: np.ndarray) -> int:
        """How many of these ages count as a lost track (older than the timeout, or never seen)."""
        return int(np.count_nonzero(ages > self.timeout))
