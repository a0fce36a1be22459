#!/usr/bin/env bash
# The transport's gtests (test_tcpros, with its tcpros_peer helper) under ThreadSanitizer and under AddressSanitizer
# with UndefinedBehaviorSanitizer: each builds moverl_tcpros once more in a folder of its own (/tmp/moverl_tcpros_<name>.*,
# removed afterwards; the workspace's build/ and devel/ are untouched), runs the tests, and fails on any report.
#   bash src/moverl_tcpros/test/sanitizers.sh              both (after ./catkin_ws_setup.sh: moverl_msgs comes from devel/)
#   bash src/moverl_tcpros/test/sanitizers.sh thread       one of: thread, address
# Only this package is instrumented: roscpp, xmlrpcpp and boost are Debian's builds, so TSan sees their locks (it
# intercepts pthread) but not their memory accesses.
set -euo pipefail
cd "$(dirname "$0")/.."
PKG=$(pwd)
ROOT=$(cd ../.. && pwd)
[ -f "$ROOT/devel/setup.bash" ] || { echo "no $ROOT/devel: run ./catkin_ws_setup.sh first" >&2; exit 1; }
set +u
# shellcheck disable=SC1091
source "$ROOT/env.sh"
set -u
names=("$@")
[ ${#names[@]} -gt 0 ] || names=(thread address)
for name in "${names[@]}"; do
  case "$name" in
    thread) flags="-fsanitize=thread" ;;
    address) flags="-fsanitize=address,undefined -fno-sanitize-recover=undefined" ;;
    *) echo "sanitizers.sh: unknown sanitizer '$name' (thread, address)" >&2; exit 2 ;;
  esac
  work=$(mktemp -d "/tmp/moverl_tcpros_${name}.XXXXXX")
  trap 'rm -rf "$work"' EXIT
  t0=$SECONDS
  echo "== $name: building in $work"
  cmake -S "$PKG" -B "$work/build" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCATKIN_DEVEL_PREFIX="$work/devel" \
    -DCATKIN_ENABLE_TESTING=ON -DPYTHON_EXECUTABLE=/usr/bin/python3 \
    -DCMAKE_CXX_FLAGS="$flags -fno-omit-frame-pointer" -DCMAKE_EXE_LINKER_FLAGS="$flags" \
    -DCMAKE_SHARED_LINKER_FLAGS="$flags" > "$work/cmake.log" 2>&1 || { tail -30 "$work/cmake.log"; exit 1; }
  make -C "$work/build" -j2 test_tcpros tcpros_peer > "$work/make.log" 2>&1 || { tail -30 "$work/make.log"; exit 1; }
  built=$((SECONDS - t0))
  echo "== $name: running test_tcpros (built in ${built} s)"
  export TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1 suppressions=$PKG/test/tsan.supp"
  export ASAN_OPTIONS="halt_on_error=1 detect_leaks=1 detect_stack_use_after_return=1"
  export UBSAN_OPTIONS="halt_on_error=1 print_stacktrace=1"
  "$work/devel/lib/moverl_tcpros/test_tcpros" --gtest_brief=1 || { echo "== $name: FAILED" >&2; exit 1; }
  echo "== $name: clean (built in ${built} s, ran in $((SECONDS - t0 - built)) s)"
  rm -rf "$work"
  trap - EXIT
done
