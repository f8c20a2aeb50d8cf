"""Vision-in-the-loop benchmark: the simulated RGB-D camera and the detector, alone and in the loop.

    python tools/bench/vision.py [--placements 200] [--episodes 20] [--skip-ros] [--quick]

1. In-process, no ROS: PyBullet's TinyRenderer against its EGL plugin at the camera's
   resolution (config/camera.yaml), then the detection error against the simulator's truth
   over ``--placements`` episode starts (object placed as in the environment, the arm at its
   noisy start pose), with exact depth and with ``--noise`` (1/m, std = noise * z^2).
2. Through ROS: ``sim_policy.launch vision:=true`` for reach (models/reach) and grasp
   (models/grasp), ``--episodes`` each, headless, on its own master. Measured from outside the
   nodes: the camera's frame rate, /joint_states and command rates, and the latency from an
   image's stamp to the first command published after the detection from it arrived.

Writes bench/results/vision.json and updates its entries in bench/results/summary.json.
Targets: detection p95 <= 5 mm; latency p99 <= one frame period + 10 ms; reach >= 95 %,
grasp >= 85 % through vision; camera >= 10 Hz while the loop keeps /joint_states >= 100 Hz and
its commands at >= 49 Hz (the policy node's own median period) with no hold on a stale joint
state. ``--busy-cores N`` keeps N cores busy with bare loops at the default niceness (a loaded
robot computer) and writes vision[...]_busy<N>.json.
"""
import argparse
import json
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

import numpy as np

from benchlib import AT_LEAST, AT_MOST, RESULTS_DIR, latency_ms, machine_info, update_summary, verdict, write_result
from roslaunch_run import run_launch

TARGETS = {"detection_p95_mm": 5.0, "latency_slack_ms": 10.0, "reach_success": 0.95, "grasp_success": 0.85,
           "camera_hz": 10.0, "joint_states_hz": 100.0, "command_hz": 49.0, "stale_joint_state_holds": 0}


def camera_config(profile: str, rate: Optional[float] = None) -> Dict[str, Any]:
    """config/camera.yaml, with config/camera_<profile>.yaml on top when a profile is given, and
    ``rate`` (Hz) on top of both when given."""
    from fr5_rl.config import load_yaml

    return {**load_yaml("camera"), **(load_yaml(f"camera_{profile}") if profile else {}),
            **({"rate": float(rate)} if rate else {})}


def offline(placements: int, noise: float, renderers: List[str], frames: int, profile: str = "") -> Dict[str, Any]:
    """Renderer timing and detection error, in this process (no ROS)."""
    from dataclasses import replace

    from fr5_rl.env_config import load_env_config
    from fr5_rl.envs import FR5Env
    from fr5_rl.perception.detector import Detection, DetectorSettings, ObjectDetector, TableRegion
    from fr5_rl.perception.camera_model import Intrinsics
    from fr5_rl.sim.camera import SimulatedCamera, depth_to_millimetres
    from fr5_rl.transforms import load_transform_files, transform_in

    camera_cfg, env_cfg = camera_config(profile), load_env_config()
    intrinsics = Intrinsics(camera_cfg["width"], camera_cfg["height"], camera_cfg["fx"], camera_cfg["fy"],
                            camera_cfg["cx"], camera_cfg["cy"])
    pose = transform_in(load_transform_files([camera_cfg["mount_config"], camera_cfg["frames_config"]]),
                        camera_cfg["base_frame"], camera_cfg["frame_id"])
    env = FR5Env("reach")
    names = list(env.robot_spec.joint_names) + list(env.robot_spec.finger_joint_names)
    result: Dict[str, Any] = {"resolution": [intrinsics.width, intrinsics.height], "renderers": {}}
    projection = intrinsics.opengl_projection(camera_cfg["near"], camera_cfg["far"])

    def make(renderer: str) -> "SimulatedCamera":
        return SimulatedCamera(env_cfg, names, pose, projection, intrinsics.width, intrinsics.height,
                               camera_cfg["near"], camera_cfg["far"], renderer)

    def show(camera, seed: int):
        env.reset(seed=seed)
        states, obj, scene = env.episode.joint_states(), env.episode.object_pose(), env.episode.scene()
        camera.set_joints(dict(zip(states.names, states.positions)))
        camera.set_object(scene.object_shape, scene.object_dims, obj.position, obj.quaternion)
        return obj

    for renderer in renderers:
        try:
            camera = make(renderer)
        except RuntimeError as error:
            result["renderers"][renderer] = {"error": str(error)}
            continue
        times = []
        for i in range(frames):
            show(camera, 900000 + i)
            start = time.perf_counter()
            camera.render()
            times.append(time.perf_counter() - start)
        camera.close()
        result["renderers"][renderer] = latency_ms(times[2:], digits=2, mean=True)
        print(f"render {renderer:5s} {intrinsics.width}x{intrinsics.height}: "
              f"p50 {result['renderers'][renderer]['p50_ms']:.1f} ms")
    usable = {k: v for k, v in result["renderers"].items() if "p50_ms" in v}
    best = min(usable, key=lambda k: usable[k]["p50_ms"])
    result["faster_renderer"] = best

    table, detector_settings = TableRegion.from_env(env_cfg), DetectorSettings.from_yaml()
    camera = make(best)
    rng = np.random.default_rng(0)
    for label, std in (("exact_depth", 0.0), (f"noise_{noise:g}_per_m2", noise)):
        settings = replace(detector_settings, top_tolerance=max(detector_settings.top_tolerance, 3.0 * std))
        detector = ObjectDetector(settings, table)
        errors, refusals, detect_s = [], {}, []
        for i in range(placements):
            truth = show(camera, 1_000_000 + i)
            rgb, depth = camera.render()
            depth = depth_to_millimetres(depth, std, rng).astype(np.float32) * 0.001
            start = time.perf_counter()
            found = detector.detect(depth, intrinsics, pose, rgb)
            detect_s.append(time.perf_counter() - start)
            if isinstance(found, Detection):
                errors.append(1000.0 * float(np.linalg.norm(np.subtract(found.position_table, truth.position))))
            else:
                refusals[found.reason.name] = refusals.get(found.reason.name, 0) + 1
        error = np.array(errors)
        result[label] = {"placements": placements, "detected": len(errors), "refusals": refusals,
                         "top_tolerance_m": settings.top_tolerance,
                         "error_p50_mm": round(float(np.percentile(error, 50)), 2) if len(error) else None,
                         "error_p95_mm": round(float(np.percentile(error, 95)), 2) if len(error) else None,
                         "error_max_mm": round(float(error.max()), 2) if len(error) else None,
                         "detect_time": latency_ms(detect_s, digits=2)}
        print(f"detection ({label}): {len(errors)}/{placements} detected, error p50 "
              f"{result[label]['error_p50_mm']} mm, p95 {result[label]['error_p95_mm']} mm, refusals {refusals}; "
              f"detect p50 {result[label]['detect_time']['p50_ms']} ms")
    camera.close()
    env.close()
    return result


def closed_loop(model: str, task: str, episodes: int, seed: int, port: int, profile: str = "",
                rate: Optional[float] = None) -> Dict[str, Any]:
    """``sim_policy.launch vision:=true`` headless; success, rates and latency seen from outside."""
    import rospy
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import CameraInfo, JointState
    from rosgraph_msgs.msg import Log
    from std_msgs.msg import Float64MultiArray, String

    lock = threading.Lock()
    arrivals: Dict[str, List[float]] = {"camera": [], "joint_states": [], "command": [], "target": []}
    pending: List[float] = []  # image stamps of detections no command has used yet
    latencies: List[float] = []
    # Where the time goes, per frame (s): the nodes' own ~timing, and arrival ages seen here.
    stages: Dict[str, List[float]] = {name: [] for name in (
        "camera_render", "camera_convert", "camera_publish", "camera_state_age_at_publish",
        "detector_image_age_at_arrival", "detector_decode", "detector_detect", "detector_track", "detector_total",
        "target_age_at_arrival", "command_wait_after_target")}
    states: Dict[str, int] = {}
    policy_holds: Dict[str, int] = {}  # the policy node's logged holds by reason (at onset, then every 2 s)
    policy_periods: List[float] = []  # s between the policy node's commands, by its own clock (~timing)
    joint_state_ages: List[float] = []  # s, the joint state's age when the policy used it (~timing)
    last_target_arrival = [0.0]

    def on_target(message: PoseStamped) -> None:
        now = rospy.Time.now().to_sec()
        with lock:
            arrivals["target"].append(time.monotonic())
            pending.append(message.header.stamp.to_sec())
            stages["target_age_at_arrival"].append(now - message.header.stamp.to_sec())
            last_target_arrival[0] = now

    def on_camera_timing(message: Float64MultiArray) -> None:
        for name, value in zip(("camera_render", "camera_convert", "camera_publish", "camera_state_age_at_publish"),
                               message.data):
            stages[name].append(value)

    def on_detector_timing(message: Float64MultiArray) -> None:
        decode, detect, track, total, age = message.data
        for name, value in (("detector_decode", decode), ("detector_detect", detect), ("detector_track", track),
                            ("detector_total", total), ("detector_image_age_at_arrival", age)):
            stages[name].append(value)

    def on_state(message: String) -> None:
        key = message.data.split(":")[0]
        states[key] = states.get(key, 0) + 1

    def on_log(message: Log) -> None:
        if message.name == "/fr5_policy" and "holding: " in message.msg:
            reason = message.msg.split("holding: ", 1)[1].split(":")[0].split(" (")[0].strip()
            policy_holds[reason] = policy_holds.get(reason, 0) + 1

    def on_policy_timing(message: Float64MultiArray) -> None:
        period, _inference, _compute, state_age = message.data[:4]
        policy_periods.append(period)
        joint_state_ages.append(state_age)

    def on_command(_message: Float64MultiArray) -> None:
        now = rospy.Time.now().to_sec()
        with lock:
            arrivals["command"].append(time.monotonic())
            if pending:  # the first command after a detection arrived is computed from it
                latencies.append(now - pending[-1])
                stages["command_wait_after_target"].append(now - last_target_arrival[0])
                pending.clear()

    def listen() -> List[Any]:
        return [
            # The CameraInfo comes with every frame: its rate is the camera's, without 1 MB images here.
            rospy.Subscriber("/camera/color/camera_info", CameraInfo,
                             lambda m: arrivals["camera"].append(time.monotonic()), queue_size=5),
            rospy.Subscriber("/camera/timing", Float64MultiArray, on_camera_timing, queue_size=20),
            rospy.Subscriber("/detector/timing", Float64MultiArray, on_detector_timing, queue_size=20),
            rospy.Subscriber("/detector/track_state", String, on_state, queue_size=20),
            rospy.Subscriber("/rosout_agg", Log, on_log, queue_size=100),
            rospy.Subscriber("/fr5_policy/timing", Float64MultiArray, on_policy_timing, queue_size=100),
            rospy.Subscriber("/joint_states", JointState, lambda m: arrivals["joint_states"].append(time.monotonic()),
                             queue_size=50, tcp_nodelay=True),
            rospy.Subscriber("/target_pose", PoseStamped, on_target, queue_size=10, tcp_nodelay=True),
            rospy.Subscriber("/fr5/arm_controller/command", Float64MultiArray, on_command, queue_size=10,
                             tcp_nodelay=True)]

    run = run_launch({"rviz": False, "vision": True, "model": model, "task": task, "episodes": episodes, "seed": seed,
                      "backend": "onnx", "camera_profile": profile, "camera_rate": rate or ""},
                     port=port, episodes=episodes, listen=listen, node_name="bench_vision")
    successes, done, failures = run.successes, run.episodes, run.failures
    # The detector's warnings are no outcome: they are only in what it prints.
    refusals: Dict[str, int] = {}
    for reason in re.findall(r"detector_node: holding: ([^:\n]*)", "".join(run.output)):
        refusals[reason] = refusals.get(reason, 0) + 1

    def rate(times: List[float]) -> Dict[str, Optional[float]]:
        times = np.asarray(times[10:])
        if len(times) < 3:
            return {"mean_hz": None, "median_interval_hz": None}
        return {"mean_hz": round(float((len(times) - 1) / (times[-1] - times[0])), 2),
                "median_interval_hz": round(float(1.0 / np.median(np.diff(times))), 2)}

    result = {"model": model, "task": task, "episodes": done, "successes": successes,
              "success_rate": successes / done if done else 0.0, "failures": failures,
              "detector_hold_warnings": refusals,
              "camera_rate": rate(arrivals["camera"]), "joint_states_rate": rate(arrivals["joint_states"]),
              "command_rate": rate(arrivals["command"]), "detection_rate": rate(arrivals["target"]),
              "policy_holds": policy_holds,
              "stale_joint_state_holds": sum(count for reason, count in policy_holds.items()
                                             if reason.startswith("joint state stale")),
              "policy_period": latency_ms(policy_periods[10:], digits=2),
              "policy_joint_state_age": latency_ms(joint_state_ages[10:], digits=2),
              "latency_image_to_command": latency_ms(latencies, digits=2),
              "latency_breakdown": {name: latency_ms(values, digits=2) for name, values in stages.items() if values},
              "track_states": states}
    for name, figures in result["latency_breakdown"].items():
        print(f"  {name:32s} p50 {figures['p50_ms']:7.1f} ms  p99 {figures['p99_ms']:7.1f} ms")
    print(f"  detector track states: {states}")
    print(f"  policy holds: {policy_holds}; period {result['policy_period']}, joint state age "
          f"{result['policy_joint_state_age']}")
    print(f"{task} through vision: {successes}/{done}; camera {result['camera_rate']}, joint states "
          f"{result['joint_states_rate']}, commands {result['command_rate']}, latency "
          f"p50 {result['latency_image_to_command']['p50_ms']} ms p99 {result['latency_image_to_command']['p99_ms']} ms")
    return result


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--placements", type=int, default=200)
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--noise", type=float, default=0.002, help="depth noise (1/m) of the second error figure")
    parser.add_argument("--seed", type=int, default=700000)
    parser.add_argument("--port", type=int, default=11431, help="ROS master port (reach; grasp +1), apart from "
                        "ros_loop.py (11411) and lockstep.py (11421): benches may run side by side")
    parser.add_argument("--skip-ros", action="store_true", help="only the in-process part")
    parser.add_argument("--quick", action="store_true", help="20 placements, 3 episodes: a smoke run")
    parser.add_argument("--results", type=Path, default=RESULTS_DIR)
    parser.add_argument("--camera-profile", default="", help="config/camera_<profile>.yaml on top of camera.yaml "
                                                               "(e.g. 320x240); results go to vision_<profile>.json")
    parser.add_argument("--camera-rate", type=float, help="the camera's frame rate (Hz) instead of the profile's; "
                                                          "results go to vision[_<profile>]_<rate>hz.json")
    parser.add_argument("--tasks", default="reach,grasp", help="closed-loop tasks to run")
    parser.add_argument("--busy-cores", type=int, default=0, help="cores kept busy during the closed loops (0)")
    parser.add_argument("--loop", choices=["reach", "grasp"], help=argparse.SUPPRESS)
    parser.add_argument("--loop-out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.loop:
        args.loop_out.write_text(json.dumps(closed_loop(f"models/{args.loop}", args.loop, args.episodes, args.seed,
                                                        args.port, args.camera_profile, args.camera_rate)))
        return 0
    if args.quick:
        args.placements, args.episodes = 20, 3
    machine = machine_info()
    profile = args.camera_profile
    rate = args.camera_rate
    camera_hz_configured = float(camera_config(profile, rate)["rate"])
    result: Dict[str, Any] = {"quick": args.quick, "camera_profile": profile or "default",
                              "camera_rate_hz": camera_hz_configured,
                              "offline": offline(args.placements, args.noise, ["tiny", "egl"], 22, profile)}
    camera_period_ms = 1000.0 / camera_hz_configured
    tasks = [task for task in ("reach", "grasp") if task in args.tasks.split(",")]
    args.results.mkdir(parents=True, exist_ok=True)
    result["busy_cores"] = args.busy_cores
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy_cores)]
    try:
        if not args.skip_ros:
            # One process per run: a rospy node cannot move to the next launch's master.
            for task, offset in ((task, ("reach", "grasp").index(task)) for task in tasks):
                out = args.results / f".vision_{task}.json"
                subprocess.run([sys.executable, __file__, "--loop", task, "--loop-out", str(out), "--episodes",
                                str(args.episodes), "--seed", str(args.seed), "--port", str(args.port + offset),
                                "--camera-profile", profile] + (["--camera-rate", str(rate)] if rate else []),
                               check=True)
                result[task] = json.loads(out.read_text())
                out.unlink()
    finally:
        for process in busy:
            process.kill()
    verdicts = {"detection_p95_mm": verdict(result["offline"]["exact_depth"]["error_p95_mm"],
                                            TARGETS["detection_p95_mm"], AT_MOST, "mm", "detection error p95")}
    if not args.skip_ros and tasks:
        first = result[tasks[0]]
        camera_hz = first["camera_rate"]["mean_hz"]
        # One frame period of the camera as it ran (the configured rate when it kept up).
        period_ms = 1000.0 / camera_hz if camera_hz else camera_period_ms
        verdicts.update({
            "latency_p99_ms": verdict(first["latency_image_to_command"]["p99_ms"],
                                      period_ms + TARGETS["latency_slack_ms"], AT_MOST, "ms",
                                      "image stamp to command p99"),
            "camera_hz": verdict(camera_hz, TARGETS["camera_hz"], AT_LEAST, "Hz", "camera frame rate in the loop"),
            "joint_states_hz": verdict(first["joint_states_rate"]["mean_hz"], TARGETS["joint_states_hz"], AT_LEAST,
                                       "Hz", "/joint_states rate with the camera running"),
        })
        for task in tasks:
            period_ms = result[task]["policy_period"]["p50_ms"]
            verdicts[f"{task}_command_hz"] = verdict(round(1000.0 / period_ms, 2) if period_ms else None,
                                                     TARGETS["command_hz"], AT_LEAST, "Hz",
                                                     f"{task}: the policy node's command rate (median period)")
            verdicts[f"{task}_stale_joint_state_holds"] = verdict(
                result[task]["stale_joint_state_holds"], TARGETS["stale_joint_state_holds"], AT_MOST, "",
                f"{task}: holds on a stale joint state")
        for task in tasks:
            verdicts[f"{task}_success"] = verdict(result[task]["success_rate"], TARGETS[f"{task}_success"], AT_LEAST,
                                                  "", f"{task} success through vision")
    for v in verdicts.values():
        print(f"  {v['text']}")
    name = "_".join(["vision"] + ([profile] if profile else []) + ([f"{rate:g}hz"] if rate else [])
                    + ([f"busy{args.busy_cores}"] if args.busy_cores else []))
    path = write_result(args.results / f"{name}.json", result, verdicts,
                        machine)
    summary = update_summary(args.results, path.stem, path)
    print(f"wrote {os.path.relpath(path)}, {os.path.relpath(summary)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
