"""Reading a sensor_msgs/JointState-like message by joint name (no ROS import needed).

``/joint_states`` carries no order guarantee and may hold other joints too: every value is
looked up by name, and anything missing, mis-sized or non-finite is rejected with a reason.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Generic, Optional, Sequence, Tuple, TypeVar

import numpy as np

T = TypeVar("T")


@dataclass(frozen=True)
class Reading(Generic[T]):
    """The newest value of one input, or why it is unusable, with its arrival time.

    :param value: the value; None when ``problem`` is set.
    :param received: arrival time (s) on the caller's monotonic clock.
    :param problem: why the input is unusable (a parse or tf failure), else None.
    """

    value: Optional[T]
    received: float
    problem: Optional[str] = None


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


class JointStateReader:
    """Turns joint-state messages into :class:`Reading` s of :class:`ArmJointState`.

    A driver that publishes no velocities (some do not) gets them estimated from consecutive
    messages' positions and stamps.

    :param arm_joint_names: the arm's joints in controller order (``j1`` … ``j6``).
    :param finger_joint_names: the gripper's finger joints (their sum is the opening width).
    """

    def __init__(self, arm_joint_names: Sequence[str], finger_joint_names: Sequence[str]) -> None:
        self.arm_joint_names = tuple(arm_joint_names)
        self.finger_joint_names = tuple(finger_joint_names)
        self._previous: Optional[Tuple[np.ndarray, float]] = None  # positions, stamp (s)

    def read(self, names: Sequence[str], positions: Sequence[float], velocities: Sequence[float],
             stamp: float, received: float) -> Reading[ArmJointState]:
        """One message, as a reading.

        :param stamp: the message's header stamp (s); 0 when the driver leaves it empty.
        :param received: arrival time (s) on the caller's monotonic clock.
        """
        try:
            state = parse_joint_state(names, positions, velocities, self.arm_joint_names, self.finger_joint_names)
        except ValueError as error:
            return Reading(None, received, str(error))
        if state.velocities is None:
            stamp = stamp or received
            state.velocities = np.zeros(len(self.arm_joint_names))
            if self._previous is not None and stamp - self._previous[1] > 1e-4:
                state.velocities = (state.positions - self._previous[0]) / (stamp - self._previous[1])
            self._previous = (state.positions, stamp)
        return Reading(state, received)
