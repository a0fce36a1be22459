"""Errors of the MoveRL env (no ROS imports)."""


class MoveRLError(RuntimeError):
    """A component of the graph failed (the shield, the planning scene, the robot driver, its joint states) or did not
    answer by its deadline: the robot did not move, and the env cannot go on with this graph. The message names the
    component."""


class NoFreeConfiguration(MoveRLError):
    """No sampled start (or goal) configuration is collision-free: the graph works, but what it knows of the world
    leaves nothing free (with sensed obstacles: space no camera sees counts as occupied). At an env's first reset the
    world cannot be used as it is (the message says why); later, the env starts the episode where the robot stands
    (info["no_free_start"]) rather than relaunch a graph that did not fail."""
