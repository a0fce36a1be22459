"""What the sensed map holds within the robot's reach, said so that a user can act on it. ROS-free.

The planning scene's ``~sensed_census`` (moverl_msgs/SensedCensus) counts the map's cells within the robot's reach:
seen free, seen occupied, never seen, and seen free once but hidden from every camera since (stale). When unseen space
counts as occupied (a world's ``sensing: unknown_occupied``, the default), a robot whose reach no camera sees has no
free start and no free goal there; :func:`describe_unseen` says how much of the reach that is, where it lies, and which
tool shows what the cameras see.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["SensedCensus", "describe_unseen", "CAMERAS_TOOL"]

#: The command that shows what a world's cameras see (moverl_sim's render_world: images and the coverage table).
CAMERAS_TOOL = "rosrun moverl_sim render_world <world.yaml> <out.png> --cameras"


@dataclass(frozen=True)
class SensedCensus:
    """moverl_msgs/SensedCensus's answer, as plain data."""

    radius: float  # m: the ball around the robot's base link counted
    cells: int
    free: int  # seen free (or known free)
    seen_occupied: int
    stale: int  # seen free once, hidden from every camera since, possibly occupied now
    unseen: int  # never seen
    unknown_occupied: bool  # unseen cells count as occupied
    #: per octant of the ball, base frame, index (x >= 0) + 2 (y >= 0) + 4 (z >= 0): its cells, and of those the
    #: unseen and stale ones
    cells_by_octant: tuple
    hidden_by_octant: tuple

    @property
    def hidden(self) -> int:
        return self.unseen + self.stale


_OCTANTS = {
    k: ("in front" if k & 1 else "behind") + "-" + ("left" if k & 2 else "right") for k in range(4)
}  # the four octants of a half-space (above or below the base), by index & 3


def _where(census: "SensedCensus") -> str:
    """Each half of the reach (above and below the base) with its share of space no camera sees, and above the base
    that share per octant (x forward, y left): where to look, and where a camera would help."""
    parts = []
    for half, name in ((4, "above its base"), (0, "below it")):
        cells = sum(census.cells_by_octant[half + k] for k in range(4))
        hidden = sum(census.hidden_by_octant[half + k] for k in range(4))
        if cells <= 0:
            continue
        text = f"{100.0 * hidden / cells:.0f} % {name}"
        if half == 4:
            octants = [
                f"{_OCTANTS[k]} {100.0 * census.hidden_by_octant[4 + k] / census.cells_by_octant[4 + k]:.0f} %"
                for k in (3, 1, 2, 0)
                if census.cells_by_octant[4 + k] > 0
            ]
            text += f" ({', '.join(octants)})"
        parts.append(text)
    return "; ".join(parts)


def describe_unseen(census: "SensedCensus | None", world: str) -> str:
    """What keeps the robot's reach from counting as free, for an error message (empty when the census tells nothing:
    no sensed map, unseen space free, or nothing hidden). ``world``: the world's name, for the tool's command."""
    if census is None or census.cells <= 0 or not census.unknown_occupied or census.hidden <= 0:
        return ""
    share = 100.0 * census.hidden / census.cells
    unseen = 100.0 * census.unseen / census.cells
    stale = 100.0 * census.stale / census.cells
    return (
        f"{share:.0f} % of the robot's reach (the {census.radius:.2f} m ball around its base) is space no camera "
        f"sees ({unseen:.0f} % never seen, {stale:.0f} % hidden since it was seen free, where something moving at the "
        f"world's sensing speed_bound may have come since): {_where(census)}; "
        f"world '{world}' counts unseen space as occupied (sensing: unknown_occupied), so the robot may not move "
        f"there. What the cameras see: {CAMERAS_TOOL}; docs/sensing.md, 'Placing your cameras'"
    )
