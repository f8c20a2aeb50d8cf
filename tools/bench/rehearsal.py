#!/usr/bin/env python3
"""The real chain rehearsed, measured on unseen placements: each model through each chain over N
episodes of ``sim_policy.launch``, real time, on its own ROS master.

Chains (``--chains``):

- ``fairino``: the FAIRINO driver profile (50 Hz j1..j6 joint states, velocities 0.0, 125 Hz
  servo cycle, no teleport: every episode begins with the policy node's start move), the gripper
  through the bridge and the simulator's emulation of the controller's XML-RPC;
- ``fairino_vision``: the same, the target through the simulated RealSense and the detector
  (the whole rehearsal);
- ``vision``: the target through camera and detector on the default driver;
- ``fairino_vision_truth``: the whole rehearsal with the camera and the detector running, but the
  policy on the simulator's true pose (``vision_target:=truth``): what the camera's target costs
  apart from the machine time the camera takes.

Prints and writes ``rehearsal.json``: per model and chain, K/N with its 95 % Wilson interval,
the failure causes and the seeds, and the policy node's own timing (``/fr5_policy/timing``:
inference, and compute latency from the period's start to its command).

``--backend`` picks the policy node's backend: ``onnx`` (the default of both launches: what a
real cell runs) or ``torch``.

    python tools/bench/rehearsal.py --models models/reach --chains fairino_vision --episodes 20 --seed 900000
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple

from benchlib import REPO, RESULTS_DIR, latency_ms, machine_info, update_summary, write_result
from fr5_rl.deploy.bundle import read_meta
from fr5_rl.env_config import load_env_config
from fr5_rl.ros.policy_node import TIMING_FIELDS
from fr5_rl.training.evaluation import by_object, wilson_interval
from fr5_rl.training.success_map import write_success_map
from roslaunch_run import run_launch

# The policy node's ~timing fields this bench summarises (policy_node.TIMING_FIELDS gives their order).
SUMMARISED = ("inference", "compute_latency", "joint_state_age")


CHAINS = {
    "fairino": {"driver": "fairino"},
    "fairino_vision": {"driver": "fairino", "vision": True},
    # The whole rehearsal's camera and detector, running, but the policy on the true pose: what
    # the camera's target costs apart from the machine time it takes.
    "fairino_vision_truth": {"driver": "fairino", "vision": True, "vision_target": "truth"},
    "vision": {"vision": True},
}


def timing_listener(samples: Dict[str, List[Tuple[float, ...]]]) -> Callable[[], List[Any]]:
    """A ``run_launch`` listener that appends every ``/fr5_policy/timing`` message to
    ``samples["policy"]`` and every ``/camera/timing`` one (render, convert, publish, the
    rendered state's age at publishing; s) to ``samples["camera"]``."""

    def listen() -> List[Any]:
        import rospy
        from std_msgs.msg import Float64MultiArray

        def keep(key: str) -> Callable[[Any], None]:
            return lambda message: samples.setdefault(key, []).append((time.monotonic(), *message.data))
        return [rospy.Subscriber("/fr5_policy/timing", Float64MultiArray, keep("policy"), queue_size=1000),
                rospy.Subscriber("/camera/timing", Float64MultiArray, keep("camera"), queue_size=1000)]
    return listen


def timing_summary(samples: Dict[str, List[Tuple[float, ...]]]) -> Dict[str, Any]:
    """The policy node's inference, compute latency and joint state age over a run (ms), and,
    with a camera, its frames per second and each frame's age when published (ms)."""
    policy = samples.get("policy", [])
    summary: Dict[str, Any] = {}
    for name in SUMMARISED:
        index = TIMING_FIELDS.index(name) + 1  # each sample starts with its arrival time
        summary[name] = latency_ms((sample[index] for sample in policy if len(sample) > index),
                                   points=(50, 90, 99), digits=2)
    camera = samples.get("camera", [])
    if len(camera) > 1:
        span = camera[-1][0] - camera[0][0]
        summary["camera_frames_per_s"] = round((len(camera) - 1) / span, 2) if span > 0 else None
        summary["camera_frame_age"] = latency_ms((sample[4] for sample in camera if len(sample) > 4),
                                                 points=(50, 90, 99), digits=1)
    return summary


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--models", nargs="+", default=["models/reach"], help="model directories (default models/reach)")
    parser.add_argument("--chains", nargs="+", choices=sorted(CHAINS), default=["fairino", "fairino_vision"])
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=900_000, help="episode k places the object with seed + k")
    parser.add_argument("--backend", choices=("onnx", "torch"), default="onnx",
                        help="the policy node's backend (default onnx, as both launches)")
    parser.add_argument("--port", type=int, default=11470)
    parser.add_argument("--results", type=Path, default=RESULTS_DIR)
    parser.add_argument("--maps", action="store_true",
                        help="also draw each run's success map by placement (map_<model>_<chain>.json/.png)")
    args = parser.parse_args(argv)
    args.results.mkdir(parents=True, exist_ok=True)
    rows: List[Dict[str, Any]] = []
    for model in args.models:
        # The simulator judges the model's own task; a relative path is the package's (as the launch reads it).
        task = read_meta(Path(model) if Path(model).is_absolute() else REPO / model)["task"]
        for chain in args.chains:
            arguments = {"rviz": False, "model": model, "task": task, "episodes": args.episodes,
                         "seed": args.seed, "backend": args.backend, **CHAINS[chain]}
            if arguments.get("driver") == "fairino":
                # The emulated controller's port follows the master's: a second rehearsal on the
                # machine (another bench, a rostest) must not drive this one's gripper. Below 32768:
                # Linux lends 32768-60999 to outgoing connections, and a node's may hold the port.
                arguments["controller_port"] = args.port + 8700
            samples: Dict[str, List[Tuple[float, ...]]] = {}
            run = run_launch(arguments, port=args.port, episodes=args.episodes, listen=timing_listener(samples),
                             node_name="bench_rehearsal")
            causes: Dict[str, int] = {}
            for cause in run.failures:
                causes[cause] = causes.get(cause, 0) + 1
            row = {"model": model, "chain": chain, "successes": run.successes, "episodes": run.episodes,
                   "success_rate_95ci": [round(bound, 3) for bound in wilson_interval(run.successes, run.episodes)], "failures": causes,
                   "seeds": [args.seed, args.seed + args.episodes - 1], "wall_s": round(run.wall_s, 1),
                   "timed_out": run.timed_out, "backend": args.backend,
                   "policy_timing": timing_summary(samples), "by_object": by_object(run.records),
                   "records": run.records}
            rows.append(row)
            if args.maps and run.records:
                stem = args.results / f"map_{Path(model).name}_{chain}"
                title = f"{model} through the {chain} chain, ROS rehearsal ({run.episodes} episodes)"
                for written in write_success_map(run.records, load_env_config(), stem, title):
                    print(f"wrote {written}")
            compute = row["policy_timing"]["compute_latency"]
            camera = (f", camera {row['policy_timing']['camera_frames_per_s']} frames/s"
                      if "camera_frames_per_s" in row["policy_timing"] else "")
            print(f"{model:24s} {chain:15s} {run.successes}/{run.episodes}  95% CI {row['success_rate_95ci']}  "
                  f"failures {causes or '-'}  ({run.wall_s:.0f} s; {args.backend}, compute latency p50/p99 "
                  f"{compute['p50_ms']}/{compute['p99_ms']} ms{camera})", flush=True)
            for kind, counts in row["by_object"].items():
                print(f"  {kind}: {counts['successes']}/{counts['episodes']}, failures {counts['failures'] or '-'}")
    args.results.mkdir(parents=True, exist_ok=True)
    path = args.results / "rehearsal.json"
    write_result(path, {"bench": "rehearsal", "machine": machine_info(), "episodes": args.episodes,
                        "seed": args.seed, "runs": rows})
    update_summary(args.results, "rehearsal", path)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
