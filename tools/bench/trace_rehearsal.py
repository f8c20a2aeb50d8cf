#!/usr/bin/env python3
"""Trace episodes of the whole rehearsal: what the detector's tracker decided, why the policy node
held, and, every ``--period`` s, the object's true pose beside the target the policy acted on,
the goal and the gripper command. For finding where the real chain parts from the training
world on one seed (docs/experiments.md, "The tracker lost objects still in the hand").

    python tools/bench/trace_rehearsal.py models/place --seed 1690003 --episodes 1

Prints one line per event, seconds since the first one; ``--out`` also writes them as JSON
lines. It runs ``sim_policy.launch driver:=fairino vision:=true`` (``--truth``: with
``vision_target:=truth``) on its own ROS master, as tools/bench/rehearsal.py does.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any, Callable, List, Optional, Tuple

from benchlib import REPO
from fr5_rl.config import load_yaml
from fr5_rl.deploy.bundle import read_meta
from fr5_rl.objects import yaw_of
from roslaunch_run import run_launch

Event = Tuple[float, str, str]


def pose_text(pose, with_yaw: bool = True) -> str:
    """x y z (m) and yaw (degrees) of a geometry_msgs/Pose."""
    text = f"{pose.position.x:+.3f} {pose.position.y:+.3f} {pose.position.z:.3f}"
    if not with_yaw:
        return text
    q = pose.orientation
    yaw = math.degrees(yaw_of((q.x, q.y, q.z, q.w))) if (q.x or q.y or q.z or q.w) else 0.0
    return f"{text} yaw {yaw:6.1f}"


def listener(events: List[Event], period_s: float) -> Callable[[], List[Any]]:
    """A ``run_launch`` listener appending to ``events``: track state and diagnostics changes,
    episode outcomes, and a line of poses every ``period_s``."""

    def listen() -> List[Any]:
        import rospy
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PoseStamped
        from sensor_msgs.msg import JointState
        from shape_msgs.msg import SolidPrimitive
        from std_msgs.msg import Float64, String
        from visualization_msgs.msg import Marker

        from fr5_rl.msg import DetectedObjects

        import tf2_geometry_msgs  # noqa: F401  (registers PoseStamped with tf2's transform)
        import tf2_ros

        latest: dict = {}
        finger_names = tuple(load_yaml("gripper")["joint_names"])
        last_text: dict = {}
        tf_buffer = tf2_ros.Buffer()
        tf_listener = tf2_ros.TransformListener(tf_buffer)

        def changed(kind: str, text: str) -> None:
            if last_text.get(kind) != text:
                last_text[kind] = text
                events.append((time.monotonic(), kind, text))

        def diagnostics(message) -> None:
            for status in message.status:
                changed(f"diag {status.name}", status.message)

        def keep(key: str) -> Callable[[Any], None]:
            return lambda message: latest.__setitem__(key, message)

        def fingers(message) -> None:
            # The opening is the sum of the finger joints (config/gripper.yaml).
            by_name = dict(zip(message.name, message.position))
            if all(name in by_name for name in finger_names):
                latest["fingers"] = sum(by_name[name] for name in finger_names)

        def chosen(message) -> None:
            # A clearing run: which object the detector gives the policy, and what else it sees.
            picked = next((item for item in message.objects if item.id == message.chosen_id), None)
            changed("chosen", "none" if picked is None else f"object {picked.id} ({picked.kind}) at "
                    f"{pose_text(picked.pose, with_yaw=False)}; {len(message.objects)} seen, "
                    f"{len(message.refused)} refused")

        def tick(_event) -> None:
            truth = latest.get("truth")
            if truth is None:
                return
            line = f"truth {pose_text(truth.pose)}"
            changed("sizes", "object {:.1f} x {:.1f} x {:.1f} mm (truth) | detected {}".format(
                *(1000 * v for v in (truth.scale.x, truth.scale.y, truth.scale.z)),
                " x ".join(f"{1000 * v:.1f}" for v in latest["shape"].dimensions) if "shape" in latest else "-"))
            target = latest.get("target")
            if target is not None:
                # The node's marker shows where the target is, not its yaw.
                line += f" | policy's target {pose_text(target.pose, with_yaw=False)} ({target.header.frame_id})"
            detected = latest.get("detected")
            if detected is not None:
                # The target's yaw as the detector gives it (its pose in the optical frame, or the
                # tcp's while held), in the base frame: what the policy's yaw features come from.
                try:
                    in_base = tf_buffer.transform(detected, "base_link", rospy.Duration(0.05))
                    line += f" yaw {pose_text(in_base.pose).split('yaw')[1].strip()}"
                except Exception:  # tf not there yet: the yaw waits for the next line
                    pass
            goal = latest.get("goal")
            if goal is not None:
                line += f" | goal {pose_text(goal.pose)} ({goal.header.frame_id})"
            gripper = latest.get("gripper")
            if gripper is not None:
                line += f" | gripper command {gripper.data * 1000:.1f} mm"
            fingers = latest.get("fingers")
            if fingers is not None:
                line += f" measured {fingers * 1000:.1f} mm"
            try:
                # The tcp beside the object: how far the hand is from what it is to take.
                tcp = tf_buffer.lookup_transform("base_link", "tcp", rospy.Time(0), rospy.Duration(0.05)).transform
                at = truth.pose.position
                offset = (tcp.translation.x - at.x, tcp.translation.y - at.y, tcp.translation.z - at.z)
                line += " | tcp - object {:+.3f} {:+.3f} {:+.3f}".format(*offset)
            except Exception:  # tf not there yet
                pass
            events.append((time.monotonic(), "poses", line))

        return [rospy.Subscriber("/fr5_sim/object", Marker, keep("truth"), queue_size=1),
                rospy.Subscriber("/detector/objects", DetectedObjects, chosen, queue_size=5),
                rospy.Subscriber("/fr5_policy/target_marker", Marker, keep("target"), queue_size=1),
                rospy.Subscriber("/target_pose", PoseStamped, keep("detected"), queue_size=1),
                rospy.Subscriber("/place_pose", PoseStamped, keep("goal"), queue_size=1),
                rospy.Subscriber("/fr5/gripper/command", Float64, keep("gripper"), queue_size=1),
                rospy.Subscriber("/target_shape", SolidPrimitive, keep("shape"), queue_size=1),
                rospy.Subscriber("/fr5/gripper/joint_states", JointState, fingers, queue_size=10),
                rospy.Subscriber("/joint_states", JointState, fingers, queue_size=10),
                rospy.Subscriber("/detector/track_state", String, lambda m: changed("track", m.data), queue_size=100),
                rospy.Subscriber("/diagnostics", DiagnosticArray, diagnostics, queue_size=100),
                rospy.Subscriber("/fr5_sim/episode_outcome", String,
                                 lambda m: events.append((time.monotonic(), "outcome", m.data)), queue_size=100),
                StoppableTimer(rospy.Timer(rospy.Duration(period_s), tick)), tf_listener]
    return listen


class StoppableTimer:
    """A rospy.Timer that ``run_launch`` can stop as it unregisters the subscribers."""

    def __init__(self, timer: Any) -> None:
        self.timer = timer

    def unregister(self) -> None:
        self.timer.shutdown()


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("model", help="model directory (e.g. models/place)")
    parser.add_argument("--seed", type=int, required=True, help="episode k places the object with seed + k")
    parser.add_argument("--episodes", type=int, default=1)
    parser.add_argument("--truth", action="store_true", help="the policy on the simulator's pose (vision_target:=truth)")
    parser.add_argument("--period", type=float, default=0.5, help="s between two lines of poses")
    parser.add_argument("--port", type=int, default=11490)
    parser.add_argument("--out", type=Path, help="also write the events as JSON lines")
    parser.add_argument("--scene", type=int, help="clear the table: trace this scene of the seed's "
                        "(sim_policy.launch scene:=clear first_scene:=K; --episodes: the objects to trace)")
    parser.add_argument("--scenes", type=int, default=1, help="with --scene: this many scenes from it")
    args = parser.parse_args(argv)
    if args.episodes < 1 or args.period <= 0.0:
        parser.error("--episodes must be >= 1 and --period > 0")
    model = Path(args.model)
    task = read_meta(model if model.is_absolute() else REPO / model)["task"]
    arguments = {"rviz": False, "model": args.model, "task": task, "episodes": args.episodes, "seed": args.seed,
                 "driver": "fairino", "vision": True, "controller_port": args.port + 8700}
    if args.truth:
        arguments["vision_target"] = "truth"
    if args.scene is not None:
        arguments.update(scene="clear", first_scene=args.scene, scenes=args.scenes)
        del arguments["episodes"]
    events: List[Event] = []
    run = run_launch(arguments, port=args.port, episodes=args.episodes, listen=listener(events, args.period),
                     node_name="trace_rehearsal")
    start = events[0][0] if events else 0.0
    for stamp, kind, text in events:
        print(f"{stamp - start:8.2f}  {kind:12s} {text}")
    print(f"{run.successes}/{run.episodes} succeeded; failures: {run.failures or 'none'}")
    if args.out is not None:
        with args.out.open("w") as out:
            for stamp, kind, text in events:
                out.write(json.dumps({"t": round(stamp - start, 3), "kind": kind, "text": text}) + "\n")
    return 0 if run.episodes == args.episodes else 1


if __name__ == "__main__":
    sys.exit(main())
