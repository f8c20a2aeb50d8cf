"""Reading a sensor_msgs/JointState-like message by joint name (no ROS import needed).

``/joint_states`` carries no order guarantee and may hold other joints too: every value is
looked up by name, and anything missing, mis-sized or non-finite is rejected with a reason.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np


@dataclass
class ArmJointState:
    """Arm state in controller order (rad, rad/s); gripper opening width (m) if reported."""

    positions: np.ndarray
    velocities: Optional[np.ndarray]
    gripper_width: Optional[float]


def parse_joint_state(names: Sequence[str], positions: Sequence[float], velocities: Sequence[float],
                      arm_joint_names: Sequence[str], finger_joint_names: Sequence[str]) -> ArmJointState:
    """Extract the arm (and finger) joints by name; raises ValueError saying what is wrong."""
    if len(positions) != len(names):
        raise ValueError(f"joint_states has {len(names)} names but {len(positions)} positions")
    index = {name: i for i, name in enumerate(names)}
    missing = [name for name in arm_joint_names if name not in index]
    if missing:
        unknown = [name for name in names if name not in arm_joint_names and name not in finger_joint_names]
        raise ValueError(f"joint_states lacks {missing}" + (f" (it has unknown joints {unknown[:8]})" if unknown else ""))
    arm = np.array([positions[index[name]] for name in arm_joint_names], dtype=np.float64)
    if not np.isfinite(arm).all():
        raise ValueError("joint_states positions contain NaN or inf")
    arm_velocities = None
    if len(velocities) == len(names):
        arm_velocities = np.array([velocities[index[name]] for name in arm_joint_names], dtype=np.float64)
        if not np.isfinite(arm_velocities).all():
            raise ValueError("joint_states velocities contain NaN or inf")
    width = None
    if all(name in index for name in finger_joint_names):
        width = float(sum(positions[index[name]] for name in finger_joint_names))
        if not np.isfinite(width):
            raise ValueError("joint_states finger positions contain NaN or inf")
    return ArmJointState(arm, arm_velocities, width)
