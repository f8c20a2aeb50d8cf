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

The node is input and output only: the simulation, the episode verdict and the scene all come
from :class:`fr5_rl.envs.FR5Env`'s public API (``advance_physics``, ``judge_period``,
``joint_states``, ``object_pose``, ``scene``).
"""
from __future__ import annotations

import json
import threading
import time
from collections import deque
from typing import Iterable, List, Sequence, Tuple

import numpy as np
import rospy
from geometry_msgs.msg import Point, PoseStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, String
from std_srvs.srv import Trigger, TriggerResponse
from visualization_msgs.msg import Marker, MarkerArray

from ..config import ConfigError, SimNodeParams
from ..envs import EpisodeVerdict, FR5Env, JointStates, Pose, SceneDescription
from ..transforms import load_static_transforms, matrix_from_quaternion, quaternion_from_matrix, transform_in
from .params import exit_if_help_asked, node_parameters


class SimulatorNode:
    """Runs one FR5Env world in wall-clock real time behind ROS topics.

    The subscriber and service callbacks run on rospy's threads; everything they share with
    the loop (targets, the episode state) is guarded by ``self.lock``.
    """

    def __init__(self) -> None:
        # ---- parameters (config/sim_node.yaml)
        self.params = params = node_parameters(SimNodeParams, "sim_node")
        task = params.task
        # The stand-in arm runs at its own physics step (finer than reach training uses), one
        # physics step per /joint_states message, so simulated time keeps pace with the clock.
        self.env = FR5Env(task=task, config={task: {"simulation": {"physics_dt": params.physics_dt,
                                                                      "solver_iterations": params.solver_iterations}}})
        self.spec = self.env.robot_spec
        self.physics_dt = self.env.physics_dt
        self.tick_dt = 1.0 / params.publish_rate
        ratio = self.tick_dt / self.physics_dt
        if ratio < 1.0 - 1e-6 or abs(ratio - round(ratio)) > 1e-6:
            raise ConfigError(f"sim_node: 1 / publish_rate ({self.tick_dt:g} s) must be a whole multiple of "
                              f"physics_dt ({self.physics_dt:g} s), or simulated time would drift from the clock")
        self.substeps_per_tick = int(round(ratio))
        self.base_in_camera = np.linalg.inv(
            transform_in(load_static_transforms(), self.spec.base_frame, params.camera_frame))
        self.rng = np.random.default_rng(params.seed)  # camera noise

        # ---- episode state, shared with the callbacks under the lock
        self.lock = threading.Lock()
        self.episode = 0  # episodes finished
        self.results: List[bool] = []  # success of each finished episode
        self.tcp_path: deque = deque(maxlen=300)  # tcp positions (m, base_link), one per control period
        # Episodes are timed from the first command on: a policy node still loading its model
        # must not lose its first episode to the step limit.
        self.commanded = False
        self._start_episode()

        # ---- ROS interfaces
        self.joint_pub = rospy.Publisher(params.joint_states_topic, JointState, queue_size=10)
        self.target_pub = rospy.Publisher(params.target_topic, PoseStamped, queue_size=10)
        self.marker_pub = rospy.Publisher("~markers", MarkerArray, queue_size=2)
        self.outcome_pub = rospy.Publisher("~episode_outcome", String, queue_size=10, latch=True)
        rospy.Subscriber(params.command_topic, Float64MultiArray, self._on_arm_command, queue_size=1)
        rospy.Subscriber(params.gripper_command_topic, Float64, self._on_gripper_command, queue_size=1)
        rospy.Service("~reset", Trigger, self._on_reset)

    # ------------------------------------------------------------------ main loop
    def spin(self) -> None:
        """Step physics and publish at ``~publish_rate`` until shutdown or the last episode.

        Simulated time is kept locked to the wall clock, as a real arm's would be: when a tick
        comes late (a loaded machine), the missed physics steps are run before publishing, so
        a command always acts for as long in simulation as it did in reality. Every
        ``control_dt`` of simulated time after the first command, the environment judges the
        episode.
        """
        params, env = self.params, self.env
        rate = rospy.Rate(params.publish_rate)
        camera_period = 1.0 / params.camera_rate
        marker_period = 1.0 / params.marker_rate
        control_dt = env.control_dt
        start = time.monotonic()
        sim_time = next_judge = next_camera = next_marker = 0.0
        max_catch_up = 10 * self.substeps_per_tick  # beyond that, let simulated time slip
        while not rospy.is_shutdown():
            with self.lock:
                if self.holding and time.monotonic() >= self.hold_until:
                    if 0 < params.episodes <= self.episode:
                        break
                    self._start_episode()
                    next_judge = sim_time
                steps = 0
                wall = time.monotonic() - start
                while sim_time < wall - 0.5 * self.physics_dt and steps < max_catch_up:
                    env.advance_physics(self.arm_target, self.gripper_target)
                    sim_time += self.physics_dt
                    steps += 1
                    if not self.commanded:
                        next_judge = sim_time
                    elif not self.holding and sim_time >= next_judge + control_dt - 1e-9:
                        next_judge += control_dt
                        verdict = env.judge_period()
                        if verdict.ended:
                            self._finish_episode(verdict)
                        self.tcp_path.append(tuple(env.tcp_position()))
                if wall - sim_time > 1.0:  # hopelessly behind: resynchronise rather than race
                    start += wall - sim_time
                stamp = rospy.Time.now()
                self.joint_pub.publish(joint_state_message(env.joint_states(), stamp))
                if sim_time >= next_camera:
                    next_camera = sim_time + camera_period - 1e-9
                    self.target_pub.publish(self._camera_message(stamp))
                if sim_time >= next_marker:
                    next_marker = sim_time + marker_period - 1e-9
                    self.marker_pub.publish(scene_markers(env.scene(), env.object_pose(), self.tcp_path, stamp))
            try:
                rate.sleep()
            except rospy.ROSInterruptException:
                break
        if params.episodes > 0 and self.results:
            print(f"success rate: {sum(self.results)}/{len(self.results)}", flush=True)

    # ------------------------------------------------------------------ episodes (lock held)
    def _start_episode(self) -> None:
        """Place a new object (seed + episode) and hold the arm where the reset put it."""
        self.env.reset(seed=self.params.seed + self.episode)
        self.arm_target = self.env.joint_positions()
        self.gripper_target = self.spec.max_opening_width
        self.holding = False
        self.hold_until = 0.0
        self.tcp_path.clear()

    def _finish_episode(self, verdict: EpisodeVerdict) -> None:
        """Publish the outcome, then hold the arm still for ``~pause_between_episodes``."""
        self.episode += 1
        self.results.append(bool(verdict.success))
        record = {"episode": self.episode, "success": bool(verdict.success), "failure": verdict.failure,
                  "steps": verdict.steps, "seed": self.params.seed + self.episode - 1}
        self.outcome_pub.publish(String(data=json.dumps(record)))
        rospy.loginfo(f"episode {self.episode}: {'success' if verdict.success else 'failure (' + str(verdict.failure) + ')'}"
                      f" after {verdict.steps} steps")
        self.holding = True
        self.hold_until = time.monotonic() + self.params.pause_between_episodes
        self.arm_target = self.env.joint_positions()

    # ------------------------------------------------------------------ callbacks
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

    # ------------------------------------------------------------------ the camera
    def _camera_message(self, stamp: rospy.Time) -> PoseStamped:
        """The object's pose as the camera sees it: in ``~camera_frame``, with optional noise."""
        pose = self.env.object_pose()
        object_in_base = matrix_from_quaternion(pose.position, pose.quaternion)
        noise = self.params.camera_noise_std
        if noise > 0:
            object_in_base[:3, 3] += self.rng.normal(0.0, noise, 3)
        object_in_camera = self.base_in_camera @ object_in_base
        message = PoseStamped()
        message.header.stamp = stamp
        message.header.frame_id = self.params.camera_frame
        position, orientation = message.pose.position, message.pose.orientation
        position.x, position.y, position.z = object_in_camera[:3, 3]
        orientation.x, orientation.y, orientation.z, orientation.w = quaternion_from_matrix(object_in_camera[:3, :3])
        return message


# ---------------------------------------------------------------------- messages
def joint_state_message(states: JointStates, stamp: rospy.Time) -> JointState:
    """``sensor_msgs/JointState`` of the eight joints, by name."""
    message = JointState()
    message.header.stamp = stamp
    message.name = list(states.names)
    message.position = list(states.positions)
    message.velocity = list(states.velocities)
    return message


def _marker(kind: int, namespace: str, rgba: Sequence[float], frame_id: str, stamp: rospy.Time) -> Marker:
    marker = Marker(type=kind, action=Marker.ADD, ns=namespace, id=0)
    marker.header.frame_id = frame_id
    marker.header.stamp = stamp
    marker.pose.orientation.w = 1.0
    marker.color.r, marker.color.g, marker.color.b, marker.color.a = rgba
    return marker


def scene_markers(scene: SceneDescription, object_pose: Pose, tcp_path: Iterable[Tuple[float, float, float]],
                  stamp: rospy.Time) -> MarkerArray:
    """rviz markers: the table, the object where it is now, and the tcp's recent path."""
    frame = scene.frame_id
    table = _marker(Marker.CUBE, "table", (0.55, 0.42, 0.3, 1.0), frame, stamp)
    table.scale.x, table.scale.y, table.scale.z = scene.table_size
    table.pose.position.x, table.pose.position.y, table.pose.position.z = scene.table_center

    kind = Marker.CYLINDER if scene.object_shape == "cylinder" else Marker.CUBE
    obj = _marker(kind, "object", (0.85, 0.2, 0.15, 1.0), frame, stamp)
    obj.scale.x, obj.scale.y, obj.scale.z = scene.object_size
    obj.pose.position.x, obj.pose.position.y, obj.pose.position.z = object_pose.position
    orientation = obj.pose.orientation
    orientation.x, orientation.y, orientation.z, orientation.w = object_pose.quaternion

    path = _marker(Marker.LINE_STRIP, "tcp_path", (0.1, 0.5, 1.0, 0.9), frame, stamp)
    path.scale.x = 0.004
    path.points = [Point(x=x, y=y, z=z) for x, y, z in tcp_path]
    return MarkerArray(markers=[table, obj, path])


def main() -> int:
    exit_if_help_asked("sim_node.py", __doc__.split("\n\n")[0], "sim_node")
    rospy.init_node("fr5_sim")
    try:
        node = SimulatorNode()
    except ConfigError as error:
        rospy.logfatal(str(error))
        return 1
    node.spin()
    node.env.close()
    if not rospy.is_shutdown():
        rospy.signal_shutdown("all episodes done")
    return 0
