"""Re-execute a script under the MoveRL venv when the current interpreter lacks a module.

catkin's devel-space relays run scripts with the workspace's PYTHON_EXECUTABLE (/usr/bin/python3),
which has rospy but not pybullet; the venv (made with --system-site-packages) has both.
"""

import importlib.util
import os
import shutil
import sys

_FLAG = "MOVERL_SIM_REEXEC"


def _candidates(script):
    venv = os.environ.get("VIRTUAL_ENV")
    if venv:
        yield os.path.join(venv, "bin", "python3")
    found = shutil.which("python3")
    if found:
        yield found
    # <repo>/src/moverl_sim/scripts/<script> -> <repo>/.venv
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.realpath(script)))))
    yield os.path.join(repo, ".venv", "bin", "python3")


def ensure_module(module, script):
    """Return when `module` is importable; else exec `script` under another python3 that may have it."""
    if importlib.util.find_spec(module) is not None:
        return
    if os.environ.get(_FLAG) != "1":
        here = os.path.abspath(sys.executable)  # a venv python is a symlink: compare paths, not targets
        for python in _candidates(script):
            if os.path.isfile(python) and os.access(python, os.X_OK) and os.path.abspath(python) != here:
                os.environ[_FLAG] = "1"
                os.execv(python, [python, script] + sys.argv[1:])
    sys.stderr.write(
        "%s: the Python module %r is missing in %s (activate the MoveRL venv: source env.sh)\n"
        % (os.path.basename(script), module, sys.executable)
    )
    sys.exit(1)
