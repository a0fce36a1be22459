#!/usr/bin/env bash
# MoveRL entry points (run ./catkin_ws_setup.sh first):
#   ./run.sh demo     short safe PPO training on the table world; prints success, interventions, contacts, steps/s
#   ./run.sh test     every test: lint, gtest (C++ cores), pytest (Python cores), rostest (live graph), env checks
#   ./run.sh lint     style checks only (clang-format, ruff, catkin_lint); --fix rewrites the files
#   ./run.sh bench    speed benchmark (env steps/s shield on/off, bare PyBullet, panda-gym, check latencies)
#   ./run.sh train .. moverl_gym's train.py with your arguments (SB3; --n-envs N parallel envs)
#   ./run.sh rllib .. rllib_train.py: RLlib PPO, N env runners on a local Ray cluster of its own or --address
#   ./run.sh scaling  steps/s and CPU per env step for 1, 2, 4 envs: SubprocVecEnv, RLlib, panda-gym
#   ./run.sh study .. the paper's Figures 6 and 7 (18 PPO runs; --quick for a short version)
#   ./run.sh eval ..  evaluate a saved model (run folder or model.zip)
set -eo pipefail
cd "$(dirname "$0")"
# shellcheck disable=SC1091
source ./env.sh
cmd=${1:-}; shift || true
case "$cmd" in
  demo)  exec python src/moverl_gym/scripts/train.py --env MoveRL/PandaReachTable-v0 -n 5000 --log-folder runs/demo "$@" ;;
  train) exec python src/moverl_gym/scripts/train.py "$@" ;;
  rllib) exec python src/moverl_gym/scripts/rllib_train.py "$@" ;;
  scaling) exec python src/moverl_gym/scripts/scaling.py "$@" ;;
  bench) exec python src/moverl_gym/scripts/benchmark.py "$@" ;;
  test)  exec bash tests/run_all.sh "$@" ;;
  lint)  exec bash tests/lint.sh "$@" ;;
  study) exec python src/moverl_gym/scripts/study.py "$@" ;;
  eval)  exec python src/moverl_gym/scripts/evaluate.py "$@" ;;
  *) sed -n '2,10p' "$0"; exit 2 ;;
esac
