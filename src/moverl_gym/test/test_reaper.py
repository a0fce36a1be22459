"""The reaper and the loopback shim without ROS: process trees of plain processes, sockets of this process.

A fake "roslaunch" leaves behind what a real graph can: a child that ignores SIGINT, a detached grandchild
(re-parented when its parent exits), and the test stops one child with SIGSTOP. The reaper must leave nothing,
whether its owner closes it or dies by SIGKILL. Live counterparts on the real graph: test_graph_lifecycle.py.
"""

import json
import os
import signal
import socket
import subprocess
import sys
import time
import uuid

import pytest

from moverl_gym import reaper
from moverl_gym.graph import loopback_shim

pytestmark = pytest.mark.core

# The fake roslaunch: three "nodes", then it waits; SIGINT ends it like a roslaunch that crashed (its nodes stay).
FAKE_LAUNCH = r"""
import subprocess, sys, time
subprocess.Popen(["sleep", "600"], start_new_session=True)                       # a node in its own session
subprocess.Popen(["sh", "-c", "trap '' INT; sleep 600"], start_new_session=True)  # one that ignores SIGINT
subprocess.Popen(["sh", "-c", "sleep 600 & exit 0"])                             # one that detaches
time.sleep(600)
"""
GRACE = 1.0


def start_reaper(tmp_path, grace=GRACE):
    graph_id = uuid.uuid4().hex
    spec = dict(
        owner=os.getpid(),
        log=str(tmp_path / "log"),
        grace=grace,
        kill_timeout=5.0,
        master=None,
        extra=[],
        launch=[sys.executable, "-I", "-S", "-c", FAKE_LAUNCH],
    )
    with open(tmp_path / "log", "ab") as log:
        handle = reaper.Handle(spec, dict(os.environ, **{reaper.MARKER: graph_id}), log)
    assert handle.wait_for(("launch",), time.monotonic() + 10)
    return handle, graph_id


@pytest.fixture
def reapers(tmp_path):
    """start_reaper(), and whatever a failed test left running is stopped (by the graph's marker too)."""
    started = []

    def start(**kwargs):
        handle, graph_id = start_reaper(tmp_path, **kwargs)
        started.append((handle, graph_id))
        return handle, graph_id

    yield start
    for handle, graph_id in started:
        handle.stop(time.monotonic() + 15)
        reaper.stop_processes(graph_id, None, None, 0.0, 5.0)


def tree(handle, graph_id, n, timeout=10.0):
    """The reaper's processes once there are n of them (the fake roslaunch starts them in its own time)."""
    deadline = time.monotonic() + timeout
    while True:
        procs = [p for p in reaper.graph_processes(graph_id, handle.proc.pid) if p.state != "Z"]
        if len(procs) >= n or time.monotonic() > deadline:
            return procs
        time.sleep(0.05)


def alive(procs):
    """Those of procs that still run (same pid, same start time, not a zombie)."""
    now = reaper.proc_table()
    return [p for p in procs if p.pid in now and now[p.pid].start == p.start and now[p.pid].state != "Z"]


def test_close_leaves_nothing_stopped_and_sigint_deaf_processes_included(reapers):
    handle, graph_id = reapers()
    procs = tree(handle, graph_id, 5)
    launcher = next(p for p in procs if p.ppid == handle.proc.pid and p.name not in ("sh", "sleep"))
    detached = next(p for p in procs if p.ppid == handle.proc.pid and p.name == "sleep")  # re-parented to the reaper
    own_session = next(p for p in procs if p.ppid == launcher.pid and p.name == "sleep")
    deaf = [p for p in procs if p.name == "sh" or p.ppid not in (handle.proc.pid, launcher.pid)]
    assert len(procs) == 5 and len(deaf) == 2, procs
    os.kill(own_session.pid, signal.SIGSTOP)
    t0 = time.monotonic()
    handle.stop(time.monotonic() + 15)
    took = time.monotonic() - t0
    assert handle.proc.returncode == 0
    assert alive(procs) == [], "every process of the tree is gone"
    assert reaper.graph_processes(graph_id, None) == [], "no process carries the graph's marker"
    assert reaper.read_proc(handle.proc.pid) is None, "the reaper itself is gone (reaped)"
    killed = {int(e[1]) for e in handle.events if e[0] == "killed"}
    # The launcher ends on SIGINT; the stopped sleep, the SIGINT-deaf sh and sleep and the detached sleep (its
    # shell ignored SIGINT for it, as POSIX shells do for background jobs) need SIGKILL.
    assert killed == {own_session.pid, detached.pid} | {p.pid for p in deaf}
    assert GRACE <= took < GRACE + 3, f"SIGINT-deaf processes are killed after the grace period, took {took:.2f} s"


def test_owner_killed_by_sigkill_leaves_nothing(tmp_path):
    owner = subprocess.Popen(
        [
            sys.executable,
            "-c",
            f"""
import json, os, sys, time
sys.path[:0] = {sys.path!r}
import test_reaper
from pathlib import Path
handle, graph_id = test_reaper.start_reaper(Path({str(tmp_path)!r}))
procs = test_reaper.tree(handle, graph_id, 5)
print(json.dumps([handle.proc.pid, graph_id, [list(p) for p in procs]]), flush=True)
time.sleep(600)
""",
        ],
        stdout=subprocess.PIPE,
        text=True,
        cwd=os.path.dirname(__file__),
    )
    try:
        reaper_pid, graph_id, procs = json.loads(owner.stdout.readline())
    finally:
        owner.kill()
        owner.wait()
    procs = [reaper.Proc(*p) for p in procs] + [reaper.read_proc(reaper_pid)]
    assert len(procs) >= 6
    deadline = time.monotonic() + GRACE + 10
    while alive(procs) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert alive(procs) == []
    assert [p for p in reaper.graph_processes(graph_id, None) if p.state != "Z"] == []


def test_marker_finds_a_process_outside_the_tree(reapers):
    """The safety net: a process of the graph that is not the reaper's descendant (here started by the test with
    the graph's marker) is stopped too."""
    # The stray gets SIGINT once the launcher has ended, SIGKILL if the grace period passes first: on a busy machine
    # a python launcher still starting up can take longer than GRACE to end, so this test waits for it to be up and
    # gives it more time.
    handle, graph_id = reapers(grace=3.0)
    tree(handle, graph_id, 5)
    # The stray must not inherit an ignored SIGINT: a test run started in the background by a non-interactive shell
    # (`./run.sh test &`) has SIGINT ignored, and a process started with SIG_IGN keeps it (then only SIGKILL stops it).
    stray = subprocess.Popen(
        ["sleep", "600"],
        env=dict(os.environ, **{reaper.MARKER: graph_id}),
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        assert stray.pid in [p.pid for p in reaper.graph_processes(graph_id, handle.proc.pid)]
        handle.stop(time.monotonic() + 15)
        assert stray.wait(timeout=5) == -signal.SIGINT
    finally:
        stray.kill()
        stray.wait()


def test_reaper_killed_the_owner_kills_by_marker(reapers):
    """If the reaper itself is killed (SIGKILL aimed at it), its children get SIGTERM (PR_SET_PDEATHSIG) and
    whatever is left is found by the marker: stop_processes without a root, as LaunchedGraph.close() does."""
    handle, graph_id = reapers()
    procs = tree(handle, graph_id, 5)
    # The detaching shell exits by itself right after it forked its sleep: wait until it has, or (on a busy machine)
    # it can still be in procs and then end on its own instead of being found by the marker.
    deadline = time.monotonic() + 10
    while (len(alive(procs)) != 5 or len(procs) != 5) and time.monotonic() < deadline:
        time.sleep(0.1)
        procs = alive(tree(handle, graph_id, 5))
    handle.proc.kill()
    handle.proc.wait()
    killed, left = reaper.stop_processes(graph_id, None, None, 0.0, 5.0)
    assert left == []
    deadline = time.monotonic() + 5
    while alive(procs) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert alive(procs) == []
    launcher = next(p for p in procs if p.ppid == handle.proc.pid and p.name not in ("sh", "sleep"))
    assert {p.pid for p in killed} >= {p.pid for p in procs if p.pid != launcher.pid}, "found by the marker"


def test_listening_sockets_of_a_process():
    tcp = socket.socket()
    tcp.bind(("127.0.0.1", 0))
    tcp.listen()
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("0.0.0.0", 0))
    connected = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    connected.connect(("127.0.0.1", 9))  # receives only from its peer: not listed
    tcp6 = socket.socket(socket.AF_INET6)
    tcp6.bind(("::1", 0))
    tcp6.listen()
    try:
        found = {(s.proto, s.address, s.port) for s in reaper.listening_sockets([reaper.read_proc(os.getpid())])}
        assert ("tcp", "127.0.0.1", tcp.getsockname()[1]) in found
        assert ("udp", "0.0.0.0", udp.getsockname()[1]) in found
        assert ("tcp6", "::1", tcp6.getsockname()[1]) in found
        assert all(port != connected.getsockname()[1] for _, _, port in found)
    finally:
        for s in (tcp, udp, connected, tcp6):
            s.close()


BIND_ALL = r"""
import json, socket
out = []
TCP, UDP, V4, V6 = socket.SOCK_STREAM, socket.SOCK_DGRAM, socket.AF_INET, socket.AF_INET6
for family, kind, address in [(V4, TCP, "0.0.0.0"), (V4, UDP, "0.0.0.0"), (V6, TCP, "::"), (V6, UDP, "::"),
                              (V4, TCP, "127.0.0.2"), (V4, TCP, None)]:
    s = socket.socket(family, kind)
    if address is not None:
        s.bind((address, 0))
    if kind == TCP:
        s.listen()  # unbound (address None): the kernel would bind the wildcard address
    out.append(s.getsockname()[0])
print(json.dumps(out))
"""


@pytest.mark.parametrize("preload", [False, True])
def test_loopback_shim(preload):
    env = dict(os.environ)
    if preload:
        env["LD_PRELOAD"] = str(loopback_shim())
    out = subprocess.run([sys.executable, "-c", BIND_ALL], env=env, capture_output=True, text=True, check=True)
    bound = json.loads(out.stdout)
    if preload:
        assert bound == ["127.0.0.1", "127.0.0.1", "::1", "::1", "127.0.0.2", "127.0.0.1"]
    else:
        assert bound == ["0.0.0.0", "0.0.0.0", "::", "::", "127.0.0.2", "0.0.0.0"]
