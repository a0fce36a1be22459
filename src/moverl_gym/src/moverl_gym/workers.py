"""Run a measurement in a fresh process: rospy binds a process to one ROS master, so every ROS graph a
script measures gets its own worker process (the script itself, re-run with its --worker arguments)."""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys
from pathlib import Path

#: One BLAS/torch thread per child run: --jobs runs plus their simulators share the cores; a 64x64 MLP gains nothing
#: from more threads, and oversubscription slows every process down.
THREADS = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def run_json_worker(script: str, args: list[str], what: str, timeout: float = 3600.0) -> dict:
    """Run `python script *args`, whose last stdout line is a JSON object, and return that object.

    Raises:
        RuntimeError: the worker failed (with the tail of its stderr) or printed no JSON.
    """
    cmd = [sys.executable, os.path.abspath(script), *map(str, args)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=os.environ)
    lines = proc.stdout.strip().splitlines()
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"{what} failed (exit code {proc.returncode}):\n{proc.stderr[-3000:]}")
    return json.loads(lines[-1])


def run_logged(cmd: list[str], log: Path, timeout: float, env: dict | None = None) -> int | str:
    """Run `cmd` with stdout and stderr into `log` (its first line: the command), at most `timeout` s; `env` is added to
    this process's environment (unbuffered Python output always). Returns the exit code, or "timeout" (the child is
    killed)."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "w") as f:
        f.write("$ " + " ".join(shlex.quote(str(c)) for c in cmd) + "\n")
        f.flush()
        try:
            return subprocess.run(
                [str(c) for c in cmd],
                stdout=f,
                stderr=subprocess.STDOUT,
                timeout=timeout,
                env=dict(os.environ, PYTHONUNBUFFERED="1", **(env or {})),
            ).returncode
        except subprocess.TimeoutExpired:
            return "timeout"
