"""The robot side of the env, ROS-free: joint limits from the URDF and the paper's action scaling (sec. 4.3)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class JointLimits:
    """Position and velocity limits of the controlled joints, in their configured order."""

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray

    @classmethod
    def from_urdf(cls, urdf_xml: str, joints: list[str]) -> "JointLimits":
        """Read the limits of `joints` from URDF text.

        Raises:
            ValueError: the URDF does not parse, a joint is missing or has no usable <limit>.
        """
        try:
            root = ET.fromstring(urdf_xml)
        except ET.ParseError as exc:
            raise ValueError(f"the robot description is not valid XML: {exc}") from exc
        by_name = {j.get("name"): j for j in root.iter("joint")}
        lower, upper, velocity = [], [], []
        for name in joints:
            joint = by_name.get(name)
            if joint is None:
                raise ValueError(f"joint '{name}' is not in the URDF (it has: {sorted(n for n in by_name if n)})")
            limit = joint.find("limit")
            if limit is None or joint.get("type") not in ("revolute", "prismatic"):
                raise ValueError(f"joint '{name}' must be revolute or prismatic with a <limit>")
            lo, hi, vel = (float(limit.get(k, "nan")) for k in ("lower", "upper", "velocity"))
            if not (np.isfinite([lo, hi, vel]).all() and lo < hi and vel > 0):
                raise ValueError(f"joint '{name}' has unusable limits lower={lo} upper={hi} velocity={vel}")
            lower.append(lo)
            upper.append(hi)
            velocity.append(vel)
        return cls(tuple(joints), np.array(lower), np.array(upper), np.array(velocity))

    @property
    def size(self) -> int:
        return len(self.names)


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
        a = np.clip(self.check(action), -1.0, 1.0)
        return np.clip(q + a * self.max_delta, self.limits.lower, self.limits.upper)
