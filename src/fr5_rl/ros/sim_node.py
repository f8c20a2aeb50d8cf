"""Simulator node: the PyBullet FR5 world in real time, standing in for the arm's driver.

It behaves like the FAIRINO ROS driver + gripper + a camera, so the policy node runs unchanged
against it:

- publishes ``/joint_states`` (j1..j6 and both finger joints, stamped) at ``~publish_rate``;
- obeys ``/fr5/arm_controller/command`` (std_msgs/Float64MultiArray, 6 positions in rad, in
  controller order j1..j6 — ros_control's JointGroupPositionController contract: a message of
  the wrong length is dropped with a throttled error) and ``/fr5/gripper/command``
  (std_msgs/Float64, opening width in m);
- acts as the camera: the object's pose on ``/target_pose`` (geometry_msgs/PoseStamped) in
  ``camera_link``, computed with config/static_transforms.yaml and optional noise;
- publishes rviz markers (table, object, tcp path) on ``~markers``;
- judges each episode with the environment's own success test, publishes the outcome (JSON in
  std_msgs/String) on ``~episode_outcome``, then places a new object and homes the arm;
  ``~reset`` (std_srvs/Trigger) does that at once. With ``~episodes`` = N > 0 it stops after N
  episodes and prints ``success rate: K/N`` as its last line.
"""
from __future__ import annotations

import json
import sys
import threading
import time
from collections import deque

import numpy as np
import pybullet as p
import rospy
from geometry_msgs.msg import Point, PoseStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, String
from std_srvs.srv import Trigger, TriggerResponse
from visualization_msgs.msg import Marker, MarkerArray

from ..config import ConfigError
from ..envs import FR5Env
from ..transforms import load_static_transforms, matrix_from_quaternion, quaternion_from_matrix, transform_in
from .params import node_parameters


class SimulatorNode:
    """Runs one FR5Env world in wall-clock real time behind ROS topics."""

    def __init__(self) -> None:
        self.params = params = node_parameters("sim_node")
        task = str(params["task"])
        # The stand-in arm runs at its own physics step (finer than reach training uses), one
        # physics step per /joint_states message, so simulated time keeps pace with the clock.
        self.env = FR5Env(task=task, config={task: {"simulation": {"physics_dt": float(params["physics_dt"]),
                                                                      "solver_iterations": int(params["solver_iterations"])}}})
        self.spec = self.env.robot_spec
        self.physics_dt = self.env.world.physics_dt
        self.tick_dt = 1.0 / float(params["publish_rate"])
        ratio = self.tick_dt / self.physics_dt
        if ratio < 1.0 - 1e-6 or abs(ratio - round(ratio)) > 1e-6:
            raise ConfigError(f"sim_node: 1 / publish_rate ({self.tick_dt:g} s) must be a whole multiple of "
                              f"physics_dt ({self.physics_dt:g} s), or simulated time would drift from the clock")
        self.substeps_per_tick = int(round(ratio))
        self.camera_in_base = transform_in(load_static_transforms(), self.spec.base_frame, str(params["camera_frame"]))
        self.base_in_camera = np.linalg.inv(self.camera_in_base)
        self.rng = np.random.default_rng(int(params["seed"]))
        self.lock = threading.Lock()
        self.episode = 0
        self.results = []
        self.max_episodes = int(params["episodes"])
        self.tcp_path: deque = deque(maxlen=300)
        # Episodes are timed from the first command on: a policy node still loading its model
        # must not lose its first episode to the step limit.
        self.commanded = False

        self.joint_pub = rospy.Publisher(params["joint_states_topic"], JointState, queue_size=10)
        self.target_pub = rospy.Publisher(params["target_topic"], PoseStamped, queue_size=10)
        self.marker_pub = rospy.Publisher("~markers", MarkerArray, queue_size=2)
        self.outcome_pub = rospy.Publisher("~episode_outcome", String, queue_size=10, latch=True)
        rospy.Subscriber(params["command_topic"], Float64MultiArray, self._on_arm_command, queue_size=1)
        rospy.Subscriber(params["gripper_command_topic"], Float64, self._on_gripper_command, queue_size=1)
        rospy.Service("~reset", Trigger, self._on_reset)
        self._start_episode()

    # ------------------------------------------------------------------ commands
    def _on_arm_command(self, message: Float64MultiArray) -> None:
        values = np.asarray(message.data, dtype=np.float64)
        if values.shape != (6,):
            rospy.logerr_throttle(1.0, f"sim_node: dropped arm command with {values.size} values (needs 6: j1..j6)")
            return
        if not np.isfinite(values).all():
            rospy.logerr_throttle(1.0, "sim_node: dropped arm command containing NaN/inf")
            return
        clamped = np.clip(values, self.spec.lower_limits, self.spec.upper_limits)
        if not np.array_equal(clamped, values):
            rospy.logwarn_throttle(1.0, "sim_node: arm command outside the joint limits was clamped")
        with self.lock:
            self.commanded = True
            if not self.holding:
                self.arm_target = clamped

    def _on_gripper_command(self, message: Float64) -> None:
        width = float(message.data)
        if not np.isfinite(width):
            rospy.logerr_throttle(1.0, "sim_node: dropped non-finite gripper command")
            return
        with self.lock:
            if not self.holding:
                self.gripper_target = float(np.clip(width, 0.0, self.spec.max_opening_width))

    def _on_reset(self, _request) -> TriggerResponse:
        with self.lock:
            self._start_episode()
        return TriggerResponse(success=True, message=f"episode {self.episode} started")

    # ------------------------------------------------------------------ episodes
    def _start_episode(self) -> None:
        seed = int(self.params["seed"]) + self.episode
        self.env.reset(seed=seed)
        self.arm_target = self.env.joint_positions()
        self.gripper_target = self.spec.max_opening_width
        self.control_steps = 0
        self.holding = False
        self.hold_until = 0.0
        self.tcp_path.clear()

    def _judge(self) -> None:
        """One control period of the episode: the environment's own success test."""
        self.control_steps += 1
        outcome = self.env.task.judge(self.env.task_state(), self.env.control_dt)
        ended = outcome.success or outcome.failure is not None
        failure = outcome.failure
        if not ended and self.control_steps >= self.env.task.max_steps:
            ended, failure = True, "timeout"
        if not ended:
            return
        self.episode += 1
        self.results.append(bool(outcome.success))
        record = {"episode": self.episode, "success": bool(outcome.success), "failure": failure,
                  "steps": self.control_steps, "seed": int(self.params["seed"]) + self.episode - 1}
        self.outcome_pub.publish(String(data=json.dumps(record)))
        rospy.loginfo(f"episode {self.episode}: {'success' if outcome.success else 'failure (' + str(failure) + ')'}"
                      f" after {self.control_steps} steps")
        self.holding = True
        self.hold_until = time.monotonic() + float(self.params["pause_between_episodes"])
        self.arm_target = self.env.joint_positions()

    # ------------------------------------------------------------------ publishing
    def _publish_joint_states(self, stamp: rospy.Time) -> None:
        q, qd, _ = self.env.robot.joint_state()
        fingers = p.getJointStates(self.env.robot.body, self.env.robot.finger_joints, physicsClientId=self.env.world.client)
        message = JointState()
        message.header.stamp = stamp
        message.name = list(self.spec.joint_names) + list(self.spec.finger_joint_names)
        message.position = list(q) + [f[0] for f in fingers]
        message.velocity = list(qd) + [f[1] for f in fingers]
        self.joint_pub.publish(message)

    def _publish_target(self, stamp: rospy.Time) -> None:
        position, quaternion = self.env.world.object_pose()
        object_in_base = matrix_from_quaternion(position, quaternion)
        noise = float(self.params["camera_noise_std"])
        if noise > 0:
            object_in_base[:3, 3] += self.rng.normal(0.0, noise, 3)
        object_in_camera = self.base_in_camera @ object_in_base
        message = PoseStamped()
        message.header.stamp = stamp
        message.header.frame_id = str(self.params["camera_frame"])
        pose = message.pose
        pose.position.x, pose.position.y, pose.position.z = object_in_camera[:3, 3]
        qx, qy, qz, qw = quaternion_from_matrix(object_in_camera[:3, :3])
        pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = qx, qy, qz, qw
        self.target_pub.publish(message)

    def _publish_markers(self, stamp: rospy.Time) -> None:
        cfg = self.env.cfg
        markers = MarkerArray()
        table = Marker(type=Marker.CUBE, action=Marker.ADD, ns="table", id=0)
        sx, sy, thickness = cfg["table"]["size"]
        table.scale.x, table.scale.y, table.scale.z = sx, sy, thickness
        table.pose.position.x, table.pose.position.y = cfg["table"]["center_xy"]
        table.pose.position.z = float(cfg["table"]["top_height"]) - thickness / 2.0
        table.pose.orientation.w = 1.0
        table.color.r, table.color.g, table.color.b, table.color.a = 0.55, 0.42, 0.3, 1.0
        obj = Marker(action=Marker.ADD, ns="object", id=0)
        position, quaternion = self.env.world.object_pose()
        obj_cfg = cfg["object"]
        if obj_cfg["shape"] == "cylinder":
            obj.type = Marker.CYLINDER
            obj.scale.x = obj.scale.y = 2.0 * float(obj_cfg["radius"])
            obj.scale.z = float(obj_cfg["height"])
        else:
            obj.type = Marker.CUBE
            obj.scale.x = obj.scale.y = obj.scale.z = 2.0 * float(obj_cfg["half_extent"])
        obj.pose.position.x, obj.pose.position.y, obj.pose.position.z = position
        obj.pose.orientation.x, obj.pose.orientation.y, obj.pose.orientation.z, obj.pose.orientation.w = quaternion
        obj.color.r, obj.color.g, obj.color.b, obj.color.a = 0.85, 0.2, 0.15, 1.0
        path = Marker(type=Marker.LINE_STRIP, action=Marker.ADD, ns="tcp_path", id=0)
        path.scale.x = 0.004
        path.pose.orientation.w = 1.0
        path.color.r, path.color.g, path.color.b, path.color.a = 0.1, 0.5, 1.0, 0.9
        path.points = [Point(x=x, y=y, z=z) for x, y, z in self.tcp_path]
        for marker in (table, obj, path):
            marker.header.frame_id = self.spec.base_frame
            marker.header.stamp = stamp
            markers.markers.append(marker)
        self.marker_pub.publish(markers)

    # ------------------------------------------------------------------ main loop
    def spin(self) -> None:
        """Step physics and publish at ``~publish_rate`` until shutdown or the last episode.

        Simulated time is kept locked to the wall clock, as a real arm's would be: when a tick
        comes late (a loaded machine), the missed physics steps are run before publishing, so
        a command always acts for as long in simulation as it did in reality.
        """
        rate = rospy.Rate(float(self.params["publish_rate"]))
        camera_period = 1.0 / float(self.params["camera_rate"])
        marker_period = 1.0 / float(self.params["marker_rate"])
        client = self.env.world.client
        control_dt = self.env.control_dt
        start = time.monotonic()
        sim_time = next_judge = next_camera = next_marker = 0.0
        max_catch_up = 10 * self.substeps_per_tick  # beyond that, let simulated time slip
        while not rospy.is_shutdown():
            with self.lock:
                if self.holding and time.monotonic() >= self.hold_until:
                    if 0 < self.max_episodes <= self.episode:
                        break
                    self._start_episode()
                    next_judge = sim_time
                steps = 0
                wall = time.monotonic() - start
                while sim_time < wall - 0.5 * self.physics_dt and steps < max_catch_up:
                    self.env.robot.command(self.arm_target, self.gripper_target, period=self.physics_dt)
                    p.stepSimulation(physicsClientId=client)
                    sim_time += self.physics_dt
                    steps += 1
                    if not self.commanded:
                        next_judge = sim_time
                    elif not self.holding and sim_time >= next_judge + control_dt - 1e-9:
                        next_judge += control_dt
                        self._judge()
                        self.tcp_path.append(tuple(self.env.tcp_position()))
                if wall - sim_time > 1.0:  # hopelessly behind: resynchronise rather than race
                    start += wall - sim_time
                stamp = rospy.Time.now()
                self._publish_joint_states(stamp)
                if sim_time >= next_camera:
                    next_camera = sim_time + camera_period - 1e-9
                    self._publish_target(stamp)
                if sim_time >= next_marker:
                    next_marker = sim_time + marker_period - 1e-9
                    self._publish_markers(stamp)
            try:
                rate.sleep()
            except rospy.ROSInterruptException:
                break
        if self.max_episodes > 0 and self.results:
            successes = sum(self.results)
            print(f"success rate: {successes}/{len(self.results)}", flush=True)


def main() -> None:
    rospy.init_node("fr5_sim")
    try:
        node = SimulatorNode()
    except ConfigError as error:
        rospy.logfatal(str(error))
        sys.exit(1)
    node.spin()
    node.env.close()
    if not rospy.is_shutdown():
        rospy.signal_shutdown("all episodes done")
