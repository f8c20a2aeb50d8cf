"""Policy node: runs a trained FR5 policy at a steady 50 Hz on /joint_states + /target_pose.

Each control period it reads the newest ``/joint_states`` *by joint name*, transforms the newest
``/target_pose`` (any frame, e.g. ``camera_link``) into ``base_link`` through tf2, builds the
observation with the environments' own :class:`~fr5_rl.observation.ObservationBuilder` and
forward kinematics, runs the policy, and turns the action into joint position targets with
the environments' own :class:`~fr5_rl.control.JointCommandShaper` (scaling, low-pass, velocity
and joint limits). It publishes ``std_msgs/Float64MultiArray`` (6 values, controller order) on
the command topic, and the gripper opening width (std_msgs/Float64) for grasp models.

It never publishes a non-finite, wrong-length or out-of-limit command. It *holds* — publishes
nothing, so the controller keeps its last target — and warns (throttled) while joint states
are stale or invalid, the target is missing, stale or not transformable, or the observation is
not finite; it resumes by itself once inputs are good. ``~enable`` (std_srvs/SetBool) pauses
and resumes it. Per-cycle timing goes to ``~timing`` (Float64MultiArray: loop period, inference
time, compute latency, joint-state age, all seconds) and a summary to ``/diagnostics`` at 1 Hz.
"""
from __future__ import annotations

import sys
import threading
import time
from collections import deque
from pathlib import Path
from typing import Optional, Tuple

import numpy as np
import rospy
import tf2_geometry_msgs  # noqa: F401  (registers PoseStamped with tf2)
import tf2_ros
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension
from std_srvs.srv import SetBool, SetBoolResponse
from visualization_msgs.msg import Marker

from ..config import ConfigError, load_env_config, load_robot_spec, package_root
from ..control import JointCommandShaper
from ..joint_state import parse_joint_state
from ..kinematics import ForwardKinematics
from ..observation import ObservationBuilder, ObservationInputs
from ..policy import load_policy
from ..training.artifacts import ModelFilesError
from .params import node_parameters


class PolicyNode:
    """The deployment loop; see the module docstring for the contract."""

    def __init__(self) -> None:
        self.params = params = node_parameters("policy_node")
        model_dir = Path(str(params["model_dir"]))
        if not model_dir.is_absolute():
            model_dir = package_root() / model_dir
        self.robot = load_robot_spec()
        self.policy = load_policy(model_dir, str(params["backend"]))
        self.env_cfg = load_env_config(self.policy.meta.get("env_overrides", {}))
        self.control_dt = float(self.env_cfg["simulation"]["control_dt"])
        rate = float(params["rate"])
        if abs(rate * self.control_dt - 1.0) > 1e-6:
            raise ConfigError(f"~rate = {rate} Hz but the model was trained at {1.0 / self.control_dt:g} Hz: "
                              "the action scaling would be wrong; set ~rate to the training rate")
        self.kinematics = ForwardKinematics(self.robot)
        self.builder = ObservationBuilder(self.robot, self.env_cfg["observation"], self.policy.task == "grasp")
        if self.builder.size != self.policy.observation_size:
            raise ModelFilesError(f"{model_dir} expects {self.policy.observation_size} observation values; "
                                  f"this fr5_rl builds {self.builder.size}: retrain or use a matching model")
        self.shaper = JointCommandShaper(self.robot, self.env_cfg["action"], self.control_dt)
        obj = self.env_cfg["object"]
        rest_height = float(obj["height"]) / 2.0 if obj["shape"] == "cylinder" else float(obj["half_extent"])
        self.object_rest_z = float(self.env_cfg["table"]["top_height"]) + rest_height
        self.command_gripper = bool(params["command_gripper"])
        self.base_frame = str(params["base_frame"])
        self.joint_timeout = float(params["joint_state_timeout"])
        self.target_timeout = float(params["target_timeout"])

        self.enabled = bool(params["enabled"])
        self.holding_reason: Optional[str] = "waiting for inputs"
        self.gripper_command_width = self.robot.max_opening_width
        self._joint_state: Optional[Tuple] = None  # (ArmJointState | error str, receipt time, stamp)
        self._previous_positions: Optional[Tuple[np.ndarray, float]] = None
        self._target: Optional[Tuple[PoseStamped, float]] = None
        self._last_tick: Optional[float] = None
        self._last_object_position: Optional[np.ndarray] = None
        self.new_target_jump = 0.05  # m between two cycles: the object was replaced
        self._timing = deque(maxlen=500)
        self._lock = threading.Lock()

        self.tf_buffer = tf2_ros.Buffer(cache_time=rospy.Duration(10.0))
        self.tf_listener = tf2_ros.TransformListener(self.tf_buffer)
        self.command_pub = rospy.Publisher(params["command_topic"], Float64MultiArray, queue_size=1)
        self.gripper_pub = rospy.Publisher(params["gripper_command_topic"], Float64, queue_size=1)
        self.timing_pub = rospy.Publisher("~timing", Float64MultiArray, queue_size=10)
        self.marker_pub = rospy.Publisher("~target_marker", Marker, queue_size=1)
        self.diagnostics_pub = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=1)
        rospy.Subscriber(params["joint_states_topic"], JointState, self._on_joint_state, queue_size=1,
                         tcp_nodelay=True)
        rospy.Subscriber(params["target_topic"], PoseStamped, self._on_target, queue_size=1, tcp_nodelay=True)
        rospy.Service("~enable", SetBool, self._on_enable)
        self.timer = rospy.Timer(rospy.Duration(self.control_dt), self._on_timer)
        self.diagnostics_timer = rospy.Timer(rospy.Duration(1.0), self._publish_diagnostics)
        rospy.loginfo(f"policy_node: {self.policy.task} model {model_dir} ({self.policy.backend}), "
                      f"{rate:g} Hz, gripper commands {'on' if self.command_gripper else 'off'}")

    # ------------------------------------------------------------------ inputs
    def _on_joint_state(self, message: JointState) -> None:
        received = time.monotonic()
        try:
            state = parse_joint_state(message.name, message.position, message.velocity,
                                      self.robot.joint_names, self.robot.finger_joint_names)
        except ValueError as error:
            self._joint_state = (str(error), received, message.header.stamp)
            return
        if state.velocities is None:  # estimate from consecutive messages
            stamp = message.header.stamp.to_sec() or received
            previous = self._previous_positions
            state.velocities = np.zeros(6)
            if previous is not None and stamp - previous[1] > 1e-4:
                state.velocities = (state.positions - previous[0]) / (stamp - previous[1])
            self._previous_positions = (state.positions, stamp)
        self._joint_state = (state, received, message.header.stamp)

    def _on_target(self, message: PoseStamped) -> None:
        self._target = (message, time.monotonic())

    def _on_enable(self, request) -> SetBoolResponse:
        self.enabled = bool(request.data)
        if not self.enabled:
            self._hold("disabled through ~enable")
        return SetBoolResponse(success=True, message="enabled" if self.enabled else "disabled")

    # ------------------------------------------------------------------ control loop
    def _hold(self, reason: str) -> None:
        # Log at once when the kind of problem changes, then at most every 2 s.
        kind = reason.split("(")[0].split(":")[0]
        previous_kind = (self.holding_reason or "").split("(")[0].split(":")[0]
        if kind != previous_kind:
            rospy.logwarn(f"policy_node: holding: {reason}")
        else:
            rospy.logwarn_throttle(2.0, f"policy_node: holding: {reason}")
        self.holding_reason = reason

    def _target_in_base(self) -> np.ndarray:
        """Newest target position (m) in the base frame; raises ValueError with the reason."""
        if self._target is None:
            raise ValueError("no target pose received yet")
        message, received = self._target
        age = time.monotonic() - received
        if age > self.target_timeout:
            raise ValueError(f"target pose is stale ({age:.2f} s old > {self.target_timeout} s)")
        try:
            transform = self.tf_buffer.lookup_transform(self.base_frame, message.header.frame_id, rospy.Time(0))
        except (tf2_ros.LookupException, tf2_ros.ConnectivityException, tf2_ros.ExtrapolationException,
                tf2_ros.InvalidArgumentException) as error:
            raise ValueError(f"no transform {message.header.frame_id} -> {self.base_frame}: {error}") from None
        pose = tf2_geometry_msgs.do_transform_pose(message, transform).pose.position
        position = np.array([pose.x, pose.y, pose.z])
        if not np.isfinite(position).all():
            raise ValueError("target pose contains NaN or inf")
        return position

    def _on_timer(self, event) -> None:
        start = time.perf_counter()
        period = start - self._last_tick if self._last_tick is not None else self.control_dt
        self._last_tick = start
        if not self.enabled:
            return
        joint_state = self._joint_state
        try:
            if joint_state is None:
                raise ValueError("no joint states received yet")
            state, received, stamp = joint_state
            if isinstance(state, str):
                raise ValueError(state)
            age = time.monotonic() - received
            if age > self.joint_timeout:
                raise ValueError(f"joint states are stale ({age * 1000:.0f} ms old > {self.joint_timeout * 1000:.0f} ms)")
            object_position = self._target_in_base()
            tcp_position, tcp_rotation = self.kinematics.tcp_pose(state.positions)
            width = state.gripper_width if state.gripper_width is not None else self.gripper_command_width
            observation = self.builder.build(ObservationInputs(
                joint_positions=state.positions, joint_velocities=state.velocities, gripper_width=width,
                gripper_command_width=self.gripper_command_width, tcp_position=tcp_position,
                tcp_approach_axis=tcp_rotation[:, 2], object_position=object_position,
                object_lift=float(object_position[2] - self.object_rest_z)))
        except ValueError as error:
            self._hold(str(error))
            return
        if self.holding_reason is not None:
            rospy.loginfo(f"policy_node: inputs good, running (was: {self.holding_reason})")
            self.holding_reason = None
            self.shaper.reset()
        elif self._last_object_position is not None and \
                np.linalg.norm(object_position - self._last_object_position) > self.new_target_jump:
            self.shaper.reset()  # a new object: start like an episode starts, without old momentum
        self._last_object_position = object_position
        inference_start = time.perf_counter()
        action = self.policy.act(observation)
        inference = time.perf_counter() - inference_start
        targets = self.shaper.arm_targets(action, state.positions)
        if not self._command_is_safe(targets, state.positions):
            self._hold("computed command failed the safety check (not published)")
            return
        message = Float64MultiArray()
        message.layout.dim = [MultiArrayDimension(label="j1..j6", size=6, stride=6)]
        message.data = targets.tolist()
        self.command_pub.publish(message)
        # The commanded width is part of the next observation whether or not it is sent, exactly
        # as in training.
        self.gripper_command_width = self.shaper.gripper_width(action)
        if self.command_gripper:
            self.gripper_pub.publish(Float64(data=self.gripper_command_width))
        published = time.perf_counter()
        state_age = (rospy.Time.now() - stamp).to_sec() if stamp and stamp.to_sec() > 0 else float("nan")
        timing = (period, inference, published - start, state_age)
        self._timing.append(timing)
        self.timing_pub.publish(Float64MultiArray(data=list(timing)))
        self._publish_marker(object_position)

    def _command_is_safe(self, targets: np.ndarray, measured: np.ndarray) -> bool:
        """Last line of defence before publishing: length, finiteness, joint and velocity limits."""
        step_limit = self.robot.velocity_limits * self.control_dt + 1e-9
        return bool(targets.shape == (6,) and np.isfinite(targets).all()
                    and (targets >= self.robot.lower_limits).all() and (targets <= self.robot.upper_limits).all()
                    and (np.abs(targets - measured) <= step_limit).all())

    # ------------------------------------------------------------------ reporting
    def _publish_marker(self, position: np.ndarray) -> None:
        marker = Marker(type=Marker.SPHERE, action=Marker.ADD, ns="policy_target", id=0)
        marker.header.frame_id = self.base_frame
        marker.header.stamp = rospy.Time.now()
        marker.pose.position.x, marker.pose.position.y, marker.pose.position.z = position
        marker.pose.orientation.w = 1.0
        marker.scale.x = marker.scale.y = marker.scale.z = 0.03
        marker.color.g, marker.color.b, marker.color.a = 0.9, 0.3, 0.6
        self.marker_pub.publish(marker)

    def _publish_diagnostics(self, event) -> None:
        status = DiagnosticStatus(name="fr5_rl policy_node", hardware_id="fr5")
        samples = np.array(self._timing) if self._timing else np.zeros((0, 4))
        if self.holding_reason is not None or not self.enabled:
            status.level, status.message = DiagnosticStatus.WARN, f"holding: {self.holding_reason or 'disabled'}"
        else:
            status.level, status.message = DiagnosticStatus.OK, "running"
        for column, name in enumerate(("loop_period", "inference", "compute_latency", "joint_state_age")):
            if len(samples):
                values = samples[:, column] * 1000.0
                status.values.append(KeyValue(f"{name}_p50_ms", f"{np.nanpercentile(values, 50):.3f}"))
                status.values.append(KeyValue(f"{name}_p99_ms", f"{np.nanpercentile(values, 99):.3f}"))
        array = DiagnosticArray(status=[status])
        array.header.stamp = rospy.Time.now()
        self.diagnostics_pub.publish(array)


def main() -> None:
    rospy.init_node("fr5_policy")
    try:
        PolicyNode()
    except (ConfigError, ModelFilesError, ValueError) as error:
        rospy.logfatal(f"policy_node: {error}")
        sys.exit(1)
    rospy.spin()
