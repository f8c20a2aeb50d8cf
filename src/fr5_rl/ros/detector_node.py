"""Detector node: the object's pose (centre, yaw) and shape from an aligned RGB-D camera, as
/target_pose (``~target_topic``) and /target_shape (``~target_shape_topic``).

It subscribes to colour, aligned depth and the colour CameraInfo, synchronised with
message_filters (``~sync_slop``), and hands each frame to
:class:`fr5_rl.perception.detector.ObjectDetector` with the camera's pose over the table from tf2
(``~table_frame`` <- the image's frame). It needs no knowledge of the object's colour: it looks
for the one thing standing on the table inside the placement region (config/env.yaml).

- a detection: geometry_msgs/PoseStamped of the object centre on ``~target_topic``, in the
  image's optical frame, with the image's stamp; its orientation is the object's, upright on the
  table at its yaw (Rz(yaw) in ``~table_frame``: the own x axis along a box's longer top side,
  any of its symmetric yaws; a cylinder's yaw 0), expressed in the optical frame. Beside it the
  object's shape on ``~target_shape_topic`` (shape_msgs/SolidPrimitive, latched, published
  before each target): a BOX's ``[longer, shorter, height]`` along that pose's x, y, z, a
  CYLINDER's ``[height, radius]`` (m; the height is its top's above the table);
- the object hidden by the robot while it goes down around it, or held in its fingers: the
  position :class:`fr5_rl.perception.tracker.ObjectTracker` keeps (the last seen one, for
  ``~tracker/hidden_timeout``; the tcp's pose from tf times the grasp offset while the fingers, from
  ``~joint_states_topics`` merged by joint name (e.g. the arm driver's and the gripper bridge's),
  are closed on it, until they open: told to open wider than they hold, on
  ``~gripper_command_topic``, and opened), stamped with the new image; ``~track_state``
  (std_msgs/String) says which: ``seen``, ``hidden``, ``in hand`` or ``holding: <why>``. Hidden,
  the pose keeps the last seen yaw and the shape the last seen one; held, the pose is in the tcp
  frame with the object's orientation in it as it was when the fingers took it (so tf turns it
  with the tcp), and the shape is the last seen one;
- no detection (nothing, several candidates, the object hidden too long or gone) or bad input
  (image sizes that differ, an unknown encoding, a missing or zero CameraInfo, depth that is
  all zero or NaN, a frame older than ``~max_image_age``): nothing is published (the policy
  node holds once its target is stale) and a warning says why, at once when the reason
  changes, then at most every 2 s.

While something subscribes to ``~objects_topic`` (``~objects``), each frame also reports every
object it shows whole there (``fr5_rl/DetectedObjects``: an id it keeps while tracked, kind, pose upright
at its yaw and shape, in the table frame, with the image's stamp), and every piece that is not one, with the reason
(:func:`fr5_rl.perception.scene_detector.detect_scene`): for a cell with several objects.

Every frame also goes to ``~debug_image_topic`` (rgb8) with the detection drawn (green: seen,
yellow: hidden, blue: in the hand; a red frame when there is none), and per-frame compute times
to ``~timing`` (Float64MultiArray: decode, detect, track, total, all seconds; and the image's
age when the frame arrived). The default topics are the RealSense driver's, so on a real camera the
node runs as it is. Parameters: ``config/detector.yaml``; its ``detector`` and ``tracker``
sections go whole to the detector and the tracker (``~detector/min_height`` sets one of them).
"""
from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Deque, List, Optional, Sequence, Tuple, Union

import message_filters
import numpy as np
import rospy
import tf2_ros
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import CameraInfo, Image, JointState
from shape_msgs.msg import SolidPrimitive
from std_msgs.msg import Float64, Float64MultiArray, String
from visualization_msgs.msg import MarkerArray

from ..config import DEFAULT_ROBOT, ConfigError, load_robot_spec
from ..deploy.joint_state import JointStateReader
from ..env_config import load_env_config
from ..perception.camera_model import Intrinsics
from ..perception.detector import Detection, DetectorSettings, ObjectDetector, Refusal, RefusalReason, TableRegion
from ..perception.images import InputError, check_frame, decode_color, decode_depth, intrinsics_from_camera_info
from ..perception.overlay import draw_detection
from ..perception.scene_detector import SceneDetectorSettings, SceneLimits, detect_scene
from ..perception.scene_tracker import SceneTracker
from ..perception.target_selection import SceneTargetTracker, Selection
from ..clearing import ClearingSettings
from ..scenes import SceneSettings
from ..perception.tracker import ObjectTracker, TrackedObject, TrackerSettings, TrackState, rotation_z
from ..objects import quaternion_of_yaw
from ..transforms import matrix_from_quaternion, quaternion_from_matrix
from .images import image_message
from .params import described_arm, exit_if_help_asked, node_parameters
from .lifetime import init_node
from .object_messages import detected_objects_message, detected_object_markers, primitive_from_shape

TF_ERRORS = (tf2_ros.LookupException, tf2_ros.ConnectivityException, tf2_ros.ExtrapolationException,
             tf2_ros.InvalidArgumentException)


@dataclass(frozen=True)
class DetectorNodeParams:
    """``config/detector.yaml``: the detector node's ~private parameters (topics and frames in
    the node's own docstring and the file's comments).

    :param sync_slop: s; colour, depth and camera_info stamps further apart are not one frame.
    :param max_image_age: s; an older frame (by stamp) is refused.
    :param startup_grace: wall s after start in which missing hand inputs (tf, finger joint
        states) are still expected to come, not yet worth a warning.
    :param detector: the detector's thresholds, handed to it whole.
    :param tracker: the tracker's settings, handed to it whole.
    :param scene: the thresholds of the report of every object (``~objects_topic``).
    :param joint_states_topics: sensor_msgs/JointState topics merged by joint name for the finger
        joints (the arm's driver and a gripper driver may publish apart).
    :param hand_check_rate: Hz at which, between frames, the tcp and the fingers alone are checked
        for a lift of the tracked object in the hand (:meth:`ObjectTracker.hand_between_frames`); 0: off.
    :param objects_topic: fr5_rl/DetectedObjects: every object a frame shows whole, with its kind,
        and every piece refused, in the table frame (:func:`fr5_rl.perception.scene_detector.detect_scene`;
        computed only while something subscribes); "" off.
    :param objects_gate: m: an object this near where one of its kind was last seen keeps that
        one's id (:class:`fr5_rl.perception.scene_tracker.SceneTracker`; unseen, an id lasts
        ``tracker.hidden_timeout``).
    :param gripper_command_topic: std_msgs/Float64 (m) the fingers are told their opening on (the
        policy node's and the gripper bridge's); "" when none: a held object whose grip widens by
        ``tracker/release_opening`` then counts as let go, also while the fingers are told to
        close (an off-centre grip turning square between the pads widens by 5-6 mm).
    :param selection_rule: "": one object on the table (a second one is refused); ``nearest``,
        ``kind`` or ``id`` (``clearing``: config/clearing.yaml's ``rule``): the target is one
        object of a scene, chosen by that rule
        (:class:`fr5_rl.perception.target_selection.SceneTargetTracker`, config/clearing.yaml),
        changed at run time through ``~select`` (fr5_rl/SelectObject); a cell's sequencer says an
        object is done, and learns the next, through ``~next`` (fr5_rl/NextObject).
    :param selection_kind: rule ``kind``: only this kind; "": clearing.yaml's ``kind_order``.
    :param selection_gate: m: with a selection, the detection of the target's kind nearest where
        it is believed, this near, is the target.
    :param object_markers_topic: visualization_msgs/MarkerArray of every object reported on
        ``~objects_topic`` (the chosen one drawn green, with its id), for rviz; "" off.
    """

    color_topic: str
    depth_topic: str
    camera_info_topic: str
    target_topic: str
    target_shape_topic: str
    debug_image_topic: str
    table_frame: str
    sync_slop: float
    max_image_age: float
    startup_grace: float
    detector: DetectorSettings
    tracker: TrackerSettings
    scene: SceneDetectorSettings
    tcp_frame: str
    objects_topic: str
    objects_gate: float
    joint_states_topics: List[str]
    track_state_topic: str
    hand_check_rate: float
    gripper_command_topic: str
    selection_rule: str = ""
    selection_kind: str = ""
    selection_gate: float = 0.04
    object_markers_topic: str = ""

    def check(self, source: str) -> None:
        if self.selection_rule and self.selection_rule != "clearing":
            try:
                Selection(self.selection_rule, self.selection_kind, 1).check()
            except ValueError as error:
                raise ConfigError(f"{source}: selection_rule/selection_kind: {error}") from None
        if self.selection_gate <= 0:
            raise ConfigError(f"{source}: 'selection_gate' must be > 0 m, got {self.selection_gate}")
        if self.hand_check_rate < 0:
            raise ConfigError(f"{source}: 'hand_check_rate' must be >= 0 Hz (0: off), got {self.hand_check_rate}")
        if self.sync_slop <= 0 or self.max_image_age <= 0:
            raise ConfigError(f"{source}: sync_slop and max_image_age must be > 0")
        if not self.joint_states_topics or len(set(self.joint_states_topics)) != len(self.joint_states_topics):
            raise ConfigError(f"{source}: joint_states_topics must list one or more topics, each once")


def target_pose(tracked: TrackedObject, table_from_optical: Optional[np.ndarray]
                ) -> Tuple[bool, Tuple[float, float, float], Tuple[float, float, float, float]]:
    """The pose to publish for ``tracked``.

    :param table_from_optical: 4x4 pose (m) of the image's optical frame in the table frame
        (unused for a held object, which needs none).
    :return: ``(held, position, quaternion)``: held, both are in the tcp frame (so the user's tf
        places it at the newest tcp pose rather than the one of an older image, and turns it with
        the tcp), else in the optical frame; position in m, quaternion (x, y, z, w).
    """
    if tracked.position_tcp is not None:
        return True, tracked.position_tcp, (tracked.orientation_tcp if tracked.orientation_tcp is not None
                                            else (0.0, 0.0, 0.0, 1.0))
    optical_from_table = np.linalg.inv(np.asarray(table_from_optical, dtype=np.float64))
    position = (optical_from_table @ np.append(tracked.position_table, 1.0))[:3]
    # Upright at its yaw in the table frame, seen from the camera.
    quaternion = quaternion_from_matrix(optical_from_table[:3, :3] @ rotation_z(tracked.yaw))
    return False, (float(position[0]), float(position[1]), float(position[2])), quaternion


class FingerWidths:
    """The gripper's opening (m, the sum of the finger joints) by stamp, from joint-state messages
    of one or several topics merged by joint name (:class:`JointStateReader`).

    A message that names a finger joint adds the merged opening, stamped with the oldest header
    stamp among the finger joints; others (the arm driver's j1..j6) add nothing. One topic that
    carries every joint gives exactly each message's own stamp and finger sum.

    :param finger_names: the finger joints (config/gripper.yaml).
    :param length: how many openings to keep (about 2 s of a 200 Hz topic).
    """

    def __init__(self, finger_names: Sequence[str], length: int) -> None:
        self.finger_names = frozenset(finger_names)
        # The fingers stand in for the reader's "arm": it then wants every finger and nothing else.
        self.reader = JointStateReader(finger_names, finger_names)
        self.widths: Deque[Tuple[float, float]] = deque(maxlen=length)
        self.lock = threading.Lock()

    def add(self, names: Sequence[str], positions: Sequence[float], velocities: Sequence[float],
            stamp: float, received: float) -> None:
        """Take one message.

        :param positions: by ``names`` (rad; m for the fingers).
        :param stamp: its header stamp (s).
        :param received: arrival time (s, monotonic).
        """
        with self.lock:
            if self.reader.update(names, positions, velocities, stamp, received) is not None:
                return  # refused by the reader (NaN, a name twice, arrays that do not fit)
            if self.finger_names.isdisjoint(names):
                return  # nothing new about the fingers
            reading = self.reader.reading()
            if reading is None or reading.value is None or reading.value.gripper_width is None:
                return  # not every finger heard of yet
            self.widths.append((reading.stamp, reading.value.gripper_width))

    def heard(self) -> bool:
        """Whether any opening was taken (else no finger joints arrive at all)."""
        with self.lock:
            return bool(self.widths)

    def at(self, stamp: float) -> Optional[float]:
        """The opening (m) nearest ``stamp`` (s) within 0.1 s; None when unknown."""
        with self.lock:
            if not self.widths:
                return None
            nearest = min(reversed(self.widths), key=lambda entry: abs(entry[0] - stamp))
        return nearest[1] if abs(nearest[0] - stamp) <= 0.1 else None


class CommandedWidths:
    """The openings (m) the fingers were told to go to, by arrival time (std_msgs/Float64 has no
    stamp: a command counts from when it reached this node).

    :param length: how many commands to keep (about 4 s at 50 Hz).
    """

    def __init__(self, length: int) -> None:
        self.commands: Deque[Tuple[float, float]] = deque(maxlen=length)
        self.lock = threading.Lock()

    def add(self, width: float, received: float) -> None:
        """Take one command (m) that arrived at ``received`` (s, ROS time); a NaN or infinite one
        tells nothing and is skipped (the bridge refuses it too)."""
        if not np.isfinite(width):
            return
        with self.lock:
            self.commands.append((received, float(width)))

    def at(self, stamp: float) -> Optional[float]:
        """The newest command (m) that had arrived by ``stamp`` (s); None when none had (or the
        ones kept are all newer: an old frame's command is then unknown)."""
        with self.lock:
            for received, width in reversed(self.commands):
                if received <= stamp:
                    return width
        return None


class DetectorNode:
    """Synchronised image subscribers, tf2, the tracker, and the target and debug publishers."""

    def __init__(self) -> None:
        self.params = params = node_parameters(DetectorNodeParams, "detector")
        # The arm the launch describes (robot_description.py names the URDF after it): its cell's
        # table and placement region, and its fingers.
        robot = described_arm(DEFAULT_ROBOT)
        cell = load_env_config({"robot": robot})
        table = TableRegion.from_env(cell)
        self.detector = ObjectDetector(params.detector, table)
        self.tracker = ObjectTracker(params.tracker, params.detector, table)
        self.tracker_lock = threading.Lock()  # frames and the between-frames hand check
        self.last_refusal: Optional[RefusalReason] = None
        self.last_track: Optional[TrackState] = None
        # Recent openings by stamp, to read the opening at an image's stamp.
        self.widths = FingerWidths(load_robot_spec(robot).finger_joint_names, 400)
        self.commanded = CommandedWidths(200)
        self.warned_no_hand = False
        self.started = time.monotonic()
        self.table_from_optical: Optional[np.ndarray] = None  # of the last frame tf could place
        self.tf_buffer = tf2_ros.Buffer(cache_time=rospy.Duration(10.0))
        self.tf_listener = tf2_ros.TransformListener(self.tf_buffer)
        self.target_pub = rospy.Publisher(params.target_topic, PoseStamped, queue_size=1)
        # Latched: a node that starts later still learns the shape of the object in view.
        self.shape_pub = rospy.Publisher(params.target_shape_topic, SolidPrimitive, queue_size=1, latch=True)
        self.debug_pub = rospy.Publisher(params.debug_image_topic, Image, queue_size=1)
        self.state_pub = rospy.Publisher(params.track_state_topic, String, queue_size=1)
        self.timing_pub = rospy.Publisher("~timing", Float64MultiArray, queue_size=10)
        self.objects_pub = self.markers_pub = self.selector = None
        if params.objects_topic or params.selection_rule:
            self.scene_limits = SceneLimits.from_objects(cell.object.variety,
                                                         SceneSettings.from_yaml().rectangular_min_difference,
                                                         params.scene)
            self.scene_tracker = SceneTracker(params.objects_gate, params.tracker.hidden_timeout)
        if params.objects_topic:
            from ..msg import DetectedObjects  # built by catkin from msg/

            self.objects_pub = rospy.Publisher(params.objects_topic, DetectedObjects, queue_size=1)
            if params.object_markers_topic:
                self.markers_pub = rospy.Publisher(params.object_markers_topic, MarkerArray, queue_size=1)
        if params.selection_rule:
            from ..srv import NextObject, SelectObject  # built by catkin from srv/

            clearing = ClearingSettings.from_yaml()
            rule = clearing.rule if params.selection_rule == "clearing" else params.selection_rule
            # Rule id starts with object 1 (the first one a frame shows): ~select names another.
            self.selector = SceneTargetTracker(self.tracker, self.scene_tracker, clearing, params.selection_gate,
                                               Selection(rule, params.selection_kind, 1 if rule == "id" else 0))
            rospy.Service("~select", SelectObject, self.on_select)
            rospy.Service("~next", NextObject, self.on_next)
        for topic in params.joint_states_topics:
            rospy.Subscriber(topic, JointState, self.on_joint_state, queue_size=10, tcp_nodelay=True)
        if params.gripper_command_topic:
            rospy.Subscriber(params.gripper_command_topic, Float64,
                             lambda message: self.commanded.add(message.data, rospy.Time.now().to_sec()),
                             queue_size=10, tcp_nodelay=True)
        # Images are large: rospy's default receive buffer would queue them behind each other.
        # One deep: when the detector falls behind, the newest frame is the one worth detecting.
        subscribers = [message_filters.Subscriber(topic, kind, queue_size=1, buff_size=1 << 24, tcp_nodelay=True)
                       for topic, kind in ((params.color_topic, Image), (params.depth_topic, Image),
                                           (params.camera_info_topic, CameraInfo))]
        self.sync = message_filters.ApproximateTimeSynchronizer(subscribers, queue_size=5, slop=params.sync_slop)
        self.sync.registerCallback(self.on_frame)
        # A missing input (no camera_info at all) never completes a frame: watch each one.
        self.last_arrival = {topic: 0.0 for topic in (params.color_topic, params.depth_topic, params.camera_info_topic)}
        self.last_frame = time.monotonic()
        for subscriber, topic in zip(subscribers, self.last_arrival):
            subscriber.registerCallback(lambda _message, topic=topic: self.last_arrival.__setitem__(topic, time.monotonic()))
        self.watchdog = rospy.Timer(rospy.Duration(1.0), self.check_inputs)
        if params.hand_check_rate > 0:
            self.hand_timer = rospy.Timer(rospy.Duration(1.0 / params.hand_check_rate), self.check_hand)
        rospy.loginfo(f"detector_node: {params.color_topic} + {params.depth_topic} + {params.camera_info_topic} "
                      f"-> {params.target_topic}, {params.target_shape_topic}")

    def on_joint_state(self, message: JointState) -> None:
        """Keep the fingers' opening by stamp (any of ``~joint_states_topics``)."""
        self.widths.add(message.name, message.position, message.velocity, message.header.stamp.to_sec(),
                        time.monotonic())

    def tcp_at(self, stamp: rospy.Time) -> Optional[np.ndarray]:
        """The tcp's pose (4x4, m) in the table frame at ``stamp``, or the newest one; None without tf."""
        for when in (stamp, rospy.Time(0)):
            try:
                transform = self.tf_buffer.lookup_transform(self.params.table_frame, self.params.tcp_frame, when)
            except TF_ERRORS:
                continue
            t, r = transform.transform.translation, transform.transform.rotation
            return matrix_from_quaternion((t.x, t.y, t.z), (r.x, r.y, r.z, r.w))
        return None

    def check_hand(self, _event) -> None:
        """Between frames: a lift of the tracked object in the fingers, from tf and the finger
        joints of now, published at once (in the tcp frame, stamped now)."""
        now = rospy.Time.now()
        tcp, width = self.tcp_at(rospy.Time(0)), self.widths.at(now.to_sec())
        with self.tracker_lock:
            tracked = self.tracker.hand_between_frames(now.to_sec(), tcp, width, self.commanded.at(now.to_sec()))
        if tracked is not None:
            try:
                self.publish_target(tracked, now, self.params.tcp_frame)
            except rospy.ROSException:
                if not rospy.is_shutdown():
                    raise

    def check_inputs(self, _event) -> None:
        """Warn when frames stopped although images come: an input is missing or out of sync."""
        now = time.monotonic()
        if now - self.last_frame < 2.0 or not any(now - t < 1.0 for t in self.last_arrival.values()):
            return
        silent = [topic for topic, t in self.last_arrival.items() if now - t >= 1.0]
        self.report(Refusal(RefusalReason.CAMERA_INFO if self.params.camera_info_topic in silent
                            else RefusalReason.STALE,
                            f"no synchronised frame for {now - self.last_frame:.0f} s; silent: {', '.join(silent) or 'none'}"
                            + ("" if silent else f" (stamps further apart than ~sync_slop {self.params.sync_slop:g} s?)")))

    def on_frame(self, color: Image, depth: Image, info: CameraInfo) -> None:
        """One synchronised frame: refuse, or detect (and track) and publish."""
        try:
            self.handle_frame(color, depth, info)
        except rospy.ROSException:
            if not rospy.is_shutdown():
                raise
            # A frame still in hand when the node shuts down: its topics are closed, nothing lost.

    def handle_frame(self, color: Image, depth: Image, info: CameraInfo) -> None:
        self.last_frame = time.monotonic()
        started = time.perf_counter()
        age = rospy.Time.now().to_sec() - color.header.stamp.to_sec()
        result: Union[Detection, Refusal]
        rgb: Optional[np.ndarray] = None
        detected = decoded = started
        try:
            intrinsics = intrinsics_from_camera_info(info.width, info.height, info.K, info.P)
            rgb = decode_color(color.encoding, color.height, color.width, color.step, color.data,
                               bool(color.is_bigendian))
            depth_m = decode_depth(depth.encoding, depth.height, depth.width, depth.step, depth.data,
                                   bool(depth.is_bigendian))
        except InputError as error:
            result = error.refusal
        else:
            stamp = color.header.stamp
            decoded = time.perf_counter()
            result = check_frame(rgb, depth_m, intrinsics, stamp.to_sec(), rospy.Time.now().to_sec(),
                                 self.params.max_image_age, self.params.detector.min_valid_depth_fraction)
            if result is None and self.selector is not None:
                result = self.choose_and_track(depth_m, intrinsics, color)
                detected = time.perf_counter()
            else:
                if result is None:
                    result = self.detect(rgb, depth_m, intrinsics, color)
                    self.report_every_object(depth_m, intrinsics, color)
                detected = time.perf_counter()
                result = self.track(result, depth_m, intrinsics, stamp)
        tracked = time.perf_counter()
        if isinstance(result, TrackedObject):
            self.publish_target(result, color.header.stamp, color.header.frame_id)
        else:
            self.report(result)
        self.timing_pub.publish(Float64MultiArray(data=[decoded - started, detected - decoded, tracked - detected,
                                                        time.perf_counter() - started, age]))
        if rgb is not None and self.debug_pub.get_num_connections() > 0:
            drawn = draw_detection(rgb, result, intrinsics, self.table_from_optical)
            self.debug_pub.publish(image_message(drawn, "rgb8", color.header.stamp, color.header.frame_id))

    def on_select(self, request):
        """``~select`` (fr5_rl/SelectObject): the rule the next object is chosen by."""
        from ..srv import SelectObjectResponse

        try:
            selection = Selection(request.rule, request.kind, int(request.id))
            with self.tracker_lock:
                message = self.selector.select(selection)
        except ValueError as error:
            return SelectObjectResponse(success=False, message=str(error))
        rospy.loginfo(f"detector_node: selection {message}")
        return SelectObjectResponse(success=True, message=message)

    def on_next(self, _request):
        """``~next`` (fr5_rl/NextObject): the current object is done; the next one, chosen now."""
        from ..srv import NextObjectResponse

        with self.tracker_lock:
            chosen = self.selector.next_object()
        if chosen is None:
            return NextObjectResponse(success=False, message="the last frame showed no object to choose outside "
                                                             "the drop area")
        track_id, found = chosen
        answer = NextObjectResponse(success=True, message=f"object {track_id} ({found.label})", id=track_id,
                                    kind=found.label)
        position, orientation = answer.pose.position, answer.pose.orientation
        position.x, position.y, position.z = found.detection.position_table
        orientation.x, orientation.y, orientation.z, orientation.w = quaternion_of_yaw(found.detection.yaw)
        rospy.loginfo(f"detector_node: next: object {track_id} ({found.label})")
        return answer

    def choose_and_track(self, depth_m: np.ndarray, intrinsics: Intrinsics, color: Image) -> Union[TrackedObject, Refusal]:
        """With a selection: every object of the frame, the chosen one followed by the tracker
        (:class:`~fr5_rl.perception.target_selection.SceneTargetTracker`), and the report of
        them all on ``~objects_topic``."""
        refusal = self.look_up_camera(color)
        if refusal is not None:
            return refusal
        scene = detect_scene(self.detector, self.scene_limits, depth_m, intrinsics, self.table_from_optical)
        stamp = color.header.stamp
        tcp, width = self.tcp_at(stamp), self.widths.at(stamp.to_sec())
        with self.tracker_lock:
            frame = self.selector.update(scene, stamp.to_sec(), depth_m, intrinsics, self.table_from_optical, tcp,
                                         width, self.commanded.at(stamp.to_sec()))
        self.publish_objects(scene, [track_id for track_id, _ in frame.objects], frame.chosen_id, stamp)
        return frame.target

    def publish_objects(self, scene, ids: List[int], chosen_id: int, stamp: rospy.Time) -> None:
        """The report of every object (and its rviz markers), to whoever subscribes."""
        if self.objects_pub is not None and self.objects_pub.get_num_connections() > 0:
            message = detected_objects_message(scene, ids, stamp, self.params.table_frame)
            message.chosen_id = chosen_id
            self.objects_pub.publish(message)
        if self.markers_pub is not None and self.markers_pub.get_num_connections() > 0:
            self.markers_pub.publish(detected_object_markers(scene, ids, chosen_id, stamp, self.params.table_frame))

    def track(self, result: Union[Detection, Refusal], depth_m: np.ndarray, intrinsics: Intrinsics,
              stamp: rospy.Time) -> Union[TrackedObject, Refusal]:
        """The tracker's answer for a frame the detector looked at (``result``).

        :param depth_m: the frame's depth (m, 0 = none).
        :param stamp: the frame's capture time.
        """
        tcp = self.tcp_at(stamp)
        width = self.widths.at(stamp.to_sec())
        # A gripper read back at 10 Hz leaves frames with no opening within 0.1 s (after a move the
        # controller's transient 0 is skipped): that is a gap, not a missing driver.
        missing_fingers = width is None and not self.widths.heard()
        if (tcp is None or missing_fingers) and not self.warned_no_hand \
                and time.monotonic() - self.started > self.params.startup_grace:
            missing = (f"tf {self.params.table_frame} <- {self.params.tcp_frame} (robot_state_publisher?)"
                       if tcp is None else f"finger joints on {', '.join(self.params.joint_states_topics)} (gripper driver?)")
            rospy.logwarn(f"detector_node: no {missing}: an object held in the gripper cannot be followed, only a "
                          "hidden one held at its last position; publish it to follow grasped objects")
            self.warned_no_hand = True
        with self.tracker_lock:
            return self.tracker.update(result, stamp.to_sec(), depth_m, intrinsics, self.table_from_optical, tcp,
                                       width, self.commanded.at(stamp.to_sec()))

    def look_up_camera(self, color: Image) -> Optional[Refusal]:
        """Place the image's optical frame in the table frame (:attr:`table_from_optical`) from
        tf; the refusal when tf cannot."""
        try:
            transform = self.tf_buffer.lookup_transform(self.params.table_frame, color.header.frame_id, rospy.Time(0))
        except TF_ERRORS as error:
            return Refusal(RefusalReason.NO_TRANSFORM, f"{color.header.frame_id} -> {self.params.table_frame}: {error}")
        t, r = transform.transform.translation, transform.transform.rotation
        self.table_from_optical = matrix_from_quaternion((t.x, t.y, t.z), (r.x, r.y, r.z, r.w))
        return None

    def detect(self, rgb: np.ndarray, depth_m: np.ndarray, intrinsics, color: Image) -> Union[Detection, Refusal]:
        refusal = self.look_up_camera(color)
        if refusal is not None:
            return refusal
        return self.detector.detect(depth_m, intrinsics, self.table_from_optical, rgb)

    def report_every_object(self, depth_m: np.ndarray, intrinsics: Intrinsics, color: Image) -> None:
        """Every object the frame shows whole, and every piece refused, on ``~objects_topic``
        (only while something subscribes: it is a second look at the frame)."""
        if self.objects_pub is None or self.table_from_optical is None or (
                self.objects_pub.get_num_connections() == 0
                and (self.markers_pub is None or self.markers_pub.get_num_connections() == 0)):
            return
        scene = detect_scene(self.detector, self.scene_limits, depth_m, intrinsics, self.table_from_optical)
        ids = [track_id for track_id, _ in self.scene_tracker.update(scene, color.header.stamp.to_sec())]
        self.publish_objects(scene, ids, 0, color.header.stamp)

    def publish_target(self, tracked: TrackedObject, stamp: rospy.Time, optical_frame: str) -> None:
        """:param stamp: the frame's capture time (or now, between frames).
        :param optical_frame: the frame's optical frame (a held object is published in the tcp frame)."""
        if self.last_refusal is not None:
            rospy.loginfo(f"detector_node: object found again (was: {self.last_refusal.value})")
            self.last_refusal = None
        if tracked.state != self.last_track:
            # Said at every change: a published position that was not seen this frame is news.
            age = stamp.to_sec() - tracked.last_seen
            rospy.loginfo(f"detector_node: object {tracked.state.value}"
                          + ("" if tracked.state is TrackState.SEEN else f" (last seen {age:.2f} s ago)"))
            self.last_track = tracked.state
        self.state_pub.publish(String(data=tracked.state.value))
        message = PoseStamped()
        message.header.stamp = stamp
        held, xyz, quaternion = target_pose(tracked, self.table_from_optical)
        message.header.frame_id = self.params.tcp_frame if held else optical_frame
        position, orientation = message.pose.position, message.pose.orientation
        position.x, position.y, position.z = xyz
        orientation.x, orientation.y, orientation.z, orientation.w = quaternion
        if tracked.shape is not None:
            # First: a policy that takes the new target finds the shape its pose's axes refer to.
            self.shape_pub.publish(primitive_from_shape(tracked.shape))
        self.target_pub.publish(message)

    def report(self, refusal: Refusal) -> None:
        self.state_pub.publish(String(data=f"holding: {refusal}"))
        self.last_track = None
        # At once when the kind of problem changes, then at most every 2 s.
        if refusal.reason != self.last_refusal:
            rospy.logwarn(f"detector_node: holding: {refusal}")
        else:
            rospy.logwarn_throttle(2.0, f"detector_node: holding: {refusal}")
        self.last_refusal = refusal.reason


def main() -> int:
    exit_if_help_asked("detector_node.py", __doc__.split("\n\n")[0], "detector")
    init_node("detector")
    try:
        DetectorNode()
    except ConfigError as error:
        rospy.logfatal(str(error))
        return 1
    rospy.spin()
    return 0
