"""From policy action to safe joint commands: the one scaling used in training and on the robot.

Action (7,) in [-1, 1]: six joint position increments, scaled by ``action.max_joint_step``
(rad per control step, checked at load time against the FR5 velocity limits), and one gripper
command mapped to an opening width in [0, max opening width] (m).
"""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from .config import RobotSpec

ACTION_SIZE = 7


class JointCommandShaper:
    """Scale, low-pass, rate-limit and clamp actions into joint position targets.

    Increments are applied to the *measured* joint positions, so a lagging or blocked arm
    never accumulates a runaway target. Every target it returns is finite, inside the FR5
    joint limits, and within ``velocity_limit * control_dt`` of the measured position.
    """

    def __init__(self, robot: RobotSpec, action_cfg: Mapping[str, Any], control_dt: float) -> None:
        self._max_step = float(action_cfg["max_joint_step"])
        self._alpha = float(action_cfg["smoothing_alpha"])
        self._step_limit = robot.velocity_limits * float(control_dt)
        self._lower, self._upper = robot.lower_limits, robot.upper_limits
        self._max_width = robot.max_opening_width
        self._filtered_step = np.zeros(len(robot.joint_names))

    def reset(self) -> None:
        """Forget the low-pass filter state (start of an episode, or after a hold)."""
        self._filtered_step[:] = 0.0

    def arm_targets(self, action: np.ndarray, measured_joint_positions: np.ndarray) -> np.ndarray:
        """Joint position targets (rad, controller order) for the next control period."""
        action = np.asarray(action, dtype=np.float64)
        measured = np.asarray(measured_joint_positions, dtype=np.float64)
        if action.shape != (ACTION_SIZE,) or measured.shape != self._lower.shape:
            raise ValueError(
                f"expected an action of shape ({ACTION_SIZE},) and {self._lower.shape[0]} joint "
                f"positions, got {action.shape} and {measured.shape}"
            )
        # One sum is finite exactly when every term is (overflowing input is refused too).
        if not math.isfinite(action.sum() + measured.sum()):
            raise ValueError("action or measured joint positions contain NaN or inf")
        step = np.minimum(action[:6], 1.0)
        np.maximum(step, -1.0, out=step)
        step *= self._alpha * self._max_step
        step += (1.0 - self._alpha) * self._filtered_step
        np.minimum(step, self._step_limit, out=step)
        np.maximum(step, -self._step_limit, out=step)
        targets = measured + step
        np.minimum(targets, self._upper, out=targets)
        np.maximum(targets, self._lower, out=targets)
        self._filtered_step = step
        return targets

    def gripper_width(self, action: np.ndarray) -> float:
        """Commanded opening width (m) from the action's last component (-1 closed, +1 open)."""
        value = float(action[ACTION_SIZE - 1])
        if not np.isfinite(value):
            raise ValueError("gripper action is NaN or inf")
        value = min(max(value, -1.0), 1.0)
        return 0.5 * (value + 1.0) * self._max_width

    def gripper_action(self, width: float) -> float:
        """Inverse of :meth:`gripper_width`: the action component that commands ``width`` (m)."""
        return float(np.clip(2.0 * width / self._max_width - 1.0, -1.0, 1.0))
