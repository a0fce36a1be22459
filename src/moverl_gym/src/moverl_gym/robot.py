"""The robot side of the env, ROS-free: joint limits from the URDF (moverl_sim.urdf.JointLimits, the one Python reading
of them) and the paper's action scaling (sec. 4.3)."""

from __future__ import annotations

import numpy as np

from moverl_sim.urdf import JointLimits, chain_reach

__all__ = ["JointLimits", "ActionScaler", "chain_reach"]


class ActionScaler:
    """Normalised action in [-1, 1]^n -> commanded joint positions (paper sec. 4.3).

    delta q = action * dt * qdot_limit (so |delta q| <= dt * qdot_limit), then q_cmd = clip(q + delta q, limits).
    """

    def __init__(self, limits: JointLimits, dt: float):
        if not dt > 0:
            raise ValueError(f"dt must be positive, got {dt}")
        self.limits = limits
        self.max_delta = limits.velocity * dt

    def check(self, action) -> np.ndarray:
        """Validate an action. Raises ValueError with the reason for a wrong shape or NaN/inf."""
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (self.limits.size,):
            raise ValueError(f"action must have shape ({self.limits.size},), got {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError(f"action contains NaN or inf: {a}")
        return a

    def command(self, q: np.ndarray, action) -> np.ndarray:
        # clip(x, lo, hi) as maximum then minimum: the same numbers for finite x (check() refused NaN/inf), without
        # np.clip's Python wrappers (a few us per call on 7 numbers, every env step).
        a = np.minimum(np.maximum(self.check(action), -1.0), 1.0)
        return np.minimum(np.maximum(q + a * self.max_delta, self.limits.lower), self.limits.upper)
