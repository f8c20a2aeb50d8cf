"""Camera node: a simulated RealSense-like RGB-D camera that photographs the simulator's scene.

It keeps its own render-only PyBullet world (:class:`fr5_rl.sim.camera.SimulatedCamera`) in its
own process, so rendering never stalls the simulator's ``/joint_states`` or the policy's
commands. It mirrors the simulator: the joints from ``~joint_states_topic`` (by name) and the
object's true pose, size and shape from ``~object_topic`` (visualization_msgs/Marker in
base_link, published by sim_node with every joint state). At up to ``~rate`` it renders the
newest state and publishes, all stamped with that state's stamp (the simulated capture time)
and in ``~frame_id`` (REP 103 optical frame):

- ``~color_topic``: sensor_msgs/Image ``rgb8``;
- ``~depth_topic``: sensor_msgs/Image ``16UC1``, millimetres along the optical axis, 0 = no
  data, aligned to colour (same camera model), with optional stereo-like noise;
- ``~camera_info_topic`` and ``~depth_camera_info_topic``: sensor_msgs/CameraInfo of the
  projection used to render (``plumb_bob``, zero distortion).

Per frame, ``~timing`` (std_msgs/Float64MultiArray) gives the seconds spent rendering, converting
and publishing, and the rendered state's age when the frame was published.

The camera's pose is config/static_transforms.yaml's ``~frame_id`` in ``~base_frame``. The
default topics are the RealSense driver's. Parameters: ``config/camera.yaml``.
"""
from __future__ import annotations

import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from typing import Dict, Optional, Tuple

import numpy as np
import rospy
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import Marker

from ..config import ConfigError, load_env_config, load_robot_spec
from ..runtime.pinhole import Intrinsics, IntrinsicsError
from ..sim.camera import RENDERERS, SimulatedCamera, depth_to_millimetres
from ..transforms import load_static_transforms, transform_in
from .images import camera_info_message, image_message
from .params import exit_if_help_asked, node_parameters


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
    joint_states_topic: str
    object_topic: str
    color_topic: str
    depth_topic: str
    camera_info_topic: str
    depth_camera_info_topic: str

    def intrinsics(self) -> Intrinsics:
        """The pinhole model these parameters describe (raises IntrinsicsError if invalid)."""
        return Intrinsics(self.width, self.height, self.fx, self.fy, self.cx, self.cy)

    def check(self, source: str) -> None:
        if self.renderer not in RENDERERS:
            raise ConfigError(f"{source}: 'renderer' must be one of {RENDERERS}, got {self.renderer!r}")
        if self.rate <= 0 or not 0 < self.near < self.far or self.depth_noise < 0:
            raise ConfigError(f"{source}: needs rate > 0, 0 < near < far, depth_noise >= 0")
        try:
            self.intrinsics()
        except IntrinsicsError as error:
            raise ConfigError(f"{source}: {error}") from None


class CameraNode:
    """Subscribers to the simulator's state, one render loop, image publishers."""

    def __init__(self) -> None:
        self.params = params = node_parameters(CameraNodeParams, "camera")
        self.intrinsics = params.intrinsics()
        spec = load_robot_spec()
        arguments = (load_env_config(), list(spec.joint_names) + list(spec.finger_joint_names),
                     transform_in(load_static_transforms(), params.base_frame, params.frame_id),
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
        self.rng = np.random.default_rng(params.seed)
        self.lock = threading.Lock()
        # Recent joint states by stamp (ns), so the object and the joints of one instant pair up.
        self.joint_states: "OrderedDict[int, Dict[str, float]]" = OrderedDict()
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
        rospy.loginfo(f"camera_node: {params.width}x{params.height} at up to {params.rate:g} Hz, "
                      f"{self.camera.renderer} renderer, frame {params.frame_id}")

    def on_joint_state(self, message: JointState) -> None:
        with self.lock:
            self.joint_states[message.header.stamp.to_nsec()] = dict(zip(message.name, message.position))
            while len(self.joint_states) > 20:
                self.joint_states.popitem(last=False)

    def on_object(self, message: Marker) -> None:
        with self.lock:
            self.object = message

    def snapshot(self) -> Optional[Tuple[int, Dict[str, float], Marker]]:
        """The newest object pose and the joint state of the same stamp (or the newest one)."""
        with self.lock:
            if self.object is None or not self.joint_states:
                return None
            stamp = self.object.header.stamp.to_nsec()
            joints = self.joint_states.get(stamp)
            if joints is None:
                stamp, joints = next(reversed(self.joint_states.items()))
            return stamp, joints, self.object

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
        if obj.type == Marker.CYLINDER:
            shape, dims = "cylinder", (obj.scale.x / 2.0, obj.scale.z)
        else:
            shape, dims = "box", (obj.scale.x / 2.0,)
        pose = obj.pose
        self.camera.set_joints(joints)
        self.camera.set_object(shape, dims, (pose.position.x, pose.position.y, pose.position.z),
                               (pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w))
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


def main() -> int:
    exit_if_help_asked("camera_node.py", __doc__.split("\n\n")[0], "camera")
    rospy.init_node("camera")
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
