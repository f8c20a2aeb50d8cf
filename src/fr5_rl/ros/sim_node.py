"""Simulator node: the PyBullet FR5 world behind ROS topics, standing in for the arm's driver.

It behaves like the FAIRINO ROS driver + gripper + a camera, so the policy node runs unchanged
against it:

- publishes ``~joint_states_topic`` (sensor_msgs/JointState: j1..j6, and both finger joints
  unless ``~publish_finger_joints`` is false, stamped) at ``~publish_rate``;
- obeys ``~command_topic`` (std_msgs/Float64MultiArray, 6 positions in rad, in controller order
  j1..j6 — ros_control's JointGroupPositionController contract: a message of the wrong length is
  dropped with a throttled error) from the physics step that runs when it arrived, through the
  driver's servo cycle (``~servo_rate``, ``~servo_delay_cycles``) and response (a first-order lag
  per joint, ``~response_time_constant_s``: a driver profile, docs/sim_to_real.md), and
  ``~gripper_command_topic`` (std_msgs/Float64, opening width in m);
- acts as the camera: the object's pose on ``~target_topic`` (geometry_msgs/PoseStamped) in
  ``~camera_frame``, computed with config/static_transforms.yaml and optional noise (unless
  ``~publish_target`` is false: a detector on a simulated camera publishes it instead);
- publishes the object's true pose, size and shape (visualization_msgs/Marker in base_link) on
  ``~object_topic`` with every joint state, stamped alike, for the simulated camera (camera_node);
- publishes rviz markers (table, object, tcp path) on ``~markers``;
- judges each episode with the environment's own success test, publishes the outcome (JSON in
  std_msgs/String) on ``~episode_outcome`` (and appends it to ``~outcome_log``), calls the policy
  node's ``~policy_reset_service``, then places a new object and homes the arm (in real time
  with ``~reset_settle_time`` > 0 it first holds the new scene that long, so a camera in the
  loop sees it before the policy starts); ``~reset``
  (std_srvs/Trigger) does that at once. With ``~episodes`` = N > 0 it stops after N episodes and
  prints ``success rate: K/N`` as its last line.

Two ways to pace the world:

- **real time** (default): physics is locked to the wall clock, as a real arm is, at the
  stand-in's own physics step (``~physics_dt``, ``~solver_iterations``).
- **lockstep** (``~lockstep``): the node publishes ``/clock`` and advances one control period
  only once that period's command has arrived (or ``~lockstep_command_timeout`` wall seconds
  passed: the policy held). Every node runs on ``/use_sim_time``. The world then is the gym
  environment's own (the task's physics step), advanced period by period as
  :meth:`~fr5_rl.envs.FR5Env.step` does, so the deployed node's outcome equals gym's episode by
  episode, faster than real time.

The node is input and output only: the simulation, the episode verdict and the scene all come
from :class:`fr5_rl.envs.FR5Env`'s public API. This module holds its parameters, its constructor,
its callbacks and the episode bookkeeping both loops share; each loop is a class in
:mod:`fr5_rl.ros.sim_loops`.
"""
from __future__ import annotations

import json
import os
import signal
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional, Tuple

import numpy as np
import rospy
from geometry_msgs.msg import PoseStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, String
from std_srvs.srv import SetBool, SetBoolResponse, Trigger, TriggerResponse
from visualization_msgs.msg import Marker, MarkerArray

from ..config import ConfigError, check_positive, check_time_constants, whole_multiple
from ..deploy.bundle import ModelFilesError, task_and_arm
from ..envs import EpisodeVerdict, FR5Env, JointStates
from ..sim.controller_emulator import ControllerEmulator, ControllerEmulatorSettings
from ..sim.pacing import ArrivalQueue
from ..sim.servo import FirstOrderResponse, ServoCycle
from ..transforms import load_static_transforms, matrix_from_quaternion, quaternion_from_matrix, transform_in
from .params import exit_if_help_asked, node_parameters
from .sim_loops import LockstepLoop, RealTimeLoop
from .sim_messages import joint_state_message, object_marker
from .lifetime import init_node


@dataclass(frozen=True)
class SimNodeParams:
    """``config/sim_node.yaml``: the simulator node's ~private parameters."""

    task: str
    model: str  # the policy's model directory: its task is judged and its arm simulated ("": none given)
    caller_dir: str  # where a relative model was typed (roslaunch's directory); "": the current one
    robot: str  # the arm, which must be the model's ("": the model's, else fr5)
    seed: int
    episodes: int
    publish_rate: float
    physics_dt: float
    solver_iterations: int
    camera_rate: float
    camera_frame: str
    camera_noise_std: float
    marker_rate: float
    pause_between_episodes: float
    reset_settle_time: float
    joint_states_topic: str
    publish_velocities: bool
    truth_joint_states_topic: str
    command_topic: str
    gripper_interface: str
    gripper_command_topic: str
    controller_port: int
    controller_emulator: ControllerEmulatorSettings
    target_topic: str
    publish_target: bool
    object_topic: str
    publish_finger_joints: bool
    servo_rate: float
    servo_delay_cycles: int
    response_time_constant_s: List[float]
    lockstep: bool
    lockstep_command_timeout: float
    lockstep_gripper: bool
    policy_reset_service: str
    policy_enable_service: str
    teleport_settle_time: float
    policy_call_timeout: float
    episode_start: str
    first_command_timeout: float
    outcome_log: str

    def check(self, source: str) -> None:
        if self.servo_rate < 0 or self.servo_delay_cycles < 0:
            raise ConfigError(f"{source}: servo_rate and servo_delay_cycles must be >= 0 (0: no servo cycle)")
        check_time_constants(source, "response_time_constant_s", self.response_time_constant_s)
        check_positive(source, lockstep_command_timeout=self.lockstep_command_timeout)
        if self.gripper_interface not in ("topic", "xmlrpc"):
            raise ConfigError(f"{source}: 'gripper_interface' must be topic or xmlrpc, got {self.gripper_interface!r}")
        if self.gripper_interface == "xmlrpc" and self.lockstep:
            raise ConfigError(f"{source}: 'gripper_interface: xmlrpc' runs in real time only (the XML-RPC path "
                              "is asynchronous); set ~lockstep false")
        if self.episode_start not in ("reset", "go_to_start"):
            raise ConfigError(f"{source}: 'episode_start' must be reset or go_to_start, got {self.episode_start!r}")
        if self.episode_start == "go_to_start" and (self.lockstep or not self.policy_reset_service):
            raise ConfigError(f"{source}: 'episode_start: go_to_start' needs real time and a policy_reset_service "
                              "(the policy node's start move begins each episode)")
        if self.task not in ("", "reach", "grasp"):
            raise ConfigError(f"{source}: 'task' must be reach, grasp or \"\" (the model's), got {self.task!r}")
        check_positive(source, publish_rate=self.publish_rate, physics_dt=self.physics_dt, camera_rate=self.camera_rate,
                  marker_rate=self.marker_rate, solver_iterations=self.solver_iterations)
        if min(self.episodes, self.camera_noise_std, self.pause_between_episodes, self.reset_settle_time,
               self.first_command_timeout, self.teleport_settle_time) < 0 or self.policy_call_timeout <= 0:
            raise ConfigError(f"{source}: episodes, camera_noise_std, pause_between_episodes, reset_settle_time, "
                              "first_command_timeout and teleport_settle_time must be >= 0, policy_call_timeout > 0")


class SimulatorNode:
    """Runs one FR5Env world behind ROS topics, in real time or in lockstep with the policy.

    The subscriber and service callbacks run on rospy's threads; everything they share with
    the loop (commands, the episode state) is guarded by ``self.lock``.
    """

    def __init__(self) -> None:
        # ---- parameters (config/sim_node.yaml)
        self.params = params = node_parameters(SimNodeParams, "sim_node")
        # The model decides what is judged and which arm is simulated; a ~task or ~robot that
        # contradicts it refuses.
        task, robot = task_and_arm(params.model or None, params.task or None, params.robot or None,
                                   params.caller_dir or None)
        if params.lockstep:
            if params.servo_rate > 0 or any(params.response_time_constant_s):
                raise ConfigError("sim_node: lockstep advances whole control periods as gym does; it cannot also "
                                  "model a servo cycle or response: set ~servo_rate 0 and "
                                  "~response_time_constant_s [] (driver:=default) or ~lockstep false")
            self.env = FR5Env(task=task, robot=robot)  # the gym world, as `evaluate.py` builds it
        else:
            # The stand-in arm runs at its own physics step, finer than reach training uses.
            self.env = FR5Env(task=task, robot=robot, config={task: {"simulation": {
                "physics_dt": params.physics_dt, "solver_iterations": params.solver_iterations}}})
        self.spec = self.env.robot_spec
        self.physics_dt = self.env.physics_dt
        # Lockstep publishes once per control period instead.
        self.steps_per_publish = whole_multiple(1.0 / params.publish_rate, self.physics_dt) or 0
        if not params.lockstep and not self.steps_per_publish:
            raise ConfigError(f"sim_node: 1 / publish_rate ({1.0 / params.publish_rate:g} s) must be a whole "
                              f"multiple of physics_dt ({self.physics_dt:g} s), or simulated time would drift")
        steps_per_servo = 0
        if params.servo_rate > 0:
            steps_per_servo = whole_multiple(1.0 / params.servo_rate, self.physics_dt)
            if steps_per_servo is None:
                raise ConfigError(f"sim_node: 1 / servo_rate ({1.0 / params.servo_rate:g} s) must be a whole "
                                  f"multiple of physics_dt ({self.physics_dt:g} s)")
        self.servo = ServoCycle(steps_per_servo, params.servo_delay_cycles, self.spec.home_joint_positions)
        # The driver's response (a driver profile's lag per joint; none by default).
        self.response = FirstOrderResponse(params.response_time_constant_s, self.physics_dt,
                                           self.spec.home_joint_positions)
        self.base_in_camera = np.linalg.inv(
            transform_in(load_static_transforms(), self.spec.base_frame, params.camera_frame))
        self.rng = np.random.default_rng(params.seed)  # camera noise
        self.outcome_log: Optional[Path] = None
        if params.outcome_log:
            self.outcome_log = Path(params.outcome_log)
            if not self.outcome_log.is_absolute():
                self.outcome_log = Path.cwd() / self.outcome_log
            self.outcome_log.parent.mkdir(parents=True, exist_ok=True)
        self.reset_policy = (rospy.ServiceProxy(params.policy_reset_service, Trigger)
                             if params.policy_reset_service else None)
        # gripper_interface xmlrpc: the FR5 controller's gripper methods on loopback, as the gripper
        # bridge finds them on the real controller; the fingers follow what it was told.
        self.controller: Optional[ControllerEmulator] = None
        if params.gripper_interface == "xmlrpc":
            self.controller = ControllerEmulator(params.controller_emulator, params.controller_port, time.monotonic)
            self.controller.start()
            rospy.loginfo(f"sim_node: the FR5 controller's gripper methods at {self.controller.url}")

        # ---- episode state, shared with the callbacks under the lock
        self.lock = threading.Lock()
        self.command_arrived = threading.Condition(self.lock)
        self.new_command = False  # lockstep: an arm command arrived since the last /clock
        self.new_gripper_command = False  # lockstep: a gripper command arrived since the last /clock
        self.episode = 0  # episodes finished
        self.results: List[bool] = []  # success of each finished episode
        self.tcp_path: deque = deque(maxlen=300)  # tcp positions (m, base_link), one per control period
        self.late_periods = 0  # lockstep: periods of this episode that went without a command
        self.loop_lateness: List[float] = []  # real time: s behind the wall clock at each wake-up, this episode
        self.arm_command: Optional[Tuple[float, ...]] = None  # newest arm command (rad), None: none yet
        # Real time: commands with their arrival (monotonic s), taken up by the physics step that
        # runs at that time; a loop catching up on late steps must not apply them early. The
        # gripper's too: applied at the loop's wake-up, a late loop closed the fingers ahead of
        # the arm by its lateness.
        self.arriving: ArrivalQueue = ArrivalQueue()
        self.gripper_arriving: ArrivalQueue = ArrivalQueue()
        self.controller_command: Optional[Tuple[float, float]] = None  # the controller's newest command taken
        self.gripper_target = self.spec.max_opening_width
        self.commanded = False  # episodes are timed from the first command
        self.holding = True  # between episodes: commands are ignored until the next one starts
        self.hold_until = 0.0
        self.settling = False  # the new scene is placed, the policy not yet told (~reset_settle_time)
        # Real time: the policy node's ~reset is in flight. With episode_start go_to_start its
        # start move runs (commands obeyed, the episode not yet timed) until it answers.
        self.positioning = False
        self.episode_starts = 0
        # Real time: the policy node was paused (it was enabled) for a teleport, to resume before its ~reset.
        self.resume_after_teleport = False
        self.pause_answers: List[str] = []  # the policy node's answer to the pause before a teleport

        # ---- ROS interfaces
        self.joint_pub = rospy.Publisher(params.joint_states_topic, JointState, queue_size=10)
        self.truth_pub = (rospy.Publisher(params.truth_joint_states_topic, JointState, queue_size=10)
                          if params.truth_joint_states_topic else None)
        self.target_pub = (rospy.Publisher(params.target_topic, PoseStamped, queue_size=10)
                           if params.publish_target else None)
        self.object_pub = (rospy.Publisher(params.object_topic, Marker, queue_size=10)
                           if params.object_topic else None)
        self.marker_pub = rospy.Publisher("~markers", MarkerArray, queue_size=2)
        self.outcome_pub = rospy.Publisher("~episode_outcome", String, queue_size=10, latch=True)
        self.clock_pub = rospy.Publisher("/clock", Clock, queue_size=1) if params.lockstep else None
        self.command_sub = rospy.Subscriber(params.command_topic, Float64MultiArray, self._on_arm_command,
                                            queue_size=1, tcp_nodelay=True)
        if self.controller is None:
            rospy.Subscriber(params.gripper_command_topic, Float64, self._on_gripper_command, queue_size=1,
                             tcp_nodelay=True)
        rospy.Service("~reset", Trigger, self._on_reset)
        # Camera calibration (calibrate_camera.py): the cup fixed in the closed gripper, no episodes.
        self.calibrating = False
        rospy.Service("~calibration", SetBool, self._on_calibration)
        if not params.lockstep:  # lockstep starts its first episode once the policy node is up
            with self.lock:
                self.start_episode()

    # ------------------------------------------------------------------ the run
    def end_of_run(self) -> None:
        """After the last episode: pause the policy (it would hold, warning of stale joint states,
        once the simulator has gone) and end the launch that started this node as a finished run,
        not as a required node that died (roslaunch's red banner). Under rostest the test ends it."""
        if self.params.policy_enable_service:
            try:
                rospy.wait_for_service(self.params.policy_enable_service, timeout=1.0)
                rospy.ServiceProxy(self.params.policy_enable_service, SetBool)(False)
            except (rospy.ServiceException, rospy.ROSException):
                pass  # no policy node, or it has gone: nothing to pause
        try:
            parent = Path(f"/proc/{os.getppid()}/cmdline").read_bytes().split(b"\0")
        except OSError:
            return
        if any(part.endswith(b"roslaunch") for part in parent[:2]):
            os.kill(os.getppid(), signal.SIGINT)

    def spin(self) -> None:
        """Step physics and publish until shutdown or the last episode, then print the result."""
        (LockstepLoop if self.params.lockstep else RealTimeLoop)(self).run()
        if self.params.episodes > 0 and self.results:
            print(f"success rate: {sum(self.results)}/{len(self.results)}", flush=True)

    # ------------------------------------------------------------------ episodes (lock held)
    def start_episode(self, settle: float = 0.0) -> None:
        """Place a new object (seed + episode), hold the arm where the reset put it, and tell
        the policy node a new episode starts; with ``settle`` (s) > 0, tell it only after the
        arm held the new scene that long (the real-time loop calls :meth:`begin_episode`)."""
        if self.params.episode_start == "go_to_start" and self.episode > 0:
            # A real arm is not teleported: only the object is placed, as a person would.
            self.env.reset(seed=self.params.seed + self.episode,
                           options={"arm_positions": self.env.joint_positions().tolist()})
        else:
            if self.episode > 0 and not self.params.lockstep:
                self._pause_policy_for_teleport()
            self.env.reset(seed=self.params.seed + self.episode)
        self.arm_command = None
        self.arriving.clear()
        self.gripper_arriving.clear()
        self.controller_command = None  # the controller's standing command applies anew
        # A driver's servo loop runs on across episodes: its cycle keeps its phase.
        self.servo.reset(self.env.joint_positions(), restart_cycle=False)
        self.response.reset(self.env.joint_positions())
        self.gripper_target = self.spec.max_opening_width
        self.commanded = False  # episodes are timed from the first command
        self.late_periods = 0
        self.loop_lateness = []
        self.tcp_path.clear()
        if settle > 0.0:
            # A camera in the loop delivers the new scene a pipeline latency later: until then
            # the policy would act on the old object's position.
            self.holding, self.settling = True, True
            self.hold_until = time.monotonic() + settle
            return
        self.begin_episode()

    def begin_episode(self) -> None:
        """Obey commands from now on and tell the policy node a new episode starts."""
        self.holding, self.settling = False, False
        self.hold_until = 0.0
        if self.reset_policy is None:
            if self.resume_after_teleport:
                threading.Thread(target=self._resume_policy_after_teleport, daemon=True).start()
            return
        if not self.params.lockstep:
            # A driver never stops publishing: the loop runs on while the policy node answers
            # (with its motion guard it answers once the arm stands at the start, which it can
            # only see in states the loop publishes). Until then its commands are obeyed but not
            # timed with go_to_start, and not obeyed after a teleport (as if the call had blocked).
            self.positioning = True
            self.episode_starts += 1
            threading.Thread(target=self._reset_policy_then_start, args=(self.episode_starts,), daemon=True).start()
            return
        try:
            self.reset_policy()
        except (rospy.ServiceException, rospy.ROSException) as error:
            # In lockstep a policy that keeps its old filter state breaks the match with gym.
            rospy.logwarn_throttle(30.0, f"sim_node: could not reset the policy node through "
                                         f"{self.params.policy_reset_service}: {error}")

    def take_controller_command(self) -> None:
        """gripper_interface xmlrpc (lock held): the width the emulated controller was given, for
        the fingers to take from when it arrived."""
        command = self.controller.newest_command()
        if command is None or self.holding or command == self.controller_command:
            return
        self.controller_command = command
        arrived, width = command
        self.gripper_arriving.push(arrived, float(np.clip(width, 0.0, self.spec.max_opening_width)))

    def report_to_controller(self) -> None:
        """gripper_interface xmlrpc (lock held): what the fingers measure now, for the controller to
        read back; still moving while a command waits to be taken up."""
        states = self.env.joint_states()
        arm = len(self.spec.joint_names)
        moving = len(self.gripper_arriving) > 0 or any(abs(speed) > 1e-3 for speed in states.velocities[arm:])
        self.controller.set_measured_width(sum(states.positions[arm:]), moving=moving)

    def _pause_policy_for_teleport(self) -> None:
        """Real time (lock held), before the arm is teleported: pause the policy node, as an
        operator does before moving the arm by hand. A teleport is no motion: to the policy node's
        joint-state check it is a jump, which holds latched until ~enable vouches for the new
        state (:meth:`_reset_policy_then_start` resumes it). A node paused by someone else stays so."""
        self.resume_after_teleport = False
        if not self.params.policy_enable_service:
            return
        answers: List[str] = []

        def pause() -> None:
            try:
                answers.append(rospy.ServiceProxy(self.params.policy_enable_service, SetBool)(False).message)
            except (rospy.ServiceException, rospy.ROSException):
                pass  # no policy node (yet), or one without ~enable

        # The loop holds the lock: a policy node that does not answer must not stall the arm's
        # states. Unanswered in time, the teleport goes on (the node may then hold on the jump
        # until the ~enable that follows).
        caller = threading.Thread(target=pause, daemon=True)
        caller.start()
        caller.join(self.params.policy_call_timeout)
        # Read when resuming, so that a late answer still counts.
        self.pause_answers = answers
        self.resume_after_teleport = True

    def _resume_policy_after_teleport(self) -> None:
        """Real time (own thread): once the teleported state has reached the policy node (states
        flow at the publish rate; ``~teleport_settle_time`` covers their way), resume it: its
        ~enable accepts the new state as the arm's."""
        with self.lock:
            resume, self.resume_after_teleport = self.resume_after_teleport, False
            answers = self.pause_answers
        if not resume:
            return
        time.sleep(self.params.teleport_settle_time)
        if not answers or "(was enabled)" not in answers[0]:
            return  # paused by someone else (or it never answered): not ours to resume
        try:
            rospy.ServiceProxy(self.params.policy_enable_service, SetBool)(True)
        except (rospy.ServiceException, rospy.ROSException) as error:
            rospy.logdebug(f"sim_node: could not resume the policy node after the teleport: {error}")

    def _reset_policy_then_start(self, start: int) -> None:
        """Real time (a thread of its own): the policy node's ~reset, which answers at once, or
        with its motion guard once the arm stands in the training start distribution; the
        episode starts with the next command, unless another start (``episode_starts``) came
        meanwhile."""
        self._resume_policy_after_teleport()
        try:
            if self.params.episode_start == "go_to_start":  # at start-up the policy node may still come
                rospy.wait_for_service(self.params.policy_reset_service, timeout=120.0)
            answer = self.reset_policy()
            ok, detail = answer.success, answer.message
        except (rospy.ServiceException, rospy.ROSException) as error:
            ok, detail = False, str(error)
        if not ok:
            # After a teleport the guard may first see the last episode's end pose and refuse it;
            # the next state, at home, starts it. Only a real start move that failed is news, not
            # a policy node that ended with its launch.
            news = self.params.episode_start == "go_to_start" and self._policy_still_there()
            log = rospy.logwarn if news else rospy.logdebug
            log(f"sim_node: the policy node's reset did not end at the start: {detail}")
        with self.lock:
            if self.episode_starts == start:
                self.positioning = False
                self.commanded = False  # timed from the policy's first command

    def _policy_still_there(self) -> bool:
        """Whether the policy node's ~reset is still offered (and this node not shutting down)."""
        if rospy.is_shutdown():
            return False
        try:
            rospy.wait_for_service(self.params.policy_reset_service, timeout=0.5)
        except (rospy.ROSException, rospy.ROSInterruptException):
            return False
        return not rospy.is_shutdown()

    def finish_episode(self, verdict: EpisodeVerdict, sim_time: float) -> None:
        """Publish and log the outcome; in real time, hold the arm still for a moment."""
        self.episode += 1
        self.results.append(bool(verdict.success))
        record = {"episode": self.episode, "seed": self.params.seed + self.episode - 1,
                  "success": bool(verdict.success), "failure": verdict.failure or "", "steps": verdict.steps,
                  "sim_time": round(sim_time, 3),
                  # How long the simulated arm now ignores commands (a pause no real arm makes):
                  # compare_run.py leaves it out of a recorded rehearsal.
                  "hold_s": self.params.pause_between_episodes + self.params.reset_settle_time}
        if self.params.lockstep:
            record["late_periods"] = self.late_periods
        elif self.loop_lateness:
            # A loaded machine wakes this loop late; the steps it then catches up on run with the
            # commands of their time, but the policy reads states that much older.
            late_ms = np.percentile(self.loop_lateness, [50, 99, 100]) * 1000.0
            record["loop_late_ms"] = {"p50": round(float(late_ms[0]), 1), "p99": round(float(late_ms[1]), 1),
                                      "max": round(float(late_ms[2]), 1)}
        self.outcome_pub.publish(String(data=json.dumps(record)))
        if self.outcome_log is not None:
            with self.outcome_log.open("a") as log:
                log.write(json.dumps(record) + "\n")
        rospy.loginfo(f"episode {self.episode} (seed {record['seed']}): "
                      f"{'success' if verdict.success else 'failure (' + str(verdict.failure) + ')'}"
                      f" after {verdict.steps} steps")
        self.holding = True
        self.hold_until = time.monotonic() + self.params.pause_between_episodes
        self.arm_command = tuple(self.env.joint_positions())
        self.arriving.clear()
        self.gripper_arriving.clear()

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
            # After a teleport (episode_start reset) the arm waits, as gym's reset leaves it,
            # until the policy node has answered its ~reset.
            teleported = self.positioning and self.params.episode_start == "reset"
            if not self.holding and not teleported:
                self.commanded = self.commanded or not self.positioning
                if self.params.lockstep:
                    self.arm_command = tuple(clamped.tolist())
                else:
                    self.arriving.push(time.monotonic(), tuple(clamped.tolist()))
            self.new_command = True
            self.command_arrived.notify_all()

    def _on_gripper_command(self, message: Float64) -> None:
        width = float(message.data)
        if not np.isfinite(width):
            rospy.logerr_throttle(1.0, "sim_node: dropped non-finite gripper command")
            return
        with self.lock:
            if not self.holding:
                width = float(np.clip(width, 0.0, self.spec.max_opening_width))
                if self.params.lockstep:
                    self.gripper_target = width
                else:
                    self.gripper_arriving.push(time.monotonic(), width)
            self.new_gripper_command = True
            self.command_arrived.notify_all()

    def _on_calibration(self, request) -> SetBoolResponse:
        """~calibration (std_srvs/SetBool), real time only. True: a calibration session: the cup
        is fixed in the closed gripper (config/calibration.yaml ``simulator.object_in_tcp``, as a
        person's hand-over would leave it), arm commands are obeyed, no episode is judged or
        reset. False: the cup is let go and a new episode starts."""
        from ..perception.hand_eye import load_calibration_settings

        if self.params.lockstep:
            return SetBoolResponse(success=False, message="calibration runs in real time only")
        with self.lock:
            env = self.env
            if request.data and not self.calibrating:
                env.hold_object(load_calibration_settings().simulator.object_in_tcp)
                self.calibrating = True
                self.arriving.clear()
                self.gripper_arriving.clear()
                self.holding = self.settling = self.positioning = False
                self.arm_command = tuple(env.joint_positions())
                self.gripper_target = float(env.scene().object_size[0])  # closed on the cup
            elif not request.data and self.calibrating:
                env.release_object()
                self.calibrating = False
                self.start_episode()
        return SetBoolResponse(success=True, message=f"calibration {'on' if request.data else 'off'}")

    def _on_reset(self, _request) -> TriggerResponse:
        with self.lock:
            self.start_episode()
        return TriggerResponse(success=True, message=f"episode {self.episode} started")

    # ------------------------------------------------------------------ outputs
    def publish_state(self, stamp: rospy.Time) -> None:
        """The joint state as the driver reports it; for the simulated camera, all joints and
        the object's true pose, stamped alike."""
        states = self.env.joint_states()
        if self.truth_pub is not None:
            self.truth_pub.publish(joint_state_message(states, stamp))
        arm = len(self.spec.joint_names) if not self.params.publish_finger_joints else len(states.names)
        # The FAIRINO driver fills positions only: its velocities are all 0.0.
        velocities = states.velocities[:arm] if self.params.publish_velocities else (0.0,) * arm
        self.joint_pub.publish(joint_state_message(JointStates(states.names[:arm], states.positions[:arm], velocities),
                                                   stamp))
        if self.object_pub is not None:
            self.object_pub.publish(object_marker(self.env.scene(), self.env.object_pose(), stamp))

    def camera_message(self, stamp: rospy.Time) -> PoseStamped:
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


def main() -> int:
    exit_if_help_asked("sim_node.py", __doc__.split("\n\n")[0], "sim_node")
    init_node("fr5_sim")
    try:
        node = SimulatorNode()
    except (ConfigError, ModelFilesError) as error:
        rospy.logfatal(str(error))
        return 2
    node.spin()
    node.env.close()
    if not rospy.is_shutdown():
        node.end_of_run()
        rospy.signal_shutdown("all episodes done")
    return 0
