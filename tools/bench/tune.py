"""Ray Tune bench: training throughput on 1 vs 2 Ray nodes, and the compute ASHA needs to find
a configuration that solves reach (95 % evaluation success) against running every trial to the end.

    python tools/bench/tune.py            # full: 37 min on 2 cores (8 trials x up to 300 k steps, twice)
    python tools/bench/tune.py --quick    # smoke: a few minutes, tiny trials (no 95 % expected)

Both parts run on a Ray cluster made on this machine with ``ray.cluster_utils.Cluster``, one
CPU per node, and call the library's experiment (:class:`fr5_rl.training.tune.TuneExperiment`),
the code ``tune.py`` runs.

1. **Throughput**: the same trials (seeds 0..K-1 of config/ppo_reach.yaml, one environment
   each, no early stopping) on 1 node and on 2 nodes; env steps of all trials per second of
   the sweep's wall time (Ray start excluded).
2. **ASHA vs full**: the same sampled configurations (random search, fixed search seed) of
   config/search_ppo_reach.yaml with ``--scheduler asha`` and ``--scheduler none``. Compute is
   counted in env steps: in all (the whole sweep), and until the first report of 95 %.

Writes bench/results/tune.json (tune_quick.json with --quick) and updates summary.json.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

import yaml

from benchlib import AT_LEAST, AT_MOST, RESULTS_DIR, update_summary, verdict, write_result

from fr5_rl.config import load_yaml
from fr5_rl.training.tune.experiment import TuneExperiment
from fr5_rl.training.tune.settings import build_settings

MB = 1024 * 1024
# mode -> settings of both parts
MODES = {
    "quick": {"throughput": {"trials": 2, "timesteps": 3072},
              "asha": {"samples": 4, "timesteps": 4096, "eval_freq": 1024, "eval_episodes": 4, "grace": 1024,
                       "tiny": True}},
    "full": {"throughput": {"trials": 2, "timesteps": 20480},
             "asha": {"samples": 8, "timesteps": None, "eval_freq": None, "eval_episodes": None, "grace": None,
                      "tiny": False}},
}
TINY = {"algo_kwargs.n_steps": 256, "algo_kwargs.batch_size": 64, "algo_kwargs.n_epochs": 2,
        "algo_kwargs.policy_kwargs.net_arch": {"pi": [32, 32], "vf": [32, 32]}}


def start_cluster(nodes: int):
    """A local Ray cluster of ``nodes`` one-CPU nodes, this process connected as the driver."""
    import ray
    from ray.cluster_utils import Cluster

    args = {"num_cpus": 1, "object_store_memory": 100 * MB}
    cluster = Cluster(initialize_head=True, head_node_args={**args, "include_dashboard": False})
    for _ in range(nodes - 1):
        cluster.add_node(**args)
    cluster.wait_for_nodes()
    ray.init(address=cluster.address, logging_level="warning", log_to_driver=False)
    return cluster


def stop_cluster(cluster) -> None:
    import ray

    ray.shutdown()
    cluster.shutdown()


def write_space(path: Path, base: Dict[str, Any], trial: Dict[str, Any], asha: Dict[str, Any],
                fixed: Dict[str, Any], space: Dict[str, Any]) -> Path:
    path.write_text(yaml.safe_dump({"base": base, "trial": trial, "asha": asha, "fixed": fixed, "space": space},
                                   sort_keys=False), encoding="utf-8")
    return path


def sweep(nodes: int, space: Path, out: Path, samples: int, search: str, scheduler: str) -> Dict[str, Any]:
    """One experiment on a fresh ``nodes``-node cluster: its rows and wall time."""
    cluster = start_cluster(nodes)
    try:
        settings = build_settings("reach", "ppo", samples, search, scheduler, out, space)
        start = time.time()
        rows = TuneExperiment(settings).run()
        wall = time.time() - start
    finally:
        stop_cluster(cluster)
    return {"rows": rows, "wall_s": wall}


def throughput(mode: Dict[str, Any], scratch: Path) -> Dict[str, Any]:
    trials, timesteps = mode["trials"], mode["timesteps"]
    space = write_space(scratch / "throughput.yaml", "ppo_reach",
                        {"n_envs": 1, "timesteps": timesteps, "eval_freq": timesteps, "eval_episodes": 2,
                         "target_success": 1.0, "stop_at_success": False, "max_failures": 0},
                        {"grace_period": timesteps, "reduction_factor": 2},
                        # one environment per trial: its rollout is the shipped update's 512 samples
                        {"algo_kwargs.n_steps": 512, "algo_kwargs.batch_size": 512},
                        {"seed": {"grid": list(range(trials))}})
    result: Dict[str, Any] = {"trials": trials, "timesteps_per_trial": timesteps}
    for nodes in (1, 2):
        run = sweep(nodes, space, scratch / f"throughput_{nodes}", 1, "random", "none")
        steps = sum(row["steps"] for row in run["rows"])
        result[f"{nodes}_node"] = {"env_steps": steps, "wall_s": round(run["wall_s"], 1),
                                   "steps_per_s": round(steps / run["wall_s"], 1),
                                   # inside the trials (train.py's clock): without Ray's and the
                                   # workers' start-up, which dominates short trials
                                   "training_steps_per_s_per_trial": round(sum(
                                       row["steps"] / max(row["wall_s"], 1e-9) for row in run["rows"])
                                       / max(len(run["rows"]), 1), 1),
                                   "nodes_used": len({row["node_id"] for row in run["rows"]})}
        print(f"throughput on {nodes} node(s): {steps} steps in {run['wall_s']:.1f} s = "
              f"{steps / run['wall_s']:.0f} steps/s")
    result["speed_up"] = round(result["2_node"]["steps_per_s"] / result["1_node"]["steps_per_s"], 2)
    return result


def compute_to_find(rows: List[Dict[str, Any]], target: float) -> Dict[str, Any]:
    """Env steps of the whole sweep, and of all trials up to the first report at ``target``."""
    reports = sorted((h[2], row["trial_id"], h[0], h[1]) for row in rows for h in row["history"])
    total = sum(row["steps"] for row in rows)
    found = next(((stamp, trial) for stamp, trial, _, success in reports if success >= target), None)
    until = None
    if found is not None:
        latest: Dict[str, int] = {}
        for stamp, trial, steps, _ in reports:
            if stamp <= found[0]:
                latest[trial] = steps
        until = sum(latest.values())
    best = rows[0] if rows else {}
    return {"total_env_steps": total, "env_steps_until_found": until, "found": found is not None,
            "best_success": best.get("success"), "best_trial_steps": best.get("steps"),
            "trials": len(rows), "stopped_early": sum(row["status"] == "stopped early" for row in rows),
            "solved": sum(row["status"] == "solved" for row in rows)}


def asha_vs_full(mode: Dict[str, Any], scratch: Path, nodes: int) -> Dict[str, Any]:
    shipped = load_yaml("search_ppo_reach")
    trial = dict(shipped["trial"], max_failures=1)
    asha = dict(shipped["asha"])
    fixed = dict(shipped["fixed"])
    space = dict(shipped["space"])
    if mode["tiny"]:
        trial.update(timesteps=mode["timesteps"], eval_freq=mode["eval_freq"], eval_episodes=mode["eval_episodes"])
        asha["grace_period"] = mode["grace"]
        fixed.update(TINY)
        space = {key: value for key, value in space.items() if key not in ("algo_kwargs.n_steps", "algo_kwargs.batch_size")}
    path = write_space(scratch / "asha.yaml", shipped["base"], trial, asha, fixed, space)
    result: Dict[str, Any] = {"samples": mode["samples"], "nodes": nodes, "trial": trial, "asha": asha,
                              "target_success": trial["target_success"]}
    for scheduler in ("asha", "none"):
        run = sweep(nodes, path, scratch / f"asha_{scheduler}", mode["samples"], "random", scheduler)
        figures = compute_to_find(run["rows"], trial["target_success"])
        figures["wall_s"] = round(run["wall_s"], 1)
        figures["table"] = [{key: row[key] for key in ("trial_id", "status", "success", "steps", "timesteps_to_solve")}
                            for row in run["rows"]]
        result[scheduler] = figures
        print(f"scheduler {scheduler}: {figures['total_env_steps']} env steps in all, "
              f"{figures['env_steps_until_found']} until {trial['target_success']:.0%} found, "
              f"best {figures['best_success']}, {run['wall_s']:.0f} s")
    if result["asha"]["total_env_steps"]:
        result["asha_compute_fraction"] = round(result["asha"]["total_env_steps"] / result["none"]["total_env_steps"], 3)
    return result


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="tiny trials: a smoke run of a few minutes")
    parser.add_argument("--nodes", type=int, default=2, help="nodes for the ASHA part (2)")
    parser.add_argument("--samples", type=int, default=None, help="trials of the ASHA part (quick 4, full 8)")
    parser.add_argument("--skip-throughput", action="store_true")
    parser.add_argument("--skip-asha", action="store_true")
    parser.add_argument("--results", type=Path, default=RESULTS_DIR,
                        help="output directory (default bench/results); its summary.json is updated")
    args = parser.parse_args(argv)
    mode = MODES["quick" if args.quick else "full"]
    if args.samples:
        mode["asha"]["samples"] = args.samples
    os.environ.setdefault("RAY_DEDUP_LOGS", "1")
    result: Dict[str, Any] = {"quick": args.quick, "load_average_start": list(os.getloadavg())}
    verdicts: Dict[str, Dict[str, Any]] = {}
    with tempfile.TemporaryDirectory(prefix="fr5_bench_tune_") as scratch:
        if not args.skip_throughput:
            result["throughput"] = throughput(mode["throughput"], Path(scratch))
            verdicts["two_node_speed_up"] = verdict(result["throughput"]["speed_up"], 1.5, AT_LEAST, "x",
                                                    "training throughput, 2 nodes over 1 node")
        if not args.skip_asha:
            result["asha_vs_full"] = asha_vs_full(mode["asha"], Path(scratch), args.nodes)
            fraction = result["asha_vs_full"].get("asha_compute_fraction")
            verdicts["asha_compute_fraction"] = verdict(fraction, 1.0, AT_MOST, "",
                                                        "ASHA's env steps as a fraction of running every trial")
            if not args.quick:
                asha = result["asha_vs_full"]["asha"]
                verdicts["asha_finds_95"] = verdict(1.0 if asha["found"] else 0.0, 1.0, AT_LEAST, "",
                                                    "ASHA found a config at 95 % (1 = yes)")
    result["load_average_end"] = list(os.getloadavg())
    path = write_result(args.results / f"tune{'_quick' if args.quick else ''}.json", result, verdicts)
    summary = update_summary(args.results, path.stem, path)
    for entry in verdicts.values():
        print(entry["text"])
    print(f"wrote {os.path.relpath(path)}, {os.path.relpath(summary)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
