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
    """Normalises :class:`ObservationInputs` into the policy's observation vector."""

    def __init__(self, robot: RobotSpec, obs_cfg: Mapping[str, Any], include_lift: bool) -> None:
        self._joint_mid = (robot.upper_limits + robot.lower_limits) / 2.0
        self._joint_half_range = (robot.upper_limits - robot.lower_limits) / 2.0
        self._velocity_limits = robot.velocity_limits.copy()
        self._max_width = robot.max_opening_width
        low = np.asarray(obs_cfg["tcp_position_low"], dtype=np.float64)
        high = np.asarray(obs_cfg["tcp_position_high"], dtype=np.float64)
        self._tcp_mid, self._tcp_half_range = (high + low) / 2.0, (high - low) / 2.0
        self._relative_scale = float(obs_cfg["relative_position_scale"])
        self._lift_scale = float(obs_cfg["lift_scale"])
        self.include_lift = include_lift
        self.size = GRASP_OBSERVATION_SIZE if include_lift else REACH_OBSERVATION_SIZE

    def build(self, inputs: ObservationInputs, out: Optional[np.ndarray] = None) -> np.ndarray:
        """Return the float32 observation in [-1, 1]; raises ValueError on non-finite input."""
        obs = np.empty(self.size, dtype=np.float32) if out is None else out
        tcp_position = np.asarray(inputs.tcp_position)
        obs[0:6] = (inputs.joint_positions - self._joint_mid) / self._joint_half_range
        obs[6:12] = inputs.joint_velocities / self._velocity_limits
        obs[12] = 2.0 * inputs.gripper_width / self._max_width - 1.0
        obs[13] = 2.0 * inputs.gripper_command_width / self._max_width - 1.0
        obs[14:17] = (tcp_position - self._tcp_mid) / self._tcp_half_range
        obs[17:20] = np.asarray(inputs.tcp_rotation)[:, 2]
        obs[20:23] = (inputs.object_position - tcp_position) / self._relative_scale
        if self.include_lift:
            obs[23] = inputs.object_lift / self._lift_scale
        if not np.isfinite(obs).all():
            raise ValueError("observation inputs contain NaN or inf")
        np.minimum(np.maximum(obs, -1.0, out=obs), 1.0, out=obs)
        return obs
