#!/usr/bin/env bash
# `make demo`: the closed loop (simulator + static transforms + robot_state_publisher + policy)
# with the shipped reach model. With a display, rviz shows it; without one (or in CI) it runs
# headless for EPISODES episodes and prints each outcome and the success rate.
# SCENE=clear: a table of several objects cleared one by one (models/place) through the whole
# rehearsal: the simulated camera, the detector choosing the next object (its detections drawn in
# rviz), the vendor driver and gripper; headless, EPISODES scenes.
set -euo pipefail
episodes="${1:-5}"
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# Runnable on its own too: enter the environment that tools/setup.sh made.
set +u; source "$repo/env.sh"; set -u
scene="${SCENE:-}"
case "$scene" in
  "") model="${MODEL:-models/reach}"; extra=(); count=(episodes:="$episodes"); what=episodes ;;
  clear) model="${MODEL:-models/place}"; extra=(vision:=true driver:=fairino scene:=clear); count=(scenes:="$episodes")
    what=scenes ;;
  *) echo "[demo] SCENE must be empty or clear, got '$scene'" >&2; exit 2 ;;
esac
if [ -n "${DISPLAY:-}" ] && [ -z "${CI:-}" ]; then
  echo "[demo] rviz on $DISPLAY; Ctrl-C to stop"
  exec roslaunch fr5_rl sim_policy.launch model:="$model" "${extra[@]}"
fi
echo "[demo] no display: running $episodes $what headless with $model"
roslaunch fr5_rl sim_policy.launch rviz:=false "${count[@]}" model:="$model" "${extra[@]}" 2>&1 \
  | grep --line-buffered -E "episode [0-9]+ \(seed|episode [0-9]+:|success rate:|clearing [0-9]+ scenes|policy_node: (reach|grasp|place) model|FATAL|ERROR|Traceback"
