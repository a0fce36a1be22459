#!/usr/bin/env bash
# The attempt to use OmniSafe 0.5 (PPOLag, CPO) for issue 27, repeatable: a venv of its own with Debian's Python (the one
# rospy is built for), our torch first, then OmniSafe. It prints what happens at each step; README "Constrained RL"
# says why MoveRL ships its own PPO-Lagrangian (moverl_gym.constrained) instead. Nothing here is used by MoveRL.
#   bash src/moverl_gym/tools/omnisafe_attempt.sh [VENV_DIR]    (default: a new temporary folder, removed at the end)
set -uo pipefail
dir=${1:-}
if [ -z "$dir" ]; then
  dir=$(mktemp -d "${TMPDIR:-/tmp}/moverl_omnisafe.XXXXXX")
  trap 'rm -rf "$dir"' EXIT
fi
step() { printf '\n== %s\n' "$*"; }
quiet_pip() { "$dir/venv/bin/pip" "$@" 2>&1 | grep -v "is ignored: it is neither"; return "${PIPESTATUS[0]}"; }

step "venv with $(/usr/bin/python3 --version) in $dir/venv; torch==2.13.0 first (the local CPU wheel)"
/usr/bin/python3 -m venv "$dir/venv" || exit 1
quiet_pip install -q --disable-pip-version-check torch==2.13.0 || exit 1

step "pip install omnisafe==0.5.0 (its safety-gymnasium pins gymnasium 0.28.1, pygame 2.1.0, mujoco 2.3.3)"
if quiet_pip install -q --disable-pip-version-check omnisafe==0.5.0 | tail -25; then
  echo "-> installed"
else
  echo "-> FAILED: pygame 2.1.0 has no wheel for Python 3.11 and does not build for it (pygame/pygame#3522); every"
  echo "   safety-gymnasium release OmniSafe accepts (0.2.0, 0.3.0, 0.4.0, 0.4.1, 1.0.0) pins it"
fi

step "the pins bypassed: omnisafe and safety-gymnasium without their dependencies, those installed one by one" \
  "with pygame 2.6.1 instead of 2.1.0"
quiet_pip install -q --disable-pip-version-check --no-deps omnisafe==0.5.0 safety-gymnasium==1.0.0 || exit 1
quiet_pip install -q --disable-pip-version-check gymnasium==0.28.1 gymnasium-robotics==1.2.2 mujoco==2.3.3 \
  pygame==2.6.1 xmltodict pyyaml imageio "numpy<2" tensorboard wandb moviepy typing-extensions "typer[all]" seaborn \
  pandas==2.0.3 matplotlib gdown | tail -5
"$dir/venv/bin/pip" list 2>/dev/null | grep -iE "^(omnisafe|safety-gymnasium|gymnasium|torch|numpy|pandas|pygame|mujoco) "

step "import omnisafe"
if "$dir/venv/bin/python" -c "import omnisafe; print('omnisafe', omnisafe.__version__)" 2>&1 | tail -4; then
  echo "-> imported"
else
  echo "-> FAILED: omnisafe.envs imports safety_gymnasium, whose dataclasses have numpy-array defaults, which Python 3.11"
  echo "   refuses (the releases 0.2.0, 0.3.0, 0.4.0, 0.4.1 and 1.0.0 all have them)"
fi
