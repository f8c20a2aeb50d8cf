"""Policy node: runs a trained FR5 policy at a steady 50 Hz on /joint_states + /target_pose.

This module is I/O only. Each control period it hands the newest joint state (read *by
name*) and the newest target, transformed into ``base_link`` through tf2, to
:class:`~fr5_rl.deploy.deployment.DeploymentStep` (observation, policy, action shaping, safety
gate: the same code the environments use), then publishes what comes back:

- a :class:`~fr5_rl.deploy.deployment.Command`: ``std_msgs/Float64MultiArray`` (6 values,
  controller order) on the command topic, and the gripper opening width (``std_msgs/Float64``,
  m) when ``~command_gripper`` is set;
- a :class:`~fr5_rl.deploy.deployment.Hold`: nothing, so the controller keeps its last
  target, and a warning (at once when the reason changes, then throttled).

``~enable`` (std_srvs/SetBool) pauses and resumes; ``~reset`` (std_srvs/Trigger) starts as an
episode starts (no action-filter momentum, gripper commanded open), for a new object after the
arm was homed. On simulated time (``/use_sim_time``, a lockstep simulator) each period first
waits, up to ``~sim_time_input_wait`` wall seconds, for the joint state and target stamped at the
period's start, so the outcome does not depend on which topic arrived first. Per-cycle timing
goes to ``~timing`` (Float64MultiArray: loop period, inference time, compute latency,
joint-state age, the wait for a new joint state, all seconds, and 1.0 where the period acted on
a state an earlier period had used, else 0.0) and a summary to ``/diagnostics`` at 1 Hz.

A model that observes the object's shape, size and yaw (``observation.object_features``) or sets
it down at a goal (the place task) also takes ``~target_shape_topic`` (shape_msgs/SolidPrimitive,
a BOX's dimensions along the target pose's frame), the yaw from the target pose's orientation,
and ``~goal_topic`` (geometry_msgs/PoseStamped in any frame tf2 can bring into the base frame:
x, y and the yaw of the object's x axis at the goal); it holds until both have come. In real
time a period waits, up to ``~fresh_state_wait``, for a joint state no period acted on (and
that arrived within ``~fresh_state_max_age``)
(:class:`~fr5_rl.deploy.joint_state.FreshStateWait`). Parameters: ``config/policy_node.yaml``.
"""
from __future__ import annotations

import gc
import threading
import time
from collections import deque
from typing import Optional

import numpy as np
import rospy
import tf2_geometry_msgs  # noqa: F401  (registers PoseStamped with tf2)
import tf2_ros
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from shape_msgs.msg import SolidPrimitive
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64, Float64MultiArray, MultiArrayDimension
from std_srvs.srv import SetBool, SetBoolResponse, Trigger, TriggerResponse
from visualization_msgs.msg import Marker

from ..config import ConfigError, load_robot_spec
from ..env_config import load_env_config
from ..deploy.bundle import ModelFilesError, resolve_model_dir
from ..deploy.deployment import Command, DeploymentStep, Hold, HoldReason, StepInputs
from ..deploy.joint_state import FreshStateWait, JointStateReader, Reading, velocities_from_positions
from ..motion_guard import StartPhase
from ..objects import yaw_of
from ..deploy.policy import load_policy
from ..deploy.policy_node_params import PolicyNodeParams
from .params import exit_if_help_asked, node_parameters
from .lifetime import init_node
from .object_messages import shape_from_primitive

TF_ERRORS = (tf2_ros.LookupException, tf2_ros.ConnectivityException, tf2_ros.ExtrapolationException,
             tf2_ros.InvalidArgumentException)


# The fields of each ~timing message, in order (s; "repeated" is 1.0 or 0.0): one place for the
# node, its diagnostics and the benches that listen to it.
TIMING_FIELDS = ("loop_period", "inference", "compute_latency", "joint_state_age", "new_state_wait", "repeated")


class PolicyNode:
    """Subscribers, tf, the 50 Hz timer and publishers around one :class:`DeploymentStep`."""

    def __init__(self) -> None:
        self.params = params = node_parameters(PolicyNodeParams, "policy_node")
        # A relative path: from the directory roslaunch was started in, then the package.
        model_dir = resolve_model_dir(params.model_dir, params.caller_dir or None)
        policy = load_policy(model_dir, params.backend, expected_robot=params.robot or None)
        env_cfg = load_env_config(policy.meta.get("env_overrides", {}))
        robot = load_robot_spec(env_cfg.robot)
        self.step = DeploymentStep(policy, robot, env_cfg, params.joint_state_timeout, params.target_timeout,
                                   target_workspace_margin=params.target_workspace_margin,
                                   future_stamp_tolerance=params.future_stamp_tolerance,
                                   guard=params.guard if params.motion_guard else None,
                                   stale_target_rise=params.stale_target_rise,
                                   stale_target_rise_speed=params.stale_target_rise_speed,
                                   stale_target_let_go=params.stale_target_let_go)
        self.control_dt = self.step.control_dt
        if abs(params.rate * self.control_dt - 1.0) > 1e-6:
            raise ConfigError(f"~rate = {params.rate:g} Hz but the model was trained at {1.0 / self.control_dt:g} Hz: "
                              "the action scaling would be wrong; set ~rate to the training rate")
        self.step.enabled = params.enabled
        self.reader = JointStateReader(robot.joint_names, robot.finger_joint_names,
                                       velocities_from_positions=velocities_from_positions(
                                           params.joint_velocity_source, env_cfg.observation.joint_velocity_source),
                                       max_joint_speeds=(robot.velocity_limits * params.guard.glitch_speed_factor
                                                         if params.motion_guard else None),
                                       # the environment estimates from one sample a control period
                                       estimate_interval=0.9 * self.control_dt,
                                       recovery_window=params.guard.jump_recovery_window)
        self.gripper_fault: Optional[str] = None
        self.joint_state_stamp = rospy.Time(0)
        self.target: Optional[PoseStamped] = None
        self.target_received = 0.0
        self.last_tick: Optional[float] = None
        self.started = time.monotonic()
        self.timing: deque = deque(maxlen=500)
        # Guards self.step (timer vs. services) and signals new inputs to a waiting period.
        self.inputs_changed = threading.Condition()
        self.sim_time = bool(rospy.get_param("/use_sim_time", False))
        self.last_input_stamp = -1.0  # sim time: stamp of the joint state the last step used
        self.reset_stamp = -1.0  # sim time: when the last ~reset came (an episode's goal is stamped then)
        # Real time: a period acts on a state no period before acted on (FreshStateWait's why).
        self.fresh_state = FreshStateWait(0.0 if self.sim_time else params.fresh_state_wait,
                                          params.fresh_state_max_age)

        self.tf_buffer = tf2_ros.Buffer(cache_time=rospy.Duration(10.0))
        self.tf_listener = tf2_ros.TransformListener(self.tf_buffer)
        if params.dry_run:  # nothing goes to the arm or the gripper: the commands draw a ghost robot
            self.ghost_pub = rospy.Publisher(params.dry_run_topic, JointState, queue_size=1)
            self.finger_names = list(robot.finger_joint_names)
            self.arm_names = list(robot.joint_names)
        else:
            self.command_pub = rospy.Publisher(params.command_topic, Float64MultiArray, queue_size=1)
            self.gripper_pub = rospy.Publisher(params.gripper_command_topic, Float64, queue_size=1)
        self.timing_pub = rospy.Publisher("~timing", Float64MultiArray, queue_size=10)
        self.marker_pub = rospy.Publisher("~target_marker", Marker, queue_size=1)
        self.diagnostics_pub = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=1)
        # The arm's driver and the gripper (its bridge) publish their joints apart; the reader
        # merges them by name.
        for topic in filter(None, (params.joint_states_topic, params.finger_joint_states_topic)):
            rospy.Subscriber(topic, JointState, self.on_joint_state, queue_size=1, tcp_nodelay=True)
        if params.gripper_fault_topic:
            rospy.Subscriber(params.gripper_fault_topic, Bool, self.on_gripper_fault, queue_size=1)
        rospy.Subscriber(params.target_topic, PoseStamped, self.on_target, queue_size=1, tcp_nodelay=True)
        # The object's shape (and, for a box given with its longer side along y, the quarter turn
        # that brings its frame to the convention's) and the place goal, where the model takes them.
        self.object_shape: Optional[Reading] = None
        self.shape_turn = 0.0
        self.goal: Optional[PoseStamped] = None
        if self.step.needs_shape or self.step.needs_goal:
            rospy.Subscriber(params.target_shape_topic, SolidPrimitive, self.on_target_shape, queue_size=1)
        if self.step.needs_goal:
            rospy.Subscriber(params.goal_topic, PoseStamped, self.on_goal, queue_size=1)
        rospy.Service("~enable", SetBool, self.on_enable)
        rospy.Service("~reset", Trigger, self.on_reset)
        rospy.Service("~go_to_start", Trigger, self.on_go_to_start)
        if self.sim_time:
            # On simulated time the period starts when /clock crosses it. rospy.Timer's sim-time
            # sleep can miss a /clock wake-up and oversleep by 0.5 s, which a lockstep simulator
            # would take for a held period; stepping from the clock's own callback cannot.
            self.next_period: Optional[rospy.Time] = None
            rospy.Subscriber("/clock", Clock, self.on_clock, queue_size=1, tcp_nodelay=True)
        else:
            self.timer = rospy.Timer(rospy.Duration(self.control_dt),
                                     lambda event: self.control_period(event.current_real))
        self.diagnostics_timer = rospy.Timer(rospy.Duration(1.0), self.publish_diagnostics)
        rospy.loginfo(f"policy_node: {policy.task} model {model_dir} ({policy.backend}), {params.rate:g} Hz, "
                      f"gripper commands {'on' if params.command_gripper else 'off'}")

    # ------------------------------------------------------------------ inputs
    def on_joint_state(self, message: JointState) -> None:
        if self.reader.update(message.name, message.position, message.velocity, message.header.stamp.to_sec(),
                              time.monotonic()) is None:
            self.joint_state_stamp = message.header.stamp
        if self.sim_time or self.fresh_state.wait_s > 0.0:
            with self.inputs_changed:
                self.inputs_changed.notify_all()

    def on_target(self, message: PoseStamped) -> None:
        self.target, self.target_received = message, time.monotonic()
        if self.sim_time:
            with self.inputs_changed:
                self.inputs_changed.notify_all()

    def on_target_shape(self, message: SolidPrimitive) -> None:
        try:
            shape, turn = shape_from_primitive(message)
            reading = Reading(shape, time.monotonic())
        except ValueError as error:
            shape, turn, reading = None, 0.0, Reading(None, time.monotonic(), f"{self.params.target_shape_topic}: {error}")
        with self.inputs_changed:
            self.object_shape, self.shape_turn = reading, turn
            self.inputs_changed.notify_all()

    def on_goal(self, message: PoseStamped) -> None:
        with self.inputs_changed:
            self.goal = message
            self.inputs_changed.notify_all()

    def on_gripper_fault(self, message: Bool) -> None:
        with self.inputs_changed:
            # True also while the bridge activates the gripper (about 3 s after it starts).
            self.gripper_fault = (f"{self.params.gripper_fault_topic} is true (not yet activated, unreachable or "
                                  "faulted: the gripper bridge's ~status says which)" if message.data else None)

    def on_enable(self, request) -> SetBoolResponse:
        """Pause or resume. Resuming is an operator's word that the arm stands where its joint
        states say: a latched jump clears. The answer says the state before, e.g. ``"enabled
        (was disabled)"``, so a caller that paused can restore what it found."""
        with self.inputs_changed:
            before = self.step.enabled
            self.step.enabled = bool(request.data)
            cleared = self.reader.accept_current() if request.data else None
        if cleared is not None:
            rospy.loginfo(f"policy_node: ~enable: the joint state as it stands is accepted (it had jumped: {cleared})")
        return SetBoolResponse(success=True, message=f"{'enabled' if self.step.enabled else 'disabled'} "
                                                     f"(was {'enabled' if before else 'disabled'})")

    def on_reset(self, _request) -> TriggerResponse:
        """Start as a new episode; with the motion guard, answer once the arm stands in the
        training start distribution and the policy has it (or the start move was refused)."""
        with self.inputs_changed:
            self.step.start_episode()
            self.reader.restart_estimates()  # as the environment's first observation: velocities 0.0
            self.reset_stamp = rospy.Time.now().to_sec()
        if self.step.guard is None or not self.step.enabled:
            return TriggerResponse(success=True, message="starting as a new episode")
        return self.wait_for_start("starting as a new episode")

    def on_go_to_start(self, _request) -> TriggerResponse:
        """The slow move into the training start distribution, asked for once."""
        if self.step.guard is None:
            return TriggerResponse(success=False, message="this node runs without the motion guard")
        with self.inputs_changed:
            self.step.guard.go_to_start_asked = True
            self.step.guard.restart()
        return self.wait_for_start("at the training start")

    def wait_for_start(self, done: str) -> TriggerResponse:
        """Wait (wall clock, ~start_move_timeout) until the guard hands the arm to the policy."""
        deadline = time.monotonic() + self.params.start_move_timeout
        while time.monotonic() < deadline and not rospy.is_shutdown():
            phase = self.step.guard.phase
            if phase is StartPhase.RUNNING:
                return TriggerResponse(success=True, message=done)
            if phase is StartPhase.REFUSED and self.step.last_hold is not None:
                return TriggerResponse(success=False, message=self.step.last_hold.detail)
            time.sleep(0.01)
        return TriggerResponse(success=False, message=f"not at the training start after "
                                                      f"{self.params.start_move_timeout:g} s")

    def wait_for_inputs_of(self, period_start: rospy.Time) -> None:
        """On simulated time: wait (bounded, wall clock) until the joint state and the target
        stamped at ``period_start`` have both arrived; they travel on separate connections."""
        wanted = period_start.to_sec() - 1e-6
        deadline = time.monotonic() + self.params.sim_time_input_wait

        def arrived() -> bool:
            reading, target = self.reader.reading(), self.target
            # The episode's shape and goal come latched when it starts, on connections of their
            # own: a period that began before they arrived would act on none (or the last one).
            shape_here = not (self.step.needs_shape or self.step.needs_goal) or self.object_shape is not None
            goal_here = not self.step.needs_goal or (
                self.goal is not None and self.goal.header.stamp.to_sec() >= self.reset_stamp - 1e-6)
            return (reading is not None and reading.stamp >= wanted
                    and target is not None and target.header.stamp.to_sec() >= wanted and shape_here and goal_here)

        with self.inputs_changed:
            while not arrived() and not rospy.is_shutdown():
                left = deadline - time.monotonic()
                if left <= 0.0:
                    rospy.logwarn_throttle(2.0, f"policy_node: inputs stamped {period_start.to_sec():.3f} s did not "
                                                f"arrive within ~sim_time_input_wait ({self.params.sim_time_input_wait:g} s)")
                    return
                self.inputs_changed.wait(left)

    def wait_for_new_state(self) -> float:
        """Real time: wait (bounded by ~fresh_state_wait) until a joint state arrives that no
        period acted on yet.

        :return: how long it waited (s).
        """
        start = time.monotonic()
        deadline = start + self.fresh_state.wait_s
        with self.inputs_changed:
            while not self.fresh_state.is_new(self.reader.reading(), time.monotonic()) and not rospy.is_shutdown():
                left = deadline - time.monotonic()
                if left <= 0.0:
                    break  # the driver is late: act on the state there is
                self.inputs_changed.wait(left)
        return time.monotonic() - start

    def pose_in_base(self, message: PoseStamped):
        """``message``'s pose in the base frame: position (m) and the yaw (rad) of the object's
        own x axis (the shape's quarter turn added), or the tf problem as a string."""
        try:
            transform = self.tf_buffer.lookup_transform(self.params.base_frame, message.header.frame_id, rospy.Time(0))
        except TF_ERRORS as error:
            return f"no transform {message.header.frame_id} -> {self.params.base_frame}: {error}"
        pose = tf2_geometry_msgs.do_transform_pose(message, transform).pose
        q = pose.orientation
        # A pose without an orientation (all zeros: a detector of positions only) has yaw 0.
        yaw = yaw_of((q.x, q.y, q.z, q.w)) if (q.x or q.y or q.z or q.w) else 0.0
        return pose.position.x, pose.position.y, pose.position.z, yaw + self.shape_turn

    def target_in_base(self) -> Optional[Reading]:
        """The newest target transformed into the base frame (position, m, and yaw, rad), or the tf problem."""
        message, received = self.target, self.target_received
        if message is None:
            return None
        pose = self.pose_in_base(message)
        if isinstance(pose, str):
            return Reading(None, received, pose)
        return Reading(pose, received, stamp=message.header.stamp.to_sec())

    def goal_in_base(self) -> Optional[Reading]:
        """The place goal in the base frame (x, y, m; yaw, rad), or the tf problem; None before one came."""
        message = self.goal
        if message is None or not self.step.needs_goal:
            return None
        pose = self.pose_in_base(message)
        if isinstance(pose, str):
            return Reading(None, 0.0, f"{self.params.goal_topic}: {pose}")
        return Reading((pose[0], pose[1], pose[3]), 0.0, stamp=message.header.stamp.to_sec())

    # ------------------------------------------------------------------ the 50 Hz loop
    def on_clock(self, message: Clock) -> None:
        if self.next_period is None or message.clock >= self.next_period:
            self.next_period = message.clock + rospy.Duration(self.control_dt)
            self.control_period(message.clock)

    def control_period(self, period_start: rospy.Time) -> None:
        """One control period starting at ``period_start`` (ROS time): step, then publish."""
        if rospy.is_shutdown():
            return
        waited = self.wait_for_new_state() if self.fresh_state.wait_s > 0.0 else 0.0
        start = time.perf_counter()
        period = start - self.last_tick if self.last_tick is not None else self.control_dt
        self.last_tick = start
        if self.sim_time and self.params.sim_time_input_wait > 0.0:
            self.wait_for_inputs_of(period_start)
        with self.inputs_changed:
            joint_state = self.reader.reading()
            repeated = not self.fresh_state.is_new(joint_state)
            self.fresh_state.used(joint_state)
            if self.sim_time and joint_state is not None:
                # A period that waited until the next period's inputs came (its own were lost
                # before the connections stood) already commanded that period: not twice.
                if joint_state.stamp > 0.0 and joint_state.stamp == self.last_input_stamp:
                    return
                self.last_input_stamp = joint_state.stamp
            previous_hold = self.step.last_hold
            was_rising = self.step.rising is not None
            previous_phase = self.step.guard.phase if self.step.guard is not None else None
            result = self.step(StepInputs(time.monotonic(), joint_state, self.target_in_base(),
                                          rospy.Time.now().to_sec(), self.gripper_fault, self.object_shape,
                                          self.goal_in_base()))
        if self.step.guard is not None and self.step.guard.phase is not previous_phase:
            self.report_start(self.step.guard.phase, joint_state)
        if isinstance(result, Hold):
            self.report_hold(result, previous_hold)
            return
        if self.step.rising is not None:
            if not was_rising:
                rospy.logwarn(f"policy_node: {self.step.rising}")
        elif previous_hold is not None or was_rising:
            rospy.loginfo(f"policy_node: inputs good, running (was: {previous_hold or 'rising clear'})")
        self.publish(result)
        stamp = self.joint_state_stamp
        state_age = (rospy.Time.now() - stamp).to_sec() if stamp.to_sec() > 0 else float("nan")
        timing = (period, result.inference_s, time.perf_counter() - start, state_age, waited, float(repeated))
        self.timing.append(timing)
        self.timing_pub.publish(Float64MultiArray(data=list(timing)))

    def publish(self, command: Command) -> None:
        if self.params.dry_run:  # the ghost robot's joint states: the command, fingers at half the width each
            ghost = JointState(name=self.arm_names + self.finger_names,
                               position=list(command.arm_positions) + [command.gripper_width / 2.0] * 2)
            ghost.header.stamp = rospy.Time.now()
            self.ghost_pub.publish(ghost)
        else:
            message = Float64MultiArray(data=list(command.arm_positions))
            message.layout.dim = [MultiArrayDimension(label="j1..j6", size=6, stride=6)]
            self.command_pub.publish(message)
            if self.params.command_gripper:
                self.gripper_pub.publish(Float64(data=command.gripper_width))
        if command.target_in_base is not None:
            self.publish_marker(command.target_in_base)

    def report_start(self, phase: StartPhase, joint_state: Optional[Reading]) -> None:
        if phase is StartPhase.MOVING and joint_state is not None and joint_state.value is not None:
            distance, joint = self.step.guard.distance_from_start(joint_state.value.positions)
            rospy.loginfo(f"policy_node: start move: {distance:.3f} rad from the training start on j{joint + 1}, "
                          f"at {self.params.guard.start_speed:g} rad/s")
        elif phase is StartPhase.RUNNING:
            rospy.loginfo("policy_node: at the training start: the policy has the arm")

    def report_hold(self, hold: Hold, previous: Optional[Hold]) -> None:
        # At once when the kind of problem changes, then at most every 2 s. A pause asked for
        # through ~enable is no problem, said once; so is an input not yet come while the other
        # nodes start (~startup_grace), which every launch goes through; a gripper still
        # activating, or a camera frame whose static transform has not come yet, is no fault either.
        starting = (hold.reason in (HoldReason.NO_JOINT_STATE, HoldReason.NO_TARGET, HoldReason.GRIPPER_FAULT,
                                    HoldReason.TARGET_UNAVAILABLE, HoldReason.NO_OBJECT_SHAPE, HoldReason.NO_GOAL)
                    and time.monotonic() - self.started < self.params.startup_grace)
        if hold.reason is HoldReason.DISABLED or starting:
            if previous is None or previous.reason != hold.reason:
                rospy.loginfo(f"policy_node: {'waiting: ' if starting else ''}{hold}")
        elif previous is None or previous.reason != hold.reason:
            rospy.logwarn(f"policy_node: holding: {hold}")
        else:
            rospy.logwarn_throttle(2.0, f"policy_node: holding: {hold}")

    # ------------------------------------------------------------------ reporting
    def publish_marker(self, position) -> None:
        marker = Marker(type=Marker.SPHERE, action=Marker.ADD, ns="policy_target", id=0)
        marker.header.frame_id = self.params.base_frame
        marker.header.stamp = rospy.Time.now()
        marker.pose.position.x, marker.pose.position.y, marker.pose.position.z = position
        marker.pose.orientation.w = 1.0
        marker.scale.x = marker.scale.y = marker.scale.z = 0.03
        marker.color.g, marker.color.b, marker.color.a = 0.9, 0.3, 0.6
        self.marker_pub.publish(marker)

    def publish_diagnostics(self, event) -> None:
        status = DiagnosticStatus(name="fr5_rl policy_node", hardware_id="fr5")
        hold = self.step.last_hold
        latched = self.reader.latched_jump()
        if latched is not None:  # a fault, not a wait: someone must look at the arm
            status.level, status.message = DiagnosticStatus.ERROR, f"holding: {latched}"
            status.values.append(KeyValue("joint_state_jump", latched))
        elif hold is not None:
            status.level, status.message = DiagnosticStatus.WARN, f"holding: {hold}"
        elif self.step.rising is not None:
            status.level, status.message = DiagnosticStatus.WARN, self.step.rising
        else:
            status.level, status.message = DiagnosticStatus.OK, "running"
        samples = np.array(self.timing) if self.timing else np.zeros((0, len(TIMING_FIELDS)))
        for column, name in enumerate(TIMING_FIELDS[:-1]):  # durations; "repeated" is a flag
            if len(samples):
                values = samples[:, column] * 1000.0
                status.values.append(KeyValue(f"{name}_p50_ms", f"{np.nanpercentile(values, 50):.3f}"))
                status.values.append(KeyValue(f"{name}_p99_ms", f"{np.nanpercentile(values, 99):.3f}"))
        if len(samples):
            status.values.append(KeyValue("repeated_joint_state_share", f"{samples[:, 5].mean():.3f}"))
        array = DiagnosticArray(status=[status])
        array.header.stamp = rospy.Time.now()
        self.diagnostics_pub.publish(array)


def main() -> int:
    exit_if_help_asked("policy_node.py", __doc__.split("\n\n")[0], "policy_node")
    init_node("fr5_policy")
    try:
        PolicyNode()
    except (ConfigError, ModelFilesError) as error:
        rospy.logfatal(f"policy_node: {error}")
        return 2
    # The start-up's objects (modules, the model, rospy) live as long as the node: out of the
    # collector's reach, a full collection walks only what the loop allocates (offline: a
    # 24 ms pause with onnxruntime loaded, 0.7 ms frozen; with torch, over 320,000 objects).
    gc.collect()
    gc.freeze()
    rospy.spin()
    return 0
