#!/usr/bin/env bash
# Every MoveRL test, in tiers: gtest (C++ cores) and pytest (Python cores) need no roscore; rostest brings up
# the real headless graph on a free port per test file. Called by `./run.sh test` (and so by CI).
#   tests/run_all.sh            all tiers
#   tests/run_all.sh --no-live  cores only
set -uo pipefail
cd "$(dirname "$0")/.."
live=1
case "${1:-}" in
  "") ;;
  --no-live) live=0 ;;
  -h|--help) sed -n '2,/^[^#]/s/^# \{0,1\}//p' "$0"; exit 0 ;;
  *) echo "run_all.sh: unknown option '$1' (--no-live, --help)" >&2; exit 2 ;;
esac
# shellcheck disable=SC1091
set +u; source ./env.sh; set -u  # ROS's setup scripts read unset variables
export ROS_LOG_DIR=${ROS_LOG_DIR:-$(mktemp -d /tmp/moverl_test_logs.XXXXXX)}
RESULTS=$(mktemp -d /tmp/moverl_test_results.XXXXXX)  # rostest's XML results (its default is a shared ~/.ros path)
passed=0; failed=0; failures=()
suite() {
  local name=$1; shift
  printf '\n\033[1m== %s\033[0m\n' "$name"
  local t0=$SECONDS
  if "$@"; then passed=$((passed + 1)); echo "-- $name: ok ($((SECONDS - t0)) s)";
  else failed=$((failed + 1)); failures+=("$name"); echo "-- $name: FAILED ($((SECONDS - t0)) s)"; fi
}

# A rostest suite. Without --text: with it, rostest exits 0 even when its tests fail or its test node dies
# ("overall test result is not accurate when --text is enabled"); without it, a failure exits non-zero and rostest
# prints the failing tests' tracebacks.
live_rostest() { rostest --results-base-dir "$RESULTS" moverl_gym "$@"; }

# Style first (clang-format, ruff, catkin_lint): tests/lint.sh, also ./run.sh lint.
suite "lint (clang-format, ruff check, ruff format, catkin_lint)" bash tests/lint.sh
# Tier 1: C++ cores (gtest binaries built by catkin_ws_setup.sh).
for bin in devel/lib/*/test_* devel/lib/*/*_test; do
  [ -x "$bin" ] && suite "gtest $(basename "$bin")" "$bin"
done
# Tier 2: Python cores.
suite "pytest (cores)" python -m pytest -q -p no:cacheprovider src/control_msgs/test src/moverl_sim/test \
  src/moverl_gym/test/test_gym_core.py src/moverl_gym/test/test_tools.py src/moverl_gym/test/test_reaper.py \
  src/moverl_gym/test/test_codes.py src/moverl_gym/test/test_env_core.py src/moverl_gym/test/test_watchdog.py \
  src/moverl_gym/test/test_goal_render_core.py src/moverl_gym/test/test_run_help.py \
  src/moverl_gym/test/test_launch_args.py src/moverl_gym/test/test_constrained.py src/moverl_gym/test/test_docs_links.py
suite "pytest geometry parity (scene shapes vs PyBullet's)" python -m pytest -q -p no:cacheprovider \
  src/moverl_planning_scene/test/test_geometry_parity.py
# Tier 3: the live graph.
if [ "$live" = 1 ]; then
  suite "pytest graph start-up errors, launch-argument check, lifecycle (close, SIGSTOP, SIGKILL, sockets), real-time clock" \
    python -m pytest -q -p no:cacheprovider src/moverl_gym/test/test_graph_errors.py \
    src/moverl_gym/test/test_launch_args_live.py src/moverl_gym/test/test_graph_lifecycle.py \
    src/moverl_gym/test/test_realtime_live.py
  suite "pytest dynamic control and the standard driver in real time (pushing policies)" python -m pytest -q \
    -p no:cacheprovider src/moverl_gym/test/test_driver_modes_live.py
  suite "pytest stalled components (SIGSTOP of sim, scene, shield; both drivers)" python -m pytest -q \
    -p no:cacheprovider src/moverl_gym/test/test_stall_live.py
  suite "pytest the shield's own TCPROS on ~step (probe, wrong MD5, cut-short and corrupt requests, non-persistent clients)" \
    python -m pytest -q -p no:cacheprovider src/moverl_gym/test/test_tcpros_live.py
  suite "pytest recovery (simulator killed mid-training: relaunched with recovery on, clear error off)" \
    python -m pytest -q -p no:cacheprovider src/moverl_gym/test/test_recovery_live.py
  suite "pytest fuzzing of every service and subscribed topic (both drivers' graphs)" python -m pytest -q \
    -p no:cacheprovider src/moverl_gym/test/test_fuzz_live.py
  suite "pytest soak, short (memory, descriptors, processes, latency sampled; the long run is scripts/soak.py)" \
    python -m pytest -q -p no:cacheprovider src/moverl_gym/test/test_soak_short.py
  suite "pytest train.py smoke (PPO, SAC, TD3, PPO with 2 envs + evaluate), study --quick, constrained_study --quick" \
    python -m pytest -q -p no:cacheprovider src/moverl_gym/test/test_train_smoke.py src/moverl_gym/test/test_study.py \
    src/moverl_gym/test/test_constrained_study_live.py
  suite "pytest every shipped robot x scenario live (check_env, determinism, random policy without contact)" \
    python -m pytest -q -p no:cacheprovider src/moverl_gym/test/test_robot_matrix_live.py
  suite "pytest a person seen only by cameras (pushing policy lockstep and real time, a person faster than the bound; a hand by a fixture or a link, a withheld camera; a parked robot backs away)" \
    python -m pytest -q -p no:cacheprovider src/moverl_gym/test/test_sensed_person_live.py \
    src/moverl_gym/test/test_sensing_assumptions_live.py src/moverl_gym/test/test_retreat_live.py
  suite "pytest goal-conditioned ids live (SAC + HER, shield on; relabelled rewards with discarded steps; rendering)" \
    python -m pytest -q -p no:cacheprovider src/moverl_gym/test/test_goal_live.py
  suite "pytest RLlib on a 2-node local Ray cluster (runners on different nodes; resumed with a simulator and a runner killed)" \
    python -m pytest -q -p no:cacheprovider src/moverl_gym/test/test_rllib_live.py
  suite "rostest shield_live" live_rostest shield_live.test
  suite "rostest scenario_human" live_rostest scenario_human.test
  suite "rostest scenario_case" live_rostest scenario_case.test
  suite "rostest strategies_live" live_rostest strategies_live.test
  suite "rostest moving_obstacle" live_rostest moving_obstacle.test
  suite "rostest sensed_obstacle (OctoMap)" live_rostest sensed_obstacle.test
  suite "rostest standard_driver (FollowJointTrajectory, real time)" live_rostest standard_driver.test
  suite "rostest minimal_driver (a driver not ours, its faults)" live_rostest minimal_driver.test
  suite "rostest env_live (shield on)" live_rostest env_live.test shield:=true
  suite "rostest env_live (shield off)" live_rostest env_live.test shield:=false
  suite "pytest collision parity + pushing policy (every robot config, short)" python -m pytest -q -p no:cacheprovider \
    src/moverl_gym/test/test_parity_live.py
fi

echo
[ ${#failures[@]} -gt 0 ] && printf 'failed suite: %s\n' "${failures[@]}"
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
