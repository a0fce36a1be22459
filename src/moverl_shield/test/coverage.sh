#!/usr/bin/env bash
# Branch coverage of the shield's decision core (src/shield.cpp, shield_core.cpp, driver_core.cpp, trajectory.cpp) by
# its gtests (test_shield, test_shield_core, test_driver_core): compiles them once more with gcc's --coverage in a
# temporary folder (the workspace's build is untouched), runs them, and prints gcovr's branch and line coverage per file.
#   bash src/moverl_shield/test/coverage.sh          (after ./catkin_ws_setup.sh: links the planning scene's core)
set -euo pipefail
cd "$(dirname "$0")/.."
PKG=$(pwd)
ROOT=$(cd ../.. && pwd)
CORE_LIB="$ROOT/devel/lib/libmoverl_planning_scene_core.so"
[ -f "$CORE_LIB" ] || { echo "no $CORE_LIB: run ./catkin_ws_setup.sh first" >&2; exit 1; }
WORK=$(mktemp -d /tmp/moverl_shield_coverage.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
SOURCES=(src/shield.cpp src/shield_core.cpp src/driver_core.cpp src/trajectory.cpp)
FLAGS=(-std=c++17 -O0 --coverage -I include -I ../moverl_planning_scene/include -I ../moverl_tcpros/include -I /usr/include/eigen3)
for t in test_shield test_shield_core test_driver_core; do
  g++ "${FLAGS[@]}" -o "$WORK/$t" "test/$t.cpp" "${SOURCES[@]}" "$CORE_LIB" -lgtest -lpthread \
    -Wl,-rpath,"$(dirname "$CORE_LIB")"
done
cd "$WORK"
for t in test_shield test_shield_core test_driver_core; do
  # Each binary writes its own .gcda files (named after the binary); gcov merges them per source below.
  (cd "$WORK" && "./$t" --gtest_brief=1 >/dev/null) || { echo "$t failed" >&2; exit 1; }
done
# gcovr merges the three binaries' data per source. Decisions: the branches the code writes (each if, loop and
# condition taken both ways), which is what "branch coverage" of the decisions means here; g++'s own branch count adds
# the hidden ones of exception cleanup and temporaries, and is printed second for completeness.
gcovr --root "$PKG" --object-directory "$WORK" --filter "$PKG/src/" --decisions --txt-metric decision --txt - "$WORK"
gcovr --root "$PKG" --object-directory "$WORK" --filter "$PKG/src/" --txt-metric line --txt - "$WORK" | tail -n 3
gcovr --root "$PKG" --object-directory "$WORK" --filter "$PKG/src/" --txt-metric branch --txt - "$WORK" | tail -n 3
