"""A process's tree, watched from /proc: which processes it started (for checks that nothing outlives a run), and what
they cost (CPU seconds, resident memory) for the scaling benchmark.

Processes are found by the ppid links of their own tree, never by name across the machine (other people's ROS
graphs and Ray clusters run on the same host). A process is named by (pid, start time), so a pid that the kernel
hands to a new process later is not mistaken for one that was seen.
"""

from __future__ import annotations

import os
import threading
import time

from .reaper import Proc, descendants, proc_table, read_proc

_TICK = os.sysconf("SC_CLK_TCK")
_PAGE = os.sysconf("SC_PAGE_SIZE")


def alive(p: Proc) -> bool:
    """True while the very process p runs (same pid and start time; a zombie counts as gone)."""
    now = read_proc(p.pid)
    return now is not None and now.start == p.start and now.state != "Z"


def cmdline(pid: int) -> str:
    """The command line of pid, arguments separated by spaces ("" when gone or unreadable)."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return f.read().replace(b"\0", b" ").decode(errors="replace").strip()
    except OSError:
        return ""


def tree(root: int, table: dict[int, Proc] | None = None) -> list[Proc]:
    """root and every process below it."""
    table = proc_table() if table is None else table
    own = [table[root]] if root in table else []
    return own + descendants(root, table)


class TreeWatch:
    """Remember every process that appears below `root` while it runs (sampled every `period` seconds).

    Use as a context manager, or start()/stop(). A process that lives shorter than the period can be missed; the
    ones that matter here (graphs, Ray workers, env processes) live for seconds at least.
    """

    def __init__(self, root: int, period: float = 0.2):
        self.root = root
        self.period = period
        self.seen: dict[tuple[int, int], Proc] = {}
        self.cmdlines: dict[tuple[int, int], str] = {}  # the latest command line of each (a process may exec)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="moverl_treewatch", daemon=True)

    def start(self) -> "TreeWatch":
        self.sample()
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)

    def __enter__(self) -> "TreeWatch":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def sample(self) -> list[Proc]:
        """Add the processes below root now; returns them."""
        now = descendants(self.root, proc_table())
        for p in now:
            # The latest view: a process seen between its fork and its exec had its parent's name then (a raylet
            # caught that early on a busy machine was not counted as one).
            self.seen[(p.pid, p.start)] = p
            line = cmdline(p.pid)
            if line:
                self.cmdlines[(p.pid, p.start)] = line
        return now

    def matching(self, text: str) -> list[Proc]:
        """The processes seen whose command line (the latest seen) contains text."""
        return sorted(self.seen[k] for k, line in self.cmdlines.items() if text in line)

    def _run(self) -> None:
        while not self._stop.wait(self.period):
            self.sample()

    def survivors(self) -> list[Proc]:
        """The processes seen below root that still run."""
        return sorted(p for p in self.seen.values() if alive(p))

    def wait_gone(self, timeout: float) -> list[Proc]:
        """Wait (at most `timeout` s) until no process seen below root runs; returns those still running."""
        deadline = time.monotonic() + timeout
        left = self.survivors()
        while left and time.monotonic() < deadline:
            time.sleep(0.2)
            left = self.survivors()
        return left


def context_switches(procs) -> dict[tuple[int, int], int]:
    """Context switches (voluntary + involuntary, summed over the threads alive now) of each process so far, keyed by
    (pid, start); gone processes are left out. A thread that ended took its count with it."""
    out = {}
    for p in procs:
        total = 0
        try:
            with open(f"/proc/{p.pid}/stat", "rb") as f:
                data = f.read()
            if int(data[data.rindex(b")") + 2 :].split()[19]) != p.start:
                continue  # the pid now names another process
            for task in os.listdir(f"/proc/{p.pid}/task"):
                with open(f"/proc/{p.pid}/task/{task}/status") as f:
                    total += sum(int(line.split()[1]) for line in f if "ctxt_switches:" in line)
        except (OSError, ValueError):
            continue
        out[(p.pid, p.start)] = total
    return out


def cpu_seconds(procs) -> dict[tuple[int, int], float]:
    """User + system CPU seconds each process has used so far, keyed by (pid, start); gone processes are left out."""
    out = {}
    for p in procs:
        try:
            with open(f"/proc/{p.pid}/stat", "rb") as f:
                data = f.read()
        except OSError:
            continue
        fields = data[data.rindex(b")") + 2 :].split()
        if int(fields[19]) != p.start:
            continue
        out[(p.pid, p.start)] = (int(fields[11]) + int(fields[12])) / _TICK
    return out


def thread_cpu_seconds(procs, renamed_only: bool = False) -> dict[tuple[int, int], dict[str, float]]:
    """User + system CPU seconds so far of each process's threads alive now, summed by thread name (its comm: what the
    thread named itself, e.g. with pthread_setname_np, else the process's name), keyed by (pid, start); gone processes
    are left out. A thread that ended took its seconds with it. renamed_only: only the threads that named themselves
    (a name other than the process's main thread's)."""
    out = {}
    for p in procs:
        try:
            with open(f"/proc/{p.pid}/stat", "rb") as f:
                data = f.read()
            if int(data[data.rindex(b")") + 2 :].split()[19]) != p.start:
                continue  # the pid now names another process
            names: dict[str, float] = {}
            main = None  # the main thread's name (its task id is the pid)
            for task in os.listdir(f"/proc/{p.pid}/task"):
                with open(f"/proc/{p.pid}/task/{task}/stat", "rb") as f:
                    data = f.read()
                name = data[data.index(b"(") + 1 : data.rindex(b")")].decode(errors="replace")
                fields = data[data.rindex(b")") + 2 :].split()
                names[name] = names.get(name, 0.0) + (int(fields[11]) + int(fields[12])) / _TICK
                if task == str(p.pid):
                    main = name
            if renamed_only:
                names = {n: t for n, t in names.items() if n != main}
        except (OSError, ValueError):
            continue
        out[(p.pid, p.start)] = names
    return out


def memory_bytes(procs) -> dict[str, int]:
    """Summed resident set (rss) and proportional set (pss: shared pages split between their users) of procs."""
    rss = pss = 0
    for p in procs:
        try:
            with open(f"/proc/{p.pid}/statm") as f:
                rss += int(f.read().split()[1]) * _PAGE
            with open(f"/proc/{p.pid}/smaps_rollup") as f:
                for line in f:
                    if line.startswith("Pss:"):
                        pss += int(line.split()[1]) * 1024
                        break
        except OSError:
            continue
    return {"rss": rss, "pss": pss}
