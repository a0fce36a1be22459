"""Run a measurement in a fresh process: rospy binds a process to one ROS master, so every ROS graph a
script measures gets its own worker process (the script itself, re-run with its --worker arguments)."""

from __future__ import annotations

import json
import os
import subprocess
import sys


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
