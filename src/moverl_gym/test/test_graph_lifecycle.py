"""Nothing outlives close(), and a launched graph listens on loopback only (issue #10), on the real graph.

Every test counts the processes of the graph's own tree (LaunchedGraph.processes(): the reaper, its descendants
and whatever carries the graph's marker variable) before and after, never processes by name across the machine;
components are found by their ROS node name (the master's lookupNode, then the node's getPid).
Core counterparts on plain processes: test_reaper.py.
"""

import json
import os
import signal
import socket
import subprocess
import sys
import time
import xmlrpc.client

import gymnasium as gym
import numpy as np
import pytest

import moverl_gym  # noqa: F401
from moverl_gym import graph, reaper
from moverl_gym import ros_backend as ros
from moverl_gym.paths import world_file

pytestmark = pytest.mark.live

#: A clean close() takes ~1-2 s (tools/graph_lifecycle.py). A stopped node is SIGKILLed at once, not after the
#: grace period (graph.GRACE, 5 s): closing with one must take less than that.
CLOSE_LIMIT = graph.GRACE
NODES = ("/sim", "/shield")  # the default graph: the shield hosts the planning scene


def node_pid(uri: str, node: str) -> int:
    """The pid of a ROS node, asked from the node itself (before it is stopped: a stopped node cannot answer)."""
    code, msg, node_uri = xmlrpc.client.ServerProxy(uri).lookupNode("/lifecycle_test", node)
    assert code == 1, msg
    code, msg, pid = xmlrpc.client.ServerProxy(node_uri).getPid("/lifecycle_test")
    assert code == 1, msg
    return pid


def alive(procs):
    """Those of procs still running: same pid and start time, not a zombie."""
    now = reaper.proc_table()
    return [p for p in procs if p.pid in now and now[p.pid].start == p.start and now[p.pid].state != "Z"]


def test_taken_port_is_retried_sockets_are_loopback_and_close_leaves_nothing(monkeypatch):
    """One graph for several checks (each graph costs ~7 s of CI): a taken port, a forked copy of the owner,
    the listening sockets, a clean close()."""
    held = socket.socket()  # a port "picked free", then taken by someone else before our master binds it
    held.bind(("127.0.0.1", 0))
    held.listen()
    taken = held.getsockname()[1]
    try:
        t0 = time.monotonic()
        # A fixed port (a process's later graphs reuse its first one's): tried again for a while, then refused,
        # naming who listens there (this process).
        with pytest.raises(
            graph.GraphError, match=rf"master port {taken} is taken by another process \({os.getpid()}/"
        ):
            graph.LaunchedGraph({"world_file": str(world_file("table"))}, port=taken)
        assert graph.TAKEN_PORT_WAIT - 0.6 <= time.monotonic() - t0 < graph.TAKEN_PORT_WAIT + 15.0
        picks, free_port = iter([taken]), graph.free_port
        monkeypatch.setattr(graph, "free_port", lambda: next(picks, None) or free_port())
        g = graph.LaunchedGraph({"world_file": str(world_file("table"))}, wait_for=ros.REQUIRED_SERVICES)
    finally:
        held.close()
    try:
        assert g.port != taken
        child = os.fork()
        if child == 0:  # a forked copy of the owner closing its copy (its atexit handlers would) stops nothing
            try:
                g.close()
            finally:
                os._exit(0)
        os.waitpid(child, 0)
        assert g.alive() and graph.master_alive(g.uri)
        procs = g.processes()
        pids = {p.pid for p in procs}
        master = xmlrpc.client.ServerProxy(g.uri).getPid("/lifecycle_test")[2]
        components = {name: node_pid(g.uri, name) for name in NODES + ("/rosout",)} | {"master": master}
        assert set(components.values()) <= pids, (components, procs)
        sockets = g.sockets()
        listening = {s.pid for s in sockets}
        assert set(components.values()) <= listening, f"every component's sockets are listed: {sockets}"
        assert {s.proto for s in sockets} >= {"tcp", "udp"}, sockets  # roscpp's UDPROS sockets are listed too
        open_to_all = [s for s in sockets if not reaper.is_loopback(s.address)]
        assert open_to_all == [], f"listening beyond loopback: {open_to_all}"
    finally:
        g.close()
    assert g.last_close["seconds"] < CLOSE_LIMIT and g.last_close["sigkilled"] == [], g.last_close
    assert alive(procs) == [], "close() left processes of the graph"
    assert reaper.graph_processes(g.graph_id, None) == [], "a process still carries the graph's marker"


@pytest.mark.parametrize("node", NODES)
def test_close_with_a_stopped_node_leaves_nothing(node):
    env = gym.make("MoveRL/PandaReachTable-v0", graph="launch")
    g = env.unwrapped._graph
    try:
        env.reset(seed=0)
        env.step(np.zeros(7, dtype=np.float32))
        pid = node_pid(g.uri, node)
        procs = g.processes()
        assert pid in {p.pid for p in procs} and len(procs) >= 6, procs  # reaper, master, rosout, roslaunch, 2 nodes
        os.kill(pid, signal.SIGSTOP)
        deadline = time.monotonic() + 2.0  # the signal is delivered asynchronously
        while reaper.read_proc(pid).state != "T" and time.monotonic() < deadline:
            time.sleep(0.01)
        assert reaper.read_proc(pid).state == "T"
    finally:
        t0 = time.monotonic()
        env.close()
        took = time.monotonic() - t0
    assert alive(procs) == [], f"close() left processes of the graph (node {node} stopped)"
    assert reaper.graph_processes(g.graph_id, None) == []
    assert any(k.endswith(f" {pid}") for k in g.last_close["sigkilled"]), g.last_close
    assert took < CLOSE_LIMIT, f"close() with {node} stopped took {took:.2f} s"


OWNER = """
import json, sys, time
import gymnasium as gym
import moverl_gym
env = gym.make("MoveRL/PandaReachTable-v0", graph="launch")
env.reset(seed=0)
g = env.unwrapped._graph
print(json.dumps([g.graph_id, [list(p) for p in g.processes()]]), flush=True)
time.sleep(600)
"""


@pytest.mark.parametrize("victims", ["owner", "reaper and owner"])
def test_owner_killed_by_sigkill_leaves_nothing(victims):
    """The env's process dies by SIGKILL: its reaper stops the graph. "reaper and owner": both are SIGKILLed (Ray
    kills a dead worker's direct children, and the reaper is one): roslaunch, the master and rosout get SIGTERM
    (PR_SET_PDEATHSIG) and roslaunch stops its nodes within its escalation, bounded by the grace period."""
    owner = subprocess.Popen([sys.executable, "-c", OWNER], stdout=subprocess.PIPE, text=True)
    try:
        line = owner.stdout.readline()
        assert line, "the owner process did not bring its env up (see its stderr above)"
        graph_id, procs = json.loads(line)
        procs = [reaper.Proc(*p) for p in procs]
        # reaper, roslaunch, master, rosout, sim, shield (the scene lives in the shield's process): the reaper first, a
        # child of the owner
        assert len(procs) >= 6 and procs[0].ppid == owner.pid, procs
        if victims == "reaper and owner":
            os.kill(procs[0].pid, signal.SIGKILL)
    finally:
        t0 = time.monotonic()
        owner.kill()
        owner.wait()
    limit = CLOSE_LIMIT if victims == "owner" else graph.GRACE + 1 + CLOSE_LIMIT
    while alive(procs) and time.monotonic() < t0 + limit + graph.KILL_TIMEOUT:
        time.sleep(0.05)
    took = time.monotonic() - t0
    assert alive(procs) == [], f"processes of the graph outlived its owner: {alive(procs)}"
    assert [p for p in reaper.graph_processes(graph_id, None) if p.state != "Z"] == []
    assert took < limit, f"the graph took {took:.2f} s to go down after its owner died"
