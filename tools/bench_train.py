"""Time-to-solve benchmark: wall-clock from start until the evaluation success rate first
reaches the target, on this machine, for the shipped configuration.

    python tools/bench_train.py                  # reach: PPO, config/ppo_reach.yaml, target 95 %
    python tools/bench_train.py --task grasp     # grasp: DAgger, config/dagger_grasp.yaml, target 90 %

Runs the real training command in a temporary run directory (reach stops at success), then
writes bench/results/time_to_solve_<task>.json. Targets: reach <= 15 min, grasp <= 2 h.
"""
import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
RESULTS = REPO / "bench" / "results"

parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
parser.add_argument("--task", choices=["reach", "grasp"], default="reach")
parser.add_argument("--seed", type=int, default=1)
args = parser.parse_args()
run_dir = Path(tempfile.mkdtemp(prefix=f"fr5_bench_{args.task}_"))
start = time.time()
if args.task == "reach":
    command = [sys.executable, str(REPO / "scripts" / "train.py"), "--task", "reach", "--run-dir", str(run_dir),
               "--seed", str(args.seed), "--stop-at-success", "--target-success", "0.95", "--no-progress"]
    target_s, target_rate = 15 * 60, 0.95
else:
    command = [sys.executable, str(REPO / "scripts" / "imitate.py"), "--task", "grasp", "--run-dir", str(run_dir),
               "--seed", str(args.seed)]
    target_s, target_rate = 2 * 3600, 0.90
subprocess.run(command, check=True, cwd=REPO)
summary = json.loads((run_dir / "summary.json").read_text())
if args.task == "reach":
    solved_s, solved_steps = summary.get("time_to_solve_s"), summary.get("timesteps_to_solve")
else:
    solved = [h for h in summary["history"] if h.get("eval_success", 0) >= target_rate]
    solved_s = solved[0]["wall_s"] if solved else None
    solved_steps = solved[0]["samples"] if solved else None
# The command as a reader would type it: no interpreter or temporary-directory paths.
shown = [Path(c).name if i < 2 else ("RUN_DIR" if c == str(run_dir) else c) for i, c in enumerate(command)]
result = {"task": args.task, "command": " ".join(shown),
          "target_success": target_rate, "time_to_solve_s": solved_s, "steps_or_samples_to_solve": solved_steps,
          "target_s": target_s, "wall_time_total_s": round(time.time() - start, 1), "machine": summary.get("machine"),
          "pass": solved_s is not None and solved_s <= target_s}
RESULTS.mkdir(parents=True, exist_ok=True)
(RESULTS / f"time_to_solve_{args.task}.json").write_text(json.dumps(result, indent=2) + "\n")
print(f"time to solve {args.task}: {solved_s} s to {target_rate:.0%} ({'PASS' if result['pass'] else 'FAIL'}, target {target_s / 60:.0f} min)")
