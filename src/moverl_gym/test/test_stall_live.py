"""A component that stalls (SIGSTOP: alive, connected, silent) never hangs the env and never moves the robot late.

For each component process of a graph the env launched (the simulator; the shield, which hosts the planning scene by
default; the planning scene in a process of its own, scene_process:=own), with the simulator's lockstep driver and
with the standard driver in real time: stopped mid-episode, the env raises
MoveRLError naming it within 5 s; resumed (SIGCONT), the request it was serving when it stopped is refused as too
late (nothing moves), and the next step gets its own answer, not the stale one.
"""

import os
import signal
import time
import xmlrpc.client

import gymnasium as gym
import numpy as np
import pytest

import moverl_gym  # noqa: F401
from moverl_gym.errors import MoveRLError

pytestmark = pytest.mark.live

HOME = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]
ACTION = np.array([0.3, 0.2, 0.0, 0.2, 0.0, 0.0, 0.0], dtype=np.float32)


def node_pid(name: str) -> int:
    import rosgraph

    uri = rosgraph.Master("/stall_test").lookupNode(name)
    code, _, pid = xmlrpc.client.ServerProxy(uri).getPid("/stall_test")
    assert code == 1
    return pid


def all_threads_stopped(pid: int) -> bool:
    """True when every thread of pid is stopped (state T in /proc/<pid>/task/*/stat)."""
    for tid in os.listdir(f"/proc/{pid}/task"):
        with open(f"/proc/{pid}/task/{tid}/stat", "rb") as f:
            data = f.read()
        if data[data.rindex(b")") + 2 : data.rindex(b")") + 3] != b"T":
            return False
    return True


def robot_state(joints) -> np.ndarray:
    """The robot's configuration from its joint states (the simulator's, latched in lockstep, streamed in real
    time)."""
    import rospy
    from sensor_msgs.msg import JointState

    msg = rospy.wait_for_message("/joint_states", JointState, timeout=5)
    return np.array([dict(zip(msg.name, msg.position))[j] for j in joints])


# (node stopped = what the env's error names, launch arguments of its graph)
COMPONENTS = [("/sim", {}), ("/shield", {}), ("/planning_scene", {"scene_process": "own"})]


@pytest.mark.parametrize("driver", ["sim_service", "follow_joint_trajectory"])
@pytest.mark.parametrize("node, graph_args", COMPONENTS)
def test_a_stalled_component(node, graph_args, driver):
    named = node
    env = gym.make("MoveRL/PandaReachTable-v0", graph="launch", launch_args={"driver": driver, **graph_args})
    pid = None
    try:
        joints = env.unwrapped.limits.names
        env.reset(seed=0, options={"start": HOME})
        for _ in range(3):
            env.step(ACTION)
        before = robot_state(joints)
        pid = node_pid(node)
        os.kill(pid, signal.SIGSTOP)
        # kill() returns before the stop takes effect: a node whose threads were busy could still serve the next
        # request. Step only once the kernel reports the whole process stopped.
        deadline = time.monotonic() + 5.0
        while not all_threads_stopped(pid):
            assert time.monotonic() < deadline, f"{node} (pid {pid}) did not stop"
            time.sleep(0.01)
        t0 = time.monotonic()
        with pytest.raises(MoveRLError) as err:
            env.step(ACTION)
        took = time.monotonic() - t0
        print(f"\n{driver}, {node} stopped: the env raised after {took:.2f} s: {err.value}")
        assert took < 5.0
        assert named in str(err.value)
        os.kill(pid, signal.SIGCONT)
        pid = None
        time.sleep(1.5)  # the resumed node serves what it had received (and refuses it as too late)
        np.testing.assert_allclose(robot_state(joints), before, atol=1e-6)  # nothing moved after the stall
        # The next step gets its own answer: the state it reports is where this step's target took the robot.
        target = env.unwrapped.scaler.command(before, -ACTION)
        _, _, _, _, info = env.step(-ACTION)
        assert info["verdict"] == "safe", info
        np.testing.assert_allclose(env.unwrapped.q, target, atol=1e-6)
        np.testing.assert_allclose(robot_state(joints), target, atol=1e-6)
    finally:
        if pid is not None:
            os.kill(pid, signal.SIGCONT)
        env.close()
