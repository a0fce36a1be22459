"""A tracker's view of the world's observed objects: poses measured at a rate, delivered after a latency, with position
noise and dropouts, as a person tracker (a skeleton tracker on a depth camera, a motion-capture system) reports them.

ROS-free. Two nodes publish what Tracker.advance returns, each measurement as a geometry_msgs/PoseStamped (stamp: when
it was measured; frame: the world's) on the object's topic, TOPIC with the object's id, as motion-capture drivers do
(vrpn_client_ros, mocap_optitrack: one PoseStamped topic per tracked body):

* the simulator (sim_node, launch argument ``obstacle_poses:=tracker``), on simulated time;
* the stand-in tracker (scripts/tracker_node), for a graph without the simulator (``simulator:=false``), on ROS time.

Any other tracker that publishes the same topics feeds the env (moverl_gym: the env reads them when launched with
``obstacle_poses:=tracker``). The model, per object and measurement:

* measured at times ``start + k / rate`` (k = 0, 1, ...) of the clock advance() is given; the truth at that time;
* position + Gaussian noise of standard deviation ``noise`` (m) per axis; the orientation as measured (the world's
  motions translate, they do not rotate: orientation noise is not modelled);
* lost with the long-run probability ``dropout``, in bursts of ``dropout_burst`` measurements on average (a
  two-state Markov chain per object, the Gilbert model of bursty losses: a person hidden behind the robot for a while,
  not single messages missing at random);
* delivered ``latency`` s after it was measured (advance() returns it once its clock passes stamp + latency).

Seeded: the same options and the same calls give the same measurements.
"""

from __future__ import annotations

import collections
import math
import random
from dataclasses import dataclass, fields

#: The topic of one tracked object's poses (geometry_msgs/PoseStamped): format with the world object's id.
TOPIC = "/tracker/{id}/pose"

#: How the tracker may lie (a test of what a lie can do; config/sim.yaml's tracker/fault): none; frozen (every
#: measurement repeats the object's first pose, freshly stamped: a track stuck where the person was); offset (every
#: position moved by fault_offset along the world's y: a track beside the person).
FAULTS = ("none", "frozen", "offset")

#: A measurement older than this (s) when advance() is called is not taken: after a long pause of the clock a tracker
#: reports what it sees now, not a backlog of the past.
MAX_BACKLOG = 1.0


class TrackerOptionsError(ValueError):
    """A tracker option is unknown, missing or out of its range."""


@dataclass(frozen=True)
class TrackerOptions:
    """How the tracker measures (config/sim.yaml's tracker: section, each key commented there)."""

    rate: float  # measurements per second
    latency: float  # s from a measurement to its delivery
    noise: float  # m, standard deviation of the position noise per axis
    dropout: float  # long-run fraction of lost measurements, in [0, 1)
    dropout_burst: float  # mean length of a run of lost measurements (measurements, >= 1)
    seed: int  # of the noise and the losses
    fault: str  # FAULTS
    fault_offset: float  # m along y (fault offset)

    @classmethod
    def from_dict(cls, values: dict, where: str = "tracker") -> "TrackerOptions":
        """Options from a mapping with exactly these keys; an unknown, missing or out-of-range one raises
        TrackerOptionsError naming `where`, the key and the valid keys or range."""
        names = [f.name for f in fields(cls)]
        if not isinstance(values, dict):
            raise TrackerOptionsError(f"{where}: expected a mapping with keys {', '.join(names)}, got {values!r}")
        unknown = sorted(set(values) - set(names))
        missing = [n for n in names if n not in values]
        if unknown or missing:
            raise TrackerOptionsError(
                f"{where}: "
                + "; ".join(
                    ([f"unknown key(s) {', '.join(unknown)}"] if unknown else [])
                    + ([f"missing key(s) {', '.join(missing)}"] if missing else [])
                )
                + f" (the keys: {', '.join(names)})"
            )
        try:
            opts = cls(
                rate=float(values["rate"]),
                latency=float(values["latency"]),
                noise=float(values["noise"]),
                dropout=float(values["dropout"]),
                dropout_burst=float(values["dropout_burst"]),
                seed=int(values["seed"]),
                fault=str(values["fault"]),
                fault_offset=float(values["fault_offset"]),
            )
        except (TypeError, ValueError) as exc:
            raise TrackerOptionsError(f"{where}: {exc}") from None
        opts.check(where)
        return opts

    def check(self, where: str = "tracker") -> None:
        def bad(key, need):
            raise TrackerOptionsError(f"{where}.{key} must be {need}, got {getattr(self, key)!r}")

        if not (math.isfinite(self.rate) and self.rate > 0.0):
            bad("rate", "a positive number of measurements per second")
        if not (math.isfinite(self.latency) and self.latency >= 0.0):
            bad("latency", "a number of seconds >= 0")
        if not (math.isfinite(self.noise) and self.noise >= 0.0):
            bad("noise", "a standard deviation in metres >= 0")
        if not (math.isfinite(self.dropout_burst) and self.dropout_burst >= 1.0):
            bad("dropout_burst", "a mean run length >= 1 measurement")
        if self.fault not in FAULTS:
            bad("fault", f"one of {', '.join(FAULTS)}")
        if not math.isfinite(self.fault_offset):
            bad("fault_offset", "a finite number of metres")
        limit = self.dropout_burst / (1.0 + self.dropout_burst)  # the chain's entry probability reaches 1 there
        if not (0.0 <= self.dropout < limit):
            bad("dropout", f"a fraction in [0, {limit:.3g}) (dropout_burst / (1 + dropout_burst))")


@dataclass(frozen=True)
class Measurement:
    """One delivered pose of one object."""

    id: str
    stamp: float  # when it was measured (the clock of advance())
    pose: tuple  # x, y, z, qx, qy, qz, qw


class Tracker:
    """Measures the objects `ids` on the clock given to advance().

    Args:
        ids: the tracked objects (the world's observed ones), in the order their measurements are taken.
        options: TrackerOptions.
        start: the clock's time of the first measurement.
    """

    def __init__(self, ids, options: TrackerOptions, start: float = 0.0):
        options.check()
        self.ids = tuple(ids)
        self.options = options
        self._period = 1.0 / options.rate
        self._start = float(start)
        self._k = 0  # index of the next measurement
        self._rng = random.Random(options.seed)
        # The Gilbert chain per object: lost now or not, and its two transition probabilities.
        self._lost = dict.fromkeys(self.ids, False)
        self._recover = 1.0 / options.dropout_burst
        self._enter = options.dropout * self._recover / (1.0 - options.dropout)
        self._pending = collections.deque()  # (delivery time, Measurement), in delivery order
        self._frozen = {}  # fault frozen: each object's first pose
        self.taken = 0  # measurements taken (per object each)
        self.dropped = 0  # of them, lost

    def next_measurement(self) -> float:
        """The clock's time of the next measurement."""
        return self._start + self._k * self._period

    def retake_from(self, at: float) -> int:
        """The truth jumped at time `at` (the simulator's reset teleports the objects to the start of their motions):
        the measurements stamped at or after `at` not yet delivered were taken from the old truth, so they are dropped,
        and the next advance() takes them again from the new one (a real tracker sees no teleport; a measurement due
        at the reset's instant was taken just before it). Returns how many were dropped. `taken` counts a measurement
        taken again twice."""
        kept = collections.deque(item for item in self._pending if item[1].stamp < at)
        dropped = len(self._pending) - len(kept)
        self._pending = kept
        # The first measurement time at or after `at` (the float product checked both ways).
        k = max(0, math.ceil((at - self._start) / self._period))
        while k > 0 and self._start + (k - 1) * self._period >= at:
            k -= 1
        while self._start + k * self._period < at:
            k += 1
        self._k = min(self._k, k)
        return dropped

    def advance(self, now: float, truth) -> list:
        """Take the measurements due up to `now` and return those delivered by `now` (oldest first).

        Args:
            now: the clock's time.
            truth: truth(t) -> {id: (x, y, z, qx, qy, qz, qw)}, every tracked object's true pose at time t (<= now).
        """
        t = self.next_measurement()
        if now - t > MAX_BACKLOG:  # the clock jumped: resume at the first measurement time within the backlog
            self._k += math.ceil((now - MAX_BACKLOG - t) / self._period)
            t = self.next_measurement()
        latency, noise, rng = self.options.latency, self.options.noise, self._rng
        frozen = self.options.fault == "frozen"
        offset = self.options.fault_offset if self.options.fault == "offset" else 0.0
        while t <= now:
            poses = truth(t)
            self.taken += 1
            for oid in self.ids:
                lost = self._lost[oid]
                self._lost[oid] = (rng.random() >= self._recover) if lost else (rng.random() < self._enter)
                if lost:
                    self.dropped += 1
                    continue
                x, y, z, qx, qy, qz, qw = self._frozen.setdefault(oid, poses[oid]) if frozen else poses[oid]
                y += offset
                if noise > 0.0:
                    x, y, z = x + rng.gauss(0.0, noise), y + rng.gauss(0.0, noise), z + rng.gauss(0.0, noise)
                self._pending.append((t + latency, Measurement(oid, t, (x, y, z, qx, qy, qz, qw))))
            self._k += 1
            t = self.next_measurement()
        out = []
        pending = self._pending
        while pending and pending[0][0] <= now:
            out.append(pending.popleft()[1])
        return out
