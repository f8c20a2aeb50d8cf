"""From policy action to safe joint commands: the one scaling used in training and on the robot.

Action (7,) in [-1, 1]: six joint position increments, scaled by ``action.max_joint_step``
(rad per control step, checked at load time against the FR5 velocity limits), and one gripper
command mapped to an opening width in [0, max opening width] (m).
"""
from __future__ import annotations

import math
from typing import List, Sequence

import numpy as np

from .config import RobotSpec
from .env_config import ActionConfig

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

    def gripper_width(self, action: Sequence[float]) -> float:
        """Commanded opening width (m) from the action's last component (-1 closed, +1 open)."""
        value = float(action[ACTION_SIZE - 1])
        if not math.isfinite(value):
            raise ValueError("gripper action is NaN or inf")
        value = min(max(value, -1.0), 1.0)
        return 0.5 * (value + 1.0) * self._max_width

    def gripper_action(self, width: float) -> float:
        """Inverse of :meth:`gripper_width`: the action component that commands ``width`` (m)."""
        return min(max(2.0 * width / self._max_width - 1.0, -1.0), 1.0)
