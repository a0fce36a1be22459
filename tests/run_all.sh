#!/usr/bin/env bash
# Every MoveRL test, in tiers: gtest (C++ cores) and pytest (Python cores) need no roscore; rostest brings up
# the real headless graph on a free port per test file. Called by `./run.sh test` (and so by CI).
#   tests/run_all.sh            all tiers
#   tests/run_all.sh --no-live  cores only
set -uo pipefail
cd "$(dirname "$0")/.."
# shellcheck disable=SC1091
set +u; source ./env.sh; set -u  # ROS's setup scripts read unset variables
export ROS_LOG_DIR=${ROS_LOG_DIR:-$(mktemp -d /tmp/moverl_test_logs.XXXXXX)}
live=1; [ "${1:-}" = "--no-live" ] && live=0
passed=0; failed=0; failures=()
suite() {
  local name=$1; shift
  printf '\n\033[1m== %s\033[0m\n' "$name"
  local t0=$SECONDS
  if "$@"; then passed=$((passed + 1)); echo "-- $name: ok ($((SECONDS - t0)) s)";
  else failed=$((failed + 1)); failures+=("$name"); echo "-- $name: FAILED ($((SECONDS - t0)) s)"; fi
}

# Tier 1: C++ cores (gtest binaries built by catkin_ws_setup.sh).
for bin in devel/lib/*/test_* devel/lib/*/*_test; do
  [ -x "$bin" ] && suite "gtest $(basename "$bin")" "$bin"
done
# Tier 2: Python cores.
suite "pytest (cores)" python -m pytest -q -p no:cacheprovider src/moverl_sim/test src/moverl_gym/test/test_gym_core.py src/moverl_gym/test/test_tools.py
# Tier 3: the live graph.
if [ "$live" = 1 ]; then
  suite "pytest graph start-up errors, real-time clock" python -m pytest -q -p no:cacheprovider \
    src/moverl_gym/test/test_graph_errors.py src/moverl_gym/test/test_realtime_live.py
  suite "pytest train.py smoke (PPO, SAC, TD3), study --quick" python -m pytest -q -p no:cacheprovider \
    src/moverl_gym/test/test_train_smoke.py src/moverl_gym/test/test_study.py
  suite "rostest shield_live" rostest --text moverl_gym shield_live.test
  suite "rostest scenario_human" rostest --text moverl_gym scenario_human.test
  suite "rostest scenario_case" rostest --text moverl_gym scenario_case.test
  suite "rostest strategies_live" rostest --text moverl_gym strategies_live.test
  suite "rostest moving_obstacle" rostest --text moverl_gym moving_obstacle.test
  suite "rostest sensed_obstacle (OctoMap)" rostest --text moverl_gym sensed_obstacle.test
  suite "rostest env_live (shield on)" rostest --text moverl_gym env_live.test shield:=true
  suite "rostest env_live (shield off)" rostest --text moverl_gym env_live.test shield:=false
fi

echo
[ ${#failures[@]} -gt 0 ] && printf 'failed suite: %s\n' "${failures[@]}"
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
