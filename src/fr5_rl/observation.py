"""The observation vector: one builder shared by the environments and the ROS policy node.

It takes plain arrays (measured joint state, gripper state, tcp pose, object position, all in
``base_link``) and returns the normalised vector in [-1, 1]. The environments call it with
PyBullet's state; the policy node with ``/joint_states`` and the tf2-transformed target.

Layout (index: content, unit before normalisation, normalisation):

======  =====================================  ======  ==================================
index   content                                unit    mapped to [-1, 1] by
======  =====================================  ======  ==================================
0-5     joint positions j1..j6                 rad     FR5 lower/upper limits
6-11    joint velocities j1..j6                rad/s   FR5 velocity limits
12      gripper opening width (measured)       m       [0, max opening width]
13      gripper opening width (commanded)      m       [0, max opening width]
14-16   tcp position in base_link              m       observation.tcp_position_low/high
17-19   tcp approach axis (tcp z) in base_link unit    already in [-1, 1]
20-22   object centre minus tcp, base_link     m       / observation.relative_position_scale
23      object lift above its resting height   m       / observation.lift_scale (grasp only)
======  =====================================  ======  ==================================

The tcp orientation is the approach axis rather than the seed's Euler angles: with the
gripper pointing down, roll sits at +-pi and Euler angles jump there.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Optional

import numpy as np

from .config import RobotSpec

REACH_OBSERVATION_SIZE = 23
GRASP_OBSERVATION_SIZE = 24


@dataclass
class ObservationInputs:
    """Raw, un-normalised inputs of one observation (all in ``base_link``, SI units)."""

    joint_positions: np.ndarray  # (6,) rad, controller order
    joint_velocities: np.ndarray  # (6,) rad/s
    gripper_width: float  # m, measured pad-to-pad opening
    gripper_command_width: float  # m, last commanded opening
    tcp_position: np.ndarray  # (3,) m
    tcp_rotation: np.ndarray  # (3, 3) tcp orientation
    object_position: np.ndarray  # (3,) m, object centre
    object_lift: float = 0.0  # m above the resting height (grasp only)


class ObservationBuilder:
    """Normalises :class:`ObservationInputs` into the policy's observation vector.

    The raw values are laid out in one float64 vector and mapped with a single affine
    transform ``(raw - offset) * gain`` followed by clipping: the layout table above, as data.
    """

    def __init__(self, robot: RobotSpec, obs_cfg: Mapping[str, Any], include_lift: bool) -> None:
        self.include_lift = include_lift
        self.size = GRASP_OBSERVATION_SIZE if include_lift else REACH_OBSERVATION_SIZE
        low = np.asarray(obs_cfg["tcp_position_low"], dtype=np.float64)
        high = np.asarray(obs_cfg["tcp_position_high"], dtype=np.float64)
        half_width = robot.max_opening_width / 2.0
        offset = np.zeros(GRASP_OBSERVATION_SIZE)
        half_range = np.ones(GRASP_OBSERVATION_SIZE)
        offset[0:6] = (robot.upper_limits + robot.lower_limits) / 2.0
        half_range[0:6] = (robot.upper_limits - robot.lower_limits) / 2.0
        half_range[6:12] = robot.velocity_limits
        offset[12:14], half_range[12:14] = half_width, half_width
        offset[14:17], half_range[14:17] = (high + low) / 2.0, (high - low) / 2.0
        half_range[20:23] = float(obs_cfg["relative_position_scale"])
        half_range[23] = float(obs_cfg["lift_scale"])
        self._offset = offset[: self.size]
        self._gain = 1.0 / half_range[: self.size]
        self._raw = np.zeros(self.size)

    def build(self, inputs: ObservationInputs, out: Optional[np.ndarray] = None) -> np.ndarray:
        """Return the float32 observation in [-1, 1]; raises ValueError on non-finite input."""
        raw = self._raw
        raw[0:6] = inputs.joint_positions
        raw[6:12] = inputs.joint_velocities
        raw[12] = inputs.gripper_width
        raw[13] = inputs.gripper_command_width
        raw[14:17] = inputs.tcp_position
        raw[17:20] = np.asarray(inputs.tcp_rotation)[:, 2]
        raw[20:23] = inputs.object_position
        raw[20:23] -= raw[14:17]
        if self.include_lift:
            raw[23] = inputs.object_lift
        scaled = (raw - self._offset) * self._gain
        if not math.isfinite(scaled.sum()):  # a single NaN or inf makes the sum non-finite
            raise ValueError("observation inputs contain NaN or inf")
        obs = np.empty(self.size, dtype=np.float32) if out is None else out
        np.clip(scaled, -1.0, 1.0, out=scaled)
        obs[:] = scaled
        return obs
