#!/usr/bin/env bash
# `make test`: every test of the package, run with env.sh sourced.
#   1. pytest: pure logic, environments, training/export, robot description (test/*.py)
#   2. catkin run_tests: roslaunch file checks and every rostest (test/rostest/*.test), each
#      with a real roscore, real tf2 and robot_state_publisher
# Ends with one line "tests: N passed, N failed" over both; exits non-zero if anything failed.
set -uo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# Runnable on its own too: enter the environment that tools/setup.sh made.
set +u; source "$repo/env.sh"; set -u
cd "$repo"
ws="$FR5_RL_WORKSPACE"
results="$ws/test_results_all"
rm -rf "$results" && mkdir -p "$results"

echo "== pytest =="
python -m pytest -q test/ --junitxml="$results/pytest.xml"
pytest_rc=$?

echo "== rostest (catkin run_tests) =="
rm -rf "$ws/build/test_results"
( cd "$ws" && catkin_make run_tests -j1 > build/run_tests.log 2>&1 )
grep -E "^\[ROSTEST\]|RESULT|FAILURE|ERROR:|\[ROSUNIT\]" "$ws/build/run_tests.log" | grep -v "^\s*$" | tail -40
catkin_test_results "$ws/build/test_results/fr5_rl"
catkin_rc=$?
cp -r "$ws/build/test_results/fr5_rl" "$results/catkin" 2>/dev/null

python tools/test_summary.py "$results"
summary_rc=$?
if [ $pytest_rc -ne 0 ] || [ $catkin_rc -ne 0 ] || [ $summary_rc -ne 0 ]; then
  echo "make test: FAILED (pytest rc=$pytest_rc, rostest rc=$catkin_rc); rostest log: $ws/build/run_tests.log" >&2
  exit 1
fi
