"""Hand-eye calibration of the fixed camera: ``rosrun fr5_rl calibrate_camera.py --out FILE``.

The cup, held in the closed gripper, is the feature. The arm (this program owns it: no policy
node may run) moves the cup to ``--poses`` configurations that vary the tcp's tilts and yaw
(:func:`fr5_rl.ros.calibration_motion.calibration_poses`), slowly and through the policy
node's motion guard and safety gate. At each pose it waits until the arm is at rest, measures
the cup's centre in the camera's optical frame on realsense2_camera's colour, aligned depth and
camera_info topics (a cylinder fit, :func:`fr5_rl.perception.hand_eye.measure_cup`, averaged
over a few frames) and the tcp pose in base_link by forward kinematics of the measured joint
states. A least-squares fit gives base_link -> camera_link and the cup's offset in the tcp
frame (:func:`fr5_rl.perception.hand_eye.solve_hand_eye`); the result is written as the whole
transforms file (config/static_transforms.yaml's format, the camera_link entry replaced).

In the simulator (``sim_policy.launch vision:=true calibration:=true``) the program asks the
simulator to hold the cup (``/fr5_sim/calibration``). On a real arm, hand the cup to the gripper
and close it first (docs/vision.md); the service is then absent and nothing is asked.

``--bag FILE.bag`` solves from a recording instead (joint states, colour, aligned depth,
camera_info): the rest periods of the joints are the poses.

Refusals print one line and exit 2, writing nothing: too few usable poses, a degenerate pose
set, a bag without a needed topic, an existing output without ``--force``.
"""
from __future__ import annotations

import argparse
import math
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Deque, Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..help_text import plain
from ..config import DEFAULT_ROBOT, ConfigError, load_robot_spec, robot_names
from .calibration_motion import CalibrationMove, calibration_poses
from ..deploy.joint_state import JointStateReader
from ..motion_guard import load_guard_settings
from ..env_config import load_env_config
from ..perception.camera_model import Intrinsics
from ..perception.hand_eye import (CalibrationRefused, CalibrationSettings, HandEyeResult, calibrated_transforms_yaml,
                                   check_pose_set, load_calibration_settings, measure_cup, rpy_from_rotation,
                                   solve_rejecting_outliers, tcp_poses_from_joints, transform_error,
                                   write_result)
from ..perception.images import InputError, decode_color, decode_depth, intrinsics_from_camera_info
from ..transforms import load_static_transforms, load_transform_files, transform_in

REFUSED = 2


@dataclass(frozen=True)
class Frame:
    """One synchronised camera frame: stamp (s), rgb (H, W, 3) uint8, depth (H, W) m, model."""

    stamp: float
    color: np.ndarray
    depth: np.ndarray
    intrinsics: Intrinsics


@dataclass(frozen=True)
class Observation:
    """One pose: the measured arm joints (rad, j1..j6, averaged at rest) and the cup centre
    (m, optical frame, the median of the frames' fits)."""

    joints: np.ndarray
    cup: np.ndarray


class Calibration:
    """The configured frames and the solve, shared by the live and the bag paths.

    :param settings: config/calibration.yaml. :param mount_config: the transforms file to start
        from and to write the result like. :param robot: the arm on the cell (``config/robots/``).
    """

    def __init__(self, settings: CalibrationSettings, mount_config: str, robot: str = DEFAULT_ROBOT) -> None:
        self.settings = settings
        self.robot = load_robot_spec(robot)
        self.mount_entries = load_static_transforms(mount_config, robot)
        entries = load_transform_files([mount_config, settings.frames_config], robot)
        self.mount = transform_in(entries, settings.base_frame, settings.mount_frame)
        self.mount_from_optical = transform_in(load_transform_files([settings.frames_config]), settings.mount_frame,
                                               settings.optical_frame)
        self.base_from_optical = self.mount @ self.mount_from_optical

    def axis_in_optical(self, joints: Sequence[float]) -> np.ndarray:
        """The cup's axis in the optical frame by FK and the configured mount (the fit's start)."""
        pose = tcp_poses_from_joints(self.robot, [joints])[0]
        return self.base_from_optical[:3, :3].T @ (pose[:3, :3] @ np.asarray(self.settings.cup.axis_in_tcp))

    def measure(self, frames: Sequence[Frame], joints: Sequence[float]) -> Optional[np.ndarray]:
        """The median cup centre (m, optical frame) over ``frames``; None if none shows the cup."""
        axis = self.axis_in_optical(joints)
        centres = [measure_cup(f.color, f.depth, f.intrinsics, axis, self.settings.cup) for f in frames]
        centres = [c for c in centres if c is not None]
        return np.median(np.array(centres), axis=0) if centres else None

    def solve(self, observations: Sequence[Observation]) -> HandEyeResult:
        """Check the poses and solve (raises CalibrationRefused)."""
        s = self.settings
        poses = tcp_poses_from_joints(self.robot, [o.joints for o in observations])
        check_pose_set(poses, s.min_poses, s.min_position_spread, s.min_rotation_spread)
        result, dropped = solve_rejecting_outliers(poses, np.array([o.cup for o in observations]), self.mount,
                                                   self.mount_from_optical, s.max_condition, s.min_poses,
                                                   s.max_residual)
        if dropped:
            print(f"dropped {len(dropped)} pose(s) further than {s.max_residual * 1e3:.1f} mm from the fit: "
                  f"{[index + 1 for index in dropped]} (of the usable ones)", flush=True)
        return result

    def result_text(self, result: HandEyeResult, source: str) -> str:
        """The transforms file of ``result``."""
        o = result.object_in_tcp * 1e3
        comment = (f"Calibrated by calibrate_camera.py ({source}): {len(result.residuals)} poses, residual RMS "
                   f"{result.rms_mm:.2f} mm, max {result.max_mm:.2f} mm,\ncondition number {result.condition:.0f}; "
                   f"cup centre in tcp ({o[0]:.1f}, {o[1]:.1f}, {o[2]:.1f}) mm.")
        return calibrated_transforms_yaml(self.mount_entries, self.settings.base_frame, self.settings.mount_frame,
                                          result.base_from_mount, comment)


def decode_frame(color_msg, depth_msg, info_msg) -> Frame:
    """A :class:`Frame` of sensor_msgs Image (colour), Image (aligned depth), CameraInfo, with
    the detector's own decoding (raises InputError)."""
    color = decode_color(color_msg.encoding, color_msg.height, color_msg.width, color_msg.step,
                         bytes(color_msg.data), bool(color_msg.is_bigendian))
    depth = decode_depth(depth_msg.encoding, depth_msg.height, depth_msg.width, depth_msg.step,
                         bytes(depth_msg.data), bool(depth_msg.is_bigendian))
    intrinsics = intrinsics_from_camera_info(info_msg.width, info_msg.height, info_msg.K, info_msg.P)
    return Frame(color_msg.header.stamp.to_sec(), color, depth, intrinsics)


def report(result: HandEyeResult, calibration: Calibration) -> str:
    """The result for the terminal: the mount (xyz m, rpy rad), its change, the residuals."""
    xyz = result.base_from_mount[:3, 3]
    rpy = rpy_from_rotation(result.base_from_mount[:3, :3])
    moved = np.linalg.norm(xyz - calibration.mount[:3, 3]) * 1e3
    turned = math.degrees(transform_error(result.base_from_mount, calibration.mount)[1])
    per_pose = ", ".join(f"{value:.1f}" for value in np.linalg.norm(result.residuals, axis=1) * 1e3)
    return (f"residual per pose (mm): {per_pose}\n"
            f"{calibration.settings.base_frame} -> {calibration.settings.mount_frame}: xyz "
            f"[{xyz[0]:.4f}, {xyz[1]:.4f}, {xyz[2]:.4f}] m, rpy [{rpy[0]:.5f}, {rpy[1]:.5f}, {rpy[2]:.5f}] rad "
            f"({moved:.1f} mm, {turned:.2f} deg from the configured mount)\n"
            f"cup centre in tcp: {np.round(result.object_in_tcp * 1e3, 1).tolist()} mm; residual RMS "
            f"{result.rms_mm:.2f} mm, max {result.max_mm:.2f} mm over {len(result.residuals)} poses; "
            f"condition number {result.condition:.0f}")


# ---------------------------------------------------------------------------- from a bag
def observations_from_bag(path: str, calibration: Calibration, joint_states_topic: str) -> List[Observation]:
    """The rest periods of a recording as observations.

    :raises CalibrationRefused: the bag lacks a needed topic (names it).
    """
    import rosbag

    s = calibration.settings
    topics = [joint_states_topic, s.color_topic, s.depth_topic, s.camera_info_topic]
    with rosbag.Bag(path) as bag:
        present = bag.get_type_and_topic_info().topics
        for topic in topics:
            if topic not in present or present[topic].message_count == 0:
                raise CalibrationRefused(f"{path} lacks the topic {topic}")
        names = calibration.robot.joint_names
        samples: List[Tuple[float, np.ndarray]] = []
        merged: Dict[str, float] = {}
        images: Dict[str, Dict[float, object]] = {s.color_topic: {}, s.depth_topic: {}, s.camera_info_topic: {}}
        for topic, message, _ in bag.read_messages(topics=topics):
            if topic == joint_states_topic:
                merged.update(zip(message.name, message.position))
                if all(n in merged for n in names):
                    samples.append((message.header.stamp.to_sec(), np.array([merged[n] for n in names])))
            else:
                images[topic][round(message.header.stamp.to_sec(), 4)] = message
    stamps = np.array([t for t, _ in samples])
    positions = np.array([q for _, q in samples])
    rests = rest_periods(stamps, positions, s.settle_speed, s.settle_time)
    observations = []
    for start, end in rests:
        frames = []
        for key in sorted(images[s.color_topic]):
            if start + s.settle_time <= key <= end and key in images[s.depth_topic]:
                info = images[s.camera_info_topic].get(key) or next(iter(images[s.camera_info_topic].values()))
                try:
                    frames.append(decode_frame(images[s.color_topic][key], images[s.depth_topic][key], info))
                except InputError:
                    continue
            if len(frames) >= s.frames_per_pose:
                break
        inside = (stamps >= start) & (stamps <= end)
        joints = positions[inside].mean(axis=0)
        cup = calibration.measure(frames, joints) if frames else None
        if cup is not None:
            observations.append(Observation(joints, cup))
    return observations


def rest_periods(stamps: np.ndarray, positions: np.ndarray, settle_speed: float, settle_time: float
                 ) -> List[Tuple[float, float]]:
    """(start, end) times (s) of the spans in which no joint moves faster than ``settle_speed``
    (rad/s, from positions over >= 0.05 s) for longer than ``settle_time`` (s)."""
    if len(stamps) < 3:
        return []
    # Speeds over a 0.05 s baseline: the 5 ms steps of a 200 Hz topic turn 1 mm quantisation into noise.
    lag = max(1, int(np.searchsorted(stamps, stamps[0] + 0.05)))
    dt = stamps[lag:] - stamps[:-lag]
    speed = np.max(np.abs(positions[lag:] - positions[:-lag]), axis=1) / np.maximum(dt, 1e-6)
    still = speed <= settle_speed
    periods, begin = [], None
    for index, ok in enumerate(still):
        if ok and begin is None:
            begin = index
        if (not ok or index == len(still) - 1) and begin is not None:
            end = index if ok else index - 1
            start_time, end_time = stamps[begin], stamps[end + lag]
            if end_time - start_time > settle_time:
                periods.append((float(start_time), float(end_time)))
            begin = None
    return periods


# ---------------------------------------------------------------------------- live
class LiveSession:
    """The ROS side of a live calibration: joint states, camera frames, commands."""

    def __init__(self, calibration: Calibration, joint_states_topic: str, command_topic: str) -> None:
        import message_filters
        import rospy
        from sensor_msgs.msg import CameraInfo, Image, JointState
        from std_msgs.msg import Float64MultiArray

        self.rospy, self.Float64MultiArray = rospy, Float64MultiArray
        s = self.settings = calibration.settings
        self.calibration = calibration
        robot = calibration.robot
        self.joints = JointStateReader(robot.joint_names, robot.finger_joint_names, velocities_from_positions=True,
                                       estimate_interval=0.02)
        self.samples: Deque[Tuple[float, np.ndarray]] = deque(maxlen=4000)
        self.frames: Deque[Tuple[object, object, object]] = deque(maxlen=30)
        self.lock = threading.Lock()
        rospy.Subscriber(joint_states_topic, JointState, self._on_joints, queue_size=50, tcp_nodelay=True)
        subscribers = [message_filters.Subscriber(topic, kind, queue_size=2, buff_size=2 ** 24) for topic, kind in
                       ((s.color_topic, Image), (s.depth_topic, Image), (s.camera_info_topic, CameraInfo))]
        self.sync = message_filters.ApproximateTimeSynchronizer(subscribers, 5, 0.02)
        self.sync.registerCallback(self._on_frame)
        self.command_pub = rospy.Publisher(command_topic, Float64MultiArray, queue_size=1)
        self.names = robot.joint_names

    def _on_joints(self, message) -> None:
        now = time.monotonic()
        self.joints.update(message.name, message.position, message.velocity, message.header.stamp.to_sec(), now)
        reading = self.joints.reading()
        if reading is not None and reading.value is not None:
            with self.lock:
                self.samples.append((message.header.stamp.to_sec(), reading.value.positions.copy()))

    def _on_frame(self, color, depth, info) -> None:
        with self.lock:
            self.frames.append((color, depth, info))

    def state(self) -> Tuple[Optional[np.ndarray], Optional[np.ndarray]]:
        reading = self.joints.reading()
        if reading is None or reading.value is None:
            return None, None
        return reading.value.positions, reading.value.velocities

    def move_to(self, target: np.ndarray, mover: CalibrationMove) -> None:
        """Drive to ``target`` (rad) and return at rest; raises RuntimeError on a gate refusal or timeout."""
        rospy, s = self.rospy, self.settings
        mover.start(target)
        rate = rospy.Rate(s.control_rate)
        deadline = time.monotonic() + s.move_timeout
        while not rospy.is_shutdown():
            if time.monotonic() > deadline:
                raise RuntimeError(f"the move did not arrive within {s.move_timeout:g} s")
            measured, velocities = self.state()
            if measured is None:
                rate.sleep()
                continue
            command, why = mover.step(measured, velocities, time.monotonic())
            if why is not None:
                raise RuntimeError(why)
            if command is None:
                return
            self.command_pub.publish(self.Float64MultiArray(data=command.tolist()))
            rate.sleep()

    def observe(self) -> Optional[Observation]:
        """At rest: the joints and the cup over ``frames_per_pose`` frames stamped after
        ``settle_time`` at rest; None when the cup is not seen."""
        rospy, s = self.rospy, self.settings
        rest_from = rospy.Time.now().to_sec() + s.settle_time
        deadline = time.monotonic() + s.settle_time + s.frame_timeout
        chosen: Dict[float, Tuple] = {}
        while time.monotonic() < deadline and len(chosen) < s.frames_per_pose and not rospy.is_shutdown():
            with self.lock:
                for color, depth, info in self.frames:
                    if color.header.stamp.to_sec() >= rest_from:
                        chosen.setdefault(color.header.stamp.to_sec(), (color, depth, info))
            time.sleep(0.02)
        with self.lock:
            # The joints while the frames were taken (the settling before is not yet rest).
            window = [q for t, q in self.samples if t >= rest_from]
        if not chosen or not window:
            return None
        frames = []
        for key in sorted(chosen)[:s.frames_per_pose]:
            try:
                frames.append(decode_frame(*chosen[key]))
            except InputError as error:
                rospy.logwarn(f"calibrate_camera: frame refused: {error}")
        joints = np.mean(np.array(window), axis=0)
        cup = self.calibration.measure(frames, joints) if frames else None
        return None if cup is None else Observation(joints, cup)


def sim_hold(service: str, on: bool, wait: float = 3.0) -> bool:
    """Ask the simulator to hold (or let go of) the cup; False where no simulator offers the
    service (a real arm). Raises RuntimeError when it is offered but fails: calibrating while the
    simulator runs episodes would fight its resets."""
    import rospy
    from std_srvs.srv import SetBool

    try:
        rospy.wait_for_service(service, timeout=wait)
    except rospy.ROSException:
        return False
    try:
        answer = rospy.ServiceProxy(service, SetBool)(on)
    except rospy.ServiceException as error:
        raise RuntimeError(f"{service}: {error}") from None
    if not answer.success:
        raise RuntimeError(f"{service}: {answer.message}")
    return True


def observations_live(calibration: Calibration, count: int, joint_states_topic: str,
                      command_topic: str) -> List[Observation]:
    """Move, settle, measure at ``count`` poses (the ROS node must be initialised)."""
    import rospy

    s = calibration.settings
    session = LiveSession(calibration, joint_states_topic, command_topic)
    robot, env_cfg = calibration.robot, load_env_config()
    guard = load_guard_settings()
    deadline = time.monotonic() + 30.0
    while session.state()[0] is None or not session.frames:
        if time.monotonic() > deadline or rospy.is_shutdown():
            raise CalibrationRefused(f"no joint states on {joint_states_topic} or no camera frames on "
                                     f"{s.color_topic} within 30 s")
        time.sleep(0.1)
    intrinsics = decode_frame(*session.frames[-1]).intrinsics
    # Where the hand-over leaves the cup is not known yet: the simulator's (a centred grip) stands in.
    poses = calibration_poses(s, robot, env_cfg, guard, calibration.base_from_optical, intrinsics, count,
                              s.simulator.object_in_tcp)
    # The planned set must be solvable before the arm moves at all.
    check_pose_set(tcp_poses_from_joints(robot, poses), s.min_poses, s.min_position_spread, s.min_rotation_spread)
    if sim_hold(s.sim_hold_service, True):
        rospy.loginfo("calibrate_camera: the simulator holds the cup in the gripper")
    mover = CalibrationMove(robot, env_cfg, guard, s.move_speed, s.arrival, s.settle_speed, 1.0 / s.control_rate)
    observations = []
    for index, target in enumerate(poses):
        session.move_to(np.asarray(target), mover)
        observation = session.observe()
        seen = "cup not seen" if observation is None else \
            f"cup at {np.round(observation.cup * 1e3, 1).tolist()} mm (optical frame)"
        print(f"pose {index + 1}/{len(poses)}: {seen}", flush=True)
        if observation is not None:
            observations.append(observation)
    return observations


# ---------------------------------------------------------------------------- command line
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="calibrate_camera.py", description=plain(__doc__.split("\n\n")[0]),
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=plain("\n\n".join(__doc__.split("\n\n")[1:])))
    parser.add_argument("--out", required=True, help="the transforms file to write (static_transforms.yaml's format)")
    parser.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    parser.add_argument("--bag", help="solve from this recording instead of moving the arm")
    parser.add_argument("--poses", type=int, help="poses to visit (default: config/calibration.yaml poses)")
    parser.add_argument("--config", default="calibration", help="settings file (a path or a name in config/)")
    parser.add_argument("--mount-config", help="the configured transforms file: the start, and what is kept "
                                               "(default: the settings' mount_config, config/static_transforms.yaml)")
    parser.add_argument("--robot", choices=robot_names(), default=None,
                        help="the arm on the cell (default: the one /robot_description names live, fr5 from a bag)")
    parser.add_argument("--joint-states", help="joint state topic (default: the settings'; FAIRINO driver: "
                                               "/frrobot/joint_states)")
    parser.add_argument("--command", help="arm command topic (default: the settings'; FAIRINO driver: "
                                          "/frrobot/joints_position_controller/command)")
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    out = Path(args.out)
    try:
        if out.exists() and not args.force:
            raise CalibrationRefused(f"{out} exists: pass --force to overwrite it")
        settings = load_calibration_settings(args.config)
        count = args.poses if args.poses is not None else settings.poses
        if count < settings.min_poses:
            raise CalibrationRefused(f"--poses {count}: at least {settings.min_poses} needed: "
                                     f"{settings.min_poses - count} more")
        robot = args.robot or DEFAULT_ROBOT
        if not args.bag and args.robot is None:
            from .params import described_arm

            robot = described_arm(DEFAULT_ROBOT)  # the arm the running launch describes
        calibration = Calibration(settings, args.mount_config or settings.mount_config, robot)
        joint_states = args.joint_states or settings.joint_states_topic
        if args.bag:
            if not Path(args.bag).is_file():
                raise CalibrationRefused(f"{args.bag}: no such bag")
            observations, source = observations_from_bag(args.bag, calibration, joint_states), f"bag {args.bag}"
        else:
            import rospy

            rospy.init_node("calibrate_camera", anonymous=True, disable_signals=False)
            try:
                observations = observations_live(calibration, count, joint_states,
                                                 args.command or settings.command_topic)
            finally:
                # Whatever happened, a simulator goes back to its episodes.
                if sim_hold(settings.sim_hold_service, False, wait=0.5):
                    rospy.loginfo("calibrate_camera: the simulator let go of the cup")
            source = "live"
        result = calibration.solve(observations)
        print(report(result, calibration), flush=True)
        write_result(out, calibration.result_text(result, source), args.force)
        print(f"written: {out}", flush=True)
        return 0
    except CalibrationRefused as error:
        print(f"calibrate_camera: refused: {error}", file=sys.stderr, flush=True)
        return REFUSED
    except (ConfigError, RuntimeError) as error:
        print(f"calibrate_camera: {error}", file=sys.stderr, flush=True)
        return 1
