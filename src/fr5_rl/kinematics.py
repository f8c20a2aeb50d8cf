"""Forward kinematics of the FR5 from its joint-origin table (``config/robot.yaml``).

The environments and the ROS policy node both compute the tcp pose with this code from
measured joint angles, so the observation cannot differ between training and deployment.
All poses are expressed in ``base_link``; positions in metres.
"""
from __future__ import annotations

from typing import Tuple

import numpy as np

from .config import RobotSpec


def rotation_from_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw (rad) to a 3x3 rotation: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


class ForwardKinematics:
    """Flange and tcp poses of the FR5 in ``base_link`` for given joint angles (rad)."""

    def __init__(self, robot: RobotSpec) -> None:
        self._origin_rotations = [rotation_from_rpy(*rpy) for rpy in robot.joint_origins_rpy]
        self._origin_translations = [np.asarray(xyz, dtype=np.float64) for xyz in robot.joint_origins_xyz]
        self._tcp_offset = float(robot.tcp_offset)

    def flange_pose(self, joint_positions: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Return (position (3,), rotation (3, 3)) of the flange (``wrist3_Link``) in base_link."""
        rotation = np.eye(3)
        position = np.zeros(3)
        for origin_rotation, origin_translation, angle in zip(
            self._origin_rotations, self._origin_translations, joint_positions
        ):
            position = position + rotation @ origin_translation
            c, s = np.cos(angle), np.sin(angle)
            # origin rotation followed by the joint's rotation about its local z axis
            joint_rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            rotation = rotation @ origin_rotation @ joint_rotation
        return position, rotation

    def joint_origins(self, joint_positions: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Origins of the joint frames j1 … j6 (rows, m, base_link; j6's is the flange) and the
        flange rotation: the points the arm's links run between."""
        rotation = np.eye(3)
        position = np.zeros(3)
        origins = []
        for origin_rotation, origin_translation, angle in zip(
            self._origin_rotations, self._origin_translations, joint_positions
        ):
            position = position + rotation @ origin_translation
            origins.append(position)
            c, s = np.cos(angle), np.sin(angle)
            rotation = rotation @ origin_rotation @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return np.array(origins), rotation

    def tcp_pose(self, joint_positions: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Return (position (3,), rotation (3, 3)) of the ``tcp`` frame in base_link.

        The tcp sits ``tcp_offset`` metres along the flange z axis with the flange's
        orientation, so its z axis is the gripper's approach direction.
        """
        position, rotation = self.flange_pose(joint_positions)
        return position + rotation[:, 2] * self._tcp_offset, rotation
