"""ROS loop benchmark: control-loop timing inside the policy node and sim-to-ROS parity.

    python tools/bench_ros.py [--model models/reach] [--episodes 20] [--backend onnx]

Starts ``sim_policy.launch`` headless on its own ROS master, records the policy node's
per-cycle timing (``/fr5_policy/timing``: loop period, inference, compute latency from reading
the inputs to publishing, age of the joint state used), and compares the closed-loop success
rate through ROS with the gym evaluation of the same model on the same placements (seeds).
Writes bench/results/ros_loop_<task>.json. Targets: latency p99 <= 3 ms, period jitter p99 <= 2 ms,
parity within 5 points.
"""
import argparse
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
RESULTS = REPO / "bench" / "results"


def percentiles(values_s):
    values = np.asarray(values_s, dtype=float) * 1000.0
    values = values[np.isfinite(values)]
    if values.size == 0:
        return {"p50_ms": None, "p99_ms": None, "max_ms": None, "samples": 0}
    return {"p50_ms": round(float(np.percentile(values, 50)), 4), "p99_ms": round(float(np.percentile(values, 99)), 4),
            "max_ms": round(float(values.max()), 4), "samples": int(values.size)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", default="models/reach")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--backend", choices=["torch", "onnx"], default="onnx")
    parser.add_argument("--seed", type=int, default=700000)
    parser.add_argument("--port", type=int, default=11411)
    args = parser.parse_args()
    meta = json.loads((REPO / args.model / "meta.json").read_text())
    task = meta["task"]
    env = dict(os.environ, ROS_MASTER_URI=f"http://localhost:{args.port}")
    os.environ["ROS_MASTER_URI"] = env["ROS_MASTER_URI"]
    launch = subprocess.Popen(
        ["roslaunch", "-p", str(args.port), "fr5_rl", "sim_policy.launch", "rviz:=false", f"model:={args.model}",
         f"task:={task}", f"backend:={args.backend}", f"episodes:={args.episodes}", f"seed:={args.seed}"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, start_new_session=True)
    import rospy
    from std_msgs.msg import Float64MultiArray

    samples = []
    deadline = time.time() + 30
    while time.time() < deadline:
        try:
            rospy.get_master().getPid()
            break
        except Exception:
            time.sleep(0.5)
    rospy.init_node("bench_ros", anonymous=True, disable_signals=True)
    rospy.Subscriber("/fr5_policy/timing", Float64MultiArray, lambda m: samples.append(tuple(m.data)), queue_size=1000)
    output = []
    for line in launch.stdout:
        output.append(line)
        if "success rate:" in line:
            break
    successes, episodes = map(int, re.search(r"success rate: (\d+)/(\d+)", "".join(output)).groups()) \
        if any("success rate:" in line for line in output) else (0, 0)
    os.killpg(launch.pid, signal.SIGINT)
    try:
        launch.wait(timeout=30)
    except subprocess.TimeoutExpired:
        os.killpg(launch.pid, signal.SIGKILL)
    rospy.signal_shutdown("done")
    timing = np.array(samples[5:]) if len(samples) > 5 else np.zeros((0, 4))  # skip start-up cycles
    control_dt = float(meta.get("control_dt", 0.02))

    from fr5_rl.training.evaluate import run_episodes
    from fr5_rl.policy import load_policy

    policy = load_policy(REPO / args.model, args.backend)
    records = run_episodes(task, {}, lambda env: (policy.act, None), list(range(args.seed, args.seed + args.episodes)))
    gym_rate = sum(r["success"] for r in records) / len(records)
    ros_rate = successes / episodes if episodes else 0.0
    result = {
        "model": args.model, "task": task, "backend": args.backend, "episodes": episodes, "seeds": [args.seed, args.seed + args.episodes - 1],
        "ros_success_rate": ros_rate, "gym_success_rate_same_seeds": gym_rate,
        "parity_gap_points": round(100 * abs(ros_rate - gym_rate), 1),
        "loop_period": percentiles(timing[:, 0]) if len(timing) else None,
        "period_jitter": percentiles(np.abs(timing[:, 0] - control_dt)) if len(timing) else None,
        "inference": percentiles(timing[:, 1]) if len(timing) else None,
        "compute_latency": percentiles(timing[:, 2]) if len(timing) else None,
        "joint_state_age_at_command": percentiles(timing[:, 3]) if len(timing) else None,
        "targets": {"compute_latency_p99_ms": 3.0, "period_jitter_p99_ms": 2.0, "parity_points": 5.0},
    }
    ok = lambda cond: "PASS" if cond else "FAIL"  # noqa: E731
    if len(timing):
        print(f"policy node ({args.backend}), {len(timing)} cycles:")
        for key in ("loop_period", "period_jitter", "inference", "compute_latency", "joint_state_age_at_command"):
            print(f"  {key:28s} p50 {result[key]['p50_ms']:.3f} ms  p99 {result[key]['p99_ms']:.3f} ms")
        print(f"  latency p99 <= 3 ms: {ok(result['compute_latency']['p99_ms'] <= 3.0)};"
              f" jitter p99 <= 2 ms: {ok(result['period_jitter']['p99_ms'] <= 2.0)}")
    print(f"closed loop through ROS: {successes}/{episodes}; gym on the same seeds: {gym_rate:.0%}; "
          f"gap {result['parity_gap_points']} points ({ok(result['parity_gap_points'] <= 5.0)})")
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"ros_loop_{task}.json").write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
