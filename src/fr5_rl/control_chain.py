"""The control chain between a policy's action and the plant, and back to its observation.

One object models what stands between the network and the arm on a real cell, as the ROS
chain has it: the command's latency (whole periods, the arm's and the gripper's), the policy
node's command shaping and motion guard, the gripper behind the bridge, the driver's timing
within a period (a command that arrives late, a joint state measured early, the servo's
response lag), and on the way back the camera's timing, sensor noise and velocities estimated
from positions. Which of them act in an episode is drawn by :func:`fr5_rl.draws.draw_episode`;
:meth:`ControlChain.begin` takes the draws.
"""
from __future__ import annotations

import copy
from collections import deque
from typing import Any, Dict, List, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np

from .config import RobotSpec
from .control import ACTION_SIZE, JointCommandShaper
from .draws import EpisodeDraws
from .env_config import EnvConfig
from .gripper import BridgedGripper
from .kinematics import ForwardKinematics
from .motion_guard import MotionGuard
from .observation import DelayedTarget, velocity_from_positions
from .sim.gripper_chain import EmulatedGripperChain
from .sim.plant import Measurement, Plant
from .sim.servo import FirstOrderResponse
from .transforms import matrix_from_quaternion, quaternion_z_axis


_new_tuple = tuple.__new__

class Sensed(NamedTuple):
    """What the policy is given of one moment, as the chain delivers it.

    :param joint_positions: rad, j1 .. j6 (noisy if the episode has noise).
    :param joint_velocities: rad/s, measured or estimated from positions.
    :param gripper_width: m, as the gripper (or the bridge) reports it.
    :param tcp_position: m, base_link. :param tcp_approach_axis: unit vector, base_link.
    :param object_position: m, base_link, as the camera's timing delivers it.
    :param tcp_jacobian: the chain's FK of the noisy joints with its Jacobian, or None.
    :param object_yaw: rad, base_link, as the camera's timing delivers it (held with the position
        while the hand hides the object, as the detector's tracker holds it).
    """

    joint_positions: Sequence[float]
    joint_velocities: Sequence[float]
    gripper_width: float
    tcp_position: Sequence[float]
    tcp_approach_axis: Sequence[float]
    object_position: Sequence[float]
    tcp_jacobian: Any
    object_yaw: float


# What ControlChain.save_state leaves out: built once, never changed by a period.
# The guard's ramp is state: it is saved (a copy), as the episode's bridge is.
_CONSTRUCTED = frozenset({"cfg", "robot", "control_dt", "shaper", "kinematics", "_bridge_model",
                          "_hidden_radius", "_velocities_from_positions", "_wants_jacobian"})


class ControlChain:
    """One period of the real chain, for the gym environment and every stand-in built on it.

    :param cfg: the environment's configuration (``randomisation``, ``observation``).
    :param robot: the arm.
    :param task: the task's name (the motion guard's start noise).
    :param control_dt: s per control period.
    :param shaper: the policy node's command shaping (the same object the environment resets).
    :param kinematics: the arm's FK (the tcp of noisy joints).
    :param wants_jacobian: the observation needs FK's Jacobian of noisy joints (the joint-step hint).
    """

    def __init__(self, cfg: EnvConfig, robot: RobotSpec, task: str, control_dt: float, shaper: JointCommandShaper,
                 kinematics: ForwardKinematics, wants_jacobian: bool) -> None:
        self.cfg, self.robot, self.control_dt, self.shaper, self.kinematics = cfg, robot, control_dt, shaper, kinematics
        self._wants_jacobian = wants_jacobian
        rnd = cfg.randomisation
        # randomisation.gripper_bridge_share: the gripper behind the bridge in some episodes.
        self._bridge_model: Union[BridgedGripper, EmulatedGripperChain, None] = None
        if rnd.enabled and rnd.gripper_bridge_share > 0.0:
            self._bridge_model = (EmulatedGripperChain.from_config(robot.max_opening_width)
                                  if rnd.gripper_bridge_emulation
                                  else BridgedGripper(cfg.deployed.bridge, robot.max_opening_width))
        # randomisation.guard_share: the policy node's motion guard limits some episodes' commands.
        self._guard: Optional[MotionGuard] = None
        if rnd.enabled and rnd.guard_share > 0.0:
            self._guard = MotionGuard(robot, cfg.deployed.guard, robot.home_joint_positions,
                                      cfg.task(task).start_joint_noise, control_dt)
        self._hidden_radius = rnd.target_hidden_radius or -1.0  # -1: never hidden
        self._hand_from_grasp = rnd.target_in_hand_from_grasp
        self._velocities_from_positions = cfg.observation.joint_velocity_source == "positions"
        # ---- per episode (begin)
        self.gripper_command_width = robot.max_opening_width  # what the fingers were last told (m)
        # What the agent last sent: what the observation shows. Behind latency the gripper is still
        # carrying out an older one; the ROS node, too, knows only what it sent.
        self.sent_gripper_width = self.gripper_command_width
        self.observed_joint_positions: Sequence[float] = robot.home_joint_positions.tolist()
        self._latency_steps = 0
        self._gripper_latency_steps: Optional[int] = None  # None: the arm's
        self._action_queue: deque = deque()
        self._noise_std = 0.0
        self._command_delay = self._observation_age = (0.0, 0.0)
        self._timing = False
        self._response: Optional[FirstOrderResponse] = None
        self._standing_command: Tuple[Sequence[float], float] = ((), 0.0)
        self._bridge: Union[BridgedGripper, EmulatedGripperChain, None] = None
        self._guard_on = False
        self._target: Optional[DelayedTarget] = None
        self._velocity_sample: Optional[Tuple[Sequence[float], float, List[float]]] = None
        # This episode sees the object through the camera's timing (sense then asks whether it is held).
        self.sees_through_camera = False
        self._substeps, self._physics_dt = 1, 0.0  # the episode's plant: physics steps per period, s each

    @property
    def bridge_periods(self) -> Optional[Tuple[float, float, float]]:
        """The bridged gripper's (call period, read period, zero debounce) in s, for the draws;
        None: no episode puts the gripper behind the bridge."""
        if self._bridge_model is None:
            return None
        timing = self._bridge_model.timing
        return timing.call_period, timing.read_period, timing.zero_debounce

    @property
    def bridge_model(self) -> Union[BridgedGripper, EmulatedGripperChain, None]:
        """The gripper behind the bridge as modelled (timing or the emulated chain), or None."""
        return self._bridge_model

    @property
    def bridge(self) -> Union[BridgedGripper, EmulatedGripperChain, None]:
        """This episode's bridged gripper, or None: driven directly."""
        return self._bridge

    @property
    def target(self) -> Optional[DelayedTarget]:
        """This episode's camera timing of the object, or None: seen as it is."""
        return self._target

    @property
    def guard(self) -> Optional[MotionGuard]:
        """The motion guard some episodes run (None: none does)."""
        return self._guard

    @property
    def guard_available(self) -> bool:
        """Some episodes run the motion guard (``randomisation.guard_share`` > 0)."""
        return self._guard is not None

    def begin(self, draws: EpisodeDraws, start: Sequence[float], physics_dt: float, substeps: int) -> None:
        """A new episode: this episode's chain as drawn, the arm standing at ``start`` (rad).

        :param physics_dt: the episode's physics step (s), the response's unit.
        :param substeps: the plant's physics steps per control period this episode.
        """
        self._latency_steps = draws.action_latency_steps
        self._gripper_latency_steps = draws.gripper_latency_steps
        self._noise_std = draws.observation_noise_std
        self._command_delay, self._observation_age = draws.command_delay_s, draws.observation_age_s
        self._response = None
        if draws.response_time_constants is not None:
            self._response = FirstOrderResponse(draws.response_time_constants, physics_dt,
                                                self.robot.home_joint_positions)
            self._response.reset(start)
        self._timing = draws.in_period_timing
        self._bridge = None
        if draws.bridge_phases is not None:
            self._bridge = self._bridge_model
            self._bridge.reset(self.robot.max_opening_width, *draws.bridge_phases)
        self._target = None
        if draws.target is not None:
            self._target = DelayedTarget(draws.target.latency, draws.target.frame_period, draws.target.phase,
                                         self._hand_from_grasp)
        self.sees_through_camera = self._target is not None
        self._substeps, self._physics_dt = substeps, physics_dt
        self._guard_on = draws.guard
        if self._guard_on:
            self._guard.restart()
        self.gripper_command_width = self.sent_gripper_width = self.robot.max_opening_width
        self._action_queue.clear()
        self._standing_command = (tuple(start), self.gripper_command_width)
        self._velocity_sample = None

    # ------------------------------------------------------------------ command path
    def command(self, action: List[float], now: float) -> Tuple[List[float], float]:
        """The policy's action (7 finite floats in [-1, 1]) through latency, shaping, the guard
        and the bridge, to what the plant is told this period.

        :param now: s since the episode's start, at the period's start.
        :return: arm targets (rad, j1 .. j6) and the gripper's opening width (m).
        """
        shaper = self.shaper
        self.sent_gripper_width = sent_width = shaper.gripper_width(action)
        applied = self._delayed(action)
        # Targets are offsets from the joint state the last observation saw (as on the robot,
        # where that is the newest /joint_states message, however old). Both lists hold finite
        # floats (the observation refuses anything else), so the shaper's checks are not repeated.
        targets = shaper.targets_from_floats(applied, self.observed_joint_positions)
        if self._guard_on:  # the ramp-in from the episode's start and the joint-limit margin, as deployed
            targets = self._guard.limit(targets, self.observed_joint_positions, now).tolist()
        width = sent_width if applied is action else shaper.gripper_width(applied)
        if self._bridge is not None:
            width = self._bridge.command(width, now)
        return targets, width

    def _delayed(self, action: List[float]) -> List[float]:
        """The action the plant gets this period: the arm ``_latency_steps`` behind, the gripper
        ``_gripper_latency_steps`` (None: the arm's). The queue keeps the newest, newest last."""
        arm = self._latency_steps
        gripper = arm if self._gripper_latency_steps is None else self._gripper_latency_steps
        if arm == gripper == 0:
            return action
        queue = self._action_queue
        queue.append(action)
        while len(queue) > max(arm, gripper) + 1:
            queue.popleft()
        # Until its first action arrives the arm holds and the gripper keeps its command.
        arm_part = queue[-1 - arm][:ACTION_SIZE - 1] if len(queue) > arm else [0.0] * (ACTION_SIZE - 1)
        gripper_part = (queue[-1 - gripper][ACTION_SIZE - 1] if len(queue) > gripper
                        else self.shaper.gripper_action(self.gripper_command_width))
        return [*arm_part, gripper_part]

    # ------------------------------------------------------------------ the period
    def run_period(self, plant: Plant, arm_targets: Sequence[float], gripper_width: float,
                   rng: np.random.Generator) -> Optional[Tuple[Measurement, float]]:
        """One control period of the plant with this episode's timing: the previous command
        stands for the first ``command_delay`` of the period (a driver's servo cycle, a late
        command), the driver's response lags the targets, and the joint state is measured
        ``observation_age`` before the period ends.

        :return: the measurement taken early and how long (s) before the period's end, or None
            when the observation is measured at its end.
        """
        if not self._timing:
            self.advance_period(plant, arm_targets, gripper_width)
            return None
        substeps, physics_dt = self._substeps, self._physics_dt
        delay = self._draw_substeps(rng, self._command_delay, physics_dt, substeps - 1)
        age = self._draw_substeps(rng, self._observation_age, physics_dt, substeps - 1)
        measured = None
        if self._response is not None:
            for substep in range(substeps):
                targets, width = self._standing_command if substep < delay else (arm_targets, gripper_width)
                plant.command(self._response.targets_for_step(targets), width, period=physics_dt)
                if substep == substeps - age and age:
                    measured = plant.measure()
                plant.step_physics()
        elif delay == 0 and age == 0:
            self.advance_period(plant, arm_targets, gripper_width)
        else:
            if delay:
                plant.command(*self._standing_command, period=delay * physics_dt)
            for substep in range(substeps):
                if substep == delay:
                    plant.command(arm_targets, gripper_width, period=(substeps - delay) * physics_dt)
                if substep == substeps - age:
                    measured = plant.measure()
                plant.step_physics()
        self.gripper_command_width = float(gripper_width)
        self._standing_command = (arm_targets, gripper_width)
        return (measured, age * physics_dt) if measured is not None else None

    def advance_period(self, plant: Plant, arm_targets: Sequence[float], gripper_width: float) -> None:
        """One control period with one command standing throughout (a lockstep driver)."""
        self.gripper_command_width = float(gripper_width)
        plant.command(arm_targets, self.gripper_command_width)
        plant.step_period()

    def advance_physics(self, plant: Plant, arm_targets: Sequence[float], gripper_width: float) -> None:
        """One physics step with the targets as they are (a real-time driver's own servo)."""
        self.gripper_command_width = float(gripper_width)
        plant.command(arm_targets, gripper_width, period=plant.physics_dt)
        plant.step_physics()

    @staticmethod
    def _draw_substeps(rng: np.random.Generator, seconds_range: Tuple[float, float], physics_dt: float,
                       most: int) -> int:
        """A duration drawn uniformly from ``seconds_range``, in whole physics steps."""
        low, high = seconds_range
        if high <= 0.0:
            return 0
        # numpy's uniform(low, high) is low + (high - low) * random(): the same draw, the same
        # bits, without its argument handling (two draws every step).
        seconds = low + (high - low) * rng.random()
        return min(int(round(seconds / physics_dt)), most)

    # ------------------------------------------------------------------ the way back
    def sense(self, measured: Measurement, tcp_axis: Optional[Sequence[float]], object_position: Sequence[float],
              tcp_to_object_distance: float, held: bool, sample_time: float, now: float,
              rng: np.random.Generator, object_yaw: float = 0.0, around: bool = False,
              read_back: Optional[float] = None) -> Sensed:
        """What the policy is given: the arm as ``measured`` (at ``sample_time``, s since the
        start), the object as the camera's timing shows it at ``now``.

        :param tcp_axis: the tcp's approach axis of ``measured`` where the caller has it; None:
            computed here.
        :param object_position: the object's true centre now (m, base_link).
        :param tcp_to_object_distance: m, now (the hand hides the object within a radius).
        :param held: the object is in the hand as the detector's tracker decides it (read only
            when :attr:`sees_through_camera`).
        :param object_yaw: the object's true yaw now (rad, base_link).
        :param around: the fingers are around the object as the tracker decides it, held or not
            (read only with ``randomisation.target_in_hand_from_grasp``).
        :param read_back: the bridge's read-back of the opening at ``sample_time`` (m), where the
            caller has already taken it (the episode, for the tracker's judgement); None: taken here.
        """
        q, velocities, width, tcp_position, tcp_quaternion = measured
        if tcp_axis is None:
            tcp_axis = quaternion_z_axis(tcp_quaternion)
        self.observed_joint_positions = q
        if self._bridge is not None:
            width = self._bridge.observe(width, sample_time) if read_back is None else read_back
        if self._target is not None:
            # The yaw travels with the position: a frame captured while the hand hides the object
            # shows the yaw last seen too (an object nudged then is carried at it, unless the pads
            # square it: the tracker's take into the hand, modelled by in-hand seeing the truth).
            tcp = None
            if self._hand_from_grasp and (held or around):
                tcp = (np.asarray(tcp_position, dtype=np.float64),
                       matrix_from_quaternion((0.0, 0.0, 0.0), tcp_quaternion)[:3, :3])
            *object_position, object_yaw = self._target.observe((*object_position, object_yaw), now, held,
                                                                tcp_to_object_distance <= self._hidden_radius,
                                                                tcp, around)
        tcp_jacobian = None
        if self._noise_std > 0.0:
            q = (np.asarray(q) + rng.normal(0.0, self._noise_std, 6)).tolist()
            object_position = (np.asarray(object_position) + rng.normal(0.0, self._noise_std, 3)).tolist()
            # The tcp pose follows the noisy joints, as FK of a noisy encoder reading would. The
            # joint-step hint needs the same chain of the same joints: computed once for both.
            if self._wants_jacobian:
                tcp_jacobian = self.kinematics.tcp_jacobian(q)
                tcp_position, tcp_axis = tcp_jacobian[0], tcp_jacobian[1]
            else:
                tcp_position, tcp_axis = self.kinematics.tcp_position_and_axis(q)
        if self._velocities_from_positions:
            velocities = self._estimate_velocities(q, sample_time)
        # tuple.__new__: the named tuple without its Python-level constructor (the step path).
        return _new_tuple(Sensed, (q, velocities, width, tcp_position, tcp_axis, object_position, tcp_jacobian,
                                   object_yaw))

    def _estimate_velocities(self, positions: Sequence[float], sample_time: float) -> List[float]:
        """Velocities from this sample and the last, as the policy node estimates them behind a
        driver that reports none; zeros at the start of an episode."""
        positions = [float(value) for value in positions]
        if self._velocity_sample is None:
            velocities = [0.0] * len(positions)
        else:
            previous, previous_time, previous_velocities = self._velocity_sample
            elapsed = sample_time - previous_time
            velocities = [velocity_from_positions(now, before, elapsed, velocity)
                          for now, before, velocity in zip(positions, previous, previous_velocities)]
        self._velocity_sample = (positions, sample_time, velocities)
        return velocities

    # ------------------------------------------------------------------ saved states
    def save_state(self) -> Dict[str, Any]:
        """Everything a period changes (queues, filters, the bridge's and camera's state)."""
        return {name: copy.deepcopy(value) for name, value in self.__dict__.items() if name not in _CONSTRUCTED}

    def restore_state(self, saved: Dict[str, Any]) -> None:
        """Back to :meth:`save_state`'s values (they stay saved)."""
        self.__dict__.update(copy.deepcopy(saved))
