"""The reaper: a small supervisor process that owns one ROS graph, and the /proc reading it needs.

Why a process between the env and roslaunch (moverl_gym.graph starts one per graph):

* roslaunch starts every node in a session of its own, so signalling roslaunch's process group misses them, and
  once roslaunch is gone (killed, crashed) its nodes are re-parented to init where nobody tracks them. The reaper
  sets PR_SET_CHILD_SUBREAPER: every process started below it, however it forks or detaches, stays its
  descendant, so "the graph's processes" is simply its tree (walked through the ppid links of /proc/*/stat).
  As a safety net every process of the graph also carries MOVERL_GRAPH=<id> in its environment
  (/proc/<pid>/environ), which finds a process that left the tree anyway (e.g. after the reaper itself was
  killed: the owner's close() then kills by that marker).
* It outlives the owner on purpose: its stdin is a pipe from the owner (the lifeline). Anything on it (close()
  writes "stop") or end of file (the owner died in any way, SIGKILL included: the kernel closes a dead process's
  pipes) means "shut the graph down". It also watches its parent pid (a child the owner forked may hold the pipe
  open after the owner died). It runs in a session of its own, so a signal to the owner's process group (Ctrl-C
  in a terminal, a job killer) does not take it down before the graph is gone. Its own children (roslaunch, the
  master, rosout) get SIGTERM from the kernel should it be SIGKILLed itself (PR_SET_PDEATHSIG), and roslaunch
  then stops its nodes.
* Shutting down cannot depend on the graph's cooperation: a node stopped with SIGSTOP never handles SIGINT, and
  roslaunch's own escalation (SIGINT, 15 s, SIGTERM, 2 s, SIGKILL: roslaunch/nodeprocess.py's defaults) is
  slower than a training job's patience. So: SIGINT to roslaunch (the nodes shut down cleanly, in parallel),
  SIGINT to whatever of the tree is left once roslaunch is gone (the master, rosout), SIGKILL at once to every
  stopped process (it cannot take part), and SIGKILL to everything after `grace` seconds; then wait, with a
  deadline, until the tree is empty.
* The master is started here before roslaunch, and the reaper checks that the master answering on the port is
  its own child: if roslaunch found someone else's master on the port (a free port can be taken before it is
  used) it would launch our nodes into that graph, and rosmaster whose port is taken hangs instead of exiting.
  A taken port is reported ("taken", with the processes listening there) and the owner retries on another one
  (or, on the fixed port a process's later graphs reuse, on the same one for a few seconds). roslaunch starts
  rosout only with a master of its own, so rosout is started here too.

Run by moverl_gym.graph as `python3 -I -S reaper.py '<json spec>'` with the graph's environment: standard
library only, so it starts quickly and shares nothing with the env. Status lines on stdout, one event each:
`master <pid>`, `taken <port> [<pid>/<name> ...]`, `master-exit <code>`, `launch <pid>`, `exit <code>` (roslaunch
ended by itself), `error <message>` (a command could not be started), `down <seconds> <n sigkilled> <n left>` and
`killed <pid> <name>` / `left <pid> <name>` lines before it.
The functions below (process table, graph processes, listening sockets, stop_processes) are also used by the
owner and the tests.
"""

from __future__ import annotations

import ctypes
import json
import os
import select
import signal
import socket
import subprocess
import sys
import time
import xmlrpc.client
from typing import Iterable, NamedTuple

#: Environment variable that marks every process of one graph: MOVERL_GRAPH=<graph id>.
MARKER = "MOVERL_GRAPH"

_PR_SET_PDEATHSIG = 1
_PR_SET_CHILD_SUBREAPER = 36
_POLL = 0.05  # s between looks at the process table while stopping (each look reads every /proc/<pid>/stat)


class Proc(NamedTuple):
    """One process: (pid, start) names it even after its pid is reused."""

    pid: int
    ppid: int
    state: str  # R, S, D, T (stopped), t (traced), Z (zombie), ...
    start: int  # start time, clock ticks after boot
    name: str


def proc_table() -> dict[int, Proc]:
    """Every process of the machine (that /proc shows us), by pid."""
    table = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        p = read_proc(int(entry))
        if p is not None:
            table[p.pid] = p
    return table


def read_proc(pid: int) -> Proc | None:
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            data = f.read()
    except OSError:
        return None
    left, right = data.index(b"("), data.rindex(b")")  # the name may hold spaces and parentheses
    fields = data[right + 2 :].split()
    name = data[left + 1 : right].decode(errors="replace")
    return Proc(pid, int(fields[1]), fields[0].decode(), int(fields[19]), name)


def descendants(root: int, table: dict[int, Proc]) -> list[Proc]:
    """The processes below root (children, their children, ...)."""
    children: dict[int, list[Proc]] = {}
    for p in table.values():
        children.setdefault(p.ppid, []).append(p)
    out, stack = [], [root]
    while stack:
        for c in children.get(stack.pop(), ()):
            out.append(c)
            stack.append(c.pid)
    return out


def marked(graph_id: str, table: dict[int, Proc]) -> list[Proc]:
    """The processes whose environment carries MOVERL_GRAPH=<graph_id> (the environment they were exec'd with)."""
    needle = f"{MARKER}={graph_id}".encode()
    out = []
    for p in table.values():
        try:
            with open(f"/proc/{p.pid}/environ", "rb") as f:
                if needle in f.read().split(b"\0"):
                    out.append(p)
        except OSError:  # gone, or not ours to read
            continue
    return out


def graph_processes(graph_id: str, root: int | None, table: dict[int, Proc] | None = None) -> list[Proc]:
    """The graph's processes: root's descendants and every process marked with graph_id (root excluded)."""
    table = proc_table() if table is None else table
    found = {p.pid: p for p in marked(graph_id, table)}
    if root is not None:
        found.update((p.pid, p) for p in descendants(root, table))
    found.pop(root, None)
    found.pop(os.getpid(), None)
    return sorted(found.values())


def send(p: Proc, sig: int) -> bool:
    """Signal exactly the process p, never a process that took its pid since (a pidfd pins it). False when gone."""
    try:
        fd = os.pidfd_open(p.pid)
    except ProcessLookupError:
        return False
    try:
        now = read_proc(p.pid)
        if now is None or now.start != p.start:
            return False  # p has exited and its pid was reused before we pinned it
        signal.pidfd_send_signal(fd, sig)
        return True
    except ProcessLookupError:
        return False
    finally:
        os.close(fd)


def reap(statuses: dict[int, int]) -> None:
    """Collect every exited child (ours, or an orphan of the graph re-parented to us); record exit codes."""
    while True:
        try:
            pid, status = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return
        statuses[pid] = os.waitstatus_to_exitcode(status)


def stop_processes(
    graph_id: str,
    root: int | None,
    first: int | None,
    grace: float,
    kill_timeout: float,
    statuses: dict[int, int] | None = None,
) -> tuple[list[Proc], list[Proc]]:
    """Stop the graph: SIGINT to `first` (roslaunch), SIGINT to the rest once `first` is gone, SIGKILL at once to
    stopped processes and to everything after `grace` s; return when none is left or `grace + kill_timeout` s
    have passed.

    Args:
        graph_id: the MARKER value of the graph.
        root: the process whose descendants are the graph (the reaper itself), or None (marker only).
        first: pid of the process to interrupt first, if any (it stops the others cleanly).
        grace: seconds for a clean shutdown before SIGKILL.
        kill_timeout: seconds after the SIGKILLs for the processes to be gone (a process in uninterruptible
            sleep dies only when its system call returns).
        statuses: when given, exited children are reaped into it (the caller is the processes' reaper).

    Returns:
        (the processes that got SIGKILL, the processes still running at the deadline).
    """
    t0 = time.monotonic()
    interrupted: set[tuple[int, int]] = set()
    killed: dict[tuple[int, int], Proc] = {}
    while True:
        if statuses is not None:
            reap(statuses)
        # A zombie has exited: the reaper collects those that become its children (reap() above, and once more
        # by the caller); others wait for their parent, which is not ours to make wait.
        live = [p for p in graph_processes(graph_id, root) if p.state not in "ZX"]
        elapsed = time.monotonic() - t0
        if not live or elapsed > grace + kill_timeout:
            return list(killed.values()), live
        first_alive = any(p.pid == first for p in live)
        for p in live:
            key = (p.pid, p.start)
            if elapsed >= grace or p.state in "Tt":
                if send(p, signal.SIGKILL):  # works on stopped and traced processes too
                    killed.setdefault(key, p)
            elif key not in interrupted and (p.pid == first or not first_alive):
                if send(p, signal.SIGINT):
                    interrupted.add(key)
        time.sleep(_POLL)


# -- sockets -----------------------------------------------------------------------------------------------------


class Socket(NamedTuple):
    """A listening TCP socket or an unconnected (hence receiving from anyone) bound UDP socket."""

    proto: str  # tcp, tcp6, udp, udp6
    address: str
    port: int
    pid: int
    name: str


def socket_inodes(pid: int) -> set[int]:
    """Inodes of the sockets process pid has open."""
    out = set()
    try:
        fds = os.listdir(f"/proc/{pid}/fd")
    except OSError:
        return out
    for fd in fds:
        try:
            link = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:
            continue
        if link.startswith("socket:["):
            out.add(int(link[8:-1]))
    return out


def _address(hex_addr: str) -> str:
    raw = bytes.fromhex(hex_addr)
    # /proc/net prints each 32-bit word of the address in host (little-endian) order.
    raw = b"".join(raw[i : i + 4][::-1] for i in range(0, len(raw), 4))
    return socket.inet_ntop(socket.AF_INET if len(raw) == 4 else socket.AF_INET6, raw)


def open_sockets() -> list[tuple[str, str, int, int]]:
    """(proto, address, port, inode) of every listening TCP and unconnected bound UDP socket of this network
    namespace (/proc/net/{tcp,tcp6,udp,udp6})."""
    out = []
    for proto, wanted in (("tcp", "0A"), ("tcp6", "0A"), ("udp", "07"), ("udp6", "07")):  # LISTEN / unconnected
        try:
            with open(f"/proc/net/{proto}") as f:
                lines = f.read().splitlines()[1:]
        except OSError:  # no IPv6 in this kernel
            continue
        for line in lines:
            fields = line.split()
            local, state, inode = fields[1], fields[3], int(fields[9])
            if state == wanted and inode:
                addr, port = local.split(":")
                out.append((proto, _address(addr), int(port, 16), inode))
    return out


def listening_sockets(procs: Iterable[Proc]) -> list[Socket]:
    """The listening TCP and bound UDP sockets the given processes hold."""
    owner = {}
    for p in procs:
        for inode in socket_inodes(p.pid):
            owner[inode] = p
    return sorted(
        Socket(proto, addr, port, owner[inode].pid, owner[inode].name)
        for proto, addr, port, inode in open_sockets()
        if inode in owner
    )


def is_loopback(address: str) -> bool:
    return address.startswith("127.") or address in ("::1", "::ffff:127.0.0.1")


class Handle:
    """The owner's end of a reaper process: its lifeline (stdin) and its status events (stdout).

    Args:
        spec: what to run (see _Supervisor).
        env: the graph's environment, MARKER included; the reaper and all it starts inherit it.
        log: file the reaper's and the graph's output go to.
    """

    def __init__(self, spec: dict, env: dict, log):
        python = sys.executable or "/usr/bin/python3"
        self.proc = subprocess.Popen(
            [python, "-I", "-S", os.path.abspath(__file__), json.dumps(spec)],
            env=env,
            bufsize=0,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=log,
            start_new_session=True,
        )
        self.events: list[list[str]] = []
        self.ended = False  # its stdout closed: it has exited (or is about to)
        self._buf = b""

    def poll(self, timeout: float) -> list[list[str]]:
        """New status events, waiting up to timeout for the first."""
        if self.ended:
            return []
        fd = self.proc.stdout.fileno()
        ready, _, _ = select.select([fd], [], [], max(0.0, timeout))
        if not ready:
            return []
        data = os.read(fd, 65536)
        if not data:
            self.ended = True
        self._buf += data
        *lines, self._buf = self._buf.split(b"\n")
        new = [line.decode(errors="replace").split() for line in lines if line.strip()]
        self.events += new
        return new

    def wait_for(self, kinds, deadline: float) -> list[str] | None:
        """The first event of one of kinds, or None when the reaper ended or the deadline passed."""
        while not self.ended and time.monotonic() < deadline:
            for event in self.poll(deadline - time.monotonic()):
                if event[0] in kinds:
                    return event
        return None

    def stop(self, deadline: float) -> None:
        """Ask the reaper to stop the graph (a byte, then end of file, on its lifeline) and wait for it to exit."""
        if self.proc.stdin.closed:
            return  # stopped already
        try:
            self.proc.stdin.write(b"stop\n")  # a forked child of ours may hold the pipe open: EOF alone is not enough
            self.proc.stdin.close()
        except OSError:  # it is gone already
            pass
        self.wait_for(("down",), deadline)
        try:
            self.proc.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            self.proc.kill()  # hung (it should never be): its children get SIGTERM, the caller kills by marker
            self.proc.wait()
        self.poll(0)
        self.proc.stdout.close()


# -- the supervisor ----------------------------------------------------------------------------------------------


def _die_with_reaper() -> None:
    """In a child of the reaper: SIGTERM when the reaper dies (only a SIGKILL aimed at it can do that), so that
    roslaunch, the master and rosout shut down by themselves even then."""
    ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


class _Supervisor:
    """The reaper process's logic. spec keys: owner (pid), log (path), grace and kill_timeout (s, see
    stop_processes), master (None, or cmd, uri and timeout), extra (commands started with roslaunch), launch
    (roslaunch's command)."""

    def __init__(self, spec: dict):
        self.spec = spec
        self.graph_id = os.environ[MARKER]
        self.owner = spec["owner"]
        self.statuses: dict[int, int] = {}
        self.children: list[subprocess.Popen] = []
        self.log = open(spec["log"], "ab", buffering=0)
        self.stop_requested = False

    def say(self, *words) -> None:
        try:
            os.write(1, (" ".join(map(str, words)) + "\n").encode())
        except OSError:  # the owner is gone: nobody to tell
            pass

    def start(self, cmd: list[str]) -> subprocess.Popen:
        p = subprocess.Popen(
            cmd, stdin=subprocess.DEVNULL, stdout=self.log, stderr=subprocess.STDOUT, preexec_fn=_die_with_reaper
        )
        self.children.append(p)
        return p

    def should_stop(self, timeout: float) -> bool:
        """Wait up to timeout for the lifeline; True when the owner is gone or closed it, or we were signalled."""
        if self.stop_requested or os.getppid() != self.owner:
            return True
        ready, _, _ = select.select([0], [], [], timeout)
        if ready:
            os.read(0, 4096)  # "stop" from close(), or end of file: the owner closed it or died
            return True
        return self.stop_requested

    def exited(self, pid: int) -> int | None:
        reap(self.statuses)
        return self.statuses.get(pid)

    def start_master(self) -> bool:
        """Start the master and wait until it answers as our child. False (and reported) when it cannot."""
        m = self.spec["master"]
        master = self.start(m["cmd"])
        port = int(m["uri"].rsplit(":", 1)[1].rstrip("/"))
        deadline = time.monotonic() + m["timeout"]
        socket.setdefaulttimeout(1.0)
        while not self.should_stop(0.05):
            code = self.exited(master.pid)
            if code is not None:
                self.say("master-exit", code)
                return False
            try:
                ok, _, pid = xmlrpc.client.ServerProxy(m["uri"]).getPid("/moverl_reaper")
                if ok == 1 and pid == master.pid:
                    self.say("master", master.pid)
                    return True
            except (OSError, xmlrpc.client.Error):
                pass
            # rosmaster does not exit when its port is taken (its server thread dies, the process hangs): a
            # listener on the port that is not the master's means the port is someone else's.
            mine = socket_inodes(master.pid)
            if any(p == port and inode not in mine for _, _, p, inode in open_sockets()):
                holders = listening_sockets(proc_table().values())  # who listens there (a scan of /proc: once)
                self.say(
                    "taken",
                    port,
                    *(f"{h.pid}/{h.name.replace(' ', '_')}" for h in holders if h.port == port and h.pid != master.pid),
                )
                return False
            if time.monotonic() > deadline:
                self.say("master-exit", "timeout")
                return False
        return False

    def run(self) -> int:
        if os.getppid() != self.owner:
            return 1  # the owner died before we started: nothing to supervise
        launch = None
        try:
            if self.spec.get("master") is None or self.start_master():
                for cmd in self.spec.get("extra", []):
                    self.start(cmd)
                launch = self.start(self.spec["launch"])
                self.say("launch", launch.pid)
                while not self.should_stop(0.2):
                    code = self.exited(launch.pid)
                    if code is not None:
                        self.say("exit", code)
                        break
        except OSError as exc:  # a command that cannot be started: stop what was, report
            self.say("error", str(exc).replace("\n", " "))
        t0 = time.monotonic()
        killed, left = stop_processes(
            self.graph_id,
            os.getpid(),
            launch.pid if launch else None,
            self.spec["grace"],
            self.spec["kill_timeout"],
            self.statuses,
        )
        reap(self.statuses)
        for p in self.children:  # exit codes collected by reap(): keep Popen from waiting on them again
            p.returncode = self.statuses.get(p.pid, p.returncode)
        for p in killed:
            self.say("killed", p.pid, p.name)
        for p in left:
            self.say("left", p.pid, p.name)
        self.say("down", f"{time.monotonic() - t0:.3f}", len(killed), len(left))
        return 0 if not left else 1


def main(argv: list[str]) -> int:
    spec = json.loads(argv[1])
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(_PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) != 0:
        os.write(2, f"reaper: PR_SET_CHILD_SUBREAPER failed: {os.strerror(ctypes.get_errno())}\n".encode())
        return 2
    reaper = _Supervisor(spec)

    def request_stop(signum, frame):  # a polite signal to the reaper itself stops the graph, then the reaper
        reaper.stop_requested = True

    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, request_stop)
    return reaper.run()


if __name__ == "__main__":
    sys.exit(main(sys.argv))
