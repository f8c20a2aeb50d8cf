#!/usr/bin/env bash
# `make demo`: the closed loop (simulator + static transforms + robot_state_publisher + policy)
# with the shipped reach model. With a display, rviz shows it; without one (or in CI) it runs
# headless for EPISODES episodes and prints each outcome and the success rate.
set -euo pipefail
episodes="${1:-5}"
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# Runnable on its own too: enter the environment that tools/setup.sh made.
set +u; source "$repo/env.sh"; set -u
model="${MODEL:-models/reach}"
if [ -n "${DISPLAY:-}" ] && [ -z "${CI:-}" ]; then
  echo "[demo] rviz on $DISPLAY; Ctrl-C to stop"
  exec roslaunch fr5_rl sim_policy.launch model:="$model"
fi
echo "[demo] no display: running $episodes episodes headless with $model"
roslaunch fr5_rl sim_policy.launch rviz:=false episodes:="$episodes" model:="$model" 2>&1 \
  | grep --line-buffered -E "episode [0-9]+:|success rate:|policy_node: (reach|grasp) model|FATAL|ERROR|Traceback"
