"""The 50 Hz deployment step and its safety gate, free of ROS.

Every control period the policy node hands :class:`DeploymentStep` the newest inputs (joint
state, target position in ``base_link``, the clock) and gets back either a :class:`Command`
that passed the :class:`SafetyGate`, or a :class:`Hold` whose :class:`HoldReason` says why
nothing should be sent. On a hold the node publishes nothing, so the controller keeps its last
target. The step builds the observation and shapes the action with the same code the
environments use (:class:`~fr5_rl.observation.ObservationBuilder`,
:class:`~fr5_rl.control.JointCommandShaper`), so what runs on the robot is what was trained.
"""
from __future__ import annotations

import enum
import math
import time
from dataclasses import dataclass
from typing import Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from ..config import RobotSpec
from ..env_config import EnvConfig
from ..motion_guard import MotionGuard, MotionGuardSettings, StartPhase
from ..control import JointCommandShaper
from ..kinematics import ForwardKinematics, InverseKinematics
from ..objects import ObjectShape
from ..observation import TASK_BLOCKS, ActionHistory, ObservationBuilder, ObservationInputs, goal_features, object_features
from .bundle import ModelFilesError
from .joint_state import ArmJointState, Reading
from .policy import Policy


class HoldReason(enum.Enum):
    """Why a control period sends no command."""

    DISABLED = "disabled"
    NO_JOINT_STATE = "no joint state received yet"
    JOINT_STATE_INVALID = "joint state unusable"
    JOINT_STATE_STALE = "joint state stale"
    NO_TARGET = "no target received yet"
    TARGET_UNAVAILABLE = "target not transformable"
    TARGET_STALE = "target stale"
    TARGET_FROM_FUTURE = "target stamped in the future"
    TARGET_INVALID = "target invalid"
    TARGET_OUT_OF_WORKSPACE = "target outside the workspace"
    OBSERVATION_INVALID = "observation invalid"
    UNSAFE_COMMAND = "command failed the safety gate"
    FAR_FROM_START = "far from the training start"
    GRIPPER_FAULT = "the gripper reports a fault"
    NO_OBJECT_SHAPE = "no object shape received yet"
    OBJECT_SHAPE_INVALID = "object shape invalid"
    NO_GOAL = "no place goal received yet"
    GOAL_INVALID = "place goal unusable"


@dataclass(frozen=True)
class Hold:
    """Send nothing this period.

    :param reason: the kind of problem (compare these, not the text).
    :param detail: a human-readable explanation with the numbers.
    """

    reason: HoldReason
    detail: str

    def __str__(self) -> str:
        return f"{self.reason.value}: {self.detail}"


@dataclass(frozen=True)
class Command:
    """A checked command for one control period.

    :param arm_positions: joint position targets (rad), controller order ``j1`` … ``j6``.
    :param gripper_width: commanded opening width (m), 0 … max opening.
    :param target_in_base: the target position (m, ``base_link``) the policy acted on; None on
        the start move (no policy).
    :param inference_s: time the policy took (s).
    """

    arm_positions: Tuple[float, ...]
    gripper_width: float
    target_in_base: Optional[Tuple[float, float, float]]
    inference_s: float


@dataclass(frozen=True)
class StepInputs:
    """The newest inputs at one control period.

    :param now: current time (s) on the same monotonic clock as the readings' ``received``.
    :param joint_state: newest joint-state reading, None if none arrived yet.
    :param target: newest target reading, None if none yet: the object's position (m) and, for a
        policy that observes its yaw, its yaw (rad: the x axis of the object's own frame,
        :mod:`fr5_rl.objects`), in ``base_link``.
    :param stamp_now: current time (s) on the clock the messages are stamped with (ROS time),
        to judge the target's stamp; 0 to judge by arrival only.
    :param gripper_fault: what the gripper (its bridge) reports wrong, None when nothing.
    :param object_shape: the object's shape and size, for a policy that observes them (None: none
        received yet); a reading whose problem is set holds.
    :param goal: where to set the object down, for a task with a goal: (x, y, yaw) in ``base_link``
        (m, m, rad; the yaw of the object's own x axis there), None if none received yet.
    """

    now: float
    joint_state: Optional[Reading[ArmJointState]]
    target: Optional[Reading[Sequence[float]]]
    stamp_now: float = 0.0
    gripper_fault: Optional[str] = None
    object_shape: Optional[Reading[ObjectShape]] = None
    goal: Optional[Reading[Sequence[float]]] = None


def segment_distance(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> float:
    """Shortest distance (m) between the segments p0-p1 and q0-q1."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, f = float(d1 @ d1), float(d2 @ d2), float(d2 @ r)
    if a < 1e-12 and e < 1e-12:
        return float(np.linalg.norm(r))
    if a < 1e-12:
        s, t = 0.0, min(max(f / e, 0.0), 1.0)
    else:
        c = float(d1 @ r)
        if e < 1e-12:
            s, t = min(max(-c / a, 0.0), 1.0), 0.0
        else:
            b = float(d1 @ d2)
            denominator = a * e - b * b
            s = min(max((b * f - c * e) / denominator, 0.0), 1.0) if denominator > 1e-12 else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                s, t = min(max(-c / a, 0.0), 1.0), 0.0
            elif t > 1.0:
                s, t = min(max((b - c) / a, 0.0), 1.0), 1.0
    return float(np.linalg.norm((p0 + d1 * s) - (q0 + d2 * t)))


class SafetyZone:
    """Where a commanded configuration would put the arm: above the table, links apart.

    The links are capsules between the joint origins (forward kinematics shared with the
    environments), plus the gripper body below the flange; the tcp (between the fingertips) is a
    point. A configuration is refused when a capsule dips below the table top plus a margin,
    the tcp goes below its minimum height, or two links that are not neighbours in the chain
    come closer than a margin. Settings: ``env.yaml`` ``safety_zone``.

    :param robot: the robot's kinematics.
    :param env_cfg: the environment configuration (``table`` and ``safety_zone``).
    """

    LINKS = ("upperarm", "forearm", "wrist1", "wrist2", "gripper")
    # Pairs that are not neighbours in the chain (neighbours touch at their joint by design).
    PAIRS = (("upperarm", "wrist1"), ("upperarm", "wrist2"), ("upperarm", "gripper"), ("forearm", "gripper"))

    def __init__(self, robot: RobotSpec, env_cfg: EnvConfig) -> None:
        zone = env_cfg.safety_zone
        self.kinematics = ForwardKinematics(robot)
        self.table_top = env_cfg.table.top_height
        self.table_margin = zone.table_margin
        self.tcp_min_height = zone.tcp_min_height
        self.self_margin = zone.self_margin
        self.radii = {name: getattr(zone.link_radii, name) for name in self.LINKS}
        # Both from the wrist centre (the j6 origin): the gripper body reaches past the flange face.
        self.gripper_length = float(robot.flange_offset) + zone.gripper_length
        self.tcp_offset = float(robot.tcp_offset_from_wrist)

    def capsules(self, joint_positions: Sequence[float]) -> Mapping[str, Tuple[np.ndarray, np.ndarray]]:
        """Each link's segment (two points, m, base_link) for joint angles (rad)."""
        origins, flange_rotation = self.kinematics.joint_origins(np.asarray(joint_positions, dtype=np.float64))
        approach = flange_rotation[:, 2]
        return {"upperarm": (origins[1], origins[2]), "forearm": (origins[2], origins[3]),
                "wrist1": (origins[3], origins[4]), "wrist2": (origins[4], origins[5]),
                "gripper": (origins[5], origins[5] + approach * self.gripper_length),
                "tcp": (origins[5] + approach * self.tcp_offset,) * 2}

    def check(self, joint_positions: Sequence[float]) -> Optional[str]:
        """None when the configuration (rad) is inside the zone, else what it would hit."""
        capsules = self.capsules(joint_positions)
        tcp_height = capsules["tcp"][0][2] - self.table_top
        if tcp_height < self.tcp_min_height:
            return (f"the tcp would be {tcp_height * 1000:.0f} mm above the table "
                    f"(minimum {self.tcp_min_height * 1000:.0f} mm)")
        for name in self.LINKS:
            start, end = capsules[name]
            clearance = min(start[2], end[2]) - self.radii[name] - self.table_top
            if clearance < self.table_margin:
                return f"the {name} link would come {clearance * 1000:.0f} mm from the table (margin {self.table_margin * 1000:.0f} mm)"
        for first, second in self.PAIRS:
            gap = segment_distance(*capsules[first], *capsules[second]) - self.radii[first] - self.radii[second]
            if gap < self.self_margin:
                return f"the {first} and {second} links would come {gap * 1000:.0f} mm apart (margin {self.self_margin * 1000:.0f} mm)"
        return None


class SafetyGate:
    """The last check before a command leaves: nothing that fails it is ever sent.

    A command passes when it has exactly one finite value per joint, lies inside the FR5
    joint limits, is within one control period's velocity limit of the measured position, and,
    when a :class:`SafetyZone` is given, keeps the arm above the table and its links apart.

    :param robot: the robot's limits.
    :param control_dt: control period (s).
    :param zone: the safety zone the commanded configuration must stay in (None: not checked).
    """

    def __init__(self, robot: RobotSpec, control_dt: float, zone: Optional[SafetyZone] = None) -> None:
        self.zone = zone
        self.lower = robot.lower_limits
        self.upper = robot.upper_limits
        self.step_limit = robot.velocity_limits * control_dt + 1e-9

    def check(self, targets: Sequence[float], measured: Sequence[float]) -> Optional[str]:
        """None when ``targets`` (rad) are safe to send from ``measured`` (rad), else what fails."""
        targets, measured = np.asarray(targets, dtype=np.float64), np.asarray(measured, dtype=np.float64)
        if targets.shape != self.lower.shape:
            return f"{targets.size} joint targets, the arm has {self.lower.size}"
        if not np.isfinite(targets).all():
            return "joint targets contain NaN or inf"
        outside = np.flatnonzero((targets < self.lower) | (targets > self.upper))
        if outside.size:
            return f"joint j{outside[0] + 1} target {targets[outside[0]]:.3f} rad is outside its limits"
        steps = np.abs(targets - measured)
        too_fast = np.flatnonzero(steps > self.step_limit)
        if too_fast.size:
            joint = too_fast[0]
            return (f"joint j{joint + 1} would move {steps[joint]:.3f} rad in one period "
                    f"(limit {self.step_limit[joint]:.3f} rad)")
        return self.zone.check(targets) if self.zone is not None else None


class DeploymentStep:
    """One control period of a trained policy on the robot: inputs in, command or hold out.

    :param policy: the loaded policy.
    :param robot: the robot's numbers (limits, kinematics).
    :param env_cfg: the environment configuration the policy was trained with.
    :param joint_state_timeout: older joint states (s) hold the arm.
    :param target_timeout: older targets (s) hold the arm.
    :param new_target_jump: a target that moves further than this (m) between two periods is a
        new object: the action filter restarts, as at the start of an episode.
    :param target_workspace_margin: a target may lie this far (m) outside the training
        workspace box (``env.yaml`` ``workspace``) before the step holds.
    :param future_stamp_tolerance: a target stamped more than this (s) ahead of ``stamp_now``
        comes from a clock that cannot be trusted: hold.
    :param guard: the real arm's start move, ramp-in and joint-limit margin
        (:class:`~fr5_rl.motion_guard.MotionGuard`); None: none (as in training).
    :param stale_target_rise: on a stale target, the tcp rises straight up (its rotation kept)
        until it is this far (m) above the last target the policy acted on, then holds; 0: hold
        where it is. An object last seen standing on the table is let go of first (the fingers
        opened for ``stale_target_let_go``, the arm still); one last seen in the air stays in the
        grip. The arm hovering over an object hides it from the camera, and the detector's
        tracker drops a track hidden for longer than its ``hidden_timeout``: held there, nothing
        would ever show it again.
    :param stale_target_rise_speed: m/s of that rise.
    :param stale_target_let_go: s the fingers open, the arm still, before the rise from an object
        last seen standing.
    """

    # m above its resting height at which an object last seen still counts as standing: the
    # in-hand estimate of one just set down drifts by 1-2 cm.
    STANDING_MARGIN = 0.02

    def __init__(self, policy: Policy, robot: RobotSpec, env_cfg: EnvConfig, joint_state_timeout: float,
                 target_timeout: float, new_target_jump: float = 0.05, target_workspace_margin: float = 0.05,
                 future_stamp_tolerance: float = 0.05, guard: Optional[MotionGuardSettings] = None,
                 stale_target_rise: float = 0.0, stale_target_rise_speed: float = 0.1,
                 stale_target_let_go: float = 0.4) -> None:
        self.policy = policy
        self.control_dt = env_cfg.simulation.control_dt
        self.kinematics = ForwardKinematics(robot)
        include_lift, include_goal = TASK_BLOCKS[policy.task]
        # What the policy observes of the object besides its position: its shape, size and yaw
        # (observation.object_features), and where to set it down (a task with a goal).
        self.needs_shape = bool(env_cfg.observation.object_features)
        self.needs_goal = include_goal
        self.builder = ObservationBuilder(robot, env_cfg.observation, include_lift, include_goal)
        if self.builder.size != policy.observation_size:
            raise ModelFilesError(f"the policy takes {policy.observation_size} observation values; this fr5_rl "
                                  f"builds {self.builder.size} for {policy.task}: retrain it")
        self.shaper = JointCommandShaper(robot, env_cfg.action, self.control_dt)
        # The actions sent, for a policy that observes its previous ones (as in training).
        self.action_history = ActionHistory(self.builder.previous_actions)
        self.gate = SafetyGate(robot, self.control_dt, SafetyZone(robot, env_cfg))
        self.object_rest_z = env_cfg.object_rest_z()
        self.table_top = env_cfg.table.top_height
        self.joint_state_timeout = float(joint_state_timeout)
        self.target_timeout = float(target_timeout)
        self.new_target_jump = float(new_target_jump)
        margin = float(target_workspace_margin)
        self.target_low = np.asarray(env_cfg.workspace.low, dtype=np.float64) - margin
        self.target_high = np.asarray(env_cfg.workspace.high, dtype=np.float64) + margin
        # Goals are drawn in the placement region in training: one further out than the margin holds.
        self.goal_low = np.asarray(env_cfg.object.region_low, dtype=np.float64) - margin
        self.goal_high = np.asarray(env_cfg.object.region_high, dtype=np.float64) + margin
        self.future_stamp_tolerance = float(future_stamp_tolerance)
        self.guard = (MotionGuard(robot, guard, robot.home_joint_positions,
                                  env_cfg.task(policy.task).start_joint_noise, self.control_dt)
                      if guard is not None else None)
        self._enabled = True
        # The commanded width is part of the next observation whether or not it is sent, as in
        # training; the gripper starts open, as every episode does.
        self.max_opening_width = robot.max_opening_width
        self.gripper_command_width = robot.max_opening_width
        self.last_hold: Optional[Hold] = Hold(HoldReason.NO_JOINT_STATE, "starting")
        self._last_target: Optional[np.ndarray] = None
        if stale_target_rise < 0.0 or stale_target_rise_speed <= 0.0 or stale_target_let_go < 0.0:
            raise ValueError(f"stale_target_rise must be >= 0 m, its speed > 0 m/s and the let-go >= 0 s, got "
                             f"{stale_target_rise} m at {stale_target_rise_speed} m/s after {stale_target_let_go} s")
        self.stale_target_rise = float(stale_target_rise)
        self.rise_step = float(stale_target_rise_speed) * self.control_dt
        self._inverse = InverseKinematics(self.kinematics) if self.stale_target_rise > 0.0 else None
        # Why the arm is rising clear of a stale target's object (None: it is not).
        self.rising: Optional[str] = None
        self._last_rest_z = self.object_rest_z  # m: where the last target's object stands on the table
        self._opened_for = 0  # periods the fingers have been opening before the rise
        self.let_go_periods = int(round(stale_target_let_go / self.control_dt))

    def start_episode(self) -> None:
        """Start as an episode starts in training: no action-filter momentum, the gripper
        commanded open, no memory of the previous target. For a new task on the same arm (an
        operator placed a new object and homed the arm, or a simulator reset)."""
        self.start_episode_filters()
        if self.guard is not None:
            self.guard.restart()

    @property
    def enabled(self) -> bool:
        """Commands are sent; False holds (``~enable``). Enabling looks at the start pose again."""
        return self._enabled

    @enabled.setter
    def enabled(self, on: bool) -> None:
        if on and not self._enabled and self.guard is not None:
            self.guard.restart()
        self._enabled = bool(on)

    def __call__(self, inputs: StepInputs) -> Union[Command, Hold]:
        """The command for this period, or why to hold."""
        result = self._step(inputs)
        self.last_hold = result if isinstance(result, Hold) else None
        if self.last_hold is not None and self.guard is not None:
            self.guard.pause()
        return result

    def _step(self, inputs: StepInputs) -> Union[Command, Hold]:
        if not self.enabled:
            return Hold(HoldReason.DISABLED, "paused through ~enable")
        if inputs.gripper_fault is not None:
            return Hold(HoldReason.GRIPPER_FAULT, inputs.gripper_fault)
        joints = inputs.joint_state
        if joints is None:
            return Hold(HoldReason.NO_JOINT_STATE, "waiting for the first joint state")
        if joints.problem is not None:
            return Hold(HoldReason.JOINT_STATE_INVALID, joints.problem)
        age = inputs.now - joints.received
        if age > self.joint_state_timeout:
            return Hold(HoldReason.JOINT_STATE_STALE,
                        f"{age * 1000:.0f} ms old > {self.joint_state_timeout * 1000:.0f} ms")
        if self.guard is not None and self.guard.phase is not StartPhase.RUNNING:
            start = self._start_move(joints.value.positions, joints.value.velocities)
            if start is not None:
                return start
        target = inputs.target
        if target is None:
            return Hold(HoldReason.NO_TARGET, "waiting for the first target pose")
        if target.problem is not None:
            return Hold(HoldReason.TARGET_UNAVAILABLE, target.problem)
        age = inputs.now - target.received
        if target.stamp > 0.0 and inputs.stamp_now > 0.0:
            ahead = target.stamp - inputs.stamp_now
            if ahead > self.future_stamp_tolerance:
                return Hold(HoldReason.TARGET_FROM_FUTURE, f"stamped {ahead:.3f} s ahead of now "
                            f"(> {self.future_stamp_tolerance:g} s): check the camera computer's clock")
            age = max(age, -ahead)  # judged by capture time: a pipeline may deliver old detections
        if age > self.target_timeout:
            return self._rise_or_hold(joints.value.positions, f"{age:.2f} s old > {self.target_timeout:g} s",
                                      inputs.now)
        self._opened_for = 0
        if self.rising is not None:
            # The policy again, straight after a rise: as after a hold, without the rise's momentum.
            self.shaper.reset()
            self.action_history.reset()
            self.rising = None
        target_pose = np.asarray(target.value, dtype=np.float64).reshape(-1)
        if target_pose.shape not in ((3,), (4,)):
            return Hold(HoldReason.TARGET_INVALID, f"target needs a position (3 values) and maybe a yaw, got {target.value}")
        if not np.isfinite(target_pose).all():
            return Hold(HoldReason.TARGET_INVALID, f"target contains NaN or inf: {target.value}")
        if self.needs_shape and target_pose.shape != (4,):
            return Hold(HoldReason.TARGET_INVALID, "the policy observes the object's yaw; the target carries none")
        target_in_base = target_pose[:3]
        if np.any(target_in_base < self.target_low) or np.any(target_in_base > self.target_high):
            return Hold(HoldReason.TARGET_OUT_OF_WORKSPACE,
                        f"target at {np.round(target_in_base, 3).tolist()} m (base) lies outside "
                        f"{np.round(self.target_low, 3).tolist()}..{np.round(self.target_high, 3).tolist()} m")

        state = joints.value
        tcp_position, tcp_rotation = self.kinematics.tcp_pose(state.positions)
        object_block, goal_block, object_rest_z = self._object_and_goal(inputs, target_pose, tcp_rotation)
        if isinstance(object_block, Hold):
            return object_block

        # Resuming after a hold, or a new object: start like an episode starts, without the
        # action filter's old momentum and with no previous actions in the observation (the arm
        # stood still through the hold).
        new_object = (self._last_target is not None
                      and math.dist(target_in_base, self._last_target) > self.new_target_jump)
        if self.last_hold is not None or new_object:
            self.shaper.reset()
            self.action_history.reset()

        width = state.gripper_width if state.gripper_width is not None else self.gripper_command_width
        try:
            observation = self.builder.build(ObservationInputs(
                joint_positions=state.positions, joint_velocities=state.velocities, gripper_width=width,
                gripper_command_width=self.gripper_command_width, tcp_position=tcp_position,
                tcp_approach_axis=tcp_rotation[:, 2], object_position=target_in_base,
                object_lift=float(target_in_base[2] - object_rest_z),
                previous_actions=self.action_history.values(), object_features=object_block, goal=goal_block))
        except ValueError as error:
            return Hold(HoldReason.OBSERVATION_INVALID, str(error))
        self._last_target, self._last_rest_z = target_in_base, object_rest_z
        started = time.perf_counter()
        action = self.policy.act(observation)
        inference = time.perf_counter() - started
        targets = self.shaper.arm_targets(action, state.positions)
        if self.guard is not None:
            targets = self.guard.limit(targets, state.positions, inputs.now)
        problem = self.gate.check(targets, state.positions)
        if problem is not None:
            return Hold(HoldReason.UNSAFE_COMMAND, problem)
        self.gripper_command_width = self.shaper.gripper_width(action)
        self.action_history.push(action)
        return Command(tuple(targets.tolist()), self.gripper_command_width,
                       tuple(target_in_base.tolist()), inference)

    def _rise_or_hold(self, measured: np.ndarray, stale: str, now: float) -> Union[Command, Hold]:
        """On a stale target: one period of the rise clear of the last target (``stale_target_rise``),
        or the hold once risen, or at once when there is no rise or no target acted on yet."""
        if self.stale_target_rise <= 0.0 or self._last_target is None:
            self.rising = None
            return Hold(HoldReason.TARGET_STALE, stale)
        # Last seen standing on the table, the object is not carried (the tracker publishes one in
        # the hand without the camera): the fingers let go of it where it stands, the arm still,
        # before the arm rises. Risen with them closed, they carried a box they half held up
        # into the air, out of the camera's sight for good (the rehearsal, stop 64). Last seen in
        # the air, it is carried: the grip stays.
        if float(self._last_target[2]) <= self._last_rest_z + self.STANDING_MARGIN:
            self.gripper_command_width = self.max_opening_width
            letting_go = self._opened_for < self.let_go_periods
        else:
            letting_go = False
        if letting_go:
            self._opened_for += 1
            targets = np.asarray(measured, dtype=np.float64)
            why = "letting go of the object where it stands, then rising clear"
        else:
            tcp_position, tcp_rotation = self.kinematics.tcp_pose(measured)
            climb = min(self.rise_step, float(self._last_target[2]) + self.stale_target_rise - float(tcp_position[2]))
            if climb <= 1e-4:
                self.rising = None
                return Hold(HoldReason.TARGET_STALE, f"{stale}; risen {self.stale_target_rise:g} m above where the "
                                                     "object was last seen, waiting for the camera to find it")
            wanted = np.asarray(tcp_position, dtype=np.float64) + np.array([0.0, 0.0, climb])
            targets, _ = self._inverse.solve(measured, wanted.tolist(), np.asarray(tcp_rotation).ravel().tolist())
            targets = np.asarray(targets, dtype=np.float64)
            why = "rising clear of where the object was last seen, so that the camera sees it"
        # Through the guard and the gate as every command is.
        if self.guard is not None:
            targets = self.guard.limit(targets, measured, now)
        problem = self.gate.check(targets, measured)
        if problem is not None:
            self.rising = None
            return Hold(HoldReason.TARGET_STALE, f"{stale}; cannot rise clear: {problem}")
        self.rising = f"target stale ({stale}): {why}"
        return Command(tuple(targets.tolist()), self.gripper_command_width, None, 0.0)

    def _object_and_goal(self, inputs: StepInputs, target_pose: np.ndarray, tcp_rotation: np.ndarray):
        """The observation's object block (shape, size, yaw), its goal block, each empty where the
        policy observes none, and the height (m, base_link) of the object's centre at rest on the
        table (what its lift is measured from: the configured object's, else the shape's); or the
        :class:`Hold` for a missing or unusable input first."""
        if not (self.needs_shape or self.needs_goal):
            return (), (), self.object_rest_z
        reading = inputs.object_shape
        if reading is None:
            return Hold(HoldReason.NO_OBJECT_SHAPE, "waiting for the object's shape and size"), (), 0.0
        if reading.problem is not None or reading.value is None:
            return Hold(HoldReason.OBJECT_SHAPE_INVALID, reading.problem or "no value"), (), 0.0
        shape = reading.value
        rest_z = self.table_top + shape.size[2] / 2.0
        object_yaw = float(target_pose[3]) if target_pose.shape == (4,) else 0.0
        object_block: Sequence[float] = ()
        if self.needs_shape:
            gripper_yaw = math.atan2(tcp_rotation[1, 0], tcp_rotation[0, 0])  # the tcp's x axis, as yaw_of
            object_block = object_features(shape, object_yaw, gripper_yaw)
        if not self.needs_goal:
            return object_block, (), rest_z
        goal = inputs.goal
        if goal is None:
            return Hold(HoldReason.NO_GOAL, "waiting for a place goal"), (), 0.0
        if goal.problem is not None:
            return Hold(HoldReason.GOAL_INVALID, goal.problem), (), 0.0
        values = np.asarray(goal.value, dtype=np.float64).reshape(-1)
        if values.shape != (3,) or not np.isfinite(values).all():
            return Hold(HoldReason.GOAL_INVALID, f"a goal is x, y (m) and yaw (rad), finite; got {goal.value}"), (), 0.0
        if np.any(values[:2] < self.goal_low) or np.any(values[:2] > self.goal_high):
            return Hold(HoldReason.GOAL_INVALID,
                        f"goal at {np.round(values[:2], 3).tolist()} m (base) lies outside the placement region "
                        f"{np.round(self.goal_low, 3).tolist()}..{np.round(self.goal_high, 3).tolist()} m"), (), 0.0
        return object_block, goal_features(shape, target_pose[:3], object_yaw, values), rest_z

    def _start_move(self, measured: np.ndarray, velocities: Optional[np.ndarray]) -> Optional[Union[Command, Hold]]:
        """One period of the slow move into the training start distribution, a refusal, or
        None once the policy may take over (then it starts as a training episode does)."""
        targets, refusal = self.guard.start_move(measured, velocities)
        if refusal is not None:
            return Hold(HoldReason.FAR_FROM_START, refusal)
        if targets is None:
            self.start_episode_filters()
            return None
        problem = self.gate.check(targets, measured)
        if problem is not None:
            return Hold(HoldReason.UNSAFE_COMMAND, f"start move: {problem}")
        return Command(tuple(targets.tolist()), self.max_opening_width, None, 0.0)

    def start_episode_filters(self) -> None:
        """The policy's memory as at a training episode's start (the guard left as it is)."""
        self.shaper.reset()
        self.action_history.reset()
        self.gripper_command_width = self.max_opening_width
        self._last_target = None
        self.rising = None
