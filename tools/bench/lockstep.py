"""Lockstep ROS-in-the-loop evaluation against gym, episode by episode.

    python tools/bench/lockstep.py [--model models/reach] [--episodes 200] [--seed 800000] [--real-time]

Runs ``sim_policy.launch lockstep:=true`` headless on its own ROS master (the policy node's own
code, on /clock), and the gym evaluation of the same model on the same seeds, then compares
each episode's outcome (success, failure cause, steps). With ``--real-time`` it also runs the
real-time loop on the same seeds and reports its gap to lockstep. Writes
bench/results/lockstep_<task>.json and updates bench/results/summary.json. Targets: every
episode agrees with gym; lockstep faster than real time.
"""
import argparse
import os
import re
import sys
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

from benchlib import AT_LEAST, REPO, RESULTS_DIR, relative_path, update_summary, verdict, write_result
from roslaunch_run import run_launch

TARGETS = {"agreement": 1.0, "speed_vs_real_time": 1.0}


def run_sim(model: str, task: str, episodes: int, seed: int, port: int, lockstep: bool,
            backend: str) -> Dict[str, Any]:
    """One headless ``sim_policy.launch``; its outcomes (the outcome log) and the node's printed
    speed (the ``lockstep:`` line: simulated time over wall time after start-up)."""
    run = run_launch({"rviz": False, "model": model, "task": task, "backend": backend, "episodes": episodes,
                      "seed": seed, "lockstep": lockstep}, port=port, episodes=episodes)
    speed_lines = run.lines_starting("lockstep:")
    return {"records": run.records, "wall_s": run.wall_s, "speed_line": speed_lines[-1] if speed_lines else ""}


def compare(gym: List[Dict[str, Any]], ros: List[Dict[str, Any]]) -> Dict[str, Any]:
    """Per seed: same success, same failure cause, same number of steps."""
    by_seed = {record["seed"]: record for record in ros}
    same_outcome = same_steps = 0
    differences = []
    for record in gym:
        other = by_seed.get(record["seed"])
        if other is None:
            differences.append({"seed": record["seed"], "gym": record, "ros": None})
            continue
        outcome_equal = other["success"] == record["success"] and other["failure"] == record["failure"]
        same_outcome += outcome_equal
        same_steps += outcome_equal and other["steps"] == record["length"]
        if not (outcome_equal and other["steps"] == record["length"]):
            differences.append({"seed": record["seed"], "gym": {k: record[k] for k in ("success", "failure", "length")},
                                "ros": {k: other[k] for k in ("success", "failure", "steps")}})
    n = len(gym)
    return {"episodes": n, "same_outcome": same_outcome, "same_outcome_and_steps": same_steps,
            "agreement": same_outcome / n if n else 0.0, "differences": differences[:20]}


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", default="models/reach", help="model directory, relative to the repository")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=800000)
    parser.add_argument("--backend", choices=["torch", "onnx"], default="torch")
    parser.add_argument("--port", type=int, default=11421)
    parser.add_argument("--real-time", action="store_true", help="also run the real-time loop on the same seeds")
    parser.add_argument("--results", type=Path, default=RESULTS_DIR,
                        help="output directory (default bench/results); its summary.json is updated")
    args = parser.parse_args(argv)
    from fr5_rl.deploy.policy import load_policy
    from fr5_rl.training.evaluation import run_episodes

    model_dir = REPO / args.model
    policy = load_policy(model_dir, args.backend)
    task = policy.task
    seeds = list(range(args.seed, args.seed + args.episodes))
    started = time.time()
    gym = run_episodes(task, policy.deployment_overrides(), lambda env: (policy.act, None), seeds)
    gym_wall = time.time() - started

    lockstep = run_sim(args.model, task, args.episodes, args.seed, args.port, True, args.backend)
    real_time = (run_sim(args.model, task, args.episodes, args.seed, args.port + 1, False, args.backend)
                 if args.real_time else None)

    simulated = sum(record["steps"] for record in lockstep["records"]) * policy.meta.get("control_dt", 0.02)
    # The node's own figure excludes start-up (ROS master, model loading): the evaluation's speed.
    reported = re.search(r"\(([\d.]+)x real time\)", lockstep["speed_line"])
    result: Dict[str, Any] = {
        "model": relative_path(model_dir), "task": task, "backend": args.backend, "seeds": [seeds[0], seeds[-1]],
        "gym_successes": sum(r["success"] for r in gym), "gym_wall_s": round(gym_wall, 1),
        "lockstep_successes": sum(r["success"] for r in lockstep["records"]),
        "lockstep_wall_s": round(lockstep["wall_s"], 1), "lockstep_episode_time_simulated_s": round(simulated, 1),
        "lockstep_speed_vs_real_time": float(reported.group(1)) if reported else None,
        "lockstep_speed_with_start_up": round(simulated / lockstep["wall_s"], 2) if lockstep["wall_s"] else None,
        "lockstep_node_report": lockstep["speed_line"],
        "lockstep_late_periods": sum(r.get("late_periods", 0) for r in lockstep["records"]),
        "lockstep_vs_gym": compare(gym, lockstep["records"]),
        "targets": dict(TARGETS),
    }
    if real_time is not None:
        lockstep_as_gym = [{"seed": r["seed"], "success": r["success"], "failure": r["failure"], "length": r["steps"]}
                           for r in lockstep["records"]]
        result["real_time_successes"] = sum(r["success"] for r in real_time["records"])
        result["real_time_wall_s"] = round(real_time["wall_s"], 1)
        result["real_time_vs_lockstep"] = compare(lockstep_as_gym, real_time["records"])
    agreement = result["lockstep_vs_gym"]
    verdicts = {
        "lockstep_agreement": verdict(agreement["agreement"], TARGETS["agreement"], AT_LEAST, "",
                                      f"{task} lockstep ROS episodes with gym's outcome"),
        "lockstep_speed": verdict(result["lockstep_speed_vs_real_time"], TARGETS["speed_vs_real_time"], AT_LEAST,
                                  "x", f"{task} lockstep speed against real time"),
    }
    print(f"gym: {result['gym_successes']}/{len(gym)} in {gym_wall:.0f} s; lockstep ROS: "
          f"{result['lockstep_successes']}/{len(lockstep['records'])} in {lockstep['wall_s']:.0f} s "
          f"({result['lockstep_speed_vs_real_time']}x real time, {result['lockstep_late_periods']} late periods)")
    print(f"per episode: {agreement['same_outcome']}/{agreement['episodes']} same outcome, "
          f"{agreement['same_outcome_and_steps']}/{agreement['episodes']} same outcome and steps")
    if real_time is not None:
        gap = result["real_time_vs_lockstep"]
        print(f"real time: {result['real_time_successes']}/{len(real_time['records'])}; "
              f"{gap['same_outcome']}/{gap['episodes']} episodes as in lockstep")
    for v in verdicts.values():
        print(f"  {v['text']}")
    path = write_result(args.results / f"lockstep_{task}.json", result, verdicts)
    update_summary(args.results, path.stem, path)
    print(f"wrote {os.path.relpath(path)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
