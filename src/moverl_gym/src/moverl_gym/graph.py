"""Bring up (or find) the ROS graph an env talks to.

One ROS master per env: an env either attaches to a graph someone started with roslaunch (its
ROS_MASTER_URI), or starts launch/moverl.launch itself on a free port. rospy allows one node, hence one
master, per process: run parallel envs in separate processes (e.g. SB3's SubprocVecEnv).

A graph the env launches lives under a reaper process (moverl_gym/reaper.py says why): close() returns only
once every process of the graph is gone, stopped and hung ones included, and the graph also goes down when the
process that launched it dies in any way (SIGKILL included). It listens on loopback only: ROS_HOSTNAME=127.0.0.1
and the moverl_loopback shim preloaded into every process of the graph, because roscpp binds its XML-RPC
server to 0.0.0.0 whatever ROS_IP or ROS_HOSTNAME say. The one sanctioned exception is a graph that a robot
driver on another host must reach: expose=<this host's name or address> (or MOVERL_GRAPH_EXPOSE), see
docs/architecture.md.
"""

from __future__ import annotations

import atexit
import os
import re
import shutil
import socket
import tempfile
import time
import uuid
import xmlrpc.client
from collections.abc import Mapping
from pathlib import Path

from . import reaper
from .launch_args import CheckedLaunch, checked
from .paths import launch_file, repo_root

#: Environment variable: the host name or address under which other hosts reach this machine. When set, graphs
#: the env launches listen on every interface (the sanctioned exception for a robot driver on another host).
EXPOSE_ENV = "MOVERL_GRAPH_EXPOSE"
#: Environment variable: seconds a graph gets to shut down cleanly on close() before SIGKILL (default GRACE).
GRACE_ENV = "MOVERL_GRAPH_GRACE"
#: Default grace period (s). A clean shutdown of the whole graph takes 1-2 s (tools/graph_lifecycle.py).
GRACE = 5.0
#: Seconds after the SIGKILLs for the processes to be gone before close() gives up and raises.
KILL_TIMEOUT = 5.0
SHIM = "libmoverl_loopback.so"
#: Seconds a graph waits for its fixed master port (a process's later graphs reuse its first one's: rospy binds the
#: process to one master) while another process listens on it: one that is exiting lets go within this.
TAKEN_PORT_WAIT = 3.0


class GraphError(RuntimeError):
    """The ROS graph could not be started or reached."""


#: roslaunch's line when a node declared required="true" (the simulator) exits: it then stops the whole graph
REQUIRED_DIED = re.compile(r"REQUIRED process \[([^\]]+)\] has died")


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def master_alive(uri: str, timeout: float = 1.0) -> bool:
    """True when a ROS master answers at uri."""
    socket.setdefaulttimeout(timeout)
    try:
        code, _, _ = xmlrpc.client.ServerProxy(uri).getPid("/moverl_probe")
        return code == 1
    except (OSError, xmlrpc.client.Error):
        return False
    finally:
        socket.setdefaulttimeout(None)


def service_exists(uri: str, service: str) -> bool:
    try:
        code, _, _ = xmlrpc.client.ServerProxy(uri).lookupService("/moverl_probe", service)
        return code == 1
    except (OSError, xmlrpc.client.Error):
        return False


class LaunchedGraph:
    """launch/moverl.launch on its own master port, under its own reaper process.

    The reaper (moverl_gym/reaper.py) starts the master, checks that it is its own, then rosout and roslaunch,
    and stops them all when close() is called or this process dies. A port taken between being picked and being
    bound is retried on another free port, `attempts` times; a given `port` is not (a process whose rospy node is
    bound to a master port must reuse it, see env.py).

    Args:
        launch_args: roslaunch arguments (world, robot, shield, gui, ...): a mapping, checked here (once, before
            anything starts), or a CheckedLaunch, taken as it is (the env's, checked where it entered).
        port: master port; a free one by default.
        wait_for: services that must exist before the graph counts as up.
        timeout: seconds to wait for them (start-up as a whole).
        expose: None (default: $MOVERL_GRAPH_EXPOSE, else loopback only), or the host name or address other
            hosts reach this machine by: then the graph binds every interface and advertises that name.
        grace: seconds for a clean shutdown on close() before SIGKILL (default: $MOVERL_GRAPH_GRACE, else GRACE).
        attempts: master ports to try when a picked port turns out taken.

    Raises:
        LaunchArgError: a launch argument moverl.launch does not take, or a value it does not accept (a ValueError,
            raised before anything starts; moverl_gym.launch_args).
        GraphError: the graph could not be started (with the tail of its log), or close() left processes.
    """

    def __init__(
        self,
        launch_args: Mapping[str, object] | CheckedLaunch,
        port: int | None = None,
        wait_for=(),
        timeout: float = 60.0,
        expose: str | None = None,
        grace: float | None = None,
        attempts: int = 5,
    ):
        launch_args = dict(checked(launch_args, whole=True).values)
        for tool in ("roslaunch", "rosmaster"):
            if shutil.which(tool) is None:
                raise GraphError(f"{tool} is not on PATH: source devel/setup.bash (see README) first")
        self.expose = expose if expose is not None else (os.environ.get(EXPOSE_ENV) or None)
        self.grace = float(grace if grace is not None else os.environ.get(GRACE_ENV, GRACE))
        self.graph_id = uuid.uuid4().hex
        self.log_dir = Path(tempfile.mkdtemp(prefix="moverl_graph_"))
        self.last_close: dict | None = None  # what the last close() did (time, processes SIGKILLed)
        self._log = open(self.log_dir / "roslaunch.log", "ab")
        self._reaper: reaper.Handle | None = None
        self._closed = False
        self._owner = os.getpid()
        atexit.register(self.close)
        try:
            self._start(launch_args, port, wait_for, timeout, attempts)
        except BaseException:
            self.close()
            raise

    def _environment(self, host: str) -> dict:
        env = dict(os.environ)
        env.update(
            ROS_MASTER_URI=self.uri,
            ROS_HOSTNAME=host,
            ROS_LOG_DIR=str(self.log_dir),
            ROS_HOME=env.get("ROS_HOME", str(Path.home() / ".ros")),
            MOVERL_ROOT=str(repo_root()),
        )
        env.pop("ROS_IP", None)  # ROS_HOSTNAME wins anyway; one name, no surprises
        env[reaper.MARKER] = self.graph_id
        if not self.expose:
            env["LD_PRELOAD"] = " ".join(filter(None, [str(loopback_shim()), env.get("LD_PRELOAD", "")]))
            # 127.0.0.1 is IPv4: with ROS_IPV6=on roscpp would bind [::], which the shim makes [::1], where
            # connections to 127.0.0.1 do not arrive.
            env.pop("ROS_IPV6", None)
        return env

    def _start(self, launch_args: dict, port: int | None, wait_for, timeout: float, attempts: int) -> None:
        start = time.monotonic()
        deadline = start + timeout
        host = self.expose or "127.0.0.1"
        taken = []  # (port, the processes that listened on it)
        while True:
            self.port = port or free_port()
            self.uri = f"http://{host}:{self.port}"
            spec = dict(
                owner=os.getpid(),
                log=str(self.log_dir / "roslaunch.log"),
                grace=self.grace,
                kill_timeout=KILL_TIMEOUT,
                master=dict(
                    uri=self.uri,
                    timeout=max(1.0, min(15.0, deadline - time.monotonic())),
                    cmd=[
                        "rosmaster",
                        "--core",
                        "-p",
                        str(self.port),
                        "-w",
                        "3",
                        f"__log:={self.log_dir / 'master.log'}",
                    ],
                ),
                extra=[[_rosout(), "__name:=rosout", f"__log:={self.log_dir / 'rosout.log'}"]],
                # roslaunch's own escalation (SIGINT, SIGTERM, SIGKILL to its nodes), bounded by the grace period:
                # it is what stops the nodes if the reaper itself is SIGKILLed (then roslaunch gets SIGTERM).
                launch=[
                    "roslaunch",
                    "-p",
                    str(self.port),
                    f"--sigint-timeout={self.grace}",
                    "--sigterm-timeout=1",
                    str(launch_file()),
                ]
                + [f"{k}:={v}" for k, v in launch_args.items()],
            )
            self._reaper = reaper.Handle(spec, self._environment(host), self._log)
            event = self._reaper.wait_for(("master", "taken", "master-exit", "error"), deadline)
            if event and event[0] == "master":
                break
            ended = self._reaper.ended
            self._stop_reaper()
            if not (event and event[0] == "taken"):
                why = " ".join(event) if event else "the graph's reaper exited" if ended else "timeout"
                raise GraphError(f"the ROS master did not start on port {self.port} ({why}):\n{self.log_tail()}")
            taken.append((self.port, " ".join(event[2:]) or "a process this one cannot see"))
            if port is None:
                if len(taken) >= attempts:
                    raise GraphError(
                        "master ports %s were all taken by other processes before the master bound them (by %s)"
                        % ([p for p, _ in taken], "; ".join(who for _, who in taken))
                    )
            elif time.monotonic() + 0.5 > min(deadline, start + TAKEN_PORT_WAIT):
                raise GraphError(
                    f"master port {port} is taken by another process ({taken[-1][1]}); this process's rospy node is "
                    "bound to that port (one master per process): start the env in a fresh process"
                )
            else:
                time.sleep(0.5)  # a process that is exiting lets go of it
        self._wait(wait_for, deadline, timeout)

    def _wait(self, services, deadline: float, timeout: float) -> None:
        pending = list(services)
        while True:
            for event in self._reaper.poll(0.1):  # start-up only, never on the step path
                if event[0] in ("exit", "error"):
                    raise GraphError(
                        f"roslaunch {'exited with code' if event[0] == 'exit' else 'failed:'} "
                        f"{' '.join(event[1:])}:\n{self.log_tail()}"
                    )
            if self._reaper.ended:
                raise GraphError(f"the graph's reaper exited (code {self._reaper.proc.poll()}):\n{self.log_tail()}")
            pending = [s for s in pending if not service_exists(self.uri, s)]
            if not pending and master_alive(self.uri):
                return
            if time.monotonic() > deadline:
                raise GraphError(f"services {pending} did not come up within {timeout:.0f} s:\n{self.log_tail()}")

    def log_tail(self, lines: int = 40) -> str:
        if not self._log.closed:
            self._log.flush()
        text = (self.log_dir / "roslaunch.log").read_text(errors="replace").splitlines()
        return "\n".join(text[-lines:])

    def alive(self) -> bool:
        """True while roslaunch runs (and nobody closed the graph)."""
        if self._reaper is None or self._closed:
            return False
        self._reaper.poll(0)
        return not self._reaper.ended and not any(e[0] in ("exit", "error") for e in self._reaper.events)

    def down(self, wait: float) -> str:
        """Why the graph is going down, or "" if it still runs after wait s: roslaunch logs a required node's death
        (the simulator) at once and then stops the rest, which takes seconds. A component that failed mid-call (a
        connection closed while its answer was awaited) may be the first sign of it."""
        deadline = time.monotonic() + wait
        while True:
            died = REQUIRED_DIED.findall(self.log_tail(200))
            if died:
                return f"roslaunch: required node {died[-1]} died"  # roslaunch's process name: <node>-<n>
            if not self.alive():
                return "roslaunch exited"
            if time.monotonic() >= deadline:
                return ""
            time.sleep(0.05)

    def processes(self) -> list[reaper.Proc]:
        """Every process of the graph: the reaper, its descendants, and any process carrying the graph's marker."""
        table = reaper.proc_table()
        root = self._reaper.proc.pid if self._reaper is not None else None
        own = [table[root]] if root in table else []
        return own + reaper.graph_processes(self.graph_id, root, table)

    def sockets(self) -> list[reaper.Socket]:
        """The graph's listening TCP and bound UDP sockets."""
        return reaper.listening_sockets(self.processes())

    def close(self) -> None:
        """Stop the graph; return when every process of it is gone (or raise GraphError naming those left)."""
        if self._closed:
            return
        self._closed = True
        atexit.unregister(self.close)
        if os.getpid() != self._owner:
            return  # a forked copy of the owner (its atexit handlers included): the graph is the owner's to stop
        t0 = time.monotonic()
        killed, left = self._stop_reaper()
        self.last_close = dict(seconds=time.monotonic() - t0, sigkilled=killed)
        self._log.close()
        if left:
            raise GraphError(
                f"processes of the graph survived SIGKILL for {KILL_TIMEOUT:.0f} s: {left} "
                f"(uninterruptible sleep?); log: {self.log_dir}"
            )

    def _stop_reaper(self) -> tuple[list[str], list[str]]:
        """Stop the current reaper and its graph; (processes SIGKILLed, processes left) as "name pid"."""
        if self._reaper is None:
            return [], []
        r, self._reaper = self._reaper, None
        r.stop(time.monotonic() + self.grace + KILL_TIMEOUT + 5.0)
        killed = [f"{e[2]} {e[1]}" for e in r.events if e[0] == "killed"]
        # The reaper is gone; anything still marked with the graph's id escaped it (it was killed, or hung): kill
        # it from here. Normally there is nothing, and this is the check that there is nothing.
        extra, left = reaper.stop_processes(self.graph_id, None, None, 0.0, KILL_TIMEOUT)
        killed += [f"{p.name} {p.pid}" for p in extra]
        return killed, [f"{p.name} {p.pid}" for p in left]


def loopback_shim() -> Path:
    """The moverl_loopback LD_PRELOAD library of the catkin workspace (CMAKE_PREFIX_PATH)."""
    prefixes = [p for p in os.environ.get("CMAKE_PREFIX_PATH", "").split(os.pathsep) if p]
    for prefix in prefixes:
        lib = Path(prefix) / "lib" / SHIM
        if lib.is_file():
            return lib
    raise GraphError(
        f"{SHIM} (package moverl_loopback) is not in the workspace {prefixes}: build it "
        "(./catkin_ws_setup.sh) and source devel/setup.bash. Without it roscpp nodes would listen on "
        f"every interface; to run a graph reachable from other hosts on purpose set {EXPOSE_ENV}"
    )


def _rosout() -> str:
    import roslib.packages

    found = roslib.packages.find_node("rosout", "rosout")
    if not found:
        raise GraphError("the rosout node is not installed (apt package ros-base-dev / rosout)")
    return found[0]
