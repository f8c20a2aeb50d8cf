"""Time-to-solve benchmark: wall-clock from start until the evaluation success rate first
reaches the target, on this machine, for the shipped configuration.

    python tools/bench_train.py                  # reach: PPO, config/ppo_reach.yaml, target 95 %
    python tools/bench_train.py --task grasp     # grasp: DAgger, config/dagger_grasp.yaml, target 90 %

Runs the real training command (``scripts/train.py`` or ``scripts/imitate.py``, as a
subprocess) in a temporary run directory (reach stops at success), then writes
bench/results/time_to_solve_<task>.json and updates that bench's entries in
bench/results/summary.json. Targets: reach <= 15 min, grasp <= 2 h.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

from benchlib import AT_MOST, REPO, RESULTS_DIR, update_summary, verdict, write_result

# task -> (seconds allowed, evaluation success that counts as solved)
TARGETS = {"reach": (15 * 60, 0.95), "grasp": (2 * 3600, 0.90)}


def time_to_solve_verdicts(result: Dict[str, Any]) -> Dict[str, Dict[str, Any]]:
    """Time to solve at most the task's target; never solved is not met."""
    return {"time_to_solve_s": verdict(result.get("time_to_solve_s"), result["target_s"], AT_MOST, "s",
                                       f"{result['task']} time to {result['target_success']:.0%} success")}


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", choices=["reach", "grasp"], default="reach")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--results", type=Path, default=RESULTS_DIR,
                        help="output directory (default bench/results); its summary.json is updated")
    args = parser.parse_args(argv)
    target_s, target_rate = TARGETS[args.task]
    run_dir = Path(tempfile.mkdtemp(prefix=f"fr5_bench_{args.task}_"))
    start = time.time()
    if args.task == "reach":
        command = [sys.executable, str(REPO / "scripts" / "train.py"), "--task", "reach", "--run-dir", str(run_dir),
                   "--seed", str(args.seed), "--stop-at-success", "--target-success", str(target_rate),
                   "--no-progress"]
    else:
        command = [sys.executable, str(REPO / "scripts" / "imitate.py"), "--task", "grasp", "--run-dir", str(run_dir),
                   "--seed", str(args.seed)]
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
              "target_s": target_s, "wall_time_total_s": round(time.time() - start, 1),
              "machine": summary.get("machine"), "pass": solved_s is not None and solved_s <= target_s}
    verdicts = time_to_solve_verdicts(result)
    path = write_result(args.results / f"time_to_solve_{args.task}.json", result, verdicts)
    summary_path = update_summary(args.results, path.stem, path)
    print(f"time to solve {args.task}: {solved_s} s to {target_rate:.0%} (target {target_s / 60:.0f} min): "
          f"{verdicts['time_to_solve_s']['verdict']}")
    print(f"wrote {os.path.relpath(path)}, {os.path.relpath(summary_path)}; the training run is in {run_dir}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
