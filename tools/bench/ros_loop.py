"""ROS loop benchmark: control-loop timing inside the policy node and sim-to-ROS parity.

    python tools/bench/ros_loop.py [--model models/reach] [--episodes 20] [--backend onnx] [--busy-cores 1]

Starts ``sim_policy.launch`` headless on its own ROS master, records the policy node's
per-cycle timing (``/fr5_policy/timing``: loop period, inference, compute latency from reading
the inputs to publishing, age of the joint state used, the wait for a new one, repeated states),
and compares the closed-loop success
rate through ROS with the gym evaluation of the same model on the same placements (seeds).
Writes bench/results/ros_loop_<task>.json and updates that bench's entries in
bench/results/summary.json. Targets: latency p99 <= 3 ms, period jitter p99 <= 2 ms, parity
within 5 points. ``--busy-cores N`` keeps N cores busy with bare ``while True`` loops (as a
robot computer's camera drivers and perception would) and writes ros_loop_<task>_busy<N>.json.
"""
import argparse
import os
import subprocess
import sys
from pathlib import Path
from typing import Any, Dict, List, Optional

import numpy as np

from benchlib import AT_LEAST, AT_MOST, REPO, RESULTS_DIR, latency_ms, relative_path, update_summary, verdict, write_result
from roslaunch_run import run_launch

TARGETS = {"compute_latency_p99_ms": 3.0, "period_jitter_p99_ms": 2.0, "parity_points": 5.0, "busy_success_rate": 0.95}


def ros_verdicts(result: Dict[str, Any]) -> Dict[str, Dict[str, Any]]:
    """Compute latency p99 <= 3 ms, period jitter p99 <= 2 ms, ROS-vs-gym gap <= 5 points; a
    timing never recorded is not met."""
    task = result.get("task")
    if result.get("busy_cores"):
        # A busy computer is judged on what the arm does: success as on a quiet one.
        return {"busy_success_rate": verdict(result.get("ros_success_rate"), TARGETS["busy_success_rate"], AT_LEAST,
                                             "", f"{task} success with {result['busy_cores']} core(s) busy")}
    return {
        "compute_latency_p99_ms": verdict((result.get("compute_latency") or {}).get("p99_ms"),
                                          TARGETS["compute_latency_p99_ms"], AT_MOST, "ms",
                                          f"{task} policy node compute latency p99"),
        "period_jitter_p99_ms": verdict((result.get("period_jitter") or {}).get("p99_ms"),
                                        TARGETS["period_jitter_p99_ms"], AT_MOST, "ms",
                                        f"{task} policy node loop period jitter p99"),
        "parity_gap_points": verdict(result.get("parity_gap_points"), TARGETS["parity_points"], AT_MOST,
                                     "points", f"{task} success gap ROS vs gym"),
    }


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", default="models/reach", help="model directory, relative to the repository")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--backend", choices=["torch", "onnx"], default="onnx")
    parser.add_argument("--seed", type=int, default=700000)
    parser.add_argument("--port", type=int, default=11411)
    parser.add_argument("--busy-cores", type=int, default=0, help="cores to keep busy during the run (0)")
    parser.add_argument("--results", type=Path, default=RESULTS_DIR,
                        help="output directory (default bench/results); its summary.json is updated")
    args = parser.parse_args(argv)
    from fr5_rl.deploy.bundle import read_meta

    model_dir = REPO / args.model
    meta = read_meta(model_dir)
    task = meta["task"]
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy_cores)]
    import rospy
    from std_msgs.msg import Float64MultiArray

    samples = []

    def listen():
        # Not handed back to be unregistered at the end: it samples until rospy shuts down below.
        rospy.Subscriber("/fr5_policy/timing", Float64MultiArray, lambda m: samples.append(tuple(m.data)),
                         queue_size=1000)
        return []

    run = run_launch({"rviz": False, "model": args.model, "task": task, "backend": args.backend,
                      "episodes": args.episodes, "seed": args.seed}, port=args.port, episodes=args.episodes,
                     listen=listen, node_name="bench_ros")
    successes, episodes = run.successes, run.episodes
    rospy.signal_shutdown("done")
    for process in busy:
        process.kill()
    from fr5_rl.ros.policy_node import TIMING_FIELDS

    timing = np.array(samples[5:]) if len(samples) > 5 else np.zeros((0, len(TIMING_FIELDS)))  # skip start-up cycles
    control_dt = float(meta.get("control_dt", 0.02))

    from fr5_rl.deploy.policy import load_policy
    from fr5_rl.training.evaluation import run_episodes

    policy = load_policy(model_dir, args.backend)
    records = run_episodes(task, policy.deployment_overrides(), lambda env: (policy.act, None), list(range(args.seed, args.seed + args.episodes)))
    gym_rate = sum(r["success"] for r in records) / len(records)
    ros_rate = successes / episodes if episodes else 0.0

    def column(name: str) -> np.ndarray:
        return timing[:, TIMING_FIELDS.index(name)]

    def timing_ms(seconds) -> Optional[Dict[str, Any]]:
        return latency_ms(seconds, digits=4) if len(timing) else None

    result = {
        "model": relative_path(model_dir), "task": task, "backend": args.backend, "episodes": episodes,
        "busy_cores": args.busy_cores, "cores": os.cpu_count(),
        "seeds": [args.seed, args.seed + args.episodes - 1],
        "ros_success_rate": ros_rate, "gym_success_rate_same_seeds": gym_rate,
        "parity_gap_points": round(100 * abs(ros_rate - gym_rate), 1),
        "loop_period": timing_ms(column("loop_period")),
        "period_jitter": timing_ms(np.abs(column("loop_period") - control_dt)),
        "inference": timing_ms(column("inference")),
        "compute_latency": timing_ms(column("compute_latency")),
        "joint_state_age_at_command": timing_ms(column("joint_state_age")),
        "new_state_wait": timing_ms(column("new_state_wait")),
        "repeated_joint_state_share": round(float(column("repeated").mean()), 4) if len(timing) else None,
        "targets": dict(TARGETS),
    }
    verdicts = ros_verdicts(result)
    if len(timing):
        print(f"policy node ({args.backend}), {len(timing)} cycles:")
        for key in ("loop_period", "period_jitter", "inference", "compute_latency", "joint_state_age_at_command",
                    "new_state_wait"):
            print(f"  {key:28s} p50 {result[key]['p50_ms']:.3f} ms  p99 {result[key]['p99_ms']:.3f} ms")
    print(f"closed loop through ROS: {successes}/{episodes}; gym on the same seeds: {gym_rate:.0%}; "
          f"gap {result['parity_gap_points']} points")
    for v in verdicts.values():
        print(f"  {v['text']}")
    name = f"ros_loop_{task}" + (f"_busy{args.busy_cores}" if args.busy_cores else "")
    path = write_result(args.results / f"{name}.json", result, verdicts)
    summary = update_summary(args.results, path.stem, path)
    print(f"wrote {os.path.relpath(path)}, {os.path.relpath(summary)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
