#!/usr/bin/env bash
# Style checks: clang-format (C++, .clang-format), ruff check + ruff format (Python, pyproject.toml) and catkin_lint
# (the catkin packages). Exits non-zero on any finding. Run by `./run.sh lint` and as the first suite of
# `./run.sh test`. The tools are pinned in requirements.txt (installed into .venv by catkin_ws_setup.sh).
#   tests/lint.sh          check
#   tests/lint.sh --fix    rewrite the files in place (clang-format -i, ruff format, ruff check --fix), then check
set -uo pipefail
cd "$(dirname "$0")/.."
case "${1:-}" in
  ""|--fix) ;;
  -h|--help) sed -n '2,/^[^#]/s/^# \{0,1\}//p' "$0"; exit 0 ;;
  *) echo "lint.sh: unknown option '$1' (--fix, --help)" >&2; exit 2 ;;
esac
bin=.venv/bin
for tool in clang-format ruff catkin_lint; do
  [ -x "$bin/$tool" ] || { echo "lint: $bin/$tool is missing: run ./catkin_ws_setup.sh" >&2; exit 2; }
done
mapfile -t cpp < <(git ls-files '*.cpp' '*.cc' '*.h' '*.hpp')
# Python: ruff finds the *.py files under . itself (pyproject.toml's excludes apply); scripts without the suffix (ROS
# nodes in scripts/ folders: rosrun names them by file name) are every other file of the checkout, tracked or new and
# not ignored, whose first line is a python shebang. ruff checks a file named on its command line whatever its suffix.
scripts=()
while IFS= read -r -d '' f; do
  case "$f" in *.py | *.pyi) continue ;; esac
  [ -f "$f" ] && [ ! -L "$f" ] || continue
  IFS= read -r first < "$f" 2>/dev/null || true
  [[ ${first:-} =~ ^#!.*python ]] && scripts+=("$f")
  first=
done < <(git ls-files -z --cached --others --exclude-standard)
if [ "${1:-}" = "--fix" ]; then
  "$bin/clang-format" -i "${cpp[@]}"
  "$bin/ruff" format -q . "${scripts[@]}"
  "$bin/ruff" check -q --fix . "${scripts[@]}"
fi
status=0
echo "clang-format: ${#cpp[@]} C++ files"
"$bin/clang-format" --dry-run --Werror "${cpp[@]}" || status=1
echo "ruff check: the *.py files and ${#scripts[@]} Python scripts without the suffix (${scripts[*]##*/})"
"$bin/ruff" check -q . "${scripts[@]}" || status=1
echo "ruff format --check"
"$bin/ruff" format --check -q . "${scripts[@]}" || status=1
# catkin_lint needs the ROS environment (package paths); rosdep's database is not used (no network here), so the
# names in package.xml are checked against the packages found, not against rosdep's keys.
echo "catkin_lint"
(set +u; source ./env.sh >/dev/null; "$bin/catkin_lint" -q -W1 --strict src 2>&1 | grep -v "rosdep" ;
 exit "${PIPESTATUS[0]}") || status=1
[ "$status" = 0 ] && echo "lint: clean" || echo "lint: FAILED (fix with tests/lint.sh --fix; catkin_lint findings by hand)"
exit "$status"
