"""proctree's accounts of a process without ROS: its CPU seconds split by what its threads call themselves (the split
step_cost.py prints for the planning scene's named integration threads)."""

import subprocess
import sys
import time

import pytest

from moverl_gym.proctree import cpu_seconds, thread_cpu_seconds, tree

pytestmark = pytest.mark.core

# A process whose second thread names itself (as pthread_setname_np does in C++) and spins for 0.6 s of CPU, while its
# main thread sleeps; it prints "done" when the spin is over, and both threads wait to be killed.
BURNER = r"""
import ctypes, threading, time
def burn():
    ctypes.CDLL(None).prctl(15, b"mps_burner", 0, 0, 0)  # PR_SET_NAME
    t0 = time.thread_time()
    while time.thread_time() - t0 < 0.6:
        pass
    print("done", flush=True)
    time.sleep(600)
threading.Thread(target=burn, daemon=True).start()
time.sleep(600)
"""


def test_a_process_cpu_is_split_by_its_threads_names():
    child = subprocess.Popen([sys.executable, "-c", BURNER], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "done"
        procs = tree(child.pid)
        assert [p.pid for p in procs] == [child.pid]
        by_name = thread_cpu_seconds(procs)[(child.pid, procs[0].start)]
        assert by_name["mps_burner"] == pytest.approx(0.6, abs=0.1)
        rest = sum(t for name, t in by_name.items() if name != "mps_burner")
        assert rest < 0.3  # the interpreter's start; its main thread sleeps
        # The threads' seconds add up to the process's (the spinning thread is still alive: it took nothing with it).
        assert sum(by_name.values()) == pytest.approx(cpu_seconds(procs)[(child.pid, procs[0].start)], abs=0.03)
        # Only the threads that named themselves: the burner, not the main thread (the interpreter's name).
        renamed = thread_cpu_seconds(procs, renamed_only=True)[(child.pid, procs[0].start)]
        assert list(renamed) == ["mps_burner"] and renamed["mps_burner"] == by_name["mps_burner"]
    finally:
        child.kill()
        child.wait(timeout=10)


def test_a_gone_process_is_left_out():
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    procs = tree(child.pid)
    child.kill()
    child.wait(timeout=10)
    deadline = time.monotonic() + 5
    while thread_cpu_seconds(procs) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert thread_cpu_seconds(procs) == {}
