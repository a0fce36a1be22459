#!/usr/bin/env bash
# Time the Python part of set-up on a fresh venv, as catkin_ws_setup.sh makes it (Debian's python3,
# --system-site-packages), for each requirements file given; prints seconds and the venv's size. pip's cache is
# whatever this machine has (warm after a first run): the figures are install times, not download times.
#   bash src/moverl_gym/tools/setup_time.sh <(git show <commit>:requirements.txt) requirements.txt
set -euo pipefail
for req in "$@"; do
  venv=$(mktemp -d /tmp/moverl_setup_time.XXXXXX)
  copy=$(mktemp /tmp/moverl_setup_req.XXXXXX)
  cat "$req" > "$copy"
  /usr/bin/python3 -m venv --system-site-packages "$venv"
  start=$(date +%s.%N)
  "$venv/bin/pip" install -q --disable-pip-version-check -r "$copy" > "$venv.log" 2>&1 || { tail "$venv.log"; exit 1; }
  end=$(date +%s.%N)
  printf '%s: %.0f s, %s MB\n' "$req" "$(echo "$end - $start" | bc)" "$(du -sm "$venv" | cut -f1)"
  rm -rf "$venv" "$venv.log" "$copy"
done
