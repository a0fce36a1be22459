#!/usr/bin/env bash
# Set up MoveRL on a fresh Debian 12 machine, idempotently: apt packages (ROS 1 + C++ libraries),
# a Python venv (.venv, with the system's rospy visible), then a catkin build of src/.
# Running it again only does what is missing. Afterwards: `source env.sh` (done by run.sh for you).
set -euo pipefail
cd "$(dirname "$0")"
ROOT=$(pwd)

APT_PACKAGES=(
  ros-base-dev python3-rospy python3-roslaunch python3-rostest librostest-dev rosbash python3-tf2-ros
  libtf2-ros-dev catkin ros-message-generation ros-message-runtime ros-std-srvs libstd-srvs-dev python3-std-srvs
  libfcl-dev libompl-dev liboctomap-dev liburdfdom-dev liburdf-dev liborocos-kdl-dev libkdl-parser-dev
  libeigen3-dev libassimp-dev libgtest-dev libyaml-cpp-dev
  ros-sensor-msgs ros-geometry-msgs ros-shape-msgs ros-trajectory-msgs ros-visualization-msgs
  libsensor-msgs-dev libgeometry-msgs-dev libshape-msgs-dev libtrajectory-msgs-dev libvisualization-msgs-dev
  libstd-msgs-dev python3-sensor-msgs python3-geometry-msgs python3-shape-msgs python3-trajectory-msgs
  python3-visualization-msgs python3-tf2-msgs libtf2-msgs-dev
  libactionlib-dev python3-actionlib ros-actionlib-msgs libactionlib-msgs-dev python3-actionlib-msgs
  python3-venv python3-dev build-essential cmake
)

log() { printf '\033[1m[setup]\033[0m %s\n' "$*"; }

# 1. apt: install only what is missing.
missing=()
for p in "${APT_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  log "installing ${#missing[@]} apt packages: ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
else
  log "apt packages: all present"
fi

# 2. Python venv with Debian's interpreter (the one rospy is built for).
if [ ! -x .venv/bin/python ]; then
  log "creating .venv"
  /usr/bin/python3 -m venv --system-site-packages .venv
fi
stamp=.venv/.requirements.sha256
want=$(sha256sum requirements.txt | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  log "installing Python requirements into .venv"
  # (this machine's pip configuration warns about local package folders it cannot use: harmless, filtered)
  .venv/bin/pip install -q --disable-pip-version-check -r requirements.txt 2>&1 | grep -v "is ignored: it is neither" || true
  .venv/bin/python -c "import torch, pybullet, gymnasium, stable_baselines3, ray.rllib" || { echo "Python requirements failed to install"; exit 1; }
  echo "$want" > "$stamp"
else
  log "Python requirements: up to date"
fi

# 3. catkin build (Debian's python3 first on PATH, or catkin fails with "No module named ament_package").
log "catkin build"
export PATH="/usr/bin:$PATH"
# The planning scene's gtests run on pybullet_data's Panda URDF, which only the venv's Python knows.
PANDA_URDF=$(.venv/bin/python -c "import pybullet_data, os; print(os.path.join(pybullet_data.getDataPath(), 'franka_panda', 'panda.urdf'))")
catkin_make -j2 -DCMAKE_BUILD_TYPE=Release -DPYTHON_EXECUTABLE=/usr/bin/python3 -DPANDA_URDF="$PANDA_URDF" \
  > "$ROOT/.catkin_build.log" 2>&1 || {
  tail -40 "$ROOT/.catkin_build.log"; echo "catkin build failed (full log: .catkin_build.log)"; exit 1; }
catkin_make -j2 tests >> "$ROOT/.catkin_build.log" 2>&1 || {
  tail -40 "$ROOT/.catkin_build.log"; echo "building the C++ tests failed (full log: .catkin_build.log)"; exit 1; }
log "done. Use ./run.sh (demo | test | bench | train ...), or 'source env.sh' for a shell."
