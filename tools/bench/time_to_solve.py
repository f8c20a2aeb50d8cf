"""Time-to-solve benchmark: wall-clock from start until the evaluation success rate first
reaches the target, on this machine, for the shipped configuration, over several seeds.

    python tools/bench/time_to_solve.py                          # reach: PPO, config/ppo_reach.yaml, seeds 1 2 3
    python tools/bench/time_to_solve.py --seeds 4 5 --hyperparams my_reach.yaml
    python tools/bench/time_to_solve.py --task grasp             # grasp: DAgger, config/dagger_grasp.yaml, target 90 %
    python tools/bench/time_to_solve.py --task grasp-from-reward # PPO + curriculum, config/ppo_grasp.yaml, target 95 %

Runs the real training command (``scripts/train.py`` or ``scripts/imitate.py``, as a
subprocess, one seed after the other) in a temporary run directory (train.py's runs stop at success),
then writes bench/results/time_to_solve_<task>.json (every seed's evaluation history, the median
and the worst, and how busy the machine's cores were while each run ran) and a learning-curve plot beside it, and updates summary.json.
Targets: reach median <= 60 s, grasp (DAgger, 90 %) <= 2 h, grasp from reward (95 %) <= 1 h.

Against the previous release (issue #30; ``--no-reference`` skips it): the same command, the
same seeds, run under that release's code (tools/bench/reference.py; the commit in
tools/bench/reference_release.yaml, or ``--reference REV``), alternating with this code's runs;
the result gets ``against_release`` (per seed, medians, new/old ratios) and two verdicts: the
median time halved, the median steps grown by at most 10 %.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

from benchlib import AT_MOST, REPO, RESULTS_DIR, update_summary, verdict, write_result
from reference import ReferenceUnavailable, alternating, reference_environment, reference_release, reference_tree

# task -> (seconds allowed, evaluation success that counts as solved)
TARGETS = {"reach": (60, 0.95), "grasp": (2 * 3600, 0.90), "grasp-from-reward": (3600, 0.95)}
DEFAULT_SEEDS = {"reach": [1, 2, 3], "grasp": [1], "grasp-from-reward": [1]}
# The bench's tasks that train.py trains, and its --task for each.
TRAIN_TASKS = {"reach": "reach", "grasp-from-reward": "grasp"}
# How often reach is evaluated, not how it trains: every 10 k steps, once half of the training
# episodes since the last evaluation succeeded (the deterministic evaluation stands at 0 % long
# before that, and 40 episodes of an untrained policy cost 4.3 s, about 6,000 training steps).
REACH_EVALUATION = ["--eval-freq", "10000", "--eval-min-training-success", "0.5"]
# Grasp from reward: 40 plain-reset episodes every 50 k steps (about 2 s of a run of 10-30 min).
GRASP_FROM_REWARD_EVALUATION = ["--eval-freq", "50000"]


def machine_cpu_times() -> List[int]:
    """The machine's CPU time so far, all cores together, per state (clock ticks, /proc/stat)."""
    with open("/proc/stat", encoding="ascii") as stat:
        return [int(value) for value in stat.readline().split()[1:]]


def cpu_use(before: List[int], after: List[int]) -> Dict[str, Any]:
    """How busy the machine's cores were between two :func:`machine_cpu_times`: busy core-seconds
    (everything but idle and I/O wait) over all core-seconds. Measured on the machine, not the
    process: the environment workers descend from multiprocessing's fork server, whose children's
    times never reach the run's own rusage. On a quiet machine this is the run's use."""
    ticks = os.sysconf("SC_CLK_TCK")
    spent = [b - a for a, b in zip(before, after)]
    idle = spent[3] + spent[4]  # idle, iowait
    total = sum(spent[:8])  # user nice system idle iowait irq softirq steal (guest is inside user)
    return {"cores": os.cpu_count(), "busy_s": round((total - idle) / ticks, 1), "total_s": round(total / ticks, 1),
            "utilisation": round((total - idle) / total, 3) if total else None}


def time_to_solve_verdicts(result: Dict[str, Any]) -> Dict[str, Dict[str, Any]]:
    """Median time to solve at most the task's target; a seed that never solved counts as never
    (so the median is None, not met, once half the seeds fail)."""
    what = f"{result['task']} median time to {result['target_success']:.0%} success over {len(result['seeds'])} seeds"
    return {"time_to_solve_s": verdict(result.get("time_to_solve_s"), result["target_s"], AT_MOST, "s", what)}


def against_release(runs: List[Dict[str, Any]], release_runs: List[Dict[str, Any]], release: str) -> Dict[str, Any]:
    """This code's runs against the release's on the same seeds: medians and their ratios
    (an unsolved seed counts as infinitely slow, so its median may be None)."""
    new_s = median_and_worst([r["time_to_solve_s"] for r in runs])[0]
    old_s = median_and_worst([r["time_to_solve_s"] for r in release_runs])[0]
    new_steps = median_and_worst([r["steps_or_samples_to_solve"] for r in runs])[0]
    old_steps = median_and_worst([r["steps_or_samples_to_solve"] for r in release_runs])[0]
    ratio = lambda a, b: round(a / b, 3) if a is not None and b else None  # noqa: E731
    return {"release": release, "new_median_s": new_s, "old_median_s": old_s, "time_ratio": ratio(new_s, old_s),
            "new_median_steps": new_steps, "old_median_steps": old_steps, "steps_ratio": ratio(new_steps, old_steps),
            "per_seed": [{"seed": new["seed"], "new_s": new["time_to_solve_s"], "old_s": old["time_to_solve_s"],
                          "new_steps": new["steps_or_samples_to_solve"], "old_steps": old["steps_or_samples_to_solve"],
                          "new_cpu_utilisation": new["cpu"]["utilisation"],
                          "old_cpu_utilisation": old["cpu"]["utilisation"]}
                         for new, old in zip(runs, release_runs)],
            "release_runs": release_runs}


def release_verdicts(comparison: Dict[str, Any]) -> Dict[str, Dict[str, Any]]:
    """Issue #30: the median time to solve halved against the release, steps grown by at most 10 %."""
    return {
        "time_halved": verdict(comparison["time_ratio"], 0.5, AT_MOST, "x",
                               "median time to solve, this code / the release, same seeds, same run"),
        "steps_within_10_percent": verdict(comparison["steps_ratio"], 1.1, AT_MOST, "x",
                                           "median steps to solve, this code / the release"),
    }


def median_and_worst(times: List[Optional[float]]):
    """(median, worst) of the seeds' times to solve; an unsolved seed is infinitely slow."""
    ordered = sorted(float("inf") if t is None else t for t in times)
    median = statistics.median(ordered)
    finite = lambda value: None if value == float("inf") else value  # noqa: E731
    return finite(median), finite(ordered[-1])


def plot_curves(runs: List[Dict[str, Any]], target: float, path: Path, title: str) -> None:
    """Evaluation success against steps and against wall time, one line per seed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (by_steps, by_time) = plt.subplots(1, 2, figsize=(10, 3.6))
    for run in runs:
        history = run["eval_history"]
        label = f"seed {run['seed']}"
        by_steps.plot([h["timesteps"] for h in history], [h["success_rate"] for h in history], marker=".", label=label)
        by_time.plot([h["wall_s"] for h in history], [h["success_rate"] for h in history], marker=".", label=label)
    for axis, xlabel in ((by_steps, "environment steps"), (by_time, "wall time (s)")):
        axis.axhline(target, color="grey", linestyle="--", linewidth=0.8)
        axis.set_xlabel(xlabel)
        axis.set_ylabel("evaluation success")
        axis.set_ylim(-0.02, 1.02)
        axis.grid(alpha=0.3)
    by_steps.legend(loc="lower right")
    figure.suptitle(title)
    figure.tight_layout()
    figure.savefig(path, dpi=90)
    plt.close(figure)


def run_seed(task: str, seed: int, target_rate: float, hyperparams: Optional[Path],
             tree: Optional[Path] = None, max_timesteps: Optional[int] = None) -> Dict[str, Any]:
    """One training run from scratch; its time and steps to solve and its evaluation history.

    :param tree: run that tree's code (the previous release, :mod:`reference`) instead of this
        checkout's; its own config files, ``hyperparams`` aside.
    :param max_timesteps: stop a run that has not solved after this many steps (train.py
        ``--timesteps``); it counts as unsolved. None: the configuration's own budget.
    """
    run_dir = Path(tempfile.mkdtemp(prefix=f"fr5_bench_{task}_{seed}_"))
    root = tree or REPO
    environment = None if tree is None else reference_environment(tree)
    trained = task in TRAIN_TASKS  # train.py; grasp is DAgger's imitate.py
    if trained:
        command = [sys.executable, str(root / "scripts" / "train.py"), "--task", TRAIN_TASKS[task],
                   "--run-dir", str(run_dir), "--seed", str(seed), "--stop-at-success",
                   "--target-success", str(target_rate), "--no-progress",
                   *(REACH_EVALUATION if task == "reach" else GRASP_FROM_REWARD_EVALUATION)]
        if hyperparams is not None:
            command += ["--hyperparams", str(hyperparams)]
        if max_timesteps is not None:
            command += ["--timesteps", str(max_timesteps)]
    else:
        command = [sys.executable, str(root / "scripts" / "imitate.py"), "--task", "grasp", "--run-dir", str(run_dir),
                   "--seed", str(seed)]
    start, machine_before = time.time(), machine_cpu_times()
    subprocess.run(command, check=True, cwd=root, env=environment)
    wall = time.time() - start
    cpu = cpu_use(machine_before, machine_cpu_times())
    summary = json.loads((run_dir / "summary.json").read_text())
    if trained:
        solved_s, solved_steps = summary.get("time_to_solve_s"), summary.get("timesteps_to_solve")
        history = summary.get("eval_history", [])
    else:
        history = [{"timesteps": h["samples"], "wall_s": h["wall_s"], "success_rate": h.get("eval_success", 0.0)}
                   for h in summary["history"]]
        solved = [h for h in history if h["success_rate"] >= target_rate]
        solved_s = solved[0]["wall_s"] if solved else None
        solved_steps = solved[0]["timesteps"] if solved else None
    # The command as a reader would type it: no interpreter or temporary-directory paths.
    shown = [Path(c).name if i < 2 else ("RUN_DIR" if c == str(run_dir) else c) for i, c in enumerate(command)]
    print(f"{'release' if tree is not None else 'this code'}, seed {seed}: solved in {solved_s} s, {solved_steps} steps; the {cpu['cores']} cores "
          f"{cpu['utilisation']:.0%} busy ({cpu['busy_s']} of {cpu['total_s']} core-seconds; run directory {run_dir})")
    return {"seed": seed, "command": " ".join(shown), "time_to_solve_s": solved_s,
            "steps_or_samples_to_solve": solved_steps, "wall_time_total_s": round(wall, 1), "cpu": cpu,
            "n_envs": summary.get("n_envs"), "machine": summary.get("machine"),
            "evaluations_skipped": summary.get("evaluations_skipped"), "eval_history": history}


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", choices=sorted(TARGETS), default="reach",
                        help="reach (PPO), grasp (DAgger) or grasp-from-reward (PPO with the expert-start curriculum)")
    parser.add_argument("--seeds", type=int, nargs="+", default=None, help="default: 1 2 3 (reach), 1 (the grasps)")
    parser.add_argument("--hyperparams", type=Path, default=None,
                        help="reach, grasp-from-reward: a hyperparameter YAML instead of the task's default")
    parser.add_argument("--results", type=Path, default=RESULTS_DIR,
                        help="output directory (default bench/results); its summary.json is updated")
    parser.add_argument("--reference", default=None,
                        help="also train the previous release's code on the same seeds, alternating with this code's "
                             "(default release: tools/bench/reference_release.yaml)")
    parser.add_argument("--no-reference", action="store_true", help="only this code")
    parser.add_argument("--max-timesteps", type=int, default=None,
                        help="reach, grasp-from-reward: stop a run unsolved after this many steps (default: the "
                             "configuration's budget, 3 M for grasp from reward, about 50 min on 2 cores)")
    args = parser.parse_args(argv)
    target_s, target_rate = TARGETS[args.task]
    seeds = args.seeds or DEFAULT_SEEDS[args.task]
    tree = None
    if not args.no_reference:
        try:
            tree = reference_tree(args.reference or reference_release())
        except ReferenceUnavailable as error:
            print(f"against the release: skipped, {error}")
    runs, release_runs = [], []
    for index, seed in enumerate(seeds):
        for which in alternating(index):
            if which == "new":
                runs.append(run_seed(args.task, seed, target_rate, args.hyperparams, max_timesteps=args.max_timesteps))
            elif tree is not None:
                release_runs.append(run_seed(args.task, seed, target_rate, args.hyperparams, tree, args.max_timesteps))
    median_s, worst_s = median_and_worst([run["time_to_solve_s"] for run in runs])
    steps = [run["steps_or_samples_to_solve"] for run in runs]
    result = {"task": args.task, "seeds": seeds, "target_success": target_rate, "target_s": target_s,
              "hyperparams": str(args.hyperparams) if args.hyperparams else None, "max_timesteps": args.max_timesteps,
              "time_to_solve_s": median_s, "worst_time_to_solve_s": worst_s,
              "steps_to_solve_median": median_and_worst(steps)[0], "solved_seeds": sum(s is not None for s in steps),
              # busy core-seconds / all core-seconds while each run ran: 1.0 keeps every core busy
              "cpu_utilisation_median": statistics.median(run["cpu"]["utilisation"] for run in runs),
              "runs": runs, "machine": runs[0]["machine"],
              "pass": median_s is not None and median_s <= target_s}
    verdicts = time_to_solve_verdicts(result)
    if release_runs:
        result["against_release"] = against_release(runs, release_runs, args.reference or reference_release())
        verdicts.update(release_verdicts(result["against_release"]))
    path = write_result(args.results / f"time_to_solve_{args.task}.json", result, verdicts)
    plot = path.with_suffix(".png")
    plot_curves(runs, target_rate, plot, f"{args.task}: evaluation success, {len(seeds)} seeds")
    summary_path = update_summary(args.results, path.stem, path)
    print(f"time to solve {args.task} over seeds {seeds}: median {median_s} s, worst {worst_s} s to "
          f"{target_rate:.0%} (target {target_s:.0f} s): {verdicts['time_to_solve_s']['verdict']}")
    if release_runs:
        comparison = result["against_release"]
        for row in comparison["per_seed"]:
            print(f"seed {row['seed']}: this code {row['new_s']} s / {row['new_steps']} steps, the release "
                  f"{row['old_s']} s / {row['old_steps']} steps")
        print(f"against the release {comparison['release']}: median time {comparison['new_median_s']} s against "
              f"{comparison['old_median_s']} s (new/old {comparison['time_ratio']}), median steps new/old "
              f"{comparison['steps_ratio']}: {verdicts['time_halved']['verdict']}, "
              f"{verdicts['steps_within_10_percent']['verdict']}")
    print(f"wrote {os.path.relpath(path)}, {os.path.relpath(plot)}, {os.path.relpath(summary_path)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
