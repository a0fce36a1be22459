"""The launch-argument check on the real thing (moverl_gym.launch_args; the no-roscore side: test_launch_args.py).

* A roslaunch user's wrong value or undeclared argument name stops roslaunch itself before it starts anything: no
  master ever answers on the port, and no process of the run is left (the test process's tree is watched, never
  processes by name across the machine).
* A graph launched with valid, non-default arguments runs with them, and says so in /moverl/launch_args.
"""

import os
import signal
import subprocess
import time
import xmlrpc.client

import pytest

import moverl_gym  # noqa: F401
from moverl_gym import graph
from moverl_gym import ros_backend as ros
from moverl_gym.launch_args import ARGS, check
from moverl_gym.paths import launch_file, world_file
from moverl_gym.proctree import TreeWatch

pytestmark = pytest.mark.quick

#: s: roslaunch's own start (~0.5 s) plus the check.
LIMIT = 3.0


@pytest.mark.parametrize(
    "arg,words",
    [
        ("obstacles:=lidar", ["obstacles='lidar' is not one of: objects, octomap, both, sensed"]),
        ("obstacle:=sensed", ["no argument 'obstacle' (did you mean 'obstacles'?)"]),
        ("robot:=ur5", ["no robot config ur5 (available: panda, xarm6)"]),
    ],
)
def test_roslaunch_starts_nothing_for_a_wrong_argument(tmp_path, arg, words):
    port = graph.free_port()
    env = dict(
        os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_HOSTNAME="127.0.0.1", ROS_LOG_DIR=str(tmp_path)
    )
    env["LD_PRELOAD"] = str(graph.loopback_shim())  # should the check let it through: the graph stays on loopback
    with TreeWatch(os.getpid(), period=0.05) as watch:
        t0 = time.perf_counter()
        p = subprocess.Popen(
            ["roslaunch", "-p", str(port), str(launch_file()), arg],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        try:
            out, err = p.communicate(timeout=30)
        finally:
            if p.poll() is None:  # it launched after all: stop what it started (its own session)
                os.killpg(p.pid, signal.SIGINT)
                p.wait(timeout=20)
        seconds = time.perf_counter() - t0
        left = watch.wait_gone(5.0)
    print(f"roslaunch ... {arg}: exit code {p.returncode} after {seconds:.2f} s")
    assert p.returncode != 0 and all(w in err for w in words), err
    assert seconds < LIMIT
    assert not graph.master_alive(f"http://127.0.0.1:{port}")
    assert not left, f"processes left: {left}"
    assert [line for line in watch.cmdlines.values() if "rosmaster" in line or "sim_node" in line] == []


def test_a_graph_runs_with_its_checked_arguments():
    args = dict(world="case", robot="xarm6", obstacles="both", strategy="discard", scene_process="own")
    args["world_file"] = str(world_file(args.pop("world")))
    g = graph.LaunchedGraph(args, wait_for=ros.REQUIRED_SERVICES)
    try:
        code, msg, launched = xmlrpc.client.ServerProxy(g.uri).getParam("/test", "/moverl/launch_args")
        assert code == 1, msg
        assert sorted(launched) == sorted(ARGS)
        assert {k: launched[k] for k in args} == check(args)
        code, msg, robot = xmlrpc.client.ServerProxy(g.uri).getParam("/test", "/robot/name")
        assert robot == "xarm6"
        code, msg, strategy = xmlrpc.client.ServerProxy(g.uri).getParam("/test", "/shield/strategy")
        assert strategy == "discard"
    finally:
        g.close()
    assert not [p for p in g.processes() if p.state != "Z"]
