"""Errors of the MoveRL env (no ROS imports)."""


class MoveRLError(RuntimeError):
    """A component of the graph failed (the shield, the planning scene, the robot driver, its joint states) or did not
    answer by its deadline: the robot did not move, and the env cannot go on with this graph. The message names the
    component."""
