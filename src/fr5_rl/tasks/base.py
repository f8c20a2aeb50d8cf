"""What every task shares: the state it judges, its outcome, the shaped reward."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Dict, Mapping, NamedTuple, Optional, Sequence, Tuple, Type

import numpy as np

from ..env_config import EnvConfig, RandomisationConfig
from ..objects import distance_to_upright_object
from ..transforms import quaternion_z_axis

if TYPE_CHECKING:
    from ..draws import EpisodeDraws
    from ..objects import ObjectShape


@dataclass
class TaskState:
    """Everything a task needs to judge one control step (base_link frame, SI units).

    Vectors are plain sequences of floats (lists or tuples, as the simulator returns them):
    the environments build one of these every step.
    """

    joint_positions: Sequence[float]  # (6,) rad, measured, controller order
    joint_velocities: Sequence[float]  # (6,) rad/s
    tcp_position: Sequence[float]  # (3,) m
    tcp_approach_axis: Sequence[float]  # (3,) unit vector: the tcp z axis (gripper pointing direction)
    gripper_width: float  # m, measured opening
    tcp_to_object_distance: float  # m, tcp to object centre
    object_position: Sequence[float]  # (3,) m, centre
    object_up_axis: Sequence[float]  # (3,) object's own z axis in base_link
    object_start_position: Sequence[float]  # (3,) m, where it was placed at reset
    robot_table_contact: bool  # any robot link touches the table
    arm_object_contact: bool  # a robot link other than the finger pads touches the object
    fingers_object_contact: int  # how many finger pads touch the object (0, 1, 2)
    tcp_in_workspace: bool
    object_quaternion: Sequence[float] = (0.0, 0.0, 0.0, 1.0)  # (x, y, z, w) of the object in base_link


@dataclass
class TaskOutcome:
    """A task's verdict on one step."""

    success: bool
    failure: Optional[str]  # None, or why the episode failed
    terms: Dict[str, float] = field(default_factory=dict)  # shaping terms, unweighted


class EpisodeVerdict(NamedTuple):
    """How one control period left the episode (:meth:`fr5_rl.episode.Episode.judge_period`).

    :param success: the task's success test passed this period.
    :param failure: why the episode failed (the task's reason, e.g. ``"collision"``, or
        ``"timeout"`` when the step limit ended it), else None.
    :param terminated: the episode ended by success or a task failure (gymnasium's
        ``terminated``).
    :param truncated: the step limit ended it first (gymnasium's ``truncated``; ``failure``
        is then ``"timeout"``).
    :param steps: control periods judged since the reset, this one included.
    :param outcome: the task's own verdict, with the unweighted shaping terms the reward
        is made of (its ``failure`` never says ``"timeout"``).
    """

    success: bool
    failure: Optional[str]
    terminated: bool
    truncated: bool
    steps: int
    outcome: TaskOutcome

    @property
    def ended(self) -> bool:
        """The episode is over (``terminated or truncated``)."""
        return self.terminated or self.truncated

    @property
    def terms(self) -> Dict[str, float]:
        """The task's unweighted shaping terms of this period, by name."""
        return self.outcome.terms


def task_state_from(measured, object_pose, contacts, object_start: Sequence[float],
                    workspace: Tuple[Sequence[float], Sequence[float]]) -> TaskState:
    """The state a task judges, from the plant's reads of one moment.

    :param measured: the arm (:class:`fr5_rl.sim.plant.Measurement`).
    :param object_pose: the object (:class:`fr5_rl.sim.plant.Pose`, base_link).
    :param contacts: what the robot touches (:class:`fr5_rl.sim.plant.Contacts`).
    :param object_start: where the object was placed (m, base_link).
    :param workspace: the tcp's allowed box (low, high), m, base_link.
    """
    q, qd, width, tcp_position, tcp_quaternion = measured
    object_position, object_quaternion = object_pose[0], object_pose[1]
    x, y, z = tcp_position
    (x_low, y_low, z_low), (x_high, y_high, z_high) = workspace
    return TaskState(
        joint_positions=q, joint_velocities=qd, tcp_position=tcp_position,
        tcp_approach_axis=quaternion_z_axis(tcp_quaternion), gripper_width=width,
        tcp_to_object_distance=math.dist(object_position, tcp_position),
        object_position=object_position, object_up_axis=quaternion_z_axis(object_quaternion),
        object_start_position=object_start, robot_table_contact=contacts.table,
        arm_object_contact=contacts.arm_object, fingers_object_contact=contacts.finger_pads,
        tcp_in_workspace=x_low <= x <= x_high and y_low <= y <= y_high and z_low <= z <= z_high,
        object_quaternion=object_quaternion,
    )


def held_as_the_camera_sees(state: TaskState, object_width: float, object_rest_z: float,
                            rnd: RandomisationConfig, object_half_height: float = 0.0) -> bool:
    """The object is in the hand as the detector's tracker decides it (then it is published in
    the tcp frame, without the camera's delay): the fingers closed to about the object's width,
    the tcp near it (its axis, from its bottom to its top), the object lifted off its resting
    height (``randomisation.target_in_hand_*``, the tracker's thresholds).

    :param object_width: m across the object where the fingers close on it.
    :param object_rest_z: z (m, base_link) of its centre standing on the table.
    :param object_half_height: m from its centre to its top (0: near its centre).
    """
    return (state.object_position[2] > object_rest_z + rnd.target_in_hand_lift
            and fingers_around_as_the_camera_sees(state, object_width, rnd, object_half_height))


def fingers_around_as_the_camera_sees(state: TaskState, object_width: float, rnd: RandomisationConfig,
                                      object_half_height: float = 0.0) -> bool:
    """The fingers are around the object as the detector's tracker decides it, lifted or not:
    closed to about its width, the tcp near it (see :func:`held_as_the_camera_sees`)."""
    return (state.gripper_width <= object_width + rnd.target_in_hand_width_margin
            and distance_to_upright_object(state.tcp_position, state.object_position, object_half_height)
            <= rnd.target_in_hand_radius)


def approach_angle(tcp_approach_axis: Sequence[float]) -> float:
    """Angle (rad) between the tcp z axis (approach direction, unit vector) and straight down (-z)."""
    return math.acos(min(max(-float(tcp_approach_axis[2]), -1.0), 1.0))


TASKS: Dict[str, Type["Task"]] = {}  # every task by its name, filled as each module defines its class


class Task:
    """Base class: shaping terms, success and failure tests.

    A new task is one module of :mod:`fr5_rl.tasks`: a subclass with its own ``name`` (it
    registers itself in :data:`TASKS`; the package imports every module) that implements
    :meth:`terms`, :meth:`judge` and may extend :meth:`reset`. Its settings are
    ``config/env.yaml``'s section of that name.
    """

    name = "task"
    include_lift = False  # the observation carries the object's lift
    include_goal = False  # the observation carries the goal (a task with a goal draws one)

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        if "name" not in cls.__dict__:
            return  # a base for tasks (ObjectTask), not a task
        if cls.name in TASKS and TASKS[cls.name] is not cls:
            raise TypeError(f"two tasks are named {cls.name!r}: {TASKS[cls.name].__name__} and {cls.__name__}")
        TASKS[cls.name] = cls

    def __init__(self, cfg: EnvConfig, max_opening_width: float) -> None:
        self.max_steps = cfg.task(self.name).max_steps
        self.max_opening_width = max_opening_width
        reward = cfg.reward
        self.weights = dataclasses.asdict(reward.weights)
        self.distance_scale = reward.distance_scale
        self.orientation_scale = reward.orientation_scale
        self.potential_gain = reward.potential_gain
        self.success_bonus = reward.success_bonus
        self.collision_penalty = reward.collision_penalty
        self.failure_penalty = reward.failure_penalty
        self.action_penalty = reward.action_penalty
        self.sparse = reward.mode == "sparse"
        self._previous_potential: Optional[float] = None

    def reset(self) -> None:
        """Start of an episode."""
        self._previous_potential = None

    def start(self, draws: "EpisodeDraws", shape: "ObjectShape") -> None:
        """The episode as drawn (its goal, if the task has one) and the object placed, after
        :meth:`reset` and before the first state is judged."""

    def terms(self, state: TaskState) -> Dict[str, float]:  # pragma: no cover - abstract
        raise NotImplementedError

    def judge(self, state: TaskState, control_dt: float) -> TaskOutcome:  # pragma: no cover
        raise NotImplementedError

    def reward(self, outcome: TaskOutcome, action: Sequence[float]) -> Dict[str, float]:
        """Reward of one step, returned as its named parts (their sum is the reward).

        Dense mode pays progress in the weighted shaping potential (potential-based shaping:
        it cannot be farmed by dawdling or ended early by crashing), plus the success bonus,
        minus the collision penalty, the penalty of the task's other failures and a small
        action-magnitude cost. Sparse mode pays only the bonus and the penalties.
        """
        success = self.success_bonus if outcome.success else 0.0
        collision = -self.collision_penalty if outcome.failure == "collision" else 0.0
        failure = -self.failure_penalty if outcome.failure not in (None, "collision") else 0.0
        if self.sparse:
            return {"success": success, "collision": collision, "failure": failure, "progress": 0.0, "action": 0.0}
        potential = self.potential(outcome.terms)
        previous = potential if self._previous_potential is None else self._previous_potential
        self._previous_potential = potential
        return {"success": success, "collision": collision, "failure": failure,
                "progress": self.potential_gain * (potential - previous),
                "action": -self.action_penalty * sum([value * value for value in action])}

    def potential(self, terms: Mapping[str, float]) -> float:
        """The shaping potential: the weighted sum of the terms."""
        weights, total = self.weights, 0.0
        for name, value in terms.items():
            total += weights[name] * value
        return total

    def prime(self, state: TaskState) -> None:
        """Record the potential of the reset state, so the first step pays its own progress."""
        self._previous_potential = self.potential(self.terms(state))

    @staticmethod
    def common_failure(state: TaskState) -> Optional[str]:
        """Failures every task shares: arm/palm collisions and leaving the workspace."""
        if state.robot_table_contact or state.arm_object_contact:
            return "collision"
        if not state.tcp_in_workspace:
            return "left_workspace"
        return None

    # Shared shaping terms -------------------------------------------------------------
    def approach_term(self, state: TaskState) -> float:
        """-distance(tcp, object centre) / distance_scale."""
        return -state.tcp_to_object_distance / self.distance_scale

    def orientation_term(self, state: TaskState) -> float:
        """-(angle between tcp z and straight down) / orientation_scale.

        Linear in the angle rather than the seed's cosine: a cosine is flat near zero tilt and
        gives no push to correct the last 10-20 degrees, which is exactly what success needs.
        """
        return -approach_angle(state.tcp_approach_axis) / self.orientation_scale

    def gripper_term(self, state: TaskState, wanted_width: float) -> float:
        """-|measured width - wanted width| / max opening width."""
        return -abs(state.gripper_width - wanted_width) / self.max_opening_width


class ObjectTask(Task):
    """A task that handles the object: besides the common failures, it fails when the object is
    knocked over or pushed out of reach.

    :param knocked_over_angle_deg: tilt beyond which the object counts as knocked over.
    :param out_of_reach_margin: m beyond the placement region where the object is out of reach.
    """

    def __init__(self, cfg: EnvConfig, max_opening_width: float, knocked_over_angle_deg: float,
                 out_of_reach_margin: float) -> None:
        super().__init__(cfg, max_opening_width)
        self.max_tilt_cos = float(np.cos(np.deg2rad(knocked_over_angle_deg)))
        self.region_low = [v - out_of_reach_margin for v in cfg.object.region_low]
        self.region_high = [v + out_of_reach_margin for v in cfg.object.region_high]

    def handling_failure(self, state: TaskState) -> Optional[str]:
        """Why the episode failed (a collision, the workspace left, the object knocked over or out
        of reach), or None."""
        failure = self.common_failure(state)
        if failure is not None:
            return failure
        if float(state.object_up_axis[2]) < self.max_tilt_cos:
            return "object_knocked_over"
        x, y = state.object_position[0], state.object_position[1]
        (x_low, y_low), (x_high, y_high) = self.region_low, self.region_high
        if not (x_low <= x <= x_high and y_low <= y <= y_high):
            return "object_out_of_reach"
        return None
