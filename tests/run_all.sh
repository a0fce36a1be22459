#!/usr/bin/env bash
# Every MoveRL test, in tiers: core (gtest and pytest on the C++ and Python cores, no roscore), quick (the fastest
# checks on a live graph), live (the rest: rostest and pytest on the real headless graph, each on a free port). Tests
# are chosen by tier, never by a list: a pytest file's module-level pytestmark, a rostest file's <arg name="tier">, a
# gtest's catkin_add_gtest (tests/tiers.py has the rules). The first suites are lint and the tier check, which fails
# when any test file belongs to no tier. Called by `./run.sh test` (and so by CI).
#   tests/run_all.sh            every tier: core, quick, live (what CI runs)
#   tests/run_all.sh --quick    core and quick: day-to-day work
#   tests/run_all.sh --no-live  core only
set -uo pipefail
cd "$(dirname "$0")/.."
case "${1:-}" in
  "") tiers=(core quick live) ;;
  --quick) tiers=(core quick) ;;
  --no-live) tiers=(core) ;;
  -h|--help) sed -n '2,/^[^#]/s/^# \{0,1\}//p' "$0"; exit 0 ;;
  *) echo "run_all.sh: unknown option '$1' (--quick, --no-live, --help)" >&2; exit 2 ;;
esac
[ $# -le 1 ] || { echo "run_all.sh: one option at most, got: $*" >&2; exit 2; }
# shellcheck disable=SC1091
set +u; source ./env.sh; set -u  # ROS's setup scripts read unset variables
export ROS_LOG_DIR=${ROS_LOG_DIR:-$(mktemp -d /tmp/moverl_test_logs.XXXXXX)}
RESULTS=$(mktemp -d /tmp/moverl_test_results.XXXXXX)  # rostest's XML results (its default is a shared ~/.ros path)
OUTPUTS=$(mktemp -d /tmp/moverl_test_outputs.XXXXXX)  # each suite's output, for the failures' summary at the end
trap 'rm -rf "$OUTPUTS"' EXIT
# A suite runs in the background (below), where a shell without job control ignores SIGINT: on Ctrl-C (or TERM) the
# suite and its children are stopped here, not left running.
suite_pid=""
interrupted() {
  if [ -n "$suite_pid" ]; then pkill -TERM -P "$suite_pid" 2>/dev/null; kill -TERM "$suite_pid" 2>/dev/null; fi
  wait 2>/dev/null
  echo "run_all.sh: interrupted" >&2
  exit 130
}
trap interrupted INT TERM
passed=0; failed=0; failures=(); failed_logs=(); t_start=$SECONDS
suite() {
  local name=$1; shift
  printf '\n\033[1m== %s\033[0m\n' "$name"
  local t0=$SECONDS log; log="$OUTPUTS/$((passed + failed)).log"
  # Into a file, shown as it grows: tail follows the suite's process, not its output, so a process a test leaves
  # behind holding the output cannot stall the run.
  local rc=0
  : > "$log"
  "$@" > "$log" 2>&1 &
  suite_pid=$!
  tail -n +1 -s 0.2 -f --pid="$suite_pid" "$log"
  wait "$suite_pid" || rc=$?
  suite_pid=""
  if [ "$rc" -eq 0 ]; then passed=$((passed + 1)); echo "-- $name: ok ($((SECONDS - t0)) s)"; rm -f "$log";
  else
    failed=$((failed + 1)); failures+=("$name"); failed_logs+=("$log")
    echo "-- $name: FAILED ($((SECONDS - t0)) s)"
  fi
}
# The end of a failed suite's output, again at the end of the run (where CI's excerpt is): the lines that say why.
# rostest and pytest print the failing tests' assertions and tracebacks near their end; ROS's own chatter is left out.
why_failed() {
  grep -v -E '^\S*\[ *(WARN|INFO|DEBUG)\]|TF_REPEATED_DATA|^\s*$' "$1" | tail -n 60
}
pytest_() { python -m pytest -q -p no:cacheprovider "$@"; }
# A rostest suite. Without --text: with it, rostest exits 0 even when its tests fail or its test node dies
# ("overall test result is not accurate when --text is enabled"); without it, a failure exits non-zero and rostest
# prints the failing tests' tracebacks.
rostest_() { rostest --results-base-dir "$RESULTS" "$@"; }
# files_of ARRAY KIND TIER: the test files of a kind in a tier (tests/tiers.py list), "path<TAB>suite name" per
# element (gtest: the binaries). Read before the suites run (no test gets them as its stdin); a failure stops the run.
files_of() {
  local -n into=$1; local out
  out=$(python tests/tiers.py list "$2" "$3") || { echo "run_all.sh: tests/tiers.py list $2 $3 failed" >&2; exit 2; }
  into=(); [ -z "$out" ] || mapfile -t into <<< "$out"
}

echo "tiers: ${tiers[*]}"
# Style first (clang-format, ruff, catkin_lint): tests/lint.sh, also ./run.sh lint.
suite "lint (clang-format, ruff check, ruff format, catkin_lint)" bash tests/lint.sh
suite "tiers (every test file in exactly one tier: tests/tiers.py check)" python tests/tiers.py check
for tier in "${tiers[@]}"; do
  if [ "$tier" = core ]; then
    # C++ cores: the gtest binaries built by catkin_ws_setup.sh. Python cores: one pytest run, selected by marker.
    files_of bins gtest core
    for bin in "${bins[@]}"; do suite "gtest $(basename "$bin")" "$bin"; done
    files_of lines pytest core
    core=("${lines[@]%%$'\t'*}")
    # On every core (pytest-xdist, -n auto): the core tests start no ROS master and share no fixed path.
    suite "pytest core (${#core[@]} files: the Python cores, geometry parity with PyBullet)" \
      pytest_ -n auto -m core "${core[@]}"
    continue
  fi
  # The live graph: one suite per file, each in its own process (rospy allows one ROS master per process).
  files_of py pytest "$tier"
  files_of ros rostest "$tier"
  for line in "${py[@]}" "${ros[@]}"; do
    file=${line%%$'\t'*}; name=${line#*$'\t'}
    case "$file" in
      *.py) suite "[$tier] $name" pytest_ -m "$tier" "$file" ;;
      *.test) suite "[$tier] $name" rostest_ "$file" ;;
    esac
  done
done

echo
for k in "${!failures[@]}"; do
  printf '\n\033[1m== why %s failed (the end of its output)\033[0m\n' "${failures[$k]}"
  why_failed "${failed_logs[$k]}"
done
[ ${#failures[@]} -gt 0 ] && printf 'failed suite: %s\n' "${failures[@]}"
echo "$passed passed, $failed failed; tiers ${tiers[*]}: $(((SECONDS - t_start) / 60)) min $(((SECONDS - t_start) % 60)) s"
[ "$failed" -eq 0 ]
