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
  ``~camera_frame``, computed with config/static_transforms.yaml and optional noise, and its
  shape on ``~target_shape_topic`` (shape_msgs/SolidPrimitive, latched, each episode) (unless
  ``~publish_target`` is false: a detector on a simulated camera publishes them instead);
- for a task with a goal (place), publishes the episode's goal on ``~goal_topic``
  (geometry_msgs/PoseStamped, latched) in ``~goal_frame``, as an operator or a line's PLC would;
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
from :class:`fr5_rl.episode.Episode` (the plant, the chain and the task gym's environment wraps). This module holds its parameters, its constructor,
its callbacks and the episode bookkeeping both loops share; each loop is a class in
:mod:`fr5_rl.ros.sim_loops`.
"""
from __future__ import annotations

import dataclasses
import json
import os
import signal
import threading
import time
from pathlib import Path
from typing import List, Optional, Tuple

import numpy as np
import rospy
from geometry_msgs.msg import PoseStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from shape_msgs.msg import SolidPrimitive
from std_msgs.msg import Float64, Float64MultiArray, String
from std_srvs.srv import SetBool, SetBoolResponse, Trigger, TriggerResponse
from visualization_msgs.msg import Marker, MarkerArray

from ..config import ConfigError, whole_multiple
from ..deploy.bundle import ModelFilesError, deployment_overrides, read_meta, resolve_model_dir, task_and_arm
from ..clearing import ClearingSettings
from ..episode_runner import EpisodeRunner, simulator_episode
from ..scene_episodes import TableClearing, scene_sizes
from ..objects import quaternion_of_yaw
from ..observation import TASK_BLOCKS
from ..sim.plant import JointStates
from ..tasks import EpisodeVerdict
from ..sim.controller_emulator import ControllerEmulator
from ..sim.node_params import SimNodeParams
from ..sim.servo import DriverModel
from ..transforms import load_static_transforms, matrix_from_quaternion, quaternion_from_matrix, transform_in
from .params import exit_if_help_asked, node_parameters
from .sim_loops import LockstepLoop, RealTimeLoop
from .object_messages import primitive_from_shape
from .sim_messages import joint_state_message, neighbour_markers, object_marker, scene_markers
from .lifetime import init_node


# s: a clearing run's first episode waits this long at most for the cell's first choice (the
# camera and the detector start with the launch); then the rule on the truth chooses.
FIRST_CHOICE_WAIT = 30.0


class SimulatorNode:
    """Runs one simulated episode (:class:`~fr5_rl.episode.Episode`) behind ROS topics, in real time or in lockstep with the policy.

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
        # The objects the model was trained to handle (object.variety), as evaluate.py keeps them.
        model_settings = (deployment_overrides(read_meta(resolve_model_dir(params.model, params.caller_dir or None)))
                          if params.model else {})
        if params.lockstep and (params.servo_rate > 0 or any(params.response_time_constant_s)):
            raise ConfigError("sim_node: lockstep advances whole control periods as gym does; it cannot also "
                              "model a servo cycle or response: set ~servo_rate 0 and "
                              "~response_time_constant_s [] (driver:=default) or ~lockstep false")
        self.sim = simulator_episode(task, robot, model_settings, params)
        clearing = None
        if params.scene == "clear":
            if not TASK_BLOCKS[task][1]:
                raise ConfigError(f"sim_node: scene: clear sets each object down at a goal: it needs a model of the "
                                  f"task place, not {task}")
            clearing = TableClearing(self.sim, ClearingSettings.from_yaml(), params.seed, params.first_scene)
            if params.scenes:
                # Every object of a scene gets one record: N scenes are that many episodes.
                sizes = scene_sizes(self.sim, clearing.settings, params.seed, params.scenes, params.first_scene)
                self.params = params = dataclasses.replace(params, episodes=sum(sizes))
                rospy.loginfo(f"sim_node: clearing {params.scenes} scenes of {', '.join(map(str, sizes))} objects")
        self.spec = self.sim.robot_spec
        self.physics_dt = self.sim.physics_dt
        # Lockstep publishes once per control period instead.
        self.steps_per_publish = whole_multiple(1.0 / params.publish_rate, self.physics_dt) or 0
        if not params.lockstep and not self.steps_per_publish:
            raise ConfigError(f"sim_node: 1 / publish_rate ({1.0 / params.publish_rate:g} s) must be a whole "
                              f"multiple of physics_dt ({self.physics_dt:g} s), or simulated time would drift")
        # The driver: its servo cycle and response (a driver profile's; none by default).
        self.driver = DriverModel(params.servo_rate, params.servo_delay_cycles, params.response_time_constant_s,
                                  self.physics_dt, self.spec.home_joint_positions)
        # The cell's own frames (the arm's: another arm's table and camera stand elsewhere).
        static_transforms = load_static_transforms(robot=self.spec.model)
        self.base_in_camera = np.linalg.inv(transform_in(static_transforms, self.spec.base_frame, params.camera_frame))
        self.base_in_goal_frame = np.linalg.inv(transform_in(static_transforms, self.spec.base_frame, params.goal_frame))
        self.rng = np.random.default_rng(params.seed)  # camera noise
        self.started = time.monotonic()
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

        # ---- episode state, shared with the callbacks under the lock: the runner's phase,
        # commands and records (ROS-free), and this node's calls to the policy node.
        self.runner = EpisodeRunner(self.sim, self.driver, params.seed, params.episode_start == "go_to_start",
                                    params.pause_between_episodes, clearing=clearing)
        self.lock = threading.Lock()
        self.command_arrived = threading.Condition(self.lock)
        self.new_command = False  # lockstep: an arm command arrived since the last /clock
        self.new_gripper_command = False  # lockstep: a gripper command arrived since the last /clock
        self.controller_command: Optional[Tuple[float, float]] = None  # the controller's newest command taken
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
        self.shape_pub = (rospy.Publisher(params.target_shape_topic, SolidPrimitive, queue_size=1, latch=True)
                          if params.publish_target else None)
        self.goal_pub = (rospy.Publisher(params.goal_topic, PoseStamped, queue_size=1, latch=True)
                         if TASK_BLOCKS[task][1] else None)  # the task has a goal
        self.marker_pub = rospy.Publisher("~markers", MarkerArray, queue_size=2)
        self.neighbours_pub = (rospy.Publisher(params.neighbours_topic, MarkerArray, queue_size=10)
                               if params.neighbours_topic and clearing is not None else None)
        self.outcome_pub = rospy.Publisher("~episode_outcome", String, queue_size=10, latch=True)
        self.clock_pub = rospy.Publisher("/clock", Clock, queue_size=1) if params.lockstep else None
        self.command_sub = rospy.Subscriber(params.command_topic, Float64MultiArray, self._on_arm_command,
                                            queue_size=1, tcp_nodelay=True)
        if self.controller is None:
            rospy.Subscriber(params.gripper_command_topic, Float64, self._on_gripper_command, queue_size=1,
                             tcp_nodelay=True)
        # A clearing run: the cell's sequencer asks its detector for the next object.
        self.cell_next = None
        if clearing is not None and params.cell_next_service:
            from ..srv import NextObject  # built by catkin from srv/

            self.cell_next = rospy.ServiceProxy(params.cell_next_service, NextObject)
        rospy.Service("~reset", Trigger, self._on_reset)
        # Camera calibration (calibrate_camera.py): the cup fixed in the closed gripper, no episodes.
        rospy.Service("~calibration", SetBool, self._on_calibration)
        if clearing is not None and self.cell_next is not None:
            # The first scene stands, and the first episode waits for the cell's choice of an
            # object in it (start_episode), as every later one does.
            clearing.show_first_scene(self.sim)
            self.runner.hold_until = time.monotonic()
        elif not params.lockstep:  # lockstep starts its first episode once the policy node is up
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
        results = self.runner.results
        if self.params.episodes > 0 and results:
            print(f"success rate: {sum(results)}/{len(results)}", flush=True)

    # ------------------------------------------------------------------ episodes (lock held)
    def start_episode(self, settle: float = 0.0) -> None:
        """Place a new object (seed + episode), hold the arm where the reset put it, and tell
        the policy node a new episode starts; with ``settle`` (s) > 0, tell it only after the
        arm held the new scene that long (the real-time loop calls :meth:`begin_episode`)."""
        runner = self.runner
        if not runner.next_start_keeps_the_arm and runner.episode > 0 and not self.params.lockstep:
            self._pause_policy_for_teleport()
        chosen = self._ask_cell_for_the_next() if runner.clearing is not None else None
        if chosen is None and runner.clearing is not None and self.cell_next is not None and runner.episode == 0 \
                and time.monotonic() - self.started < FIRST_CHOICE_WAIT:
            runner.hold_until = time.monotonic() + 0.5  # the camera and the detector are still starting: ask again
            return
        runner.place_next(settle, chosen)
        self.publish_object_and_goal()
        self.controller_command = None  # the controller's standing command applies anew
        if settle <= 0.0:
            self.begin_episode()

    def begin_episode(self) -> None:
        """Obey commands from now on and tell the policy node a new episode starts."""
        if self.reset_policy is None:
            self.runner.begin(positioning=False)
            if self.resume_after_teleport:
                threading.Thread(target=self._resume_policy_after_teleport, daemon=True).start()
            return
        if not self.params.lockstep:
            # A driver never stops publishing: the loop runs on while the policy node answers
            # (with its motion guard it answers once the arm stands at the start, which it can
            # only see in states the loop publishes). Until then its commands are obeyed but not
            # timed with go_to_start, and not obeyed after a teleport (as if the call had blocked).
            start = self.runner.begin(positioning=True)
            threading.Thread(target=self._reset_policy_then_start, args=(start,), daemon=True).start()
            return
        self.runner.begin(positioning=False)
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
        if command is None or self.runner.holding or command == self.controller_command:
            return
        self.controller_command = command
        arrived, width = command
        self.runner.take_gripper_command(width, arrived)

    def report_to_controller(self) -> None:
        """gripper_interface xmlrpc (lock held): what the fingers measure now, for the controller to
        read back; still moving while a command waits to be taken up."""
        states = self.sim.joint_states()
        arm = len(self.spec.joint_names)
        moving = len(self.runner.gripper_arriving) > 0 or any(abs(speed) > 1e-3 for speed in states.velocities[arm:])
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
        episode starts with the next command, unless another start came meanwhile."""
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
            self.runner.positioned(start)  # timed from the policy's first command

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
        record = self.runner.finish(verdict, sim_time, self.params.lockstep)
        # How long the simulated arm now ignores commands (a pause no real arm makes):
        # compare_run.py leaves it out of a recorded rehearsal.
        record["hold_s"] = self.params.pause_between_episodes + self.params.reset_settle_time
        for outcome in [record] + self.runner.extra_records:
            self.outcome_pub.publish(String(data=json.dumps(outcome)))
            if self.outcome_log is not None:
                with self.outcome_log.open("a") as log:
                    log.write(json.dumps(outcome) + "\n")
        rospy.loginfo(f"episode {record['episode']} (seed {record['seed']}): "
                      f"{'success' if record['success'] else 'failure (' + str(record['failure']) + ')'}"
                      f" after {verdict.steps} steps"
                      + (f"; knocked over: {', '.join(record['knocked'])}" if record.get("knocked") else ""))

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
            self.runner.take_arm_command(clamped.tolist(), None if self.params.lockstep else time.monotonic())
            self.new_command = True
            self.command_arrived.notify_all()

    def _on_gripper_command(self, message: Float64) -> None:
        width = float(message.data)
        if not np.isfinite(width):
            rospy.logerr_throttle(1.0, "sim_node: dropped non-finite gripper command")
            return
        with self.lock:
            self.runner.take_gripper_command(width, None if self.params.lockstep else time.monotonic())
            self.new_gripper_command = True
            self.command_arrived.notify_all()

    def _ask_cell_for_the_next(self) -> Optional[Tuple[float, float]]:
        """A clearing run (lock held): the cell's detector is told the last object is done and
        answers with the next one (``~cell_next_service``); where it stands (m, base_link), or
        None (no detector, no answer in ``~policy_call_timeout``, or none to choose: the rule's
        choice on the truth then stands)."""
        if self.cell_next is None:
            return None
        answers: List = []

        def ask() -> None:
            try:
                answers.append(self.cell_next())
            except (rospy.ServiceException, rospy.ROSException) as error:
                # Before the first episode the detector may still be starting: that is no news.
                log = rospy.logwarn_throttle if self.runner.episode > 0 else rospy.logdebug_throttle
                log(10.0, f"sim_node: no next object from {self.params.cell_next_service}: {error}")

        # The loop holds the lock: a detector that does not answer must not stall the arm's states.
        caller = threading.Thread(target=ask, daemon=True)
        caller.start()
        caller.join(self.params.policy_call_timeout)
        if not answers or not answers[0].success:
            return None
        position = answers[0].pose.position
        return (position.x, position.y)

    def _on_calibration(self, request) -> SetBoolResponse:
        """~calibration (std_srvs/SetBool), real time only. True: a calibration session: the cup
        is fixed in the closed gripper (config/calibration.yaml ``simulator.object_in_tcp``, as a
        person's hand-over would leave it), arm commands are obeyed, no episode is judged or
        reset. False: the cup is let go and a new episode starts."""
        from ..perception.hand_eye import load_calibration_settings

        if self.params.lockstep:
            return SetBoolResponse(success=False, message="calibration runs in real time only")
        with self.lock:
            changed = self.runner.calibrate(bool(request.data), load_calibration_settings().simulator.object_in_tcp)
            if changed and not request.data:
                self.start_episode()
        return SetBoolResponse(success=True, message=f"calibration {'on' if request.data else 'off'}")

    def _on_reset(self, _request) -> TriggerResponse:
        with self.lock:
            self.start_episode()
        return TriggerResponse(success=True, message=f"episode {self.runner.episode} started")

    # ------------------------------------------------------------------ outputs
    def publish_state(self, stamp: rospy.Time) -> None:
        """The joint state as the driver reports it; for the simulated camera, all joints and
        the object's true pose, stamped alike."""
        states = self.sim.joint_states()
        if self.truth_pub is not None:
            self.truth_pub.publish(joint_state_message(states, stamp))
        arm = len(self.spec.joint_names) if not self.params.publish_finger_joints else len(states.names)
        # The FAIRINO driver fills positions only: its velocities are all 0.0.
        velocities = states.velocities[:arm] if self.params.publish_velocities else (0.0,) * arm
        self.joint_pub.publish(joint_state_message(JointStates(states.names[:arm], states.positions[:arm], velocities),
                                                   stamp))
        if self.object_pub is not None:
            self.object_pub.publish(object_marker(self.sim.scene(), self.sim.object_pose(), stamp))
        if self.neighbours_pub is not None:
            self.neighbours_pub.publish(neighbour_markers(self.sim.neighbour_shapes, self.sim.neighbour_poses(), stamp,
                                                          self.spec.base_frame))

    def publish_markers(self, stamp: rospy.Time) -> None:
        """rviz: the table, the object, the tcp's path, the goal, and a scene's other objects."""
        markers = scene_markers(self.sim.scene(), self.sim.object_pose(), self.runner.tcp_path, stamp)
        if self.runner.clearing is not None:
            markers.markers += neighbour_markers(self.sim.neighbour_shapes, self.sim.neighbour_poses(), stamp,
                                                 self.spec.base_frame).markers
        self.marker_pub.publish(markers)

    def publish_object_and_goal(self) -> None:
        """The new episode's object shape (as the camera stand-in) and goal, latched."""
        scene = self.sim.scene()
        if self.shape_pub is not None:
            self.shape_pub.publish(primitive_from_shape(scene.object_description))
        if self.goal_pub is None or scene.goal is None:
            return
        x, y, yaw = scene.goal
        goal_in_base = matrix_from_quaternion((x, y, scene.table_top_height), quaternion_of_yaw(yaw))
        goal_in_frame = self.base_in_goal_frame @ goal_in_base
        message = PoseStamped()
        message.header.stamp = rospy.Time.now()
        message.header.frame_id = self.params.goal_frame
        position, orientation = message.pose.position, message.pose.orientation
        position.x, position.y, position.z = goal_in_frame[:3, 3]
        orientation.x, orientation.y, orientation.z, orientation.w = quaternion_from_matrix(goal_in_frame[:3, :3])
        self.goal_pub.publish(message)

    def camera_message(self, stamp: rospy.Time) -> PoseStamped:
        """The object's pose as the camera sees it: in ``~camera_frame``, with optional noise."""
        pose = self.sim.object_pose()
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
    node.sim.close()
    if not rospy.is_shutdown():
        node.end_of_run()
        rospy.signal_shutdown("all episodes done")
    return 0
