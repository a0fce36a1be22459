#!/usr/bin/env bash
# MoveRL entry points (run ./catkin_ws_setup.sh first). ./run.sh <command> --help (or -h): that command's options.
#   ./run.sh demo     short safe PPO training on the table world; prints success, interventions, contacts, steps/s
#   ./run.sh test     every test, as CI runs them: lint, then the tiers core, quick, live (tests/run_all.sh);
#                     --quick: the cores and the fastest live checks; --no-live: the cores only
#   ./run.sh lint     style checks only (clang-format, ruff, catkin_lint); --fix rewrites the files
#   ./run.sh bench    speed benchmark (env steps/s shield on/off, bare PyBullet, panda-gym, check latencies)
#   ./run.sh train .. moverl_gym's train.py with your arguments (SB3; --n-envs N parallel envs)
#   ./run.sh rllib .. rllib_train.py: RLlib PPO, N env runners on a local Ray cluster of its own or --address
#   ./run.sh scaling  steps/s and CPU per env step for 1, 2, 4 envs: SubprocVecEnv, RLlib, panda-gym
#   ./run.sh study .. the paper's Figures 6 and 7 (18 PPO runs; --quick for a short version)
#   ./run.sh eval ..  evaluate a saved model (run folder or model.zip)
set -eo pipefail
cd "$(dirname "$0")"
commands() { sed -n '2,/^[^#]/s/^# \{0,1\}//p' "$0"; }  # the comment above
wants_help() { for a in "$@"; do [[ $a == -h || $a == --help ]] && return 0; done; return 1; }
cmd=${1:-}; shift || true
case "$cmd" in
  -h|--help|help) commands; exit 0 ;;
  "") commands >&2; exit 2 ;;
esac
# shellcheck disable=SC1091
source ./env.sh  # (none of run.sh's arguments reaches ROS's setup scripts: env.sh sees to it)
scripts=src/moverl_gym/scripts  # the entry points
tools=src/moverl_gym/tools      # audits, fuzzing, soak, benchmarks, probes
demo=(--env MoveRL/PandaReachTable-v0 -n 5000 --log-folder runs/demo)
case "$cmd" in
  demo)
    if wants_help "$@"; then
      echo "usage: ./run.sh demo [train.py options]"
      echo "A short safe PPO training: train.py ${demo[*]}"
      echo "and the options given (a later one wins: --shield off, -n 20000). train.py's options:"
      exec python $scripts/train.py --help
    fi
    exec python $scripts/train.py "${demo[@]}" "$@" ;;
  train) exec python $scripts/train.py "$@" ;;
  rllib) exec python $scripts/rllib_train.py "$@" ;;
  scaling) exec python $tools/scaling.py "$@" ;;
  bench) exec python $tools/benchmark.py "$@" ;;
  test)  exec bash tests/run_all.sh "$@" ;;
  lint)  exec bash tests/lint.sh "$@" ;;
  study) exec python $scripts/study.py "$@" ;;
  eval)  exec python $scripts/evaluate.py "$@" ;;
  *) echo "run.sh: no command '$cmd'" >&2; commands >&2; exit 2 ;;
esac
