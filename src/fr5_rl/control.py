"""From policy action to safe joint commands: the one scaling used in training and on the robot.

Action (7,) in [-1, 1]: six arm values and one gripper command mapped to an opening width in
[0, max opening width] (m). The arm's six are, by ``action.space``:

- ``joint``: joint position increments, scaled by ``action.max_joint_step`` (rad per control
  step, checked at load time against the arm's velocity limits);
- ``tcp``: a step of the tcp, pointing straight down: its translation in base_link (values 0-2,
  ``max_tcp_translation_step`` m) and its turn about the vertical (value 5,
  ``max_tcp_rotation_step`` rad; values 3 and 4 are not used), which the arm's inverse kinematics
  turns into the joint increment that makes it (in ``max_joint_step`` units, the largest no more
  than 1, the direction kept). What a policy then has to learn does not depend on the arm's
  geometry.

Either way the same low-pass, rate limit and joint-limit clamp follow. The gripper's value is an
opening width (``action.gripper: width``) or, with ``open_close``, open (above 0) or closed.
"""
from __future__ import annotations

import math
from typing import List, Sequence

import numpy as np

from .config import RobotSpec
from .env_config import ActionConfig
from .kinematics import ForwardKinematics, InverseKinematics

ACTION_SIZE = 7


def finite_values(values: Sequence[float], size: int, what: str) -> List[float]:
    """``values`` as a list of ``size`` finite Python floats.

    Raises ValueError, naming ``what``, for anything else: a wrong shape, something that is
    not a number, NaN or inf (overflowing input too). A list of floats passes without a copy.
    """
    if type(values) is not list:
        if type(values) is np.ndarray and values.dtype.kind == "f" and values.shape == (size,):
            values = values.tolist()
        else:  # anything else: let numpy check the shape and convert once
            try:
                array = np.asarray(values, dtype=np.float64)
            except (TypeError, ValueError) as error:
                raise ValueError(f"{what} must be {size} numbers: {error}") from None
            if array.shape != (size,):
                raise ValueError(f"{what} must have shape ({size},), got {array.shape}")
            values = array.tolist()
    elif len(values) != size:
        raise ValueError(f"{what} must have {size} values, got {len(values)}")
    try:
        finite = math.isfinite(sum(values))  # one sum is finite exactly when every term is
    except TypeError:  # a list holding something other than numbers
        raise ValueError(f"{what} must be {size} numbers") from None
    if not finite:
        raise ValueError(f"{what} contains NaN or inf")
    return values


def pointing_down(yaw: float) -> List[float]:
    """The tcp rotation (9 floats, row-major, base_link) with its approach axis (z) straight down
    and its x axis at ``yaw`` (rad) about base_link z."""
    cosine, sine = math.cos(yaw), math.sin(yaw)
    return [cosine, sine, 0.0, sine, -cosine, 0.0, 0.0, 0.0, -1.0]


def yaw_of_rotation(rotation: Sequence[float]) -> float:
    """The yaw (rad, about base_link z) of a tcp rotation's x axis (9 floats, row-major)."""
    return math.atan2(rotation[3], rotation[0])


class JointCommandShaper:
    """Scale, low-pass, rate-limit and clamp actions into joint position targets.

    Increments are applied to the *measured* joint positions, so a lagging or blocked arm
    never accumulates a runaway target. Every target it returns is finite, inside the FR5
    joint limits, and within ``velocity_limit * control_dt`` of the measured position.

    The arithmetic runs on plain floats: for six joints that is several times faster than
    numpy's per-call overhead, and it runs in every simulated step.
    """

    def __init__(self, robot: RobotSpec, action_cfg: ActionConfig, control_dt: float) -> None:
        self._max_step = action_cfg.max_joint_step
        self._alpha = action_cfg.smoothing_alpha
        self._n_joints = len(robot.joint_names)
        self._step_limit = (robot.velocity_limits * float(control_dt)).tolist()
        self._lower, self._upper = robot.lower_limits.tolist(), robot.upper_limits.tolist()
        self._max_width = robot.max_opening_width
        self._filtered_step = [0.0] * self._n_joints
        self._tcp_space = action_cfg.space == "tcp"
        # The gripper told only to open or to close, as the scripted expert does: a learner's
        # half-open command (0.6 of 80 mm) went on squeezing a 69 mm box it meant to let go of.
        self._open_close = action_cfg.gripper == "open_close"
        if self._tcp_space:
            self._translation_step = action_cfg.max_tcp_translation_step
            self._rotation_step = action_cfg.max_tcp_rotation_step
            self._kinematics = ForwardKinematics(robot)
            self._inverse = InverseKinematics(self._kinematics)

    def reset(self) -> None:
        """Forget the low-pass filter state (start of an episode, or after a hold)."""
        self._filtered_step = [0.0] * self._n_joints

    def arm_targets(self, action: Sequence[float], measured_joint_positions: Sequence[float]) -> np.ndarray:
        """Joint position targets (rad, controller order) for the next control period.

        Raises ValueError for an action that is not 7 finite values or measured joint
        positions that are not 6 finite values.
        """
        return np.array(self.arm_target_list(action, measured_joint_positions))

    def arm_target_list(self, action: Sequence[float], measured_joint_positions: Sequence[float]) -> List[float]:
        """:meth:`arm_targets` as a list of floats (what PyBullet and ROS messages take)."""
        return self.targets_from_floats(
            finite_values(action, ACTION_SIZE, "the action"),
            finite_values(measured_joint_positions, self._n_joints, "the measured joint positions"),
        )

    def targets_from_floats(self, action: List[float], measured_joint_positions: List[float]) -> List[float]:
        """:meth:`arm_target_list` without the input checks, for inputs known to be lists of
        finite floats of the right lengths (the environments' step, which checked them)."""
        measured = measured_joint_positions
        if self._tcp_space:
            action = self.joint_action_from_tcp(action, measured)
        gain, keep = self._alpha * self._max_step, 1.0 - self._alpha
        filtered, targets = [], []
        # Conditional expressions rather than min/max calls: this loop runs in every step.
        for value, previous, limit, lower, upper, position in zip(
                action, self._filtered_step, self._step_limit, self._lower, self._upper, measured):
            value = 1.0 if value > 1.0 else (-1.0 if value < -1.0 else value)
            step = gain * value + keep * previous
            step = limit if step > limit else (-limit if step < -limit else step)
            filtered.append(step)
            target = position + step
            targets.append(upper if target > upper else (lower if target < lower else target))
        self._filtered_step = filtered
        return targets

    def joint_action_from_tcp(self, action: List[float], measured_joint_positions: List[float]) -> List[float]:
        """The joint-space action (seven values, ``max_joint_step`` units) that makes the tcp step
        ``action`` asks for (``space: tcp``) from the measured joints; the gripper's value as given.

        The tcp pose wanted: the measured position moved by the clipped translation (values 0-2,
        base_link), and the approach axis straight down with the hand's yaw turned by value 5
        (about base_link z). Values 3 and 4 are not used: no policy tilts the hand, and one that
        had to hold the tilt at zero itself let its small errors add up. The inverse kinematics
        solves for that pose from the measured joints. A step the joints cannot make within one
        ``max_joint_step`` is shrunk whole, so the tcp keeps its direction (near a singular pose,
        it slows).
        """
        clipped = [1.0 if value > 1.0 else (-1.0 if value < -1.0 else value) for value in action[:6]]
        position, rotation, _ = self._kinematics.tcp_pose_and_jacobian(measured_joint_positions)
        yaw = yaw_of_rotation(rotation)
        delta = self._joint_step_for(clipped, measured_joint_positions, position, yaw)
        largest = max(abs(value) for value in delta)
        if largest > 1.0 and math.isfinite(largest):
            # Solve again for the tcp step shrunk by as much: the joints' step is not linear in
            # the tcp's, so scaling the first answer would bend the path (by 4 mm in 17 mm).
            delta = self._joint_step_for([value / largest for value in clipped], measured_joint_positions,
                                         position, yaw)
            largest = max(abs(value) for value in delta)
        if not math.isfinite(largest):  # a solve that diverged: no arm motion
            delta, largest = [0.0] * len(delta), 0.0
        scale = 1.0 / largest if largest > 1.0 else 1.0
        return [value * scale for value in delta] + [action[ACTION_SIZE - 1]]

    def _joint_step_for(self, tcp_step: List[float], measured_joint_positions: List[float],
                        position: List[float], yaw: float) -> List[float]:
        """The joint increment (``max_joint_step`` units) that moves the tcp from ``position`` (m,
        base_link) by the translation of ``tcp_step`` (six values in [-1, 1]) and points it
        straight down at ``yaw`` (rad) turned by its value 5."""
        wanted_position = [p + self._translation_step * v for p, v in zip(position, tcp_step[:3])]
        wanted_rotation = pointing_down(yaw + self._rotation_step * tcp_step[5])
        joints, _ = self._inverse.solve(measured_joint_positions, wanted_position, wanted_rotation,
                                        max_iterations=4, tolerance=1e-6)
        return [(wanted - angle) / self._max_step for wanted, angle in zip(joints, measured_joint_positions)]

    def gripper_width(self, action: Sequence[float]) -> float:
        """Commanded opening width (m) from the action's last component (-1 closed, +1 open; with
        ``action.gripper: open_close``, open above 0 and closed otherwise)."""
        value = float(action[ACTION_SIZE - 1])
        if not math.isfinite(value):
            raise ValueError("gripper action is NaN or inf")
        if self._open_close:
            return self._max_width if value > 0.0 else 0.0
        value = min(max(value, -1.0), 1.0)
        return 0.5 * (value + 1.0) * self._max_width

    def gripper_action(self, width: float) -> float:
        """Inverse of :meth:`gripper_width`: the action component that commands ``width`` (m)."""
        return min(max(2.0 * width / self._max_width - 1.0, -1.0), 1.0)
