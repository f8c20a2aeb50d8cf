"""Camera node: a simulated RealSense-like RGB-D camera that photographs the simulator's scene.

It keeps its own render-only PyBullet world (:class:`fr5_rl.sim.camera.SimulatedCamera`) in its
own process, so rendering never stalls the simulator's ``/joint_states`` or the policy's
commands. It mirrors the simulator: the joints from ``~joint_states_topic`` (the simulator's
ground truth; merged by name, so a topic with only some joints works) and the object's true
pose, size and shape from ``~object_topic`` (visualization_msgs/Marker in base_link, published
by sim_node with every joint state). At up to ``~rate`` it renders the newest state and
publishes, all stamped with that state's stamp (the simulated capture time) and in ``~frame_id``
(``camera_color_optical_frame``, REP 103), as realsense2_camera (ros1-legacy,
``align_depth:=true``) does:

- ``~color_topic``: sensor_msgs/Image ``rgb8``;
- ``~depth_topic``: sensor_msgs/Image ``16UC1``, millimetres along the optical axis, 0 = no
  data, aligned to colour (same camera model), with optional stereo-like noise;
- ``~camera_info_topic`` and ``~depth_camera_info_topic``: sensor_msgs/CameraInfo of the
  projection used to render (``plumb_bob``, zero distortion).

Per frame, ``~timing`` (std_msgs/Float64MultiArray) gives the seconds spent rendering, converting
and publishing, and the rendered state's age when the frame was published.

Frames, as the wrapper's: the project publishes only the mount ``~base_frame`` -> camera_link
(``~mount_config``); the camera's own chain camera_link -> camera_color_frame ->
camera_color_optical_frame (and camera_aligned_depth_to_color_frame) is ``~frames_config``. With
``~publish_tf`` true (the wrapper's default) this node publishes that chain on /tf_static; with
false the launch must (static_transforms_node.py). Either way the picture is taken from
``~frame_id``'s pose through both files, read once at start. Parameters: ``config/camera.yaml``.

``~mount_offset`` (dx dy dz m, droll dpitch dyaw rad; default zeros) is a hidden mount error,
for rehearsing the camera's calibration: the picture is taken from the configured mount composed
with this offset in the camera_link frame (T_base_link · T(offset), URDF fixed-axis rpy), while
every transform on tf stays the configured one, as with a real camera mounted slightly off.
"""
from __future__ import annotations

import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import rospy
import tf2_ros
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import Marker, MarkerArray

from ..config import DEFAULT_ROBOT, ConfigError, load_robot_spec
from ..env_config import load_env_config
from ..perception.camera_model import Intrinsics, IntrinsicsError
from ..perception.hand_eye import offset_transform
from ..sim.camera import RENDERERS, SimulatedCamera, depth_to_millimetres
from ..transforms import load_transform_files, transform_in
from .images import camera_info_message, image_message
from .params import described_arm, exit_if_help_asked, node_parameters
from .scheduling import lower_priority, runs_idle
from .static_transforms import to_messages
from .lifetime import init_node


class JointStateHistory:
    """Recent joint states by stamp, each merged by name over the ones before it, so the camera
    poses every joint it has ever heard of even when a message carries only some.

    :param length: how many stamps to keep (a few frame periods of the simulator's 200 Hz).
    """

    def __init__(self, length: int) -> None:
        self.length = length
        self.states: "OrderedDict[int, Dict[str, float]]" = OrderedDict()

    def add(self, stamp_ns: int, names: Sequence[str], positions: Sequence[float]) -> None:
        """Take one message.

        :param stamp_ns: its header stamp (ns).
        :param positions: by ``names`` (rad; m for the fingers).
        """
        merged = dict(next(reversed(self.states.values()))) if self.states else {}
        merged.update(zip(names, positions))
        self.states[stamp_ns] = merged
        self.states.move_to_end(stamp_ns)
        while len(self.states) > self.length:
            self.states.popitem(last=False)

    def at(self, stamp_ns: int) -> Optional[Tuple[int, Dict[str, float]]]:
        """(stamp ns, joints) of ``stamp_ns`` (ns) if held, else the newest; None before any."""
        if not self.states:
            return None
        joints = self.states.get(stamp_ns)
        return (stamp_ns, joints) if joints is not None else next(reversed(self.states.items()))


@dataclass(frozen=True)
class CameraNodeParams:
    """``config/camera.yaml``: the simulated camera's ~private parameters."""

    rate: float
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    near: float
    far: float
    renderer: str
    depth_noise: float
    seed: int
    frame_id: str
    base_frame: str
    publish_tf: bool
    mount_config: str
    frames_config: str
    mount_offset: List[float]
    nice: int
    idle: bool
    joint_states_topic: str
    object_topic: str
    neighbours_topic: str
    color_topic: str
    depth_topic: str
    camera_info_topic: str
    depth_camera_info_topic: str

    def transforms(self, robot: Optional[str] = None) -> Tuple[np.ndarray, List[Dict]]:
        """Read the frames once: ``~frame_id``'s pose in ``~base_frame`` (4x4, m), the mount and
        then the camera's chain, the same transforms tf carries, so the picture is taken where
        tf says it is, unless ``~mount_offset`` moves the render pose (not the entries) off it;
        and the chain's entries (``~frames_config``), for /tf_static.

        :param robot: the arm on the cell: the shipped mount file stands for its own.

        :raises ConfigError: a file is wrong, a frame has a parent in both files, the chain does
            not give ``frame_id`` a parent, or the files do not connect it to ``base_frame``.
        """
        entries = load_transform_files([self.mount_config, self.frames_config], robot)
        frames = [entry for entry in entries if entry["source"] == self.frames_config]
        if self.frame_id not in {entry["child"] for entry in frames}:
            raise ConfigError(f"{self.frames_config}: no transform to the camera's frame_id {self.frame_id}")
        if not any(self.mount_offset):  # bit for bit the configured chain
            return transform_in(entries, self.base_frame, self.frame_id), frames
        # The chain's root (camera_link): the one parent in the camera's file that is no child there.
        children = {entry["child"] for entry in frames}
        root = next(entry["parent"] for entry in frames if entry["parent"] not in children)
        render = (transform_in(entries, self.base_frame, root) @ offset_transform(self.mount_offset)
                  @ transform_in(frames, root, self.frame_id))
        return render, frames

    def intrinsics(self) -> Intrinsics:
        """The pinhole model these parameters describe (raises IntrinsicsError if invalid)."""
        return Intrinsics(self.width, self.height, self.fx, self.fy, self.cx, self.cy)

    def check(self, source: str) -> None:
        if self.renderer not in RENDERERS:
            raise ConfigError(f"{source}: 'renderer' must be one of {RENDERERS}, got {self.renderer!r}")
        if len(self.mount_offset) != 6 or not np.all(np.isfinite(self.mount_offset)):
            raise ConfigError(f"{source}: 'mount_offset' must be 6 finite numbers (dx dy dz m, droll dpitch dyaw "
                              f"rad), got {self.mount_offset}")
        if self.rate <= 0 or not 0 < self.near < self.far or self.depth_noise < 0:
            raise ConfigError(f"{source}: needs rate > 0, 0 < near < far, depth_noise >= 0")
        if not 0 <= self.nice <= 19:
            raise ConfigError(f"{source}: 'nice' must be 0..19 (19: lowest priority), got {self.nice}")
        try:
            self.intrinsics()
        except IntrinsicsError as error:
            raise ConfigError(f"{source}: {error}") from None


class CameraNode:
    """Subscribers to the simulator's state, one render loop, image publishers."""

    def __init__(self) -> None:
        self.params = params = node_parameters(CameraNodeParams, "camera")
        # Before the renderer starts its threads (they inherit it): the camera stands in for
        # hardware, so it must never take the CPU from the loop it feeds (the simulator's
        # joint states, the policy's commands). When the CPU is short, frames come less often.
        lower_priority(params.nice, idle=params.idle)
        self.intrinsics = params.intrinsics()
        # The arm the launch describes (robot_description.py names the URDF after it), as rviz and
        # robot_state_publisher draw it: the camera sees the same arm.
        robot = described_arm(DEFAULT_ROBOT)
        spec = load_robot_spec(robot)
        render_pose, camera_frames = params.transforms(robot)
        arguments = (load_env_config({"robot": robot}), list(spec.joint_names) + list(spec.finger_joint_names), render_pose,
                     self.intrinsics.opengl_projection(params.near, params.far),
                     params.width, params.height, params.near, params.far)
        try:
            self.camera = SimulatedCamera(*arguments, renderer=params.renderer)
        except RuntimeError as error:
            if params.renderer != "egl":
                raise
            # A machine without EGL still gets images, about half as fast (TinyRenderer, CPU).
            rospy.logwarn(f"camera_node: {error}; rendering with the TinyRenderer instead")
            self.camera = SimulatedCamera(*arguments, renderer="tiny")
        if params.publish_tf:
            # Latched; kept on self so the publisher lives as long as the node.
            self.tf_broadcaster = tf2_ros.StaticTransformBroadcaster()
            self.tf_broadcaster.sendTransform(to_messages(camera_frames, rospy.Time.now()))
        self.rng = np.random.default_rng(params.seed)
        self.lock = threading.Lock()
        self.joint_states = JointStateHistory(20)
        self.object: Optional[Marker] = None
        self.rendered_stamp = -1
        self.frames = 0
        self.color_pub = rospy.Publisher(params.color_topic, Image, queue_size=1)
        self.depth_pub = rospy.Publisher(params.depth_topic, Image, queue_size=1)
        self.info_pub = rospy.Publisher(params.camera_info_topic, CameraInfo, queue_size=1)
        self.depth_info_pub = rospy.Publisher(params.depth_camera_info_topic, CameraInfo, queue_size=1)
        self.timing_pub = rospy.Publisher("~timing", Float64MultiArray, queue_size=10)
        rospy.Subscriber(params.joint_states_topic, JointState, self.on_joint_state, queue_size=5, tcp_nodelay=True)
        rospy.Subscriber(params.object_topic, Marker, self.on_object, queue_size=5, tcp_nodelay=True)
        self.neighbours: Optional[List[Marker]] = None  # a scene's other objects, newest (None: no scene)
        if params.neighbours_topic:
            rospy.Subscriber(params.neighbours_topic, MarkerArray, self.on_neighbours, queue_size=5, tcp_nodelay=True)
        rospy.loginfo(f"camera_node: {params.width}x{params.height} at up to {params.rate:g} Hz, "
                      f"{self.camera.renderer} renderer, frame {params.frame_id}, "
                      f"{'publishing' if params.publish_tf else 'not publishing'} its tf, niceness {params.nice}"
                      f"{' and SCHED_IDLE' if runs_idle() else ''}")

    def on_joint_state(self, message: JointState) -> None:
        with self.lock:
            self.joint_states.add(message.header.stamp.to_nsec(), message.name, message.position)

    def on_object(self, message: Marker) -> None:
        with self.lock:
            self.object = message

    def on_neighbours(self, message: MarkerArray) -> None:
        with self.lock:
            self.neighbours = [marker for marker in message.markers if marker.action == Marker.ADD]

    def snapshot(self) -> Optional[Tuple[int, Dict[str, float], Marker]]:
        """The newest object pose and the joint state of the same stamp (or the newest one)."""
        with self.lock:
            if self.object is None:
                return None
            state = self.joint_states.at(self.object.header.stamp.to_nsec())
            return None if state is None else (state[0], state[1], self.object)

    def spin(self) -> None:
        """Render and publish at up to ``~rate`` until shutdown; a frame is only taken of a new state."""
        period = 1.0 / self.params.rate
        next_frame = time.monotonic()
        while not rospy.is_shutdown():
            delay = next_frame - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            next_frame = max(next_frame + period, time.monotonic())
            state = self.snapshot()
            if state is None or state[0] == self.rendered_stamp:
                next_frame = time.monotonic() + 0.002  # nothing new yet: look again soon
                continue
            self.publish_frame(*state)

    def publish_frame(self, stamp_ns: int, joints: Dict[str, float], obj: Marker) -> None:
        """Render the scene at one instant and publish colour, depth and both CameraInfos."""
        self.rendered_stamp = stamp_ns
        self.camera.set_joints(joints)
        with self.lock:
            neighbours = None if self.neighbours is None else list(self.neighbours)
        if neighbours is not None:  # a scene: the object and the others, each its own body
            self.camera.set_objects([body_of_marker(marker) for marker in [obj] + neighbours])
        else:
            self.camera.set_object(*body_of_marker(obj))
        started = time.perf_counter()
        rgb, depth = self.camera.render()
        rendered = time.perf_counter()
        depth_mm = depth_to_millimetres(depth, self.params.depth_noise, self.rng)
        stamp, frame = rospy.Time(0, stamp_ns), self.params.frame_id
        color_message = image_message(rgb, "rgb8", stamp, frame)
        depth_message = image_message(depth_mm, "16UC1", stamp, frame)
        converted = time.perf_counter()
        self.info_pub.publish(camera_info_message(self.intrinsics, stamp, frame))
        self.depth_info_pub.publish(camera_info_message(self.intrinsics, stamp, frame))
        self.depth_pub.publish(depth_message)
        self.color_pub.publish(color_message)
        published = time.perf_counter()
        self.timing_pub.publish(Float64MultiArray(data=[rendered - started, converted - rendered, published - converted,
                                                        rospy.Time.now().to_sec() - stamp.to_sec()]))
        self.frames += 1


def body_of_marker(marker: Marker) -> Tuple[str, Tuple[float, ...], Tuple[float, float, float],
                                             Tuple[float, float, float, float]]:
    """``(shape, dims, position, quaternion)`` of an object's marker, as the simulated camera
    places bodies: a CYLINDER's (radius, height), a box's three half extents (m, base_link)."""
    if marker.type == Marker.CYLINDER:
        shape, dims = "cylinder", (marker.scale.x / 2.0, marker.scale.z)
    else:  # a box of any proportions
        shape, dims = "box", (marker.scale.x / 2.0, marker.scale.y / 2.0, marker.scale.z / 2.0)
    position, orientation = marker.pose.position, marker.pose.orientation
    return (shape, dims, (position.x, position.y, position.z),
            (orientation.x, orientation.y, orientation.z, orientation.w))


def main() -> int:
    exit_if_help_asked("camera_node.py", __doc__.split("\n\n")[0], "camera")
    init_node("camera")
    try:
        node = CameraNode()
    except (ConfigError, RuntimeError) as error:
        rospy.logfatal(str(error))
        return 1
    try:
        node.spin()
    finally:
        node.camera.close()
    return 0
