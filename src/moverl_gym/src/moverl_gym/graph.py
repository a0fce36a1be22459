"""Bring up (or find) the ROS graph an env talks to.

One ROS master per env: an env either attaches to a graph someone started with roslaunch (its
ROS_MASTER_URI), or starts launch/moverl.launch itself on a free port. rospy allows one node, hence one
master, per process: run parallel envs in separate processes (e.g. SB3's SubprocVecEnv).
"""

from __future__ import annotations

import atexit
import ctypes
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
import xmlrpc.client
from pathlib import Path

from .paths import launch_file, repo_root


class GraphError(RuntimeError):
    """The ROS graph could not be started or reached."""


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
    """A roslaunch of launch/moverl.launch on its own master port, in its own process group.

    Args:
        launch_args: roslaunch arguments (world, robot, shield, gui, ...).
        port: master port; a free one by default.
        wait_for: services that must exist before the graph counts as up.
        timeout: seconds to wait for them.
    """

    def __init__(self, launch_args: dict, port: int | None = None, wait_for=(), timeout: float = 60.0):
        if shutil.which("roslaunch") is None:
            raise GraphError("roslaunch is not on PATH: source devel/setup.bash (see README) first")
        self.port = port or free_port()
        self.uri = f"http://127.0.0.1:{self.port}"
        self.log_dir = Path(tempfile.mkdtemp(prefix="moverl_graph_"))
        env = dict(os.environ)
        env.update(ROS_MASTER_URI=self.uri, ROS_HOSTNAME="127.0.0.1", ROS_LOG_DIR=str(self.log_dir),
                   ROS_HOME=env.get("ROS_HOME", str(Path.home() / ".ros")), MOVERL_ROOT=str(repo_root()))
        cmd = ["roslaunch", "-p", str(self.port), str(launch_file())]
        cmd += [f"{k}:={_launch_value(v)}" for k, v in launch_args.items()]
        self._log = open(self.log_dir / "roslaunch.log", "wb")
        self.proc = subprocess.Popen(cmd, env=env, stdout=self._log, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, preexec_fn=_own_session_dies_with_parent)
        atexit.register(self.close)
        try:
            self._wait(wait_for, timeout)
        except BaseException:
            self.close()
            raise

    def _wait(self, services, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        pending = list(services)
        while True:
            if self.proc.poll() is not None:
                raise GraphError(f"roslaunch exited with code {self.proc.returncode}:\n{self.log_tail()}")
            pending = [s for s in pending if not service_exists(self.uri, s)]
            if not pending and master_alive(self.uri):
                return
            if time.monotonic() > deadline:
                raise GraphError(f"services {pending} did not come up within {timeout:.0f} s:\n{self.log_tail()}")
            time.sleep(0.1)  # start-up only, never on the step path

    def log_tail(self, lines: int = 40) -> str:
        self._log.flush()
        text = (self.log_dir / "roslaunch.log").read_text(errors="replace").splitlines()
        return "\n".join(text[-lines:])

    def alive(self) -> bool:
        return self.proc.poll() is None

    def close(self) -> None:
        if self._log.closed:
            return
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGINT)
                self.proc.wait(timeout=10)
            except (subprocess.TimeoutExpired, ProcessLookupError):
                try:
                    os.killpg(self.proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                self.proc.wait(timeout=5)
        self._log.close()


def _own_session_dies_with_parent() -> None:
    """In the roslaunch child: its own process group (closed as a whole), and SIGTERM when the process that
    launched it dies, even by SIGKILL, so that no graph outlives its env."""
    os.setsid()
    pr_set_pdeathsig = 1
    ctypes.CDLL("libc.so.6", use_errno=True).prctl(pr_set_pdeathsig, signal.SIGTERM)


def _launch_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    return str(v)
