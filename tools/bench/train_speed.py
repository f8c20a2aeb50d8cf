#!/usr/bin/env python3
"""Training speed of this code against the previous release: the same ``train.py`` command, the
same seed and number of steps, run under both, alternately, in the same minutes (issue #30).

    python tools/bench/train_speed.py --task grasp --timesteps 200000      # PPO from reward (config/ppo_grasp.yaml)
    python tools/bench/train_speed.py --task reach --timesteps 60000 --repeats 3
    python tools/bench/train_speed.py --task grasp --timesteps 61440 \
        --baseline-hyperparams ppo_grasp_inline_starts    # this code, one setting changed

Both must train to the same weights (the final ``policy.pth`` is hashed): when they do, the run
to any success rate takes the same steps under both, so the ratio of their speeds is the ratio
of their times to solve, measured here in minutes instead of the 20-25 of a grasp run to 95 %.
Should the weights differ, the bench says so, and the speed ratio no longer stands for the time to
solve.

``--baseline-hyperparams FILE`` compares this code with itself instead: the task's default file
against FILE (a variant that changes one setting), alternately, e.g. the curriculum's starts
prepared ahead or at each reset. The two may train to different weights; each one's repeats must
not (``repeats_same_weights``). Writes train_speed_<task>_against_<FILE's stem>.json.

The release is the commit in tools/bench/reference_release.yaml (``--reference REV``), exported by
tools/bench/reference.py. Writes bench/results/train_speed_<task>.json and updates summary.json.
"""
from __future__ import annotations

import argparse
import hashlib
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path
from typing import Any, Dict, List, Optional

from benchlib import AT_MOST, REPO, RESULTS_DIR, update_summary, verdict, write_result
from reference import (ReferenceUnavailable, alternating, reference_environment, reference_release, reference_tree,
                       resolve)
from time_to_solve import cpu_use, machine_cpu_times


def policy_hash(run_dir: Path) -> str:
    """SHA-256 (16 hex digits) of the final model's policy weights."""
    with zipfile.ZipFile(run_dir / "final" / "model.zip") as archive:
        return hashlib.sha256(archive.read("policy.pth")).hexdigest()[:16]


def run_once(root: Path, environment: Optional[Dict[str, str]], task: str, seed: int, timesteps: int,
             hyperparams: Optional[str] = None) -> Dict[str, Any]:
    """One ``train.py`` run of ``root``'s code: wall time, steps/s, CPU use, the weights' hash.

    :param hyperparams: a hyperparameter file instead of the task's default (None: the default).
    """
    run_dir = Path(tempfile.mkdtemp(prefix=f"fr5_train_speed_{task}_"))
    command = [sys.executable, str(root / "scripts" / "train.py"), "--task", task, "--seed", str(seed),
               "--timesteps", str(timesteps), "--run-dir", str(run_dir), "--no-progress",
               "--eval-freq", str(10 * timesteps)]  # no evaluation: it is not what is compared
    if hyperparams is not None:
        command += ["--hyperparams", hyperparams]
    try:
        start, before = time.perf_counter(), machine_cpu_times()
        subprocess.run(command, check=True, cwd=root, env=environment, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - start
        return {"wall_s": round(wall, 2), "steps_per_s": round(timesteps / wall, 1),
                "cpu": cpu_use(before, machine_cpu_times()), "policy_hash": policy_hash(run_dir)}
    finally:
        shutil.rmtree(run_dir, ignore_errors=True)


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", choices=["reach", "grasp"], default="grasp")
    parser.add_argument("--timesteps", type=int, default=200_000)
    parser.add_argument("--seed", type=int, default=31)
    parser.add_argument("--repeats", type=int, default=2, help="runs of each code (default 2)")
    parser.add_argument("--reference", default=None, help="default: tools/bench/reference_release.yaml")
    parser.add_argument("--results", type=Path, default=RESULTS_DIR)
    parser.add_argument("--baseline-hyperparams", default=None, metavar="FILE",
                        help="compare with this code under FILE (a name in config/ or a path) instead of the release")
    args = parser.parse_args(argv)
    baseline = args.baseline_hyperparams
    if baseline is None:
        revision = args.reference or reference_release()
        try:
            tree = reference_tree(revision)
        except ReferenceUnavailable as error:
            print(f"train_speed: {error}")
            return 2
        tree_environment = reference_environment(tree)
        old_name = "the release"
    else:
        revision, tree, tree_environment, old_name = None, REPO, None, f"this code under {baseline}"
    runs: Dict[str, List[Dict[str, Any]]] = {"new": [], "old": []}
    for repeat in range(args.repeats):
        for which in alternating(repeat):
            root, environment = (REPO, None) if which == "new" else (tree, tree_environment)
            run = run_once(root, environment, args.task, args.seed, args.timesteps,
                           baseline if which == "old" else None)
            runs[which].append(run)
            print(f"{'this code' if which == 'new' else old_name}: {run['wall_s']} s for {args.timesteps} steps "
                  f"({run['steps_per_s']:.0f}/s), cores {run['cpu']['utilisation']:.0%} busy, weights {run['policy_hash']}")
    new_s = round(statistics.median(r["wall_s"] for r in runs["new"]), 2)
    old_s = round(statistics.median(r["wall_s"] for r in runs["old"]), 2)
    hashes = {r["policy_hash"] for r in runs["new"] + runs["old"]}
    result = {"task": args.task, "seed": args.seed, "timesteps": args.timesteps, "new_median_s": new_s,
              "old_median_s": old_s, "time_ratio": round(new_s / old_s, 3), "same_weights": len(hashes) == 1,
              "cpu_utilisation_new_median": statistics.median(r["cpu"]["utilisation"] for r in runs["new"]),
              "cpu_utilisation_old_median": statistics.median(r["cpu"]["utilisation"] for r in runs["old"]),
              "runs": runs}
    # Each side's repeats alike: training is deterministic whatever the timing.
    differing = sum(r["policy_hash"] != runs[side][0]["policy_hash"] for side in runs for r in runs[side])
    result["repeats_same_weights"] = differing == 0
    if baseline is None:
        result.update(release=revision, commit=resolve(revision))
        name = f"train_speed_{args.task}"
    else:
        try:
            commit = resolve("HEAD")
        except ReferenceUnavailable:  # not a git checkout: the figures stand without it
            commit = None
        result.update(baseline_hyperparams=baseline, commit=commit)
        name = f"train_speed_{args.task}_against_{Path(baseline).stem}"
    verdicts = {"repeats_deterministic": verdict(
        differing, 0, AT_MOST, "runs", "repeats that trained to other weights than their side's first")}
    if baseline is None:  # issue #30's target is against the release; a setting against itself has none
        verdicts["time_halved"] = verdict(result["time_ratio"], 0.5, AT_MOST, "x",
                                          f"{args.task} training time for the same steps, this code / {old_name}")
    path = write_result(args.results / f"{name}.json", result, verdicts)
    update_summary(args.results, path.stem, path)
    print(f"{args.task}, {args.timesteps} steps, seed {args.seed}: this code {new_s} s, {old_name} {old_s} s "
          f"(new/old {result['time_ratio']}); the same weights: {result['same_weights']}"
          + "".join(f"; {one['text']}" for one in verdicts.values()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
